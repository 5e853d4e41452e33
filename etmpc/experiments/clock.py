"""Where ``etmpc reproduce``'s time goes: the wall time of each of a task's stages, kept in the task's folder.

A run is long and continues after an interruption, so each stage's time is written when the stage
finishes (``DIR/<domain>/<task>/stage_seconds.json``, atomically) and read back by later invocations: the
report's table of where the time went (:func:`time_table`) covers every stage, whichever invocation
played it. A stage whose files an earlier invocation made before its time was kept is recorded as not
timed (``None``), never as the instant it takes to find them; a stage an interruption cut short is
timed by the invocation that finished it (the part before the interruption is lost).
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from etmpc.common import progress
from etmpc.common.documents import loads
from etmpc.policies.learned import write_json_atomically

FILE = "stage_seconds.json"
# The report's columns: each groups stages of the same kind (a learner's training and its evaluations).
GROUPS = {
    "fixed policies": ("fixed policies",),
    "GPOMDP": ("GPOMDP training", "GPOMDP evaluation"),
    "DPI": ("DPI training", "DPI evaluation"),
    "rollout and oracle": ("rollout", "oracle"),
    "PPO": ("PPO training", "PPO evaluation"),
    "other learners": ("learner ",),  # a prefix: one stage per registered learner, "learner NAME"
    "figures, recording, video": ("figures, recording, video",),
}


def _in(group: str, stage: str) -> bool:
    return any(stage == s or (s.endswith(" ") and stage.startswith(s)) for s in GROUPS[group])


class StageClock:
    """The stage times of one task's folder: ``with clock.stage(name, *outputs): ...`` times the block,
    unless ``name`` was timed already; ``outputs`` are the files that show the stage was done before. The
    block's progress lines name the stage (:func:`etmpc.common.progress.stage`)."""

    def __init__(self, folder: Path):
        self.path = Path(folder) / FILE

    def read(self) -> dict[str, float | None]:
        """``{stage: wall seconds, or None if it was not timed}``, in the order the stages finished."""
        return loads(self.path.read_text()) if self.path.exists() else {}

    @contextmanager
    def stage(self, name: str, *outputs: Path) -> Iterator[None]:
        if name in self.read():
            with progress.stage(name):
                yield
            return
        made_before = bool(outputs) and all(Path(p).exists() for p in outputs)
        started = time.perf_counter()
        with progress.stage(name):
            yield
        seconds = None if made_before else time.perf_counter() - started
        write_json_atomically(self.path, self.read() | {name: seconds})


def time_table(systems: dict[str, dict]) -> list[str]:
    """Markdown: per task, the minutes of each group of stages, its total and its share of the run (the
    sum over tasks), and the costliest task; ``[]`` when no task kept its stage times."""
    timed = {task: r["stage_seconds"] for task, r in systems.items() if r.get("stage_seconds")}
    if not timed:
        return []
    groups = [g for g in GROUPS if any(_in(g, s) for times in timed.values() for s in times)]
    totals = {task: sum(v for v in times.values() if v is not None) for task, times in timed.items()}
    run = sum(totals.values())
    lines = [
        "## Where the time went",
        "",
        "Wall minutes of each task's stages (a learner's training and its test-set evaluations together), on the "
        "run's workers; the share is of the sum over tasks.",
        "",
        "| task | " + " | ".join(groups) + " | total | share |",
        "|---|" + "---|" * (len(groups) + 2),
    ]
    for task, times in timed.items():
        cells = []
        for group in groups:
            kept = [v for s, v in times.items() if _in(group, s)]
            cells.append("–" if not kept else "not timed" if None in kept else f"{sum(kept) / 60:.1f}")
        untimed = any(v is None for v in times.values())
        total = f"{'≥ ' if untimed else ''}{totals[task] / 60:.1f}"
        share = f"{100 * totals[task] / run:.0f} %" if run > 0 else "–"
        lines.append(f"| {task} | " + " | ".join(cells) + f" | {total} | {share} |")
    costliest = max(totals, key=lambda task: totals[task])
    lines += [
        "",
        f"Costliest: {costliest}, {totals[costliest] / 60:.1f} min of {run / 60:.1f}"
        + (
            " (stages an earlier invocation made before their time was kept are not counted)."
            if any(v is None for times in timed.values() for v in times.values())
            else "."
        ),
        "",
    ]
    return lines
