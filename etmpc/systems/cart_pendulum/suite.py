"""The cart pendulum's tasks as ``dm_control.suite`` names a domain's: ``SUITE``, their factories,
tagged, each added here by name (``balance`` from ``task.py``, ``kicks`` from ``kicks.py``), so that
importing one task's module registers nothing."""

from dm_control.utils import containers

from etmpc.systems.cart_pendulum import kicks, task
from etmpc.systems.episodes import add_task

SUITE = containers.TaggedTasks()
add_task(
    SUITE,
    "balance",
    task.make_environment,
    task.EPISODE_STEPS,
    task.CONTROL_DT_S,
    "Balance the pole under the angular disturbance: 100 control intervals of 0.1 s by default (plant=...).",
    episode=task.Episode,
)
add_task(
    SUITE,
    "kicks",
    kicks.make_environment,
    kicks.EPISODE_STEPS,
    kicks.CONTROL_DT_S,
    "Keep the pole up on a 5 m rail through random kicks: 150 control intervals of 0.1 s by default (plant=...).",
    episode=kicks.KickEpisode,
)
for name, what in (
    ("kicks_late", "solves take one control interval"),
    ("kicks_levels", "compute levels and solves that take time"),
):
    add_task(
        SUITE,
        name,
        kicks.make_environment,
        kicks.EPISODE_STEPS,
        kicks.CONTROL_DT_S,
        f"The kicks world, for the task whose {what} (they are the controller's).",
        tags=("benchmarking", "timing"),
        episode=kicks.KickEpisode,
    )
add_task(
    SUITE,
    "kicks_noisy",
    kicks.make_environment,
    kicks.EPISODE_STEPS,
    kicks.CONTROL_DT_S,
    "The kicks world, for the task whose controller reads two of its four states, with noise, through a Kalman filter.",
    tags=("benchmarking", "sensing"),
    episode=kicks.KickEpisode,
)
