"""The classic event trigger ``threshold:X``: recompute when the weighted prediction error exceeds ``X``; on a
task with compute levels, ``threshold:X:iterate`` makes one SQP iteration from the shifted plan there instead
of a full solve (an event-triggered real-time iteration: the answer that arrives soonest)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from etmpc.common.numerics import norm
from etmpc.control.timing import ITERATE, KEEP
from etmpc.loop import AugmentedState, Decision


@dataclass(frozen=True)
class Threshold:
    """Event trigger: recompute when ``|W (x_i - x_hat_i)|_2 > X``.

    ``weights`` is the diagonal of ``W``, chosen per task (for the cart pendulum the square root
    of the LQR's state weights, so the norm is the LQR's own measure of the error).
    """

    level: float
    weights: np.ndarray
    stochastic: bool = False
    iterate: bool = False  # on a task with compute levels: one SQP iteration, not a full solve
    reads: bool = False  # the error on this step's readings, not on the filter's estimate
    observes: ClassVar[bool] = False

    @property
    def spec(self) -> str:
        return f"threshold:{self.level:g}" + (":iterate" if self.iterate else "") + (":reading" if self.reads else "")

    def decide(self, s: AugmentedState, rng: np.random.Generator | None) -> Decision:
        if self.reads and s.belief is not None:
            read = ~np.isnan(s.belief.reading)
            error = self.weights[read] * (s.belief.reading[read] - s.x_predicted[read])
        else:
            error = self.weights * (s.x - s.x_predicted)
        fired = norm(error) > self.level
        if self.iterate:
            return ITERATE if fired else KEEP
        return fired
