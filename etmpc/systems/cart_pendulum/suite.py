"""The cart pendulum's tasks as ``dm_control.suite`` names a domain's: ``SUITE``, their factories,
tagged, each added here by name (``balance`` from ``task.py``, ``kicks`` from ``kicks.py``), so that
importing one task's module registers nothing."""

from dm_control.utils import containers

from etmpc.systems.cart_pendulum.kicks import Kicks
from etmpc.systems.cart_pendulum.task import Balance
from etmpc.systems.tracking import add_tracking_task

SUITE = containers.TaggedTasks()
add_tracking_task(
    SUITE,
    "balance",
    Balance,
    "Balance the pole under the angular disturbance: 100 control intervals of 0.1 s by default (plant=...).",
)
add_tracking_task(
    SUITE,
    "kicks",
    Kicks,
    "Keep the pole up on a 5 m rail through random kicks: 150 control intervals of 0.1 s by default (plant=...).",
)
for name, what in (
    ("kicks_late", "solves take one control interval"),
    ("kicks_levels", "compute levels and solves that take time"),
):
    add_tracking_task(
        SUITE,
        name,
        Kicks,
        f"The kicks world, for the task whose {what} (they are the controller's).",
        tags=("benchmarking", "timing"),
    )
add_tracking_task(
    SUITE,
    "kicks_noisy",
    Kicks,
    "The kicks world, for the task whose controller reads two of its four states, with noise, through a Kalman filter.",
    tags=("benchmarking", "sensing"),
)
