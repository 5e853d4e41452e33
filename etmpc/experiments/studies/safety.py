"""The safety audit: does each shipped learner fail more often than the best fixed schedule, on fresh episodes?
``docs/results/safety.{json,md}``.

    etmpc study safety --work runs/safety                       # every safety task, 1000 episodes: ~50 min on 2 cores
    etmpc study safety --work runs/safety --task cart_pendulum/kicks --episodes 20
    etmpc study safety --page-only                               # the page again from the JSON

On each safety task (:func:`safety_tasks`: those whose system reads a margin to a failure, ``safety_margin``, so
that its failures are safety events: the pole's falls, the quadrotor's geofence and ground), the best fixed
schedule (the stored references') and every shipped learner row of the leaderboard on that task (its DPI, its
PPO, and each under the task's shield where the leaderboard has that row: :func:`leaderboard_rows.learner_entries`)
are played on the first ``--episodes`` episodes of the **audit stream** (:data:`AUDIT_ENTROPY`): the training
distribution, drawn apart from training, selection, validation and the stored test sets, for reporting only.
Nothing is chosen here. Each learner row is paired with the schedule episode by episode (:mod:`.safety_stats`);
the issue's target is met where the upper bound of the paired difference's 95 % CI, learner failures minus the
schedule's per episode, is at most :data:`TARGET`. Each (task, policy) is kept in WORK as it finishes: run again,
the study continues where it stopped.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import re
from pathlib import Path

import numpy as np

from etmpc.common.errors import EtmpcError
from etmpc.common.outputs import write_json
from etmpc.common.progress import Progress
from etmpc.evaluation.backends import make_backend
from etmpc.evaluation.inputs import policy_files
from etmpc.evaluation.references import stored
from etmpc.experiments.leaderboard_rows import learner_entries
from etmpc.experiments.studies import runner
from etmpc.experiments.studies.safety_page import page
from etmpc.experiments.studies.safety_stats import TARGET, outcome, paired
from etmpc.learning.config import AUDIT_ENTROPY
from etmpc.learning.jobs import episode_outcomes
from etmpc.systems import folder_name, make_system, names, task_version
from etmpc.systems.base import system_type
from etmpc.systems.capabilities import Failures, SafetyMargin, offers

__all__ = ["TARGET", "arguments", "run", "safety_tasks"]

EPISODES = 1000  # the target is judged on at least this many fresh episodes


def safety_tasks() -> list[str]:
    """The tasks whose failures are safety events: those that count failures and read a margin to one
    (``safety_margin``, what a shield reads), in the suite's order. The others count something else: see the
    page's :data:`~.safety_page.NOT_SAFETY`."""
    return [task for task in names() if offers(system_type(task), SafetyMargin) and offers(system_type(task), Failures)]


def policies(task: str) -> list[tuple[str, str]]:
    """``(row, spec)``: the best fixed schedule first, then each shipped learner row of the leaderboard on ``task``."""
    rows = [("best fixed", stored(task).best)]
    return rows + [(entry.name, entry.specs[task]) for entry in learner_entries([task]) if task in entry.specs]


def _key(task: str, spec: str, episodes: int) -> dict:
    """What a kept policy's outcomes were played with: another key plays it again."""
    key = {"spec": spec, "episodes": episodes, "audit_entropy": AUDIT_ENTROPY, "task_version": task_version(task)}
    key["files_sha256"] = {str(f): hashlib.sha256(f.read_bytes()).hexdigest() for f in policy_files(spec)}
    return key


def _kept_path(work: Path, task: str, row: str) -> Path:
    slug = re.sub(r"[^a-z0-9]+", "-", row.lower()).strip("-")  # "DPI (shipped) + shield" -> dpi-shipped-shield
    return work / folder_name(task) / f"{slug}.json"


