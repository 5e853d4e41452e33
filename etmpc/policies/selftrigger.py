"""Self-triggering: at each solve, say how long the new plan will be kept (``self:PATH``).

The paper names it as future work: instead of asking at every step whether to recompute (event
triggering), the controller announces, when it makes a plan, the number of steps ``n`` in
``CANDIDATES`` it will keep it, so the next solve is known in advance. The loop then keeps the plan
exactly ``n`` steps (or until it runs out: ``n = N`` is ``never``).

**The policy** is a multinomial logistic model over the candidates, greedy: ``n = argmax_c
theta_c . [1, z]``, with ``z`` the normalised features of the plan as it is made
(:func:`plan_features`: the state it starts from, the spread of its predicted states, the mean
size of its inputs, and the spread of each forecast it was made with). Nothing measured after the
solve enters, so the announcement is made at the solve.

Training (:mod:`etmpc.learning.selftrigger`, ``etmpc train-self``) fits ``theta`` by one step of
rollout policy improvement over a periodic base.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from etmpc.common import checks
from etmpc.common.documents import loads
from etmpc.common.errors import EtmpcError
from etmpc.common.numerics import matvec
from etmpc.loop import AugmentedState
from etmpc.systems import same_task

FORMAT = "etmpc-self-trigger"
CANDIDATES = (1, 2, 3, 4, 5, 6, 8, 10, 12, 15, 20)


def plan_features(plan) -> np.ndarray:
    """What a plan says about itself when it is made: ``x_k``, ``x_k^2``, the range of each predicted
    state over the horizon, its first input and mean |input| per input, and the mean and standard
    deviation of each forecast it was made with."""
    x = np.asarray(plan.states[0], float)
    spread = np.ptp(np.asarray(plan.states, float), axis=0)
    inputs = np.asarray(plan.inputs, float)
    forecasts = [f(plan.forecasts[name]) for name in sorted(plan.forecasts) for f in (np.mean, np.std)]
    return np.concatenate([x, x * x, spread, inputs[0], np.mean(np.abs(inputs), axis=0), np.asarray(forecasts, float)])


@dataclass(eq=False)
class SelfTrigger:
    """``self:PATH``: keep each plan for the number of steps announced when it was made."""

    path: str
    domain: str
    candidates: tuple[int, ...]
    theta: np.ndarray  # (len(candidates), 1 + p)
    mean: np.ndarray  # (p,) feature normalisation
    scale: np.ndarray
    stochastic: bool = False
    observes: ClassVar[bool] = False
    _plan: Any = None
    _keep: int = 0

    @property
    def spec(self) -> str:
        return f"self:{self.path}"

    def announce(self, plan) -> int:
        """The number of steps ``plan`` will be kept, decided as it is made."""
        z = (plan_features(plan) - self.mean) / self.scale
        logits = matvec(self.theta, np.concatenate([[1.0], z]))  # not @: the choice must not depend on the BLAS kernel
        if not np.all(np.isfinite(logits)):
            raise EtmpcError(f"self-trigger policy {self.path} gives a non-finite score for a plan")
        return int(self.candidates[int(np.argmax(logits))])

    def decide(self, s: AugmentedState, rng: np.random.Generator | None) -> bool:
        if s.plan is not self._plan:  # a plan seen for the first time: its announcement
            self._plan, self._keep = s.plan, self.announce(s.plan)
        return s.age >= self._keep

    def __getstate__(self):
        return {k: v for k, v in self.__dict__.items() if k not in ("_plan", "_keep")} | {"_plan": None, "_keep": 0}

    def to_json(self, hyperparameters: dict | None = None) -> dict:
        return {
            "format": FORMAT,
            "version": 1,
            "domain": self.domain,
            "candidates": list(self.candidates),
            "theta": self.theta.tolist(),
            "mean": self.mean.tolist(),
            "scale": self.scale.tolist(),
            "hyperparameters": hyperparameters or {},
        }

    @classmethod
    def constant(cls, path: str, domain: str, candidates: tuple[int, ...], n: int, p: int) -> SelfTrigger:
        """The self-trigger that always announces ``n`` (``every:n``), over ``p`` features."""
        theta = np.zeros((len(candidates), 1 + p))
        theta[candidates.index(n), 0] = 1.0
        return cls(path, domain, tuple(candidates), theta, np.zeros(p), np.ones(p))


def load_self(path: str, domain: str | None) -> SelfTrigger:
    """A self-triggering policy from its file; any problem is one :class:`EtmpcError`."""
    try:
        data = loads(Path(path).read_text())
    except FileNotFoundError:
        raise EtmpcError(f"self-trigger policy {path} not found") from None
    except (OSError, ValueError) as exc:
        raise EtmpcError(f"self-trigger policy {path} is unreadable: {exc}") from None
    return from_json(data, str(path), domain)


def from_json(data: Any, path: str, domain: str | None) -> SelfTrigger:
    """A self-triggering policy from its JSON (``path``: its name in messages and its spec)."""
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise EtmpcError(f"{path} is not a self-trigger policy (format {FORMAT!r})")
    if domain is not None and not same_task(data.get("domain"), domain):
        raise EtmpcError(f"self-trigger policy {path} is for {data.get('domain')!r}, not {domain!r}")
    try:
        candidates = tuple(int(c) for c in data["candidates"])
        # each number checked as a learned policy's are (etmpc.policies.learned.LogisticPolicy.from_json says why)
        theta = checks.json_numbers(data["theta"], "theta", checks.MAX_WEIGHT)
        mean = checks.json_numbers(data["mean"], "mean", checks.MAX_SCALE)
        scale = checks.json_numbers(data["scale"], "scale", checks.MAX_SCALE, checks.MIN_SCALE)
    except checks.BadValue as exc:
        raise EtmpcError(f"self-trigger policy {path}: {exc}") from None
    except (KeyError, TypeError, ValueError) as exc:
        raise EtmpcError(f"self-trigger policy {path} is incomplete or malformed ({exc})") from None
    if (
        not candidates
        or min(candidates) < 1
        or len(set(candidates)) != len(candidates)
        or theta.shape != (len(candidates), mean.size + 1)
        or scale.shape != mean.shape
        or not (np.all(np.isfinite(theta)) and np.all(scale > 0))
    ):
        raise EtmpcError(f"self-trigger policy {path} has inconsistent or non-finite parameters")
    return SelfTrigger(str(path), data["domain"], candidates, theta, mean, scale)
