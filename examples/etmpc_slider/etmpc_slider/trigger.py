"""A policy kind of this package's: ``driftage:X:T``, recompute when the weighted prediction error
``||W (x - x_hat)||`` exceeds ``X`` or the plan is ``T`` steps old.

``threshold:X`` with a deadline: the event trigger catches a plan that drifts from the plant, the
age catches what the state cannot show (a reference that jumped). ``W`` is the task's
``error_weights`` (the slider's: ``sqrt(Q)`` of its LQR, so 0.5 is 5 cm of position error). It works
on every task; announced by this package's ``etmpc.policies`` entry point
(``driftage = "etmpc_slider.trigger:KIND"``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from etmpc.common.errors import EtmpcError
from etmpc.common.numerics import norm
from etmpc.loop import AugmentedState
from etmpc.policies.specs import Kind


@dataclass(frozen=True)
class DriftOrAge:
    """Recompute when ``|W (x_i - x_hat_i)|_2 > level`` or the plan is ``max_age`` steps old."""

    level: float
    max_age: int
    weights: np.ndarray  # the diagonal of W
    stochastic: bool = False
    observes: ClassVar[bool] = False  # decides from the states alone (the loop's fast path skips the observation)

    @property
    def spec(self) -> str:
        return f"driftage:{self.level:g}:{self.max_age}"

    def decide(self, s: AugmentedState, rng: np.random.Generator) -> bool:
        return s.age >= self.max_age or norm(self.weights * (s.x - s.x_predicted)) > self.level


def build(arg: str, spec: str, system) -> DriftOrAge:
    """``driftage:X:T`` from its argument ``"X:T"`` (X a finite number >= 0, T a whole number >= 1);
    ``system`` is anything with ``error_weights`` (a system, or the policy registry's context). Bad
    input raises :class:`EtmpcError` with a one-line message."""
    level_text, colon, age_text = arg.partition(":")
    if not colon or ":" in age_text:
        raise EtmpcError(f"bad policy {spec!r}: write driftage:X:T (X the error level, T the plan's largest age)")
    try:
        if level_text != level_text.strip():  # float(" 1") is 1, but "driftage: 1:4" is not how a spec is written
            raise ValueError
        level = float(level_text)
    except ValueError:
        raise EtmpcError(f"bad policy {spec!r}: {level_text!r} is not a number") from None
    if not (math.isfinite(level) and level >= 0):
        raise EtmpcError(f"bad policy {spec!r}: the error level must be a finite number >= 0")
    if not (age_text.isdigit() and age_text.isascii() and int(age_text) >= 1):
        raise EtmpcError(f"bad policy {spec!r}: the age must be a whole number of steps >= 1, got {age_text!r}")
    return DriftOrAge(level, int(age_text), np.asarray(system.error_weights, dtype=float))


# What etmpc's registry of policy kinds reads (this package's entry point: driftage = "etmpc_slider.trigger:KIND").
KIND = Kind(
    "driftage",
    "driftage:X:T",
    "recompute when the weighted prediction error exceeds X or the plan is T steps old",
    build,
    family="event",
)
