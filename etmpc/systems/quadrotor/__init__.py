"""Quadrotor: a nano quadrotor (``models/quadrotor.xml``; its MuJoCo plant in ``physics.py``) held on a
waypoint that changes at random times while gusts push it, inside a geofence: the ``waypoints`` task
(``task.py``), the analytic rigid body as the MPC's predictor (``model.py``), and the system the loop
plays (``system.py``: a Gauss-Newton MPC with the waypoint as a parameter and a time-varying LQR
along each plan), and the same task seen through noisy sensors and a Kalman filter (``noisy.py``:
``waypoints_noisy``).
"""

from etmpc.systems.registry import lazy

# Its tasks, the default first: what etmpc.systems lists without loading MuJoCo or dm-control (which
# pick their OpenGL backend on import). SYSTEMS and SUITE load the domain's modules when first asked.
TASKS = ("waypoints", "waypoints_noisy")
# The seed of each task's stored test set (tasks/quadrotor/<task>/testset.npz: etmpc testset --task TASK --seed SEED).
# waypoints_noisy plays waypoints' episodes (the same seed): their scores pair episode by episode.
TEST_SET_SEEDS = {"waypoints": 20261127, "waypoints_noisy": 20261127}
# Version 1: the MPC flies the condensed route (etmpc.control.condensed) instead of sqpmethod; version 2: at
# most 10 of its QPs, and the plant's arithmetic the same on any CPU with FMA. waypoints_noisy's version 1: its
# state estimator's algebra is CasADi's, run as C, instead of NumPy's on BLAS and LAPACK (docs/versioning.md).
VERSIONS = {"waypoints": 2, "waypoints_noisy": 1}

__getattr__ = lazy(
    __name__,
    {
        "waypoints": "etmpc.systems.quadrotor.system:QuadrotorSystem",
        "waypoints_noisy": "etmpc.systems.quadrotor.noisy:WaypointsNoisySystem",
    },
    "etmpc.systems.quadrotor.task:SUITE",
)
