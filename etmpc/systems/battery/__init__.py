"""Battery storage trading: a plain-numpy plant under dm-control (``task.py``), prices, production and
forecasts drawn by ``market.py`` from the numbers in ``parameters.py``, the economic MPC as a linear
program (``mpc.py``, checked against ``reference.py``), and the system the loop plays (``system.py``).
"""

from etmpc.systems.registry import lazy

# Its tasks, the default first: what etmpc.systems lists without loading MuJoCo or dm-control (which
# pick their OpenGL backend on import). SYSTEMS and SUITE load the domain's modules when first asked.
TASKS = ("trading",)
# The seed of each task's stored test set (tasks/battery/<task>/testset.npz: etmpc testset --task TASK --seed SEED).
TEST_SET_SEEDS = {"trading": 20210602}
# Each task's version, where it is not 0 (docs/versioning.md says what bumps it): 1 since its observation
# gained how today's forecasts revise the kept plan's (0b5a03e).
VERSIONS = {"trading": 1}

__getattr__ = lazy(__name__, {"trading": "etmpc.systems.battery.system:BatterySystem"}, "etmpc.systems.battery.task:SUITE")
