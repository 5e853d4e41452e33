"""The leaderboard's rows (:mod:`etmpc.experiments.leaderboard` builds the table from them): which entries it
has and their spec on each task (:func:`entries`: the fixed ones, the shipped learners, the best threshold chosen on
training-distribution episodes and kept), and each (entry, task) row, kept in the work directory as it finishes,
sealed, under the key of what it was played with, and read back (:func:`_row`, :func:`_kept`, :func:`check_kept`).
"""

from __future__ import annotations

import hashlib
import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from etmpc.common.documents import SEAL, check_seal, loads, sealed
from etmpc.common.errors import EtmpcError
from etmpc.common.outputs import write_json
from etmpc.common.progress import Progress
from etmpc.common.provenance import commit_and_date
from etmpc.common.resources import data_root
from etmpc.evaluation import metrics
from etmpc.evaluation.backends import make_backend
from etmpc.evaluation.inputs import policy_files
from etmpc.evaluation.references import SUITE_VERSION, References, rollout_meter_spec
from etmpc.evaluation.scorecard import TaskScore, play_and_score, task_score
from etmpc.experiments.leaderboard_page import ORACLE_NOTE
from etmpc.learning.base import shipped
from etmpc.learning.config import VALIDATION_ENTROPY
from etmpc.learning.jobs import mean_scores
from etmpc.loop.closed import cpu_clock
from etmpc.systems import folder_name, make_system, names, task_version
from etmpc.systems.base import system_type
from etmpc.systems.capabilities import Experiments, require

VALIDATION_EPISODES = 20  # training-distribution episodes that choose the best threshold


@dataclass(frozen=True)
class Entry:
    """A row of the leaderboard: a name, what kind of policy it is, and its spec on each task."""

    name: str
    kind: str  # reference | baseline | learned | meter | oracle | submitted (a verified card's)
    specs: dict[str, str]
    note: str = ""


# The rows, in order (``etmpc score --help`` lists them from here): the fixed entries around the shipped learners.
FIRST = ("always", "best periodic", "best threshold")
LAST = ("rollout meter", "oracle")


def shipped_learners() -> list[tuple[str, str, str, str]]:
    """The learners whose policies the project ships in policies/<task>/: ``(entry, file, spec prefix, what
    it is)``, from each registered learner's ``shipped`` (:func:`etmpc.learning.base.shipped`): a new
    learner that ships its policies joins the leaderboard with no edit here."""
    return shipped()


SHIELDED = " + shield"  # a shipped learner's row under the task's shield (on a task that declares one)


def row_names() -> list[str]:
    """The leaderboard's rows, in order (a shipped learner's shielded row only where it ships a policy for a
    task that declares a shield)."""
    guarded = [task for task in names() if system_type(task).shield is not None]
    rows = [*FIRST]
    for name, file, *_ in shipped_learners():
        rows += [name, name + SHIELDED] if any(shipped_policy(t, file) for t in guarded) else [name]
    return [*rows, *LAST]


def shipped_policy(task: str, file: str = "learned.json") -> Path | None:
    """A policy shipped for ``task`` in a checkout's ``policies/`` (``file`` there), if there is one."""
    path = data_root() / "policies" / folder_name(task) / file
    if not path.is_file():
        return None
    try:  # named from where the command runs (make leaderboard: the checkout), so the page names no machine's paths
        return path.relative_to(Path.cwd())
    except ValueError:
        return path


def _meters(tasks: list[str], best: dict[str, str]) -> dict[str, str]:
    """The rollout meter's spec over each task's best fixed schedule, on the tasks that have one."""
    found = {}
    for task in tasks:
        meter = rollout_meter_spec(make_system(task), best[task])
        if meter is not None:
            found[task] = meter
    return found


def best_threshold(task: str, workers: int, say: Callable[[str], None], specs: list[str] | None = None) -> str:
    """The ``threshold:X`` of the task's grid (or of ``specs``) with the best mean objective on training-distribution
    episodes."""
    system = make_system(task)
    require(system, Experiments, "the leaderboard's best threshold")
    specs = system.benchmark.threshold_specs(system.compute_levels) if specs is None else specs
    jobs = len(specs) * VALIDATION_EPISODES
    with make_backend("local", workers) as pool, Progress(jobs, f"{task}: best threshold") as bar:
        means = mean_scores(pool, system.name, specs, VALIDATION_ENTROPY, VALIDATION_EPISODES, lambda job: bar.update())
    chosen = metrics.best(zip(specs, means), system.objective_sense, key=lambda pair: pair[1])[0]
    say(f"{task}: best threshold on {VALIDATION_EPISODES} training-distribution episodes: {chosen}")
    return chosen


def kept_threshold(task: str, work: Path | None, workers: int, say: Callable[[str], None]) -> str:
    """:func:`best_threshold`, kept in ``work`` (``best-threshold/<task>.choice.json``, sealed) for the grid,
    the validation episodes and the task's version it was chosen on: a run that continues does not choose
    again (one that changed any of them does)."""
    system = make_system(task)
    key = {
        "grid": system.benchmark.threshold_specs(system.compute_levels),
        "validation_entropy": VALIDATION_ENTROPY,
        "validation_episodes": VALIDATION_EPISODES,
        "suite_version": SUITE_VERSION,
        "task_version": task_version(task),
    }
    path = None if work is None else work / _slug(FIRST[2]) / f"{folder_name(task)}.choice.json"
    if (kept := path and _read_kept(path)) and SEAL in kept and kept.get("key") == key and kept.get("chosen") in key["grid"]:
        return kept["chosen"]
    chosen = best_threshold(task, workers, say)
    if path is not None:
        write_json(path, sealed({"key": key, "chosen": chosen}))
    return chosen


