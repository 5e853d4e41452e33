"""Cart pendulum: the MuJoCo plant (``task.py``: physics, episodes, the ``balance`` task), the paper's
analytic model as the MPC's predictor (``model.py``), and the system the loop plays (``system.py``:
the Gauss-Newton MPC and the LQR on the prediction error). ``mismatch.py`` measures the model
against the plant; ``dompc.py`` solves the same OCP with do-mpc, the paper's stack, for ``etmpc bench``.
"""

# Its tasks, the default first: what etmpc.systems lists without loading MuJoCo or dm-control (which
# pick their OpenGL backend on import). SYSTEMS and SUITE load the domain's modules when first asked.
TASKS = ("balance",)


def __getattr__(name: str):
    if name == "SYSTEMS":  # task -> the System class the loop plays
        from etmpc.systems.cart_pendulum.system import CartPendulumSystem

        return {"balance": CartPendulumSystem}
    if name == "SUITE":  # the dm-control task factories, as a dm_control.suite domain has them
        from etmpc.systems.cart_pendulum.task import SUITE

        return SUITE
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
