"""Cart pendulum: the MuJoCo plant (``physics.py``), the paper's analytic model as the MPC's predictor
(``model.py``), and its tasks: ``balance`` (the paper's: ``task.py``, and the system the loop plays,
``system.py``: the Gauss-Newton MPC and the LQR on the prediction error) and ``kicks`` (the pole
kicked at random times on a rail with bumpers: ``kicks.py``, ``kicks_system.py``), and kicks with time in
the loop (``timing.py``: ``kicks_late``, whose solves take an interval, and ``kicks_levels``, whose
policy chooses how much to compute), and kicks seen through noisy sensors and a Kalman filter
(``noisy.py``: ``kicks_noisy``). ``mismatch.py`` measures the model
against the plant; ``dompc.py`` solves the same OCP with do-mpc, the paper's stack, for ``etmpc bench``.
"""

from etmpc.systems.registry import lazy

# Its tasks, the default first: what etmpc.systems lists without loading MuJoCo or dm-control (which
# pick their OpenGL backend on import). SYSTEMS and SUITE load the domain's modules when first asked.
TASKS = ("balance", "kicks", "kicks_late", "kicks_levels", "kicks_noisy")
# The seed of each task's stored test set (tasks/cart_pendulum/<task>/testset.npz: etmpc testset --task TASK --seed SEED).
# The timing and noisy variants play kicks' episodes (the same seed): their scores pair with kicks' episode by episode.
TEST_SET_SEEDS = {
    "balance": 20210601,
    "kicks": 20261126,
    "kicks_late": 20261126,
    "kicks_levels": 20261126,
    "kicks_noisy": 20261126,
}

# Version 1 of kicks_noisy: its state estimator's algebra is CasADi's, run as C, instead of NumPy's on BLAS and
# LAPACK: the same on any CPU (docs/versioning.md).
VERSIONS = {"kicks_noisy": 1}

__getattr__ = lazy(
    __name__,
    {
        "balance": "etmpc.systems.cart_pendulum.system:CartPendulumSystem",
        "kicks": "etmpc.systems.cart_pendulum.kicks_system:KicksSystem",
        "kicks_late": "etmpc.systems.cart_pendulum.timing:KicksLateSystem",
        "kicks_levels": "etmpc.systems.cart_pendulum.timing:KicksLevelsSystem",
        "kicks_noisy": "etmpc.systems.cart_pendulum.noisy:KicksNoisySystem",
    },
    "etmpc.systems.cart_pendulum.suite:SUITE",
)
