"""The scorecard as text (``etmpc score``'s table): per task and policy, then the suite's aggregate per policy.
The card itself, and what its numbers mean, is :mod:`etmpc.evaluation.scorecard`'s."""

from __future__ import annotations

import math

from etmpc.common.wording import counted, interval, spread
from etmpc.systems.options import options_line, shown
from etmpc.evaluation.metrics import CI_EPISODES
from etmpc.evaluation.results import failures_cell

_CPU = (("total", 11), ("solve", 9), ("feedback", 10), ("decide", 10))  # a row's CPU columns and their widths


def format_scorecard(card) -> str:
    """The scorecard as text: per task and policy, then the suite's aggregate per policy. ``card``: a
    :class:`~etmpc.evaluation.scorecard.Scorecard` (which imports this module, so it is not imported here)."""
    width = max([18] + [len(r.policy) + 2 for r in card.rows])
    task_width = max([14] + [len(t) + 2 for t in card.tasks])
    head = (
        f"{'task':<{task_width}}{'policy':<{width}}{'objective':>11}{'recomputes':>14}{'failures ± CI':>16}"
        f"{'score':>9}{'± 95 % CI':>11}{'CPU ms/ep':>11}{'(solve':>9}{'feedback':>10}{'policy)':>10}"
    )
    lines = [
        *options_line(_options(card)),
        "normalized score per task: 0 = its best periodic schedule, 100 = the oracle over it (a one-step "
        "lookahead: above 100 is possible); failures: the task's own per episode (falls, ...), 95 % CI over the "
        "episodes; CPU: measured on this machine, per episode",
        head,
        "-" * len(head),
    ]
    for r in card.rows:
        if r.error is not None:
            lines.append(f"{r.task:<{task_width}}{r.policy:<{width}}failed: {r.error}")
            continue
        failures = failures_cell(r.failures_mean, r.failures_ci95)  # per episode, the task's own (falls, ...)
        score = (
            f"{r.score:>9.1f}{spread(r.score_ci95, '.1f'):>11}"
            if math.isfinite(r.score)
            else f"{'-':>9}{f'{r.nonfinite_episodes} non-finite':>11}"
        )
        cpu = "".join(f"{r.cpu_ms[k]:>{w}.1f}" if k in r.cpu_ms else f"{'-':>{w}}" for k, w in _CPU)  # -: not measured
        lines.append(
            f"{r.task:<{task_width}}{r.policy:<{width}}{r.objective_mean:>11.4f}{r.recomputes_mean:>14.2f}"
            f"{failures:>16}{score}{cpu}"
        )
    lines += [
        "",
        "the suite: interquartile mean of every task's episode scores and probability of improvement over the best "
        "periodic schedule, 95 % stratified bootstrap CIs",
        f"{'policy':<{width}}{'tasks':>6}{'IQM':>9}{'95 % CI':>18}{'P(improve)':>12}{'95 % CI':>16}",
    ]
    for a in card.aggregates:
        lines.append(
            f"{a.policy:<{width}}{a.tasks:>6}{a.iqm:>9.1f}{interval(a.iqm_ci95):>18}"
            f"{a.probability_of_improvement:>12.2f}"
            f"{interval(a.probability_of_improvement_ci95, '.2f'):>16}"
        )
    refs = "; ".join(
        f"{t}: {r['best_periodic']} and {r['oracle']}"
        + ("" if r.get("stored") else " (computed)")
        + (f" with {shown(tuple(r['options'].items()))}" if r.get("options") else "")
        for t, r in card.references.items()
    )
    lines.append(f"references: {refs}")
    few = {r.task: r.episodes for r in card.rows if r.error is None and r.episodes < CI_EPISODES}
    if few:
        lines.append(
            f"note: {_few(few, card.tasks)}, fewer than the {CI_EPISODES} a 95 % CI needs to cover about 95 % (episode "
            "scores are skewed): read these CIs as too narrow, or score more episodes"
        )
    return "\n".join(lines)


def _options(card) -> dict[str, str]:
    """The options the card's tasks were played with (the same for every task: score takes one set)."""
    return next((r["options"] for r in card.references.values() if r.get("options")), {})


def _few(few: dict[str, int], tasks) -> str:
    """The tasks scored on too few episodes, each count said once: ``1 episode on every task``, ``3 episodes on
    reacher/jumps and battery/trading, 5 on ...``."""
    by_count: dict[int, list[str]] = {}
    for task, n in few.items():
        by_count.setdefault(n, []).append(task)
    if len(by_count) == 1 and len(few) == len(tasks):
        return f"{counted(next(iter(by_count)), 'episode')} on {'the task' if len(tasks) == 1 else 'every task'}"
    return ", ".join(f"{counted(n, 'episode')} on {' and '.join(names)}" for n, names in sorted(by_count.items()))
