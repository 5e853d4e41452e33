"""The ``EnvSpec`` of a task's environment: gymnasium's own, whose ``max_episode_steps`` is the task's
episode length, read when first asked rather than when the environments are registered.

``import etmpc`` registers every task's environment and must load neither MuJoCo nor CasADi; a task's
episode length is declared once, where its dm-control factory joins its domain's suite (``add_task``),
which loads them. So ``gymnasium.spec(ID).max_episode_steps`` reads it from the task's System class
(:attr:`etmpc.systems.TaskSpec.system_class`) once per process and keeps the answer;
``gymnasium.make(ID)`` reads it to put its ``TimeLimit`` around the
environment, which ends each episode itself at that same step (:class:`etmpc.envs.gym.TriggerEnv`).

Setting ``max_episode_steps`` on the spec replaces the task's (``None``: no ``TimeLimit``), as on any
``EnvSpec``; ``gymnasium.make(ID, max_episode_steps=-1)`` leaves the wrapper out for one environment.
"""

from __future__ import annotations

from functools import cache

from gymnasium.envs.registration import EnvSpec

from etmpc.common.errors import EtmpcError


@cache
def episode_steps(task: str) -> int:
    """Task ``task``'s episode length: its System class's ``episode_steps``, as its suite entry declares it."""
    from etmpc.systems.base import system_type  # here: importing etmpc loads no CasADi (tests/envs)

    cls = system_type(task)
    steps = cls.episode_steps
    if isinstance(steps, bool) or not isinstance(steps, int) or steps < 1:
        raise EtmpcError(f"task {task}'s episode_steps is {steps!r}, not a whole number >= 1")
    return steps


class TaskEnvSpec(EnvSpec):
    """An ``EnvSpec`` whose ``max_episode_steps``, when none is given, is the episode length of the task
    its environment plays (``kwargs["task"]`` when registered), read when first asked."""

    _steps: int | None  # max_episode_steps as given (None: none given, or not read yet)
    _given: bool  # _steps holds the answer: given, or read off the task
    _task: str | None  # the task its environment plays (kwargs["task"])

    def __post_init__(self) -> None:
        super().__post_init__()
        # The task is kept apart from kwargs: gymnasium.make_vec empties a copy's kwargs before it makes each
        # environment from it (and reads max_episode_steps then).
        task = self.kwargs.get("task")
        self._task = task if isinstance(task, str) else None
        self._given = self.__dict__["_steps"] is not None or self._task is None

    @property
    def max_episode_steps(self) -> int | None:
        if not self._given:
            self._steps, self._given = episode_steps(self._task), True
        return self._steps

    @max_episode_steps.setter
    def max_episode_steps(self, steps: int | None) -> None:
        # EnvSpec's __init__ sets it (None when registered: __post_init__ then marks it as the task's to read)
        self._steps, self._given = steps, True
