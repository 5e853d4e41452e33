"""Fixed schedules: ``always`` (standard MPC), ``never`` (keep each plan to its end), ``every:T`` and,
on a task with compute levels, ``iterate:T`` (real-time iterations)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from etmpc.control.timing import ITERATE, KEEP
from etmpc.loop import AugmentedState


class _Schedule:
    """A fixed schedule decides from the plan's age alone: it never reads the observation."""

    observes: ClassVar[bool] = False


@dataclass(frozen=True)
class _Constant(_Schedule):
    """The same answer at every step: :attr:`answer` (True: recompute)."""

    spec: str
    stochastic: bool = False
    answer: ClassVar[bool] = False

    def decide(self, s: AugmentedState, rng: np.random.Generator | None) -> bool:
        return self.answer


@dataclass(frozen=True)
class Every(_Schedule):
    """Static schedule: recompute when the plan is ``period`` steps old."""

    period: int
    stochastic: bool = False

    @property
    def spec(self) -> str:
        return f"every:{self.period}"

    def decide(self, s: AugmentedState, rng: np.random.Generator | None) -> bool:
        return s.age >= self.period


@dataclass(frozen=True)
class Iterate(_Schedule):
    """Real-time iterations: one SQP iteration from the shifted plan when the plan is ``period`` steps
    old (a full solve only where the loop forces one). On a task with compute levels only."""

    period: int
    stochastic: bool = False

    @property
    def spec(self) -> str:
        return f"iterate:{self.period}"

    def decide(self, s: AugmentedState, rng: np.random.Generator | None) -> int:
        return ITERATE if s.age >= self.period else KEEP


@dataclass(frozen=True)
class Always(_Constant):
    """Standard MPC: recompute at every step."""

    spec: str = "always"
    answer: ClassVar[bool] = True


@dataclass(frozen=True)
class Never(_Constant):
    """Follow each plan to its end (a forced recompute every N steps)."""

    spec: str = "never"
