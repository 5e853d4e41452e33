"""The solve in flight (:mod:`etmpc.control.timing`): what :class:`~etmpc.loop.closed.ClosedLoop` asks about
the time a recompute takes. On a task with a latency, a solve started at step ``k`` delivers its plan at
``k + d`` while the kept plan runs; one solve is in flight at a time, the policy is not asked meanwhile, and
a late plan comes into force at its own time index. Latency 0 (the paper's loop) delivers every plan at once.

:class:`Flight` keeps that state for one episode (the solve under way, and whether the next plan is made
before the interval) and answers from it: whether the decision is forced, from which state a
delay-compensated solve starts, and when a started solve arrives. Putting a plan in force stays the loop's.
"""

from __future__ import annotations

import numpy as np

from etmpc.common.frozen import readonly
from etmpc.control.plan import Plan
from etmpc.systems.base import System


class Flight:
    """The solve in flight of one episode of a loop on ``system``.

    :attr:`pending` is the solve under way, ``(arrives at, made for, plan, started)``, or None.
    :attr:`instant` says the next plan is made before the interval, so it is in force at once: the
    episode's first plan, and the one after the task put the plant back."""

    __slots__ = ("system", "latency", "pending", "instant")

    def __init__(self, system: System):
        self.system = system
        self.latency = system.latency
        self.pending: tuple[int, int, Plan, int] | None = None
        self.instant = True

    def restart(self, pending: tuple[int, int, Plan, int] | None = None, instant: bool = True) -> None:
        """Start again: at an episode's start or after the task put the plant back (nothing in flight, the next
        plan made before the interval), or, resuming a snapshot, with its ``pending`` solve."""
        self.pending = pending
        self.instant = instant

    @property
    def in_flight(self) -> bool:
        """A solve is under way: its plan is not in force yet, and no other starts."""
        return self.pending is not None

    def forced(self, plan: Plan | None, age: int) -> bool:
        """``plan``, at ``age``, has run out (age = N; with a latency of ``d`` intervals, it would run out
        before a solve started now arrives: age >= N - d), or there is none yet. Never while a solve is in
        flight."""
        if self.pending is not None:
            return False
        return plan is None or age >= plan.horizon - (0 if self.instant else self.latency.intervals)

    def compensates(self, plan: Plan | None) -> bool:
        """A solve started now is made from the state predicted for when it arrives (delay compensation)."""
        return self.latency.compensate and self.latency.intervals > 0 and not self.instant and plan is not None

    def solve_from(self, x: np.ndarray, u_prev: np.ndarray, plan: Plan | None, age: int) -> tuple[np.ndarray, np.ndarray, int]:
        """``(x, u_prev, age)`` a new plan is made from: those now, or, delay-compensated, those the kept
        ``plan`` predicts for when the new one arrives (its predictor under the kept plan's inputs)."""
        if plan is None or not self.compensates(plan):
            return x, u_prev, age
        predict = self.system.predict
        assert predict is not None  # a task with a latency offers TimeInTheLoop (the registry requires it)
        intervals = self.latency.intervals
        ahead = np.array([plan.input_at(age + j) for j in range(intervals)])
        return readonly(predict(x, ahead)[-1]), readonly(ahead[-1]), age + intervals

    def start(self, new: Plan, i: int, plan: Plan | None) -> bool:
        """A recompute started at step ``i`` (with ``plan`` in force) gave ``new``: True if it is in force now
        (no delay), else it is in flight, made for step ``i`` (or, delay-compensated, for the step its
        prediction is of) and arriving after its delay."""
        delay = 0 if self.instant else self.latency.delay(new.iterations, self.system.control_interval_s)
        if delay != 0:
            made = i + (self.latency.intervals if self.compensates(plan) else 0)
            self.pending = (i + delay, made, new, i)
        self.instant = False
        return delay == 0

    def arrives(self, now: int) -> tuple[int, int, Plan, int] | None:
        """The solve that arrives at step ``now``, taken out of flight (as :attr:`pending` was); None if none does."""
        pending = self.pending
        if pending is None or pending[0] != now:
            return None
        self.pending = None
        return pending
