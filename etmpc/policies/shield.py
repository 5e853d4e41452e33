"""A shield around any policy: ``shield:BASE`` (the task's own rule) or ``shield:AGE[:MARGIN[:DEVIATION]]:BASE``.

Runtime assurance (a "shield", Alshiekh et al. 2018, "Safe reinforcement learning via shielding"): the
base policy decides, and the shield overrides a *keep* with a recompute when keeping is no longer safe
to trust to a learner:

* the kept plan is ``AGE`` steps old (a plan kept long on the way down is how a learner crashes a drone);
* the state's safety margin (the task's ``safety_margin``: radians before the pole falls, metres to the
  geofence or the ground, one control interval on at the current rate) is below ``MARGIN``;
* the state has left the kept plan's prediction by more than ``DEVIATION`` (``shield:AGE:MARGIN:DEVIATION``),
  measured as ``threshold:X`` measures it, ``|W (x_i - x_hat_i)|`` with the task's ``error_weights``: a plan
  the state no longer follows is one the feedback is correcting far from where it was linearised (the way a
  drone flips on a kept plan, before any margin to the ground has shrunk).

It never turns a recompute into a keep, so the shielded policy computes at least as often as its base,
and the base is asked at every decision (its own draws stay the ones it makes unshielded). On a task with
compute levels the forced answer is one SQP iteration from the shifted plan (the real-time iteration,
the answer that arrives soonest); elsewhere a solve.

Why a shield and not a failure cost in learning: it holds for every policy (PPO's, DPI's, a user's) and
every version of it without training again, and its two numbers are read in the task's own units. A task
that offers a margin may declare its own rule (:class:`etmpc.systems.capabilities.ShieldRule`), chosen on
training-distribution episodes (``etmpc study shields``), never the test set; ``shield:BASE`` plays it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from etmpc.common.numerics import norm
from etmpc.control.timing import ITERATE
from etmpc.loop import AugmentedState, Decision, Policy, observes, simulates
from etmpc.systems.capabilities import ShieldRule


@dataclass(eq=False)
class Shield:
    """``base`` under a shield: compute when the plan is ``max_age`` steps old, when the margin of the state
    (``margin_of(x)``) is below ``margin`` (``None``: by age alone), or when ``|weights (x - x_hat)|`` is above
    ``deviation`` (``None``: not read)."""

    base: Policy
    max_age: int
    margin: float | None = None
    margin_of: Callable[[np.ndarray], float] | None = None  # the task's safety_margin; needed when margin is set
    levels: bool = False  # the task's decisions are compute levels: force one SQP iteration
    deviation: float | None = None
    weights: np.ndarray | None = None  # the task's error_weights (W); needed when deviation is set

    def __post_init__(self):
        rule = ShieldRule(self.max_age, self.margin, self.deviation)  # the rule, checked
        self.spec = f"shield:{rule.text}:{self.base.spec}"
        self.stochastic = self.base.stochastic
        self.simulates = simulates(self.base)
        self.observes = observes(self.base)
        self.overrides = 0  # decisions the shield turned from a keep into a recompute

    def unsafe(self, s: AugmentedState) -> bool:
        """Whether keeping is not left to the base at ``s``."""
        if s.age >= self.max_age:
            return True
        if self.margin is None:
            return False
        assert self.margin_of is not None  # given with a margin (shield: refuses a margin on a task without one)
        if float(self.margin_of(np.asarray(s.x))) < self.margin:
            return True
        if self.deviation is None:
            return False
        assert self.weights is not None  # given with a deviation (shield: passes the task's error_weights)
        return norm(self.weights * (np.asarray(s.x) - np.asarray(s.x_predicted))) > self.deviation

    def decide(self, s: AugmentedState, rng: np.random.Generator | None) -> Decision:
        choice = self.base.decide(s, rng)
        if not choice and self.unsafe(s):  # a keep (False, or the level KEEP = 0) where keeping is not safe
            self.overrides += 1
            return ITERATE if self.levels else True
        return choice
