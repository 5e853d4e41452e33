"""Reading a recording back (``etmpc replay``): each episode's figures, recomputed from the file with
the same formulas as the live run.

``read_recording`` reads a ``.rrd`` with Rerun's own reader (``rerun.chunk.RrdReader``); a file
without the end marker :data:`etmpc.views.schema.END_MARKER` was cut short and is refused.
"""

from __future__ import annotations

import re
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from etmpc.common.errors import EtmpcError
from etmpc.common.wording import spread
from etmpc.evaluation import metrics
from etmpc.evaluation.results import failures_cell
from etmpc.common.sense import higher_or_lower, oriented
from etmpc.loop import computation_cost
from etmpc.views.schema import COMPUTE_SERIES, DECISION_SERIES, END_MARKER, OBJECTIVE_SERIES
from etmpc.systems import canonical

_ROOT = re.compile(r"^(.*/episode_\d+/repeat_\d+)/(.+)$")

# Entity (relative to its episode's root) -> the series it holds, in column order. ``objective``
# with three columns is how files written before the objective's series were split hold them.
READ = {
    "objective/reward": ("reward",),
    "objective/running": ("running",),
    "objective": OBJECTIVE_SERIES,
    "decision": DECISION_SERIES,
    "prediction_error": ("prediction_error",),
    "compute": COMPUTE_SERIES,  # a task with time in the loop only
}


def read_recording(path: str | Path) -> dict[str, dict]:
    """``{episode root: {"identity": {...}, "reward": (steps, values), "recompute": …, "forced": …,
    "computation": …, "running": …, "prediction_error": …}}`` from a ``.rrd`` file, read with
    Rerun's own reader; on a task with time in the loop also ``"level"``, ``"work"``, ``"in_flight"``."""
    from rerun.chunk import RrdReader

    path = Path(path)
    if not path.is_file():
        raise EtmpcError(f"recording {path} not found")
    with warnings.catch_warnings(record=True) as caught:  # said in the error below, not as a second line
        warnings.simplefilter("always")
        try:
            chunks = list(RrdReader(str(path)).stream())
        except Exception as exc:  # the reader raises its own types for a file that is not a recording
            short = any("no footer" in str(w.message) for w in caught)
            raise EtmpcError(
                f"recording {path} is cut short (no footer; {exc})"
                if short
                else f"{path} is not a readable Rerun recording ({exc})"
            ) from None
    episodes: dict[str, dict] = {}
    pieces: dict[tuple[str, str], list] = {}
    end = None
    for chunk in chunks:
        if str(chunk.entity_path) == END_MARKER and chunk.is_static:
            batch = chunk.to_record_batch()
            end = int(batch.column("episodes").to_pylist()[0][0])
            continue
        found = _ROOT.match(str(chunk.entity_path))
        if found is None:
            continue
        root, leaf = found.groups()
        if leaf != "identity" and leaf not in READ:
            continue
        batch = chunk.to_record_batch()
        if leaf == "identity" and chunk.is_static:
            identity = {
                name: batch.column(name).to_pylist()[0][0] for name in batch.schema.names if not name.startswith("rerun.")
            }
            episodes.setdefault(root, {})["identity"] = identity
        elif leaf in READ and "Scalars:scalars" in batch.schema.names:
            values = batch.column("Scalars:scalars").flatten().to_numpy().reshape(batch.num_rows, len(READ[leaf]))
            pieces.setdefault((root, leaf), []).append((batch.column("step").to_numpy(), values))
    for (root, leaf), parts in pieces.items():
        steps = np.concatenate([s for s, _ in parts])
        values = np.concatenate([v for _, v in parts])
        order = np.argsort(steps, kind="stable")
        for j, name in enumerate(READ[leaf]):
            episodes.setdefault(root, {})[name] = (steps[order], values[order, j])
    complete = {root: data for root, data in episodes.items() if "identity" in data and "reward" in data}
    if end is None:
        raise EtmpcError(
            f"recording {path} is incomplete: it has no end marker (the file was cut short, or its run did not finish)"
            if complete
            else f"{path} holds no etmpc episodes"
        )
    if len(complete) != end:
        raise EtmpcError(f"recording {path} is incomplete: {len(complete)} of its {end} episodes can be read")
    return complete


@dataclass(frozen=True)
class ReplayedEpisode:
    domain: str
    task: str  # the task's name as the command line takes it: DOMAIN for a domain's default task, else DOMAIN/TASK
    policy: str
    episode: int
    repeat: int
    seed: int
    objective_sense: str
    objective: float
    control_objective: float
    recomputes: int
    steps: int
    prediction_error_mean: float
    prediction_error_max: float
    prediction_error_at_recompute: float  # mean error at the steps where the policy chose to recompute
    work: float = float("nan")  # the priced work: the recomputes, or their SQP iterations on a task with compute levels
    solver_failures: int | None = None  # None: a recording of an older etmpc, which did not keep them
    failures: float | None = None  # the task's own (falls, ...); None where it counts none, or an older recording
    failure_name: str | None = None
    options: str = ""  # the task's options as the command line writes them ("" for the task as it is)


