"""How the experiments measure a task (``etmpc reproduce``, ``etmpc sweep``, the leaderboard's rows): its
:class:`Benchmark`, stored beside its test set as ``benchmark.json`` and read by :func:`read_benchmark`.

This module may import ``etmpc.common``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

from etmpc.common.documents import loads
from etmpc.common.errors import EtmpcError


@dataclass(frozen=True)
class Benchmark:
    """How the experiments measure a task (``etmpc reproduce`` and ``etmpc sweep``), kept with it."""

    prices: tuple[float, ...]  # the sweep's prices of a recompute, in the objective's unit
    sweep_thresholds: tuple[float, ...]  # threshold:X levels that span the periodic schedules' rates
    report_thresholds: tuple[float, ...]  # the few threshold:X levels in reproduce's table of fixed policies
    periods: tuple[int, ...] = (2, 3, 4, 5, 7, 10, 15)  # every:T in that table, beside always and never
    objective_unit: str = "-"  # the objective's unit, for recordings and figures
    # The sweep's size: test-set episodes, rollout futures, and whether a self-trigger is trained at
    # each price (a task whose simulated steps cost more can ask for less).
    sweep_episodes: int = 20
    sweep_futures: int = 4
    sweep_self_trigger: bool = True
    # The most steps a rollout looks ahead (the rollout meter's H and the DPI labels'): on a task whose
    # events come often, a long lookahead sums their random timing, the same for both answers only in
    # distribution, into noise that swamps the price of a recompute.
    lookahead: int = 20

    def capped(self, horizon: int | None) -> int:
        """A rollout's horizon ``horizon`` (None: to the episode's end) within the task's ``lookahead``."""
        return self.lookahead if horizon is None else min(horizon, self.lookahead)

    def threshold_specs(self, levels: bool = False) -> list[str]:
        """``threshold:X`` for each of the sweep's levels: the grid a best threshold is chosen from; with compute
        ``levels``, ``threshold:X:iterate`` too (the event trigger that answers one SQP iteration)."""
        solves = [f"threshold:{x:g}" for x in self.sweep_thresholds]
        return solves + [f"{spec}:iterate" for spec in solves] if levels else solves

    def baselines(self, levels: bool = False) -> list[str]:
        """Reproduce's fixed policies: always, never, every:T and threshold:X; with compute ``levels``,
        iterate:T too (one SQP iteration every step, and at the same periods)."""
        iterations = [f"iterate:{t}" for t in (1, *self.periods)] if levels else []
        return (
            ["always", "never"]
            + [f"every:{t}" for t in self.periods]
            + iterations
            + [f"threshold:{x:g}" for x in self.report_thresholds]
        )


def read_benchmark(path: Path) -> Benchmark:
    """A :class:`Benchmark` from its JSON file (its fields, and an optional ``notes`` object that says
    why a value is what it is); a file that is not one raises :class:`EtmpcError` in one line."""
    try:
        data = loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise EtmpcError(f"{path}: not a task's benchmark file ({exc})") from None
    names = {f.name: f for f in fields(Benchmark)}
    if (
        not isinstance(data, dict)
        or not set(data) <= set(names) | {"notes"}
        or not {"prices", "sweep_thresholds", "report_thresholds"} <= set(data)
    ):
        raise EtmpcError(
            f"{path}: a task's benchmark holds prices, sweep_thresholds, report_thresholds and optionally "
            f"{', '.join(n for n in names if n not in ('prices', 'sweep_thresholds', 'report_thresholds'))}, notes"
        )
    values: dict[str, Any] = {k: tuple(v) if isinstance(v, list) else v for k, v in data.items() if k != "notes"}  # checked below
    numbers = all(
        isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)
        for k, v in values.items()
        if isinstance(v, tuple)
        for x in v
    )
    if not numbers:
        raise EtmpcError(f"{path}: prices, thresholds and periods must be lists of finite numbers")
    return Benchmark(**values)
