"""Fixed schedules: ``always`` (standard MPC), ``never`` (keep each plan to its end), ``every:T`` and,
on a task with compute levels, ``iterate:T[:K]`` (real-time iterations, up to ``K`` at a time)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from etmpc.control.timing import ITERATE, KEEP, Iterations
from etmpc.loop import AugmentedState, Decision


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
    old (a full solve only where the loop forces one), or up to ``count`` of them, stopping when they
    converge: the extra iterations of the advanced-step RTI (Frey, Nurkanovic and Diehl 2024), or a fixed
    iteration budget per solve. On a task with compute levels only."""

    period: int
    count: int = 1
    stochastic: bool = False

    @property
    def spec(self) -> str:
        return f"iterate:{self.period}" + (f":{self.count}" if self.count > 1 else "")

    def decide(self, s: AugmentedState, rng: np.random.Generator | None) -> Decision:
        if s.age < self.period:
            return KEEP
        return ITERATE if self.count == 1 else Iterations(self.count)


@dataclass(frozen=True)
class Always(_Constant):
    """Standard MPC: recompute at every step."""

    spec: str = "always"
    answer: ClassVar[bool] = True


@dataclass(frozen=True)
class Never(_Constant):
    """Follow each plan to its end (a forced recompute every N steps)."""

    spec: str = "never"
