"""An episode's decisions as a recording holds them (:mod:`etmpc.views.schema`): each step's decision
(recompute, forced), the recomputes by kind at the age of the plan each replaced, with a line of text each,
what a self-trigger announced, the prediction error the policies read, and a threshold policy's threshold."""

from __future__ import annotations

import re
from collections.abc import Callable

import numpy as np

from etmpc.loop.records import EpisodeRecord
from etmpc.views import blueprint as look
from etmpc.views.layout import _timeline


def log_decisions(rr, stream, root: str, record: EpisodeRecord, series: Callable[..., None], steps) -> list[str]:
    """Log ``record``'s decisions under ``root``: ``series(path, index, values, names, kind=..., **style)``
    writes a series (and notes its path), ``steps`` is the index of the episode's steps; returns the paths
    written here other than by ``series``."""
    identity = record.identity
    dt = identity["control_interval_s"]
    n = record.steps
    realised = dict(colors=[look.REALISED], widths=[look.REALISED_WIDTH])
    written: list[str] = []
    decisions = np.stack([record.recompute, record.forced], axis=1).astype(float)
    stream.send_columns(f"{root}/decision", steps, rr.Scalars.columns(scalars=decisions))  # for replay
    written.append("decision")
    events = np.flatnonzero(record.recompute)
    if len(events):
        made_at = np.array([k for k, *_ in record.plans], dtype=np.int64)
        previous = made_at[np.maximum(np.searchsorted(made_at, events) - 1, 0)] if len(made_at) else events
        age = np.where(events > 0, events - previous, 0)
        forced = record.forced[events] & (events > 0)  # step 0 is forced too (there is no plan yet): the first plan
        # A series per kind of recompute, at the recomputes only (NaN: another kind), at the age
        # of the plan each one replaced.
        kinds = np.stack([(events > 0) & ~forced, forced, events == 0], axis=1)
        series(
            "recompute",
            _timeline(events, dt),
            np.where(kinds, age[:, None], np.nan),
            ["chosen by the policy", "forced: the plan ran out", "first plan"],
            kind="SeriesPoints",
            colors=[look.CHOSEN, look.FORCED, look.FIRST],
            markers=["circle", "cross", "diamond"],
            marker_sizes=[3.0, 4.5, 4.0],
        )
        error = record.prediction_error[events]
        text = [
            "first plan"
            if i == 0
            else f"{'FORCED, the plan ran out' if f else 'chosen by the policy'}: plan age {a}, ‖W (x − x̂)‖ {e:.4g}"
            for i, f, a, e in zip(events, forced, age, error)
        ]
        if record.announced:  # a self-trigger: what it announced as it made each plan
            announced = dict(record.announced)
            text = [
                t + (f"; announced: keep {announced[i]} steps, next solve at step {i + announced[i]}" if i in announced else "")
                for t, i in zip(text, events)
            ]
        stream.send_columns(
            f"{root}/events",
            _timeline(events, dt),
            rr.TextLog.columns(text=text, level=["WARN" if f else "INFO" for f in forced]),
        )
        written.append("events")
    if record.announced:
        made, keep = (np.array(v, dtype=np.int64) for v in zip(*record.announced))
        series(
            "announced",
            _timeline(made, dt),
            keep.astype(float),
            ["announced at the solve: steps the plan will be kept"],
            kind="SeriesPoints",
            colors=[look.ANNOUNCED],
            markers=["up"],
            marker_sizes=[4.0],
        )
    known = np.flatnonzero(np.isfinite(record.prediction_error))
    series("prediction_error", _timeline(known, dt), record.prediction_error[known], ["‖W (x − x̂)‖"], **realised)
    threshold = re.fullmatch(r"threshold:(.+)", identity["policy"])
    if threshold:
        x = float(threshold.group(1))
        series(
            "threshold",
            _timeline(np.array([0, n - 1]), dt),
            np.array([x, x]),
            [f"threshold {x:g}"],
            colors=[look.BOUND],
            widths=[1.0],
        )
    return written
