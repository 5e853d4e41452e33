"""How an episode is laid out in a recording: its title line, the plans' slots and fans on the timeline,
and the timeline of a series (for :class:`etmpc.views.recording.Recorder`)."""

from __future__ import annotations

import numpy as np

from etmpc.common.sense import cost_or_profit, higher_or_lower
from etmpc.views import blueprint as look
from etmpc.views.record import EpisodeRecord


def _about(name: str, record: EpisodeRecord, objective: float) -> str:
    """The episode's title line (Markdown)."""
    identity = record.identity
    spec = identity["policy"]
    bound = " (an upper bound, not a policy)" if identity.get("upper_bound") else ""
    sense = f"{cost_or_profit(identity['objective_sense'])}: {higher_or_lower(identity['objective_sense'])}"
    forced = int(record.forced[1:].sum())
    task = look.task_part(identity["domain"], identity["task"])
    unit = look.objective_unit(identity["domain"], identity["task"])
    return (
        f"**{name}**{bound} · {task} · **test-set episode {identity['episode']}**"
        + (f", repeat {identity['repeat']}" if identity["repeat"] else "")
        + f" · objective **{objective:.5g}** {unit if unit != '-' else ''} ({sense} is better)"
        f" · {int(record.recompute.sum())} computations, {forced} forced · seed {identity['seed']}"
        + (f" · policy `{spec}`" if spec != name else "")
        + "  \n"
        "Orange: what happened. Thin lines: each plan's prediction from the step it was made, coloured by when: "
        f"blue (early) → violet → teal → green (late). A step is {identity['control_interval_s']:g} s."
    )


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
