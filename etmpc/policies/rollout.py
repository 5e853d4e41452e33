"""Rollout policies: decide by simulating both answers to "recompute now?" (Bertsekas' rollout).

At each decision of the control loop, ``rollout:BASE[:K[:H]]`` takes a :class:`etmpc.loop.Snapshot`
of the running episode and plays it on twice per future (:func:`etmpc.loop.play_on`): once keeping
the plan for this step, once recomputing now, then following the fixed policy ``BASE`` in both. It
does so over ``K`` futures sampled by the task's own generators from what the controller knows at
that step (``system.sample_future``: never the stored future), with the same futures and the same
draws of ``BASE`` for both answers (common random numbers), and picks the answer whose mean return
(rewards minus the price of the recomputes) is higher; on a tie it keeps the plan. ``H`` stops each
simulation ``H`` steps ahead and adds ``system.truncation_value`` of the state it ends in
(default: play to the episode's end).

A rollout policy is a real, if expensive, policy: it uses only what the controller knows, and by
the rollout property it does at least as well as ``BASE`` in expectation (up to the sampling noise
of ``K`` futures). It measures how much a state-dependent policy can gain over ``BASE``. With a
sensor that is not exact, the controller knows the plant's state only as its filter's belief: each
future then also starts from a state drawn from that belief (the simulated controller reads the filter
as the loop's does), never from the plant's true state.

``oracle:BASE`` is the same one-step lookahead with the episode's **stored** future, which no
controller knows: a **reference** for what such a policy can gain, never a contender. Its spec
and every table, JSON file, figure and recording that show it carry the word ``oracle``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from etmpc.common.errors import EtmpcError
from etmpc.common.numerics import fsum
from etmpc.control.timing import ITERATE, KEEP, SOLVE
from etmpc.loop import AugmentedState, Continuation, Decision, DecisionContext, Policy, Snapshot, play_on
from etmpc.systems.capabilities import RewardFailures, Rollouts, require

DEFAULT_FUTURES = 8
MAX_FUTURES = 1000


def q_values(
    context: DecisionContext,
    base: Policy,
    futures: int,
    rng: np.random.Generator | None,
    twin,
    horizon: int | None = None,
    oracle: bool = False,
    memo: OracleMemo | None = None,
    failure_cost: float = 0.0,
    from_belief: bool = True,
) -> np.ndarray:
    """Returns of each answer at ``context``'s decision, one row per answer and one column per future
    (paired): keeping and recomputing, or, on a task with compute levels, keeping, one SQP iteration
    and a full solve (:func:`answers`).

    ``twin`` is an environment of the same task to simulate in (``context.env`` is left untouched).
    With ``oracle``, the one future is the episode's stored one; then ``memo`` (an oracle's, whose
    base is deterministic and which plays to the episode's end) may already hold one of the two
    answers, and is given the plays made here. ``failure_cost``: each of the task's failures in a play costs this
    much more (its ``failures_in_rewards``; DPI's safety weight), never with a ``memo`` (an oracle's plays are scored
    as the task scores them). Where the sensor is not exact, each sampled future also starts from a plant state
    drawn from the filter's belief (:meth:`~etmpc.control.sensing.Belief.sample`, after the futures' other
    draws; the same state for every answer), since the controller knows no more; ``from_belief=False`` starts
    every play from the plant's true state instead (privileged: DPI's labels). The oracle starts from the true state.
    """
    system = context.system
    if not oracle:
        require(system, Rollouts, "a rollout over sampled futures")
    if failure_cost:
        require(system, RewardFailures, "a failure cost in learning")
        if memo is not None:
            raise ValueError("a failure cost is not an oracle's: give it without a memo")
    snapshot = Snapshot.take(context)
    episodes = [None] if oracle else [system.sample_future(snapshot.episode, context.step, rng) for _ in range(futures)]
    seeds = rng.integers(2**63, size=len(episodes)) if (base.stochastic and rng is not None) else [None] * len(episodes)
    believed = from_belief and not oracle and snapshot.belief is not None
    starts = [snapshot.belief.sample(rng) for _ in episodes] if believed else [None] * len(episodes)
    known = memo.lookup(snapshot) if memo is not None else None
    stop = None if horizon is None else context.step + horizon
    options = answers(system)
    returns = np.empty((len(options), len(episodes)))
    # The plan a recompute now gives is the same for every future: solved once, where the loop would
    # solve it now from the state now (no latency, no levels); else the loop solves it in each play.
    shared = system.latency.instant and not system.compute_levels
    for index, first in enumerate(options):
        if known is not None and known[0] == int(first):
            returns[index, 0] = known[1]
            continue
        solved = None
        if first and shared:
            solved = system.plan(snapshot.seen, snapshot.u_prev, snapshot.plan, snapshot.age, context.timestep)
        for k, (episode, seed, start) in enumerate(zip(episodes, seeds, starts)):
            base_rng = None if seed is None else np.random.default_rng(seed)
            trace = Continuation(context.step) if memo is not None else None
            returns[index, k] = play_on(
                system, twin, snapshot, base, base_rng, first, episode, solved, stop, trace, failure_cost, start
            )
            if memo is not None:
                assert trace is not None  # made where there is a memo
                memo.played(int(first), trace, returns[index, k])
    return returns


def answers(system) -> tuple:
    """What a policy may answer at a decision of ``system``: keep or recompute (``False``, ``True``), or,
    on a task with compute levels, keep, one SQP iteration, a full solve (``0``, ``1``, ``2``)."""
    return (KEEP, ITERATE, SOLVE) if system.compute_levels else (False, True)


def best_answer(system, returns: np.ndarray):
    """The answer whose mean return over the same futures is highest (``returns`` as :func:`q_values`
    gives them); on a tie the cheaper one (keep before an iteration before a solve)."""
    options = answers(system)
    means = [fsum(row.tolist()) for row in returns]
    best = 0
    for index in range(1, len(options)):
        if means[index] > means[best]:
            best = index
    return options[best]


@dataclass(eq=False)
class OracleMemo:
    """The oracle's plays, kept from one decision to the next: half its cost, the same numbers.

    At its decision of step ``i`` the oracle plays both answers on with the stored future and the
    deterministic ``BASE``, and takes the better one. The play it took went through step ``i`` exactly
    as the loop then does (:func:`etmpc.loop.play_on` is bit for bit :func:`etmpc.loop.run_episode`),
    so at step ``i + 1`` one answer, the one ``BASE`` gave there, was played already: its return is
    the rest of that play, summed as a new play would sum it. The memo is used only where the loop's
    state is exactly the play's (``x``, the plan, its age, ``u_prev``); anywhere else both answers are
    played, as without it (tests/loop/test_rollout.py checks the decisions are the same).
    """

    episode: Any = None  # the episode the kept play belongs to
    taken: tuple[Continuation, int] | None = None  # the play taken, and how many of its steps the loop has made
    _plays: dict = field(default_factory=dict)  # this decision's plays, by answer

    def lookup(self, snapshot: Snapshot) -> tuple[int, float] | None:
        """``(answer, return)`` known at ``snapshot``'s decision, or None."""
        self._plays = {}
        if self.taken is None or snapshot.episode is not self.episode:
            return None
        trace, k = self.taken
        if trace.start + k != snapshot.step or k >= len(trace.added):
            return None
        x, plan, age, u_prev, pending, belief = trace.after[k - 1]
        same = (
            pending is None
            and snapshot.pending is None
            and age == snapshot.age
            and np.array_equal(x, snapshot.x)
            and (belief is None) == (snapshot.belief is None)
            and (belief is None or np.array_equal(belief.mean, snapshot.belief.mean))
            and np.array_equal(u_prev, snapshot.u_prev)
            and (
                plan is snapshot.plan
                or (np.array_equal(plan.inputs, snapshot.plan.inputs) and np.array_equal(plan.states, snapshot.plan.states))
            )
        )
        if not same:
            return None
        answer = int(trace.levels[k]) if trace.levels else int(trace.recomputed[k])
        self._plays[answer] = (trace, k)
        return answer, trace.return_from(k)

    def played(self, first: int, trace: Continuation, value: float) -> None:
        self._plays[int(first)] = (trace, 0) if math.isfinite(value) else None

    def take(self, answer: bool, episode: Any) -> None:
        """The oracle answered ``answer``: the loop now makes the first step of that play."""
        chosen = self._plays.get(int(answer))
        self.episode = episode
        self.taken = None if chosen is None else (chosen[0], chosen[1] + 1)


