"""The etmpc tasks, loaded as ``dm_control.suite`` loads its own.

>>> env = load("cart_pendulum", "balance", task_kwargs={"random": 0})

The same conventions as ``dm_control.suite``: :data:`ALL_TASKS` (``(domain, task)`` pairs),
:data:`TASKS_BY_DOMAIN`, :data:`BENCHMARKING`, and :func:`load` with the same arguments and
meaning. ``task_kwargs`` go to the task's factory: ``random`` (an int seed, a
``np.random.Generator`` or a ``np.random.RandomState``; ``None`` draws fresh entropy),
``time_limit`` (seconds; a whole number of control intervals) and each task's own settings (the
cart pendulum's ``plant``). Unknown names raise ``ValueError`` as the suite does (the error is also
etmpc's :class:`~etmpc.common.errors.UnknownNameError`, so the CLI prints it as one line).
"""

from __future__ import annotations

from types import ModuleType

from etmpc.common.errors import UnknownNameError
from etmpc.systems import domains as _domains


class UnknownSuiteNameError(UnknownNameError, ValueError):
    """An unknown domain or task: ``ValueError``, as ``dm_control.suite.load`` raises."""


def domains() -> tuple[str, ...]:
    return tuple(_domains())


def _domain(name: str) -> ModuleType:
    if name not in _domains():
        raise UnknownSuiteNameError(f"unknown domain {name!r}; valid: {', '.join(_domains())}")
    return _domains()[name]


def tasks(domain_name: str) -> tuple[str, ...]:
    return tuple(_domain(domain_name).SUITE)


def _tagged(tag: str) -> tuple[tuple[str, str], ...]:
    return tuple((d, t) for d in _domains() for t in _domain(d).SUITE.tagged(tag))


ALL_TASKS: tuple[tuple[str, str], ...] = tuple((d, t) for d in _domains() for t in _domain(d).SUITE)
TASKS_BY_DOMAIN: dict[str, tuple[str, ...]] = {d: tasks(d) for d in _domains()}
BENCHMARKING: tuple[tuple[str, str], ...] = _tagged("benchmarking")


def load(
    domain_name: str,
    task_name: str,
    task_kwargs: dict | None = None,
    environment_kwargs: dict | None = None,
    visualize_reward: bool = False,
):
    """Build ``domain_name/task_name`` (a ``dm_control.rl.control.Environment``).

    ``task_kwargs`` go to the task factory (``random``, ``time_limit``, ...); ``environment_kwargs``
    to ``control.Environment`` (``flat_observation``, ``n_sub_steps``, ...); ``visualize_reward``
    colours what a renderer shows by the reward, as in the suite.
    """
    suite = _domain(domain_name).SUITE
    if task_name not in suite:
        raise UnknownSuiteNameError(f"unknown task {task_name!r} for domain {domain_name!r}; valid: {', '.join(suite)}")
    kwargs = dict(task_kwargs or {})
    if environment_kwargs is not None:
        kwargs["environment_kwargs"] = environment_kwargs
    env = suite[task_name](**kwargs)
    env.task.visualize_reward = visualize_reward
    return env
