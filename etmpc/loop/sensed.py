"""What the controller sees of the plant (:mod:`etmpc.control.sensing`): :class:`Sensed`, which
:class:`~etmpc.loop.closed.ClosedLoop` holds and asks after each interval.

The loop's ``x`` is always the plant's state (recorded, rewarded, judged for failures); what the controller
reads of it, :attr:`Sensed.seen`, is ``x`` itself with an exact sensor, else the filter's estimate
(:attr:`Sensed.belief`'s mean) after this step's reading. The MPC plans from it, the feedback corrects
from it, and the policy is shown it.
"""

from __future__ import annotations

from typing import Any

import dm_env
import numpy as np

from etmpc.systems.base import System


class Sensed:
    """The sensor and the filter of one loop on ``system`` in ``env``, and what they make of the state.

    :attr:`seen` is what the controller reads of the state now; :attr:`belief` the filter's
    :class:`~etmpc.control.sensing.Belief` (None with an exact sensor); :attr:`reading` the last step's
    reading ``y``. The episode's draws of the sensor's noise are made when first read."""

    __slots__ = ("system", "env", "sensor", "estimator", "belief", "seen", "reading", "_readings")

    def __init__(self, system: System, env: dm_env.Environment):
        self.system = system
        self.env = env
        self.sensor = system.sensor
        self.estimator = system.estimator
        self.belief: Any = None
        self.seen: np.ndarray | None = None
        self.reading: np.ndarray | None = None
        self._readings: Any = None

    @property
    def exact(self) -> bool:
        """The controller reads the state itself (no filter)."""
        return self.estimator is None

    def new_episode(self) -> None:
        """An episode starts: its readings are drawn again when first read."""
        self._readings = None

    def resume(self, belief: Any, seen: np.ndarray) -> None:
        """Continue a snapshot's ``belief`` and ``seen`` (on the episode the loop then plays)."""
        self.belief = belief
        self.seen = seen
        self._readings = None

    def sense(self, x: np.ndarray, u: np.ndarray | None, step: int) -> bool:
        """See the plant's state ``x`` at ``step``: with an exact sensor, or a plant that failed (nothing to
        read), ``x`` itself (False); else this step's reading, filtered after the interval under ``u`` (None:
        the filter starts again, at the episode's start or after the task put the plant back) (True)."""
        if self.estimator is None or not np.isfinite(x).all():
            self.seen = x
            return False
        if self._readings is None:  # the episode's draws (those of the episode a light loop plays on)
            self._readings = self.sensor.readings(self.env.task.episode, self.system.episode_steps, x.shape[0])
        y, read = self.sensor.read(np.array(x), self._readings, step)
        self.belief = self.estimator.start(y, read) if u is None else self.estimator.step(self.belief, u, y, read)
        self.seen = self.belief.mean
        self.reading = y
        return True
