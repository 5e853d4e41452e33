"""Reacher: a two-link planar arm (``models/reacher.xml``; its MuJoCo plant in ``physics.py``) whose
fingertip chases a target that jumps at random times: the ``jumps`` task (``task.py``), the analytic
arm as the MPC's predictor (``model.py``), and the system the loop plays (``system.py``: a
Gauss-Newton MPC with the target as a parameter and a time-varying LQR along each plan).
"""

# Its tasks, the default first: what etmpc.systems lists without loading MuJoCo or dm-control (which
# pick their OpenGL backend on import). SYSTEMS and SUITE load the domain's modules when first asked.
TASKS = ("jumps",)


def __getattr__(name: str):
    if name == "SYSTEMS":  # task -> the System class the loop plays
        from etmpc.systems.reacher.system import ReacherSystem

        return {"jumps": ReacherSystem}
    if name == "SUITE":  # the dm-control task factories, as a dm_control.suite domain has them
        from etmpc.systems.reacher.task import SUITE

        return SUITE
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
