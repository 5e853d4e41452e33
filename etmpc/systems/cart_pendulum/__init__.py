"""Cart pendulum: the MuJoCo plant (``physics.py``), the paper's analytic model as the MPC's predictor
(``model.py``), and two tasks: ``balance`` (the paper's: ``task.py``, and the system the loop plays,
``system.py``: the Gauss-Newton MPC and the LQR on the prediction error) and ``kicks`` (the pole
kicked at random times on a rail with bumpers: ``kicks.py``, ``kicks_system.py``). ``mismatch.py`` measures the model
against the plant; ``dompc.py`` solves the same OCP with do-mpc, the paper's stack, for ``etmpc bench``.
"""

# Its tasks, the default first: what etmpc.systems lists without loading MuJoCo or dm-control (which
# pick their OpenGL backend on import). SYSTEMS and SUITE load the domain's modules when first asked.
TASKS = ("balance", "kicks")


def __getattr__(name: str):
    if name == "SYSTEMS":  # task -> the System class the loop plays
        from etmpc.systems.cart_pendulum.kicks_system import KicksSystem
        from etmpc.systems.cart_pendulum.system import CartPendulumSystem

        return {"balance": CartPendulumSystem, "kicks": KicksSystem}
    if name == "SUITE":  # the dm-control task factories, as a dm_control.suite domain has them
        from etmpc.systems.cart_pendulum.kicks import SUITE  # balance's, with kicks added

        return SUITE
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
