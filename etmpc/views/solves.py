"""Time in the loop, as the views show it: each recompute of an episode with the step it started and
the step its plan came into force (:func:`solves`), which plan is in force at each step
(:func:`in_force`), and a caption per video frame (:func:`frame_captions`).

The loop's trajectory keeps each plan put in force with the step it was made for and the step it
arrived (``Trajectory.plans``, ``Trajectory.arrivals``), and each step's recompute (``recompute``,
``level``, ``work``, ``in_flight``); :func:`etmpc.loop.records.plan_starts` pairs each plan with the
step its solve started. Without delay compensation a plan is made for the step its solve started;
with it, for the step its prediction starts from (``Latency.intervals`` later), except a plan made
before the interval (the episode's first, or after a restart: the decision was forced and the plan
arrived at once). A solve whose plan was never put in force (it failed while the plan in force still
had steps left, a restart cancelled it, or the episode ended first) ends where its steps in flight end.

Views only receive: this module reads arrays, and imports nothing of etmpc.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Caption colours (RGB): the plan in force, a new plan, a solve in flight, a solve that gave no plan.
PLAIN, NEW, SOLVING, UNUSED = (235, 235, 235), (120, 220, 110), (250, 200, 60), (240, 110, 100)


@dataclass(frozen=True)
class Solve:
    """One recompute: started at step ``start`` (from the state measured then), its plan in force
    from step ``due`` (``due == start``: made before the interval, in force at once)."""

    start: int
    level: int  # 1 one SQP iteration, 2 a full solve (etmpc.control.timing)
    work: float  # its priced work: 1 per solve, or its SQP iterations on a task with compute levels
    due: int  # the step its plan came into force, or, not put in force, the step its time in flight ended
    made_for: int  # the step its plan was made for (-1: not put in force)
    delivered: bool  # its plan was put in force

    @property
    def kind(self) -> str:
        return "one SQP iteration" if self.level == 1 else "full solve"


def in_force(arrivals, made, steps: int) -> np.ndarray:
    """The step the plan in force at each of steps ``0..steps-1`` was made for (its input is applied
    then; -1 where no plan is)."""
    j = np.searchsorted(np.asarray(arrivals, dtype=np.int64), np.arange(steps), side="right") - 1
    made = np.asarray(made, dtype=np.int64)
    return np.where(j >= 0, made[np.maximum(j, 0)] if len(made) else -1, -1)


def solves(record) -> list[Solve]:
    """Every recompute of an episode (an :class:`etmpc.loop.records.EpisodeRecord`), in order."""
    n = record.steps
    made = [int(k) for k, *_ in record.plans]
    plan_of = {int(s): j for j, s in enumerate(record.starts)}
    in_flight = np.append(np.asarray(record.in_flight[:n], bool), False)
    out = []
    for step in np.flatnonzero(record.recompute[:n]):
        s = int(step)
        j = plan_of.get(s)
        if j is not None:
            due, made_for = int(record.arrivals[j]), made[j]
        else:  # never in force: its time in flight ended with the steps in flight that follow it
            due, made_for = s + 1 + int(np.argmin(in_flight[s + 1 :])), -1
        out.append(Solve(s, int(record.level[s]), float(record.work[s]), due, made_for, j is not None))
    return out


def describe(solve: Solve, levels: bool) -> str:
    """``full solve, 6 SQP iterations`` on a task with compute levels (the work is the iterations); ``solve`` else."""
    if not levels:
        return "solve"
    iterations = f"{solve.work:g} SQP iteration{'s' if solve.work != 1 else ''}"
    return iterations if solve.level == 1 else f"full solve, {iterations}"


def solve_log(record, levels: bool) -> tuple[np.ndarray, list[str], list[str]]:
    """``(steps, lines, levels)``: a log line where each solve started and where it came into force (or did not)."""
    rows = []
    for v in solves(record):
        what = describe(v, levels)
        if v.due == v.start:
            rows.append((v.start, 0, f"{what} at step {v.start}: in force at once (made before the interval)", "INFO"))
            continue
        ahead = f"arrives step {v.due}" if v.delivered else f"due at step {v.due}"
        rows.append((v.start, 0, f"{what} started at step {v.start} ({ahead})", "INFO"))
        if v.delivered:
            line = f"plan made for step {v.made_for} in force (started step {v.start}, {v.due - v.start} step(s) in flight)"
            rows.append((v.due, 1, line, "INFO"))
        else:
            rows.append((v.due, 1, f"the {what} started at step {v.start} gave no plan in force", "WARN"))
    rows.sort(key=lambda r: (r[0], r[1]))
    return np.array([r[0] for r in rows], dtype=np.int64), [r[2] for r in rows], [r[3] for r in rows]


def frame_captions(record, levels: bool) -> list[list[tuple[str, tuple]]]:
    """A caption per video frame (frame ``i`` shows the state of step ``i``; ``0..steps``): the plan in
    force; "new plan in force" where one came into force; "solving (started step k, arrives step
    k+d)" from the step a solve started until its plan is in force. Lines of ``(text, RGB)``."""
    n = record.steps
    made = [int(k) for k, *_ in record.plans]
    current = in_force(record.arrivals, made, n + 1)
    captions = [[(f"step {i} · plan in force: made for step {current[i]}", PLAIN)] for i in range(n + 1)]
    for v in solves(record):
        what = "" if not levels else f" · {describe(v, levels)}"
        if v.due <= n and v.delivered:
            captions[v.due].append((f"NEW PLAN in force (made for step {v.made_for}, started step {v.start})", NEW))
        elif v.due <= n:
            captions[v.due].append((f"solve started at step {v.start} gave no plan in force", UNUSED))
        ahead = f"arrives step {v.due}" if v.delivered else f"due step {v.due}"
        for i in range(v.start, min(v.due, n + 1)):
            captions[i].append((f"solving (started step {v.start}, {ahead}){what}", SOLVING))
    return captions