@dataclass(eq=False)
class Rollout:
    """``rollout:BASE[:K[:H]]`` and ``oracle:BASE`` (see the module docstring)."""

    base: Policy
    futures: int = DEFAULT_FUTURES
    horizon: int | None = None
    oracle: bool = False
    simulates: bool = True  # the loop hands it a DecisionContext
    _twin: Any = field(default=None, repr=False)
    _memo: OracleMemo | None = field(default=None, repr=False)

    @property
    def stochastic(self) -> bool:
        return not self.oracle or self.base.stochastic

    @property
    def clairvoyant(self) -> bool:
        """The oracle knows each episode's future: a reference, not a policy."""
        return self.oracle

    @property
    def spec(self) -> str:
        if self.oracle:
            return f"oracle:{self.base.spec}"
        return f"rollout:{self.base.spec}:{self.futures}" + (f":{self.horizon}" if self.horizon is not None else "")

    def __getstate__(self):  # the twin environment and the oracle's memo stay in their process
        return {k: v for k, v in self.__dict__.items() if k not in ("_twin", "_memo")} | {"_twin": None, "_memo": None}

    def twin(self, system):
        if self._twin is None or self._twin[0] is not system:
            self._twin = (system, system.make_env())
        return self._twin[1]

    def decide(self, s: AugmentedState, rng: np.random.Generator | None) -> Decision:
        if s.context is None:
            raise EtmpcError(f"{self.spec} simulates the episode: it needs the control loop's context")
        memo = None
        if self.oracle and not self.base.stochastic and self.horizon is None:
            memo = self._memo = self._memo or OracleMemo()
        system = s.context.system
        returns = q_values(s.context, self.base, self.futures, rng, self.twin(system), self.horizon, self.oracle, memo)
        answer = best_answer(system, returns)  # the better mean over the same futures
        if memo is not None:
            memo.take(answer, s.context.env.task.episode)
        return answer


