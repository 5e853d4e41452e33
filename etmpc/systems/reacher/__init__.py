"""Reacher: a two-link planar arm (``models/reacher.xml``; its MuJoCo plant in ``physics.py``) whose
fingertip chases a target that jumps at random times: the ``jumps`` task (``task.py``), the analytic
arm as the MPC's predictor (``model.py``), and the system the loop plays (``system.py``: a
Gauss-Newton MPC with the target as a parameter and a time-varying LQR along each plan), and
``jumps_late`` (``timing.py``), whose solves take a control interval.
"""

from etmpc.systems.registry import lazy

# Its tasks, the default first: what etmpc.systems lists without loading MuJoCo or dm-control (which
# pick their OpenGL backend on import). SYSTEMS and SUITE load the domain's modules when first asked.
TASKS = ("jumps", "jumps_late")
# The seed of each task's stored test set (tasks/reacher/<task>/testset.npz: etmpc testset --task TASK --seed SEED).
# jumps_late plays jumps' episodes (the same seed): its scores pair with jumps' episode by episode.
TEST_SET_SEEDS = {"jumps": 20261125, "jumps_late": 20261125}

__getattr__ = lazy(
    __name__,
    {"jumps": "etmpc.systems.reacher.system:ReacherSystem", "jumps_late": "etmpc.systems.reacher.timing:JumpsLateSystem"},
    "etmpc.systems.reacher.task:SUITE",
)
