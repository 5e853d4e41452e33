"""Time in the control loop: how long a solve takes (:class:`Latency`) and how much a policy may compute at a
decision (:data:`KEEP`, :data:`ITERATE`, :data:`SOLVE`).

The paper's loop solves instantly and all or nothing. A task whose ``Config`` has a ``latency``
delivers each plan ``d`` control intervals after the solve started, from the state measured then:
the kept plan and its feedback run meanwhile, one solve is in flight at a time (the policy is not
asked then), and the late plan comes into force at its own time index (its age is ``d`` when it
arrives). A task with ``compute_levels`` lets the policy choose, at a decision, between keeping the
plan, one SQP iteration from the shifted last plan (a real-time iteration) and a full solve; each is
priced by its work, SQP iterations, and the latency applies to each. A policy may also ask for at most
``k`` SQP iterations from the shifted plan (:class:`Iterations`): the extra iterations of the advanced-step
real-time iteration (AS-RTI), or an iteration budget per solve such as acados' ``timeout_max_time``.

``d`` is deterministic, so runs stay bit-reproducible: a fixed number of intervals plus, on a named
target platform, the solve's own work, its SQP iterations times the time one takes there, rounded up
to whole intervals. Latency 0 is the paper's loop, bit for bit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from etmpc.common.checks import BadType, BadValue
from etmpc.common.declared import Checked, setting
from etmpc.control.settings import MAX_HORIZON

MAX_ITERATION_S = 10.0  # the longest time one SQP iteration may take: a solve of 1000 iterations then takes hours

#: What a policy may ask for at a decision on a task with compute levels (``Discrete(3)``); on any other
#: task a decision is a yes or no, and a yes is a full solve.
KEEP, ITERATE, SOLVE = 0, 1, 2
LEVEL_NAMES = ("keep", "iterate", "solve")
#: What a policy may answer, on a task without compute levels (False) and with them (True).
ANSWERS = {
    False: "False or 0 (keep) or True or 1 (a full solve)",
    True: f"{KEEP} ({LEVEL_NAMES[0]}), {ITERATE} ({LEVEL_NAMES[1]}), Iterations(k) or {SOLVE} ({LEVEL_NAMES[2]}), "
    "or False/True (keep/solve)",
}


@dataclass(frozen=True)
class Iterations:
    """An answer on a task with compute levels: at most ``count`` SQP iterations from the shifted plan,
    stopping early when they converge (the level :data:`ITERATE`; ``Iterations(1)`` is one real-time
    iteration, as ``ITERATE`` is). Priced, and delayed, by the iterations made."""

    count: int

    def __post_init__(self):
        if isinstance(self.count, bool) or not isinstance(self.count, (int, np.integer)) or self.count < 1:
            raise BadValue(f"Iterations: a whole number of SQP iterations >= 1 is needed, got {self.count!r}")


def iterations_of(answer: Any) -> int:
    """How many SQP iterations at most an answer whose level is :data:`ITERATE` asks for: ``answer.count``
    for an :class:`Iterations`, else 1 (``ITERATE`` itself)."""
    return int(answer.count) if isinstance(answer, Iterations) else 1


def level_of(answer: Any, levels: bool) -> int | None:
    """The level a policy's ``answer`` asks for (:data:`KEEP`, :data:`ITERATE`, :data:`SOLVE`), or None if it
    is no answer on a task with compute ``levels`` (or without): the one check of an answer, shared by the
    loop and the check of a user's policy. A bool (Python's or numpy's) is keep or a full solve; an integer
    (Python's or numpy's) is a level by its value: 0 or 1 (keep, a full solve) on a task without levels, 0, 1
    or 2 with them; an :class:`Iterations` is :data:`ITERATE` on a task with levels. Anything else is no
    answer, never read by its truth: 2 on a keep-or-solve task was taken as a solve, and a float, a string
    or None as whatever its truth said. Asked at every decision: the common answers cost an identity test
    or two."""
    if answer is True or answer is False or isinstance(answer, np.bool_):
        return SOLVE if answer else KEEP
    if isinstance(answer, (int, np.integer)):
        if answer == KEEP:
            return KEEP
        if answer == 1:
            return ITERATE if levels else SOLVE
        if answer == SOLVE and levels:
            return SOLVE
    if isinstance(answer, Iterations) and levels:
        return ITERATE
    return None


@dataclass(frozen=True)
class Latency(Checked):
    """How many control intervals a solve takes before its plan is in force.

    ``d = intervals + ceil(iterations * iteration_s / interval_s)``: a fixed part (communication, a
    solver with a fixed budget) and, where ``iteration_s > 0``, the solve's SQP iterations on the
    target platform ``platform``, each taking ``iteration_s`` seconds there (a hard solve takes
    longer). ``compensate``: the MPC solves from the state predicted ``intervals`` steps ahead under
    the kept plan (its predictor and the kept plan's inputs), as made for the step it arrives at:
    delay compensation, the controller's choice. The plan that starts an episode (or follows a
    plant the task put back) is made before the first interval: it is in force at once.
    """

    intervals: int = setting(
        0, low=0, high=MAX_HORIZON - 1, unit="intervals", why="a solve's fixed delay; shorter than the horizon"
    )
    iteration_s: float = setting(
        0.0, low=0, high=MAX_ITERATION_S, unit="s", why="one SQP iteration's time on the target platform (0: not counted)"
    )
    platform: str = setting("", label=True, why="the platform iteration_s was measured on: a name, shown in results")
    compensate: bool = setting(False, why="solve from the state predicted for when the plan arrives")

    def __post_init__(self):
        super().__post_init__()  # each field of its type and range, never read by its truth: compensate="no" is refused
        if self.iteration_s and not self.platform:
            raise BadValue("latency: a time per SQP iteration needs the platform it was measured on (platform=...)")

    @property
    def instant(self) -> bool:
        """No latency at all: the paper's loop."""
        return self.intervals == 0 and self.iteration_s == 0

    @property
    def counts_work(self) -> bool:
        """The delay depends on the solve's SQP iterations (the MPC then counts them)."""
        return self.iteration_s > 0

    def delay(self, iterations: int, interval_s: float) -> int:
        """``d`` for a solve of ``iterations`` SQP iterations, in control intervals of ``interval_s``."""
        if not self.iteration_s:
            return self.intervals
        # rounded up, with a relative slack so that an exact multiple is not pushed up by rounding error
        return self.intervals + math.ceil(iterations * self.iteration_s / interval_s - 1e-9)

    def describe(self) -> str:
        if self.instant:
            return "none"
        parts = [f"{self.intervals} interval(s)"] if self.intervals else []
        if self.iteration_s:
            parts.append(f"{self.iteration_s * 1e3:g} ms per SQP iteration on {self.platform}")
        return " + ".join(parts) + (", delay-compensated" if self.compensate else "")


def checked_latency(latency: Any, horizon: int) -> Latency:
    """``latency``, a task's ``Config.latency``, if its system can play it: a :class:`Latency` (an int read as
    one failed with an AttributeError in the middle of an episode) whose fixed ``intervals`` are fewer than
    the MPC's ``horizon`` N. A plan that arrives ``d`` intervals late has ``N - d`` steps left when it comes
    into force: with ``d >= N`` every plan would arrive after it ran out, and the loop would play a whole
    episode of plans that never apply. (A delay that grows with a solve's iterations is the platform's, and
    is not known before the solve.)"""
    if not isinstance(latency, Latency):
        raise BadType(
            f"latency: a Latency(...) is needed (etmpc.control.timing.Latency), got {type(latency).__name__} {latency!r}"
        )
    if latency.intervals >= horizon:
        raise BadValue(
            f"latency: {latency.intervals} intervals is not shorter than the MPC's horizon of {horizon} steps: "
            "every plan would arrive after it ran out"
        )
    return latency