def _split_count(spec: str, text: str, what: str, low: int, high: int) -> int:
    try:
        value = int(text)
    except ValueError:
        raise EtmpcError(f"bad policy {spec!r}: {what} {text!r} is not a whole number") from None
    if not low <= value <= high:
        raise EtmpcError(f"bad policy {spec!r}: {what} must be in {low}..{high}, got {value}")
    return value


def parse_rollout(spec: str, parse_base, steps: int, simulating) -> Rollout:
    """``rollout:BASE[:K[:H]]`` or ``oracle:BASE``; ``parse_base`` parses BASE (a fixed or learned
    policy) and ``simulating(BASE)`` says whether it is written as a kind that simulates the loop
    itself; ``steps`` is the episode length (H's upper bound). Bad specs raise :class:`EtmpcError`."""
    name, _, rest = spec.partition(":")
    usage = "rollout:BASE[:K[:H]] (e.g. rollout:every:3:8)" if name == "rollout" else "oracle:BASE (e.g. oracle:every:3)"
    if not rest:
        raise EtmpcError(f"bad policy {spec!r}: give the base policy, {usage}")
    tokens = rest.split(":")
    if simulating(rest):
        raise EtmpcError(f"bad policy {spec!r}: the base policy must not simulate; {usage}")
    # BASE may hold colons itself (every:3): take the longest head of the tokens that parses as a policy.
    extra_allowed = 2 if name == "rollout" else 0
    error = None
    for extra in range(0, min(extra_allowed, len(tokens) - 1) + 1):
        head, tail = ":".join(tokens[: len(tokens) - extra]), tokens[len(tokens) - extra :]
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
