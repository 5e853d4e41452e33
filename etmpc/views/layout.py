"""How an episode is laid out in a recording: its title line, the plans' slots and fans on the timeline,
each solve's start and arrival (a task with time in the loop), and the timeline of a series (for
:class:`etmpc.views.recording.Recorder`)."""

from __future__ import annotations

import numpy as np

from etmpc.common.sense import cost_or_profit, higher_or_lower
from etmpc.views import blueprint as look
from etmpc.loop.records import EpisodeRecord
from etmpc.views.solves import in_force, solves


def _about(name: str, record: EpisodeRecord, objective: float) -> str:
    """The episode's title line (Markdown)."""
    identity = record.identity
    spec = identity["policy"]
    clairvoyant = identity.get("clairvoyant", identity.get("upper_bound"))  # upper_bound: an older etmpc's
    bound = " (the oracle: knows the future, not a policy)" if clairvoyant else ""
    sense = f"{cost_or_profit(identity['objective_sense'])}: {higher_or_lower(identity['objective_sense'])}"
    forced = int(record.forced[1:].sum())
    task = look.task_part(identity["domain"], identity["task"])
    unit = look.objective_unit(identity["domain"], identity["task"])
    return (
        f"**{name}**{bound} · {task} · **test-set episode {identity['episode']}**"
        + (f", repeat {identity['repeat']}" if identity["repeat"] else "")
        + f" · objective **{objective:.5g}** {unit if unit != '-' else ''} ({sense} is better)"
        f" · {int(record.recompute.sum())} recomputes, {forced} forced · seed {identity['seed']}"
        + (f" · policy `{spec}`" if spec != name else "")
        + (f" · latency: {identity['latency']}" if "latency" in identity else "")
        + (f" · work {record.work.sum():g} SQP iterations" if identity.get("compute_levels") else "")
        + "  \n"
        "Orange: what happened. Thin lines: each plan's prediction from the step it was made, coloured by when: "
        f"blue (early) → violet → teal → green (late). A step is {identity['control_interval_s']:g} s."
        + (" A plan is in force from the step it arrives (▲), after its solve started (●)." if record.timed else "")
    )


def _solve_series(record: EpisodeRecord) -> list[tuple]:
    """A task with time in the loop: ``(path, steps, values, names, kind, style)`` of the series that show
    each step's recompute (``compute``: level, work, in flight, in the order ``replay`` reads them),
    the plan in force (``solve/in_force``: the step it was made for) and, on the same axis, each
    solve's start (``solve/started``, at the step it started) and arrival (``solve/arrived``, at the
    step it was made for; one that gave no plan, at the step it started)."""
    n, levels = record.steps, bool(record.identity.get("compute_levels"))
    steps = np.arange(n)
    made = [k for k, *_ in record.plans]
    work_unit = "SQP iterations" if levels else "solves"
    compute = np.column_stack([record.level, record.work, record.in_flight]).astype(float)
    out = [
        (
            "compute",
            steps,
            compute,
            ["level (0 keep, 1 one SQP iteration, 2 full solve)", f"work [{work_unit}]", "in flight (policy not asked)"],
            "SeriesLines",
            dict(colors=[look.FORCED, look.REALISED, look.BOUND], widths=[1.5, 2.0, 1.0]),
        ),
        (
            "solve/in_force",
            steps,
            in_force(record.arrivals, made, n).astype(float),
            ["plan in force: the step it was made for [step]"],
            "SeriesLines",
            dict(colors=[look.REALISED], widths=[look.REALISED_WIDTH]),
        ),
    ]
    every = solves(record)
    if not every:
        return out
    start = np.array([v.start for v in every])
    kinds = [("one SQP iteration started", np.array([v.level == 1 for v in every]))] if levels else []
    kinds.append(("full solve started" if levels else "solve started", np.array([v.level != 1 for v in every])))
    out.append(
        (
            "solve/started",
            start,
            np.column_stack([np.where(k, start, np.nan) for _, k in kinds]).astype(float),
            [what for what, _ in kinds],
            "SeriesPoints",
            dict(
                colors=[look.ITERATION, look.CHOSEN][-len(kinds) :],
                markers=["circle"] * len(kinds),
                marker_sizes=[3.5] * len(kinds),
            ),
        )
    )
    arrived = sorted((v.due, v.delivered, v.made_for if v.delivered else v.start) for v in every if v.due <= n)
    if arrived:
        due, delivered, y = (np.array(c) for c in zip(*arrived))
        out.append(
            (
                "solve/arrived",
                due,
                np.column_stack([np.where(delivered, y, np.nan), np.where(delivered, np.nan, y)]).astype(float),
                ["plan in force from here (y: the step it was made for)", "no plan in force (y: the step it started)"],
                "SeriesPoints",
                dict(colors=[look.ANNOUNCED, look.FORCED], markers=["up", "cross"], marker_sizes=[4.0, 4.5]),
            )
        )
    return out


def _slots(made: np.ndarray, length: int) -> tuple[np.ndarray, int]:
    """A series ("slot") per plan: the first slot whose last plan ended at least two steps before
    this one starts, so that a NaN row parts two plans of one slot. ``length``: a plan's points."""
    ends: list[int] = []
    slots = np.empty(len(made), dtype=np.int64)
    for p, k in enumerate(made):
        s = next((s for s, end in enumerate(ends) if end + 1 < k), len(ends))
        if s == len(ends):
            ends.append(0)
        ends[s] = int(k) + length - 1
        slots[p] = s
    return slots, len(ends)


def _fan(made, slots, n_slots: int, values: np.ndarray, last: int, colours) -> list:
    """The columns of plans ``values (P, L)``, each from the step it was made, as ``n_slots``
    series over steps ``0..last`` (NaN where a slot has no plan), each point coloured by its plan."""
    import rerun as rr

    rows = made[:, None] + np.arange(values.shape[1])
    keep = rows <= last
    cols = np.broadcast_to(slots[:, None], rows.shape)[keep]
    grid = np.full((last + 1, n_slots), np.nan)
    grid[rows[keep], cols] = values[keep]
    paint = np.zeros((last + 1, n_slots), dtype=np.uint32)
    paint[rows[keep], cols] = np.broadcast_to(colours[:, None], rows.shape)[keep]
    return [
        *rr.Scalars.columns(scalars=grid),
        *rr.SeriesLines.columns(colors=paint.ravel()).partition(np.full(last + 1, n_slots)),
    ]


def _timeline(steps: np.ndarray, dt: float) -> list:
    import rerun as rr

    steps = np.asarray(steps, dtype=np.int64)
    # Whole nanoseconds as timedelta64: exact, and Rerun's fast path (floats go element by element).
    return [
        rr.TimeColumn("step", sequence=steps),
        rr.TimeColumn("time", duration=(steps * round(dt * 1e9)).astype("timedelta64[ns]")),
    ]
