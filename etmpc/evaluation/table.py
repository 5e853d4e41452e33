"""An evaluation as the table ``etmpc evaluate`` prints: one row per policy (objective, its spread, the
control objective, recomputes, the task's failures where it counts them, solver failures, non-finite
episodes), under a line naming the task, its test set and the price of a recompute."""

from __future__ import annotations

from etmpc.common.sense import higher_or_lower
from etmpc.common.wording import counted
from etmpc.evaluation.results import Evaluation, failures_cell
from etmpc.systems import has_levels
from etmpc.systems.options import options_line


def format_table(evaluation: Evaluation) -> str:
    """``evaluation`` as the table ``etmpc evaluate`` prints."""
    sense = evaluation.summaries[0].objective_sense if evaluation.summaries else "min"
    names = {s.policy: s.policy + (" (oracle)" if s.clairvoyant else "") for s in evaluation.summaries}
    width = max([16] + [len(name) + 2 for name in names.values()])  # long rl:PATH specs stay aligned
    task_failures = next((s.failure_name for s in evaluation.summaries if s.failure_name), None)
    failures_width = max(len(task_failures) + 10, 16) if task_failures else 0
    extra = f"{task_failures + '/episode':>{failures_width}}" if task_failures else ""
    head = (
        f"{'policy':<{width}}{'objective':>12}{'± std':>10}{'control':>11}{'recomputes':>12}{extra}"
        f"{'solver failures':>17}{'non-finite':>12}"
    )
    levels = has_levels(f"{evaluation.domain}/{evaluation.task}")
    lines = [
        f"{evaluation.domain}/{evaluation.task}: objective ({higher_or_lower(sense)} is better), "
        f"test set {evaluation.testset_sha256[:12]}, {evaluation.recompute_price:g} per "
        + ("SQP iteration (recomputes: solves and iterations started)" if levels else "recompute"),
        *options_line(evaluation.options),
        head,
        "-" * len(head),
    ]
    for s in evaluation.summaries:
        column = f"{failures_cell(s.failures_mean, s.failures_ci95):>{failures_width}}" if task_failures else ""
        lines.append(
            f"{names[s.policy]:<{width}}{s.objective_mean:>12.5f}{s.objective_std:>10.5f}{s.control_objective_mean:>11.5f}"
            f"{s.recomputes_mean:>12.2f}{column}{s.solver_failures:>17d}{s.nonfinite_episodes:>12d}"
        )
    first = evaluation.summaries[0] if evaluation.summaries else None
    lines.append(f"{counted(first.episodes, 'episode')} x {counted(first.repeats, 'repeat')} per policy" if first else "")
    if task_failures:
        lines.append(f"{task_failures}/episode: the task's failures, mean ± 95 % CI over the episodes (1.96 sd / √n)")
    if any(s.clairvoyant for s in evaluation.summaries):
        lines.append("(oracle): it knows each episode's future, a reference and not a policy; a policy can do better than it")
    return "\n".join(lines)
