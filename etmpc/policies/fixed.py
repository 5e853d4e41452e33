"""Fixed schedules: ``always`` (standard MPC), ``never`` (keep each plan to its end) and ``every:T``."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from etmpc.loop import AugmentedState


@dataclass(frozen=True)
class Always:
    """Standard MPC: recompute at every step."""

    spec: str = "always"
    stochastic: bool = False
    observes: ClassVar[bool] = False

    def decide(self, s: AugmentedState, rng: np.random.Generator) -> bool:
        return True


@dataclass(frozen=True)
class Never:
    """Follow each plan to its end (a forced recompute every N steps)."""

    spec: str = "never"
    stochastic: bool = False
    observes: ClassVar[bool] = False

    def decide(self, s: AugmentedState, rng: np.random.Generator) -> bool:
        return False


@dataclass(frozen=True)
class Every:
    """Static schedule: recompute when the plan is ``period`` steps old."""

    period: int
    stochastic: bool = False
    observes: ClassVar[bool] = False

    @property
    def spec(self) -> str:
        return f"every:{self.period}"

    def decide(self, s: AugmentedState, rng: np.random.Generator) -> bool:
        return s.age >= self.period