def replay_summary(path: str | Path) -> list[ReplayedEpisode]:
    """Each recorded episode's figures, with the live run's formulas (``etmpc.evaluation.evaluate.scores``)."""
    out = []
    for root, data in read_recording(path).items():
        identity = data["identity"]
        _, rewards = data["reward"]
        _, recompute = data["recompute"]
        _, forced = data.get("forced", (None, np.zeros_like(recompute)))
        steps_err, errors = data.get("prediction_error", (np.zeros(0, int), np.zeros(0)))
        recomputes = int(recompute.sum())
        # The same expressions as Trajectory.policy_return and evaluate.scores, on the same floats: each
        # each recompute priced by its work (a file without ``work``: one per recompute, the same floats).
        work = float(data["work"][1].sum()) if "work" in data else recomputes
        ret = float(rewards.sum() - computation_cost(work, identity["recompute_price"]))
        control = float(rewards.sum())
        objective, control = oriented(ret, identity["objective_sense"]), oriented(control, identity["objective_sense"])
        chosen = np.flatnonzero((recompute > 0) & (forced == 0))
        at_recompute = errors[np.isin(steps_err, chosen)]
        out.append(
            ReplayedEpisode(
                domain=identity["domain"],
                task=_task_name(identity),
                policy=identity["policy"],
                episode=int(identity["episode"]),
                repeat=int(identity["repeat"]),
                seed=int(identity["seed"]),
                objective_sense=identity["objective_sense"],
                objective=objective,
                control_objective=control,
                recomputes=recomputes,
                steps=len(rewards),
                prediction_error_mean=_mean(errors),
                prediction_error_max=float(errors.max()) if len(errors) else float("nan"),
                prediction_error_at_recompute=_mean(at_recompute),
                work=float(work),
                solver_failures=_whole(identity.get("solver_failures")),
                failures=None if identity.get("failures") is None else float(identity["failures"]),
                failure_name=identity.get("failure_name"),
                options=str(identity.get("options", "")),
            )
        )
    out.sort(key=lambda r: (r.task, r.policy, r.episode, r.repeat))
    return out


def _whole(value) -> int | None:
    return None if value is None else int(value)


def _mean(values) -> float:
    values = np.asarray(values, float)
    values = values[np.isfinite(values)]
    return float(values.mean()) if len(values) else float("nan")


def _task_name(identity: dict) -> str:
    """``cart_pendulum/kicks``, not ``cart_pendulum``: the name ``etmpc evaluate`` took (a recording of a
    task this install does not know keeps ``DOMAIN/TASK`` as recorded)."""
    domain_name, task = str(identity["domain"]), identity.get("task")
    if task is None:
        return domain_name
    try:
        return canonical(f"{domain_name}/{task}")
    except EtmpcError:
        return f"{domain_name}/{task}"


def _sense(group) -> str:
    return group[0].objective_sense


def format_replay(episodes: list[ReplayedEpisode], per_episode: bool = False) -> str:
    """The table ``etmpc replay`` prints: per task (with its options), one line per policy (and with
    ``per_episode`` one per episode), with evaluate's columns: objective, control, recomputes, the task's
    failures per episode, solver failures; then the prediction errors. ``n/a`` where a figure cannot be had
    (no recompute chosen, no step), ``-`` where the recording does not hold it (an older etmpc's)."""
    lines = []
    groups: dict[tuple[str, str], list[ReplayedEpisode]] = {}
    for e in episodes:
        groups.setdefault((e.task, e.policy), []).append(e)
    labels = [f"  episode {e.episode} repeat {e.repeat}" for e in episodes] if per_episode else []
    width = max([16] + [len(p) + 2 for _, p in groups] + [len(label) + 2 for label in labels])
    current = None
    for (task, policy), group in groups.items():
        named = next((e.failure_name for e in episodes if e.task == task and e.failure_name), None)
        failures_width = max(len(named) + 10, 16) if named else 0
        if task != current:
            head = (
                f"{'policy':<{width}}{'episodes':>9}{'objective':>12}{'control':>11}{'recomputes':>12}"
                + (f"{named + '/episode':>{failures_width}}" if named else "")
                + f"{'solver failures':>17}{'pred.err mean':>15}{'max':>10}{'at recompute':>14}"
            )
            lines += [
                f"{task}: objective ({higher_or_lower(_sense(group))}"
                " is better); prediction error ‖W (x − x̂)‖ against the plan in force",
                *([f"options: {group[0].options}"] if group[0].options else []),
                head,
                "-" * len(head),
            ]
            current = task
        rows: list[ReplayedEpisode | None] = [None, *(group if per_episode else [])]
        for row in rows:  # the policy's line (None), then its episodes
            chosen = group if row is None else [row]
            label = policy if row is None else f"  episode {row.episode} repeat {row.repeat}"
            lines.append(f"{label:<{width}}{_row(chosen, failures_width)}")
    return "\n".join(lines)


def _row(chosen: list[ReplayedEpisode], failures_width: int) -> str:
    """One line's figures over the episodes ``chosen`` (its label aside)."""
    mean = lambda attr: _mean([getattr(x, attr) for x in chosen])  # noqa: E731
    top = max((x.prediction_error_max for x in chosen if np.isfinite(x.prediction_error_max)), default=float("nan"))
    failures = [x.failures for x in chosen]
    cell = "-" if None in failures else failures_cell(_mean(failures), metrics.mean_ci95(np.array(failures, float)))
    solver = [x.solver_failures for x in chosen if x.solver_failures is not None]  # None: a recording that kept none
    return (
        f"{len(chosen):>9}{mean('objective'):>12.5f}{mean('control_objective'):>11.5f}{mean('recomputes'):>12.2f}"
        + (f"{cell:>{failures_width}}" if failures_width else "")
        + f"{'-' if len(solver) < len(chosen) else sum(solver):>17}"
        f"{spread(mean('prediction_error_mean'), '.4f'):>15}{spread(top, '.4f'):>10}"
        f"{spread(mean('prediction_error_at_recompute'), '.4f'):>14}"
    )
