"""Recomputation policies: given the augmented state ``s``, decide whether to solve a new plan.

The augmented state (paper, section 2.2) is ``s = [x_i, x_k, i - k]``: the current state, the state
the plan was made from, and the plan's age. The plan's prediction ``x_hat_i`` is a function of
``s`` and is handed along for the event trigger. When the plan runs out (age = N) the control loop
forces a recompute whatever the policy says.

Specs (``parse_policy``): ``always``, ``never``, ``every:T`` (T >= 1), ``threshold:X`` (X >= 0),
``rl:PATH`` (a learned policy saved by ``etmpc train``, see :mod:`etmpc.policies.learned`), ``self:PATH`` (a
self-triggering policy, see :mod:`etmpc.policies.selftrigger`), and the policies
that simulate futures (see :mod:`etmpc.policies.rollout`): ``rollout:BASE[:K[:H]]`` and the upper bound
``oracle:BASE``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from collections.abc import Mapping
from typing import Any, ClassVar, Protocol

import numpy as np

from etmpc.common.errors import EtmpcError, UnknownNameError
from etmpc.common.numerics import norm


@dataclass(frozen=True)
class AugmentedState:
    x: np.ndarray  # x_i, measured now
    x_plan: np.ndarray  # x_k, measured when the plan was made
    age: int  # i - k
    x_predicted: np.ndarray  # x_hat_i, the plan's prediction for now
    plan: Any = None  # the kept Plan (its inputs and the forecasts it was made with)
    observation: Mapping | None = None  # what the task shows now (for the exogenous features)
    context: Any = None  # etmpc.loop.DecisionContext: the loop's whole state, for policies that simulate


class Policy(Protocol):
    spec: str
    stochastic: bool
    # Optional ``observes = False``: decide never reads ``s.observation`` (the fast path of
    # etmpc.loop.play_on then skips making it). Without the attribute, a policy is assumed to read it.

    def decide(self, s: AugmentedState, rng: np.random.Generator) -> bool: ...


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


@dataclass(frozen=True)
class Threshold:
    """Event trigger: recompute when ``|W (x_i - x_hat_i)|_2 > X``.

    ``weights`` is the diagonal of ``W``, chosen per system (for the cart pendulum the square root
    of the LQR's state weights, so the norm is the LQR's own measure of the error).
    """

    level: float
    weights: np.ndarray
    stochastic: bool = False
    observes: ClassVar[bool] = False

    @property
    def spec(self) -> str:
        return f"threshold:{self.level:g}"

    def decide(self, s: AugmentedState, rng: np.random.Generator) -> bool:
        return norm(self.weights * (s.x - s.x_predicted)) > self.level


def _number(text: str, kind: type, spec: str):
    try:
        value = kind(text)
    except ValueError:
        raise EtmpcError(f"bad policy {spec!r}: {text!r} is not a{'n integer' if kind is int else ' number'}") from None
    return value


def parse_policy(spec: str, error_weights: np.ndarray, domain: str | None = None, steps: int = 100) -> Policy:
    """Build a policy from its command-line spec; bad specs raise :class:`EtmpcError`.

    ``rl:PATH`` is checked against ``domain`` and the state size ``len(error_weights)``; ``steps``
    (the episode length) bounds a rollout's look-ahead.
    """
    name, _, arg = spec.partition(":")
    if name in ("rollout", "oracle"):
        from etmpc.policies.rollout import parse_rollout

        return parse_rollout(spec, lambda base: parse_policy(base, error_weights, domain, steps), steps)
    if name in ("always", "never"):
        if arg:
            raise EtmpcError(f"bad policy {spec!r}: {name!r} takes no argument")
        return Always() if name == "always" else Never()
    if name == "every":
        period = _number(arg, int, spec)
        if period < 1:
            raise EtmpcError(f"bad policy {spec!r}: the period must be a whole number of steps >= 1")
        return Every(period)
    if name == "threshold":
        level = _number(arg, float, spec)
        if not (math.isfinite(level) and level >= 0):
            raise EtmpcError(f"bad policy {spec!r}: the threshold must be a finite number >= 0")
        return Threshold(level, np.asarray(error_weights, dtype=float))
    if name == "self":
        if not arg:
            raise EtmpcError(f"bad policy {spec!r}: give the policy file, self:PATH")
        from etmpc.policies.selftrigger import load_self

        return load_self(arg, domain)
    if name == "rl":
        if not arg:
            raise EtmpcError(f"bad policy {spec!r}: give the policy file, rl:PATH")
        from etmpc.policies.learned import load_policy

        return load_policy(arg, domain, nx=len(error_weights))
    raise UnknownNameError(f"unknown policy {spec!r}; valid: always, never, every:T, threshold:X, rl:PATH, self:PATH, "
                           "rollout:BASE[:K[:H]], oracle:BASE")
