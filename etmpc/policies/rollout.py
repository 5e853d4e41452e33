"""Rollout policies: decide by simulating both answers to "recompute now?" (Bertsekas' rollout).

At each decision of the control loop, ``rollout:BASE[:K[:H]]`` takes a :class:`etmpc.loop.Snapshot`
of the running episode and plays it on twice per future (:func:`etmpc.loop.play_on`): once keeping
the plan for this step, once recomputing now, then following the fixed policy ``BASE`` in both. It
does so over ``K`` futures sampled by the task's own generators from what the controller knows at
that step (``system.sample_future``: never the stored future), with the same futures and the same
draws of ``BASE`` for both answers (common random numbers), and picks the answer whose mean return
(rewards minus the price of computations) is higher; on a tie it keeps the plan. ``H`` stops each
simulation ``H`` steps ahead and adds ``system.truncation_value`` of the state it ends in
(default: play to the episode's end).

A rollout policy is a real, if expensive, policy: it uses only what the controller knows, and by
the rollout property it does at least as well as ``BASE`` in expectation (up to the sampling noise
of ``K`` futures). It measures how much a state-dependent trigger can gain over ``BASE``.

``oracle:BASE`` is the same one-step lookahead with the episode's **stored** future, which no
controller knows: an **upper bound** on what such a trigger can gain, never a contender. Its spec
and every table, JSON file, figure and recording that show it carry the word ``oracle``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from etmpc.common.errors import EtmpcError
from etmpc.loop import DecisionContext, Snapshot, play_on
from etmpc.common.numerics import fsum
from etmpc.loop import AugmentedState, Policy

DEFAULT_FUTURES = 8
MAX_FUTURES = 1000


def q_values(context: DecisionContext, base: Policy, futures: int, rng: np.random.Generator | None, twin,
             horizon: int | None = None, oracle: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Returns of keeping and of recomputing at ``context``'s decision, one per future (paired).

    ``twin`` is an environment of the same task to simulate in (``context.env`` is left untouched).
    With ``oracle``, the one future is the episode's stored one.
    """
    system = context.system
    snapshot = Snapshot.take(context)
    episodes = [None] if oracle else [system.sample_future(snapshot.episode, context.step, rng) for _ in range(futures)]
    seeds = rng.integers(2**63, size=len(episodes)) if (base.stochastic and rng is not None) else [None] * len(episodes)
    solved = system.plan(snapshot.x, snapshot.u_prev, snapshot.plan, snapshot.age, context.timestep)
    stop = None if horizon is None else context.step + horizon
    returns = np.empty((2, len(episodes)))
    for first in (0, 1):
        for k, (episode, seed) in enumerate(zip(episodes, seeds)):
            base_rng = None if seed is None else np.random.default_rng(seed)
            returns[first, k] = play_on(system, twin, snapshot, base, base_rng, bool(first), episode, solved, stop)
    return returns[0], returns[1]


@dataclass(eq=False)
class Rollout:
    """``rollout:BASE[:K[:H]]`` and ``oracle:BASE`` (see the module docstring)."""

    base: Policy
    futures: int = DEFAULT_FUTURES
    horizon: int | None = None
    oracle: bool = False
    simulates: bool = True  # the loop hands it a DecisionContext
    _twin: Any = field(default=None, repr=False)

    @property
    def stochastic(self) -> bool:
        return not self.oracle or self.base.stochastic

    @property
    def spec(self) -> str:
        if self.oracle:
            return f"oracle:{self.base.spec}"
        return f"rollout:{self.base.spec}:{self.futures}" + (f":{self.horizon}" if self.horizon is not None else "")

    def __getstate__(self):  # the twin environment stays in its process
        return {k: v for k, v in self.__dict__.items() if k != "_twin"} | {"_twin": None}

    def twin(self, system):
        if self._twin is None or self._twin[0] is not system:
            self._twin = (system, system.make_env())
        return self._twin[1]

    def decide(self, s: AugmentedState, rng: np.random.Generator) -> bool:
        if s.context is None:
            raise EtmpcError(f"{self.spec} simulates the episode: it needs the control loop's context")
        keep, recompute = q_values(s.context, self.base, self.futures, rng, self.twin(s.context.system), self.horizon, self.oracle)
        return fsum(recompute.tolist()) > fsum(keep.tolist())  # the better mean over the same futures


def _split_count(spec: str, text: str, what: str, low: int, high: int) -> int:
    try:
        value = int(text)
    except ValueError:
        raise EtmpcError(f"bad policy {spec!r}: {what} {text!r} is not a whole number") from None
    if not low <= value <= high:
        raise EtmpcError(f"bad policy {spec!r}: {what} must be in {low}..{high}, got {value}")
    return value


def parse_rollout(spec: str, parse_base, steps: int) -> Rollout:
    """``rollout:BASE[:K[:H]]`` or ``oracle:BASE``; ``parse_base`` parses BASE (a fixed or learned
    policy); ``steps`` is the episode length (H's upper bound). Bad specs raise :class:`EtmpcError`."""
    name, _, rest = spec.partition(":")
    usage = "rollout:BASE[:K[:H]] (e.g. rollout:every:3:8)" if name == "rollout" else "oracle:BASE (e.g. oracle:every:3)"
    if not rest:
        raise EtmpcError(f"bad policy {spec!r}: give the base policy, {usage}")
    tokens = rest.split(":")
    if tokens[0] in ("rollout", "oracle"):
        raise EtmpcError(f"bad policy {spec!r}: the base policy must not simulate; {usage}")
    # BASE may hold colons itself (every:3): take the longest head of the tokens that parses as a policy.
    extra_allowed = 2 if name == "rollout" else 0
    error = None
    for extra in range(0, min(extra_allowed, len(tokens) - 1) + 1):
        head, tail = ":".join(tokens[: len(tokens) - extra]), tokens[len(tokens) - extra:]
        try:
            base = parse_base(head)
        except EtmpcError as exc:
            error = error or exc
            continue
        if name == "oracle":
            return Rollout(base, futures=1, oracle=True)
        futures = _split_count(spec, tail[0], "K (futures)", 1, MAX_FUTURES) if tail else DEFAULT_FUTURES
        horizon = _split_count(spec, tail[1], "H (steps ahead)", 1, steps) if len(tail) > 1 else None
        return Rollout(base, futures, horizon)
    raise EtmpcError(f"bad policy {spec!r}: {error} (use {usage})") from None