def entries(
    tasks: list[str], references: dict[str, References], workers: int, say: Callable[[str], None], work: Path | None = None
) -> list[Entry]:
    best = {t: references[t].best for t in tasks}
    found = [
        Entry(FIRST[0], "baseline", {t: "always" for t in tasks}, "standard MPC: a new plan every step"),
        Entry(
            FIRST[1],
            "reference",
            {t: best[t] for t in tasks},
            "each task's best fixed schedule on its test set (every:T, or iterate:T on a task with compute levels)",
        ),
        Entry(
            FIRST[2],
            "baseline",
            {t: kept_threshold(t, work, workers, say) for t in tasks},
            f"threshold:X chosen on {VALIDATION_EPISODES} training-distribution episodes",
        ),
    ]
    found += learner_entries(tasks)
    found += [
        Entry(
            LAST[0],
            "meter",
            _meters(tasks, best),
            "one-step lookahead over sampled futures, a real policy: on a noisy variant each future also starts "
            "from a state drawn from the filter's belief",
        ),
        Entry(LAST[1], "oracle", {t: references[t].oracle_spec for t in tasks}, ORACLE_NOTE),
    ]
    return found


def learner_entries(tasks: list[str]) -> list[Entry]:
    """The shipped learners' rows on ``tasks``: each learner that ships a policy for one of them, and its row under
    the task's shield where the task declares one (what the safety audit, ``etmpc study safety``, plays too)."""
    found: list[Entry] = []
    rules = {t: make_system(t).shield for t in tasks}
    for name, file, prefix, note in shipped_learners():
        shipped = {t: shipped_policy(t, file) for t in tasks}
        if any(path is not None for path in shipped.values()):
            found.append(
                Entry(
                    name,
                    "learned",
                    {t: f"{prefix}{p}" for t, p in shipped.items() if p is not None},
                    f"{note}; policies/<task>/{file}",
                )
            )
        shielded = {t: f"shield:{rules[t].text}:{prefix}{p}" for t, p in shipped.items() if p is not None and rules[t]}
        if shielded:
            found.append(
                Entry(
                    name + SHIELDED,
                    "learned",
                    shielded,
                    f"the same policy under the task's shield (a recompute when the plan is AGE steps old, the margin "
                    f"to a failure is below MARGIN or the state is DEVIATION off the plan; docs/policies.md#shields-shield); "
                    f"policies/<task>/{file}",
                )
            )
    return found


def _slug(name: str) -> str:
    return re.sub(r"[^a-z0-9]+", "-", name.lower()).strip("-")


def _row(
    entry: Entry, task: str, refs: References, work: Path, episodes: int, workers: int, say: Callable[[str], None]
) -> tuple[TaskScore, dict]:
    """The entry's score on ``task``, from the work directory if an earlier run finished it, and when and
    at which commit it was played."""
    spec = entry.specs[task]
    path = work / _slug(entry.name) / f"{folder_name(task)}.json"
    key = {
        "spec": spec,
        "episodes": episodes,
        "test_set_sha256": refs.test_set_sha256,
        "suite_version": SUITE_VERSION,
        "task_version": task_version(task),
        # what the row counts as a failure and how it timed the controller: a row kept by an etmpc that counted
        # none (or other ones), or timed the wall clock rather than the loop thread's CPU, is played again
        "failures": make_system(task).failure_name,
        "cpu_clock": cpu_clock.__name__,
    }
    files = policy_files(spec)
    if files:  # a policy read from files (rl:, sb3:): a row played with other files is played again
        key["files_sha256"] = {str(f): hashlib.sha256(f.read_bytes()).hexdigest() for f in files}
    kept = _kept(path, key)
    if kept is not None:
        return kept
    if (played := refs.kept_evaluation(spec)) is not None:  # as the references played it: not again
        say(f"{task}: {entry.name} ({spec}), from the stored references")
        row = task_score(refs, played, spec)
    else:
        say(f"{task}: {entry.name} ({spec})")
        row = play_and_score(task, refs, spec, workers=workers, progress=False)
    played_at = commit_and_date()
    write_json(path, sealed({"key": key, "row": row.to_json(), "played": played_at}))
    return row, played_at


def _kept(path: Path, key: dict) -> tuple[TaskScore, dict] | None:
    """The row kept in ``path`` for ``key`` and when it was played; None if there is none to keep (no
    file, an older etmpc's without a seal, or another key: it is played again). A kept row that was
    changed after it was written, or is not a row, is refused in one line (:func:`check_kept`)."""
    kept = _read_kept(path)
    if kept is None or SEAL not in kept or kept.get("key") != key:
        return None
    try:
        return TaskScore.from_json(kept["row"]), dict(kept["played"])
    except (KeyError, TypeError, ValueError) as exc:
        raise EtmpcError(f"kept leaderboard row {path} is not a row ({exc!r}); {_DELETE}") from None


_DELETE = "delete it to play the row again"


def _read_kept(path: Path) -> dict | None:
    if not path.is_file():
        return None
    try:
        kept = loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise EtmpcError(f"kept leaderboard row {path} cannot be read ({exc}); {_DELETE}") from None
    if not isinstance(kept, dict):
        raise EtmpcError(f"kept leaderboard row {path} is not a row (a JSON {type(kept).__name__}); {_DELETE}")
    if SEAL in kept:
        check_seal(kept, f"kept leaderboard row {path}", _DELETE)
    return kept


def check_kept(work: Path) -> None:
    """Every row kept in ``work``, checked before any is played (see :func:`_kept`)."""
    for path in sorted(Path(work).glob("*/*/*.json")):  # ENTRY/DOMAIN/TASK.json
        _read_kept(path)
