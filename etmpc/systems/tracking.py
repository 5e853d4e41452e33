"""The base of the tasks played on a MuJoCo plant whose episodes are drawn whole with their disturbances: the
quadrotor's ``waypoints``, the reacher's ``jumps``, the cart pendulum's ``balance`` and ``kicks``. Each keeps a
reference (a waypoint, a target, a cart reference; upright for ``balance``) against what its world draws.

A task names its pieces as class attributes, and :class:`TrackingTask` does the rest the same way for all:

* ``episode_class`` and ``disturbances_class``: its ``Episode`` (``draw(rng, steps, disturbances)``) and the
  ``Disturbances`` options it is drawn with; ``intervals``: the episode's field with a row per interval, and
  those rows in words (an episode too short for the task is refused, naming them);
* ``observation_names`` (the observation is one float per name) and ``action_name`` (the action is one
  float per actuator, within its ``ctrlrange``);
* ``interval_s``, ``episode_steps`` and :meth:`TrackingTask.make_physics`: from which
  :meth:`TrackingTask.environment` builds the dm-control environment (a domain's ``make_environment``), and
  :func:`add_tracking_task` adds the task to its domain's suite.

This module may import ``etmpc.common`` and the modules of ``etmpc.systems`` beside it, never a domain.
"""

from __future__ import annotations

import collections
from typing import Any, ClassVar

import numpy as np
from dm_control.rl import control
from dm_env import specs

from etmpc.systems.episodes import EpisodeTask, Random, add_task, build_environment


class TrackingTask(EpisodeTask):
    """A task whose episode (its initial state and its world's exogenous signals) is drawn in advance with
    its ``Disturbances``, played on a MuJoCo plant (see the module's docstring for what a subclass names)."""

    episode_class: ClassVar[Any]  # the task's Episode: draw(rng, steps, disturbances)
    disturbances_class: ClassVar[Any]  # its Disturbances (the options of how episodes are drawn and played)
    intervals: ClassVar[tuple[str, str]]  # the Episode's field with a row per interval, and its rows in words
    observation_names: ClassVar[tuple[str, ...]]
    action_name: ClassVar[str]
    interval_s: ClassVar[float]  # the control interval
    episode_steps: ClassVar[int]  # an episode's intervals, unless the environment is asked for another length

    def __init__(self, random: Random = None, steps: int | None = None, disturbances: Any = None):
        super().__init__(random)
        self.disturbances = self.disturbances_class() if disturbances is None else disturbances
        self._steps = self.episode_steps if steps is None else steps
        self._step = 0

    @staticmethod
    def make_physics(plant: str) -> Any:
        """The task's MuJoCo physics at plant setting ``plant`` (``mismatched``, ``matched``)."""
        raise NotImplementedError

    @classmethod
    def environment(
        cls,
        random: Random = None,
        plant: str = "mismatched",
        steps: int | None = None,
        environment_kwargs: dict | None = None,
        disturbances: Any = None,
    ) -> control.Environment:
        """The task's dm-control environment on ``plant``: ``steps`` intervals of ``interval_s``
        (``episode_steps`` by default), drawn from ``random`` with ``disturbances`` (the task's by default),
        then the user's other ``environment_kwargs`` (:func:`~etmpc.systems.episodes.build_environment`)."""
        steps = cls.episode_steps if steps is None else steps
        physics = cls.make_physics(plant)
        task = cls(random=random, steps=steps, disturbances=disturbances)
        return build_environment(physics, task, steps, cls.interval_s, environment_kwargs)

    def check_episode(self, episode: Any) -> None:
        field, rows = self.intervals
        have = getattr(episode, field).shape[0]
        if have < self._steps:
            raise ValueError(f"episode has {have} {rows}, need {self._steps}")

    def draw_episode(self, random: np.random.Generator) -> Any:
        return self.episode_class.draw(random, self._steps, self.disturbances)

    def current(self, field: str) -> Any:
        """The episode's ``field`` in the interval about to be played (the last one's once the episode is over)."""
        values = getattr(self._episode, field)
        return values[min(self._step, values.shape[0] - 1)]

    def action_spec(self, physics: Any) -> specs.BoundedArray:
        low, high = physics.model.actuator_ctrlrange.T
        return specs.BoundedArray(low.shape, np.float64, low, high, name=self.action_name)

    def observation_spec(self, physics: Any) -> collections.OrderedDict:
        return collections.OrderedDict((name, specs.Array((), np.float64, name=name)) for name in self.observation_names)

    def get_observation(self, physics: Any) -> collections.OrderedDict:
        return collections.OrderedDict(zip(self.observation_names, self.observation_values(physics)))

    def observation_values(self, physics: Any) -> np.ndarray:
        """The observation's values, in the order of ``observation_names``: the plant's state, unless the task
        observes more (its reference, where it has one)."""
        return physics.state()


def add_tracking_task(suite: Any, name: str, task: type[TrackingTask], summary: str, tags: tuple[str, ...] = ("benchmarking",)):
    """Add ``name`` to ``suite``, played by ``task`` (:func:`~etmpc.systems.episodes.add_task`): its environment,
    its episode's length and interval and its ``Episode`` are the task class's own."""
    return add_task(suite, name, task.environment, task.episode_steps, task.interval_s, summary, tags, task.episode_class)


def initial_state_range(low: np.ndarray, high: np.ndarray) -> dict[str, list[float]]:
    """An episode's drawn initial state's range ``U(low, high)``, as a task's ``episode_parameters`` record it."""
    return {"initial_state_low": low.tolist(), "initial_state_high": high.tolist()}
