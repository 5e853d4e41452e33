"""What the tasks of every domain share: one owner of randomness, and stored episodes replayed exactly."""

from __future__ import annotations

from typing import Any

import numpy as np
from dm_control.rl import control


class EpisodeTask(control.Task):
    """A dm-control task whose episodes are drawn in advance, whole.

    Randomness has one owner: the task's ``random`` generator draws each episode on reset
    (:meth:`draw_episode`), unless :meth:`use_episode` has queued a stored one (a test-set episode),
    which is then replayed exactly.
    """

    def __init__(self, random: np.random.Generator | int | None = None):
        self._random = random if isinstance(random, np.random.Generator) else np.random.default_rng(random)
        self._queued: Any = None
        self._episode: Any = None

    @property
    def random(self) -> np.random.Generator:
        return self._random

    @property
    def episode(self) -> Any:
        """The episode being played (drawn or stored)."""
        return self._episode

    def use_episode(self, episode: Any) -> None:
        """Play ``episode`` at the next reset (``None``: draw from ``random`` again)."""
        if episode is not None:
            self.check_episode(episode)
        self._queued = episode

    def next_episode(self) -> Any:
        """The queued episode, or a new one drawn from ``random``; becomes :attr:`episode`."""
        episode, self._queued = self._queued, None
        self._episode = episode if episode is not None else self.draw_episode(self._random)
        return self._episode

    def resume(self, episode: Any, step: int) -> None:
        """Continue ``episode`` from ``step`` (the next ``before_step`` applies step ``step``'s
        exogenous values): how a rollout puts the task back where a snapshot was taken, possibly
        with another future. The episode is not checked: it comes from this task or its sampler."""
        self._episode, self._step = episode, step

    def check_episode(self, episode: Any) -> None:
        """Raise ``ValueError`` if ``episode`` cannot be played by this task."""

    def draw_episode(self, random: np.random.Generator) -> Any:
        raise NotImplementedError