def _kept(path: Path, key: dict) -> dict | None:
    """What is kept at ``path`` for ``key`` (``outcomes``: rows of objective, failures, recomputes; ``seconds``:
    the wall time they took; ``played``: the commit and date they were played at), or None."""
    if not path.is_file():
        return None
    try:
        kept = json.loads(path.read_text())
    except (OSError, ValueError):
        return None  # an unfinished or foreign file: played again
    return kept if isinstance(kept, dict) and kept.get("key") == key else None


def play(task: str, episodes: int, workers: int, work: Path) -> tuple[dict[str, tuple[str, np.ndarray]], float]:
    """Each policy's audit outcomes on ``task``, ``row -> (spec, outcomes)``, from WORK where kept, else played
    (each policy kept as it finishes); and the wall seconds they took to play, kept or not."""
    found: dict[str, tuple[str, np.ndarray]] = {}
    seconds = 0.0
    for row, spec in policies(task):
        key, path = _key(task, spec, episodes), _kept_path(work, task, row)
        kept = _kept(path, key)
        if kept is None:
            clock = runner.Stopwatch()
            with make_backend("local", workers) as pool, Progress(episodes, f"{task}: {row}") as bar:
                outcomes = episode_outcomes(pool, task, [spec], AUDIT_ENTROPY, episodes, lambda job: bar.update())[0]
            kept = {"key": key, "outcomes": outcomes.tolist(), "seconds": clock.seconds(), "played": runner.made()}
            write_json(path, kept, indent=None)
        found[row] = (spec, np.asarray(kept["outcomes"], dtype=float))
        seconds += kept["seconds"]
    return found, seconds


def audit(task: str, episodes: int, workers: int, work: Path) -> dict:
    """``task``'s part of the document: each policy's outcomes and each learner row's pairing with the schedule."""
    played, seconds = play(task, episodes, workers, work)
    sense = make_system(task).objective_sense
    fixed_spec, fixed = played.pop("best fixed")
    rows = [{"row": row, "spec": spec, **outcome(o), **paired(o, fixed, sense)} for row, (spec, o) in played.items()]
    return {
        "made": runner.made(),
        "episodes": episodes,
        "failure_name": make_system(task).failure_name,
        "objective_sense": sense,
        "best_fixed": {"spec": fixed_spec, **outcome(fixed)},
        "rows": rows,
        "passes": all(r["meets_target"] for r in rows),
        "seconds": seconds,
    }


def checked_tasks(tasks: list[str] | None, episodes: int) -> list[str]:
    """The tasks asked for (default: every safety task), or one line saying what is wrong."""
    if episodes < 2:
        raise EtmpcError(f"--episodes must be at least 2 (a paired CI needs two), got {episodes}")
    known, safe = names(), safety_tasks()
    for task in tasks or []:
        if task not in known:
            raise EtmpcError(f"unknown task {task!r}; the safety tasks: {', '.join(safe)}")
        if task not in safe:
            raise EtmpcError(
                f"{task} is not a safety task (its failures are not safety events); the safety tasks: {', '.join(safe)}"
            )
    return list(dict.fromkeys(tasks)) if tasks else safe


def arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--episodes", type=int, default=EPISODES, help=f"audit episodes per policy (default {EPISODES})")
    parser.add_argument("--task", action="append", default=None, help="a safety task (repeatable; default: every one)")
    parser.add_argument(
        "--work", type=Path, default=Path("runs/safety"), help="where each policy's outcomes are kept (resumable)"
    )
    runner.options(parser)


def run(args: argparse.Namespace) -> None:
    results = runner.Results(args.out, "safety")
    if args.page_only:
        results.write_page(page)
        return
    tasks = checked_tasks(args.task, args.episodes)
    document = results.kept(lambda: {"tasks": {}})
    for task in tasks:  # the document written after each task: a stopped run keeps what finished
        document["tasks"][task] = audit(task, args.episodes, args.workers, args.work)
        document["tasks"] = {t: document["tasks"][t] for t in safety_tasks() if t in document["tasks"]}
        document |= {"machine": runner.machine(args.workers), "target": TARGET, "audit_entropy": AUDIT_ENTROPY}
        results.write(document, page)
