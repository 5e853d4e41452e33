"""``etmpc score --leaderboard``: every built-in trigger scored on the suite, written as a generated page.

The entries, each one spec per task (:func:`entries`):

* ``always``: standard MPC;
* **best periodic**: the task's best ``every:T`` on its stored test set (its reference: 0);
* **best threshold**: the event trigger ``threshold:X`` whose mean objective is best on
  training-distribution episodes (the validation stream of ``etmpc train``, never the test set), over
  the task's ``Benchmark.sweep_thresholds`` (the choice is kept with the rows: a run that continues does not
  choose again);
* the learners shipped in ``policies/<task>/`` (from a checkout): **GPOMDP** (``gpomdp.json``, the
  paper's tasks), **DPI** (``learned.json``) and **PPO** (``ppo.zip``), each where it is shipped;
* **rollout meter**: ``rollout:BEST:4:H``, the one-step lookahead over sampled futures with the task's
  lookahead ``H``: a real policy, and the costliest to run (its CPU column shows it);
* **oracle**: ``oracle:BEST`` (its reference: 100), the clairvoyant reference: a one-step lookahead over the best
  periodic schedule with each episode's future known. Not a policy, and no bound on every trigger: it bounds a
  one-step lookahead over that schedule, so a trigger that saves computations it spends can score above 100 (the
  page says, per task, where and why).

The rollout meter's and the oracle's rows are scored from the runs the task's sealed references kept when they
were built (:meth:`References.kept_evaluation`), not played again: they are the two costliest rows, and the
same runs (a test plays them again and compares).

Each (entry, task) is scored by :mod:`etmpc.evaluation.scorecard` and kept in the work directory as it
finishes, so an interrupted run continues where it stopped. A kept row is sealed with the SHA-256 of its
content: one edited by hand is refused in one line, never published; one of an older etmpc (no seal, or
no failures counted, wall-clock times) or of other policy files is played again. The page (``docs/leaderboard.md``), its
JSON and the performance profiles are written at the end, with the commit, date, machine and
software that produced them; the README's headline table is the page's, rewritten between its markers.
"""

from __future__ import annotations

import hashlib
import os
import platform
import re
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from etmpc.common.documents import SEAL, check_seal, loads, sealed
from etmpc.common.errors import EtmpcError
from etmpc.common.outputs import write_json, write_text
from etmpc.common.provenance import commit_and_date
from etmpc.common.resources import data_root
from etmpc.evaluation import metrics
from etmpc.evaluation.references import SUITE_VERSION, References, rollout_meter_spec, software, stored
from etmpc.evaluation.evaluate import parse_policies
from etmpc.evaluation.inputs import policy_files
from etmpc.evaluation.scorecard import Scorecard, TaskScore, aggregate, play_and_score, profiles, task_score
from etmpc.evaluation.verify import read_card, verify
from etmpc.evaluation.backends import make_backend, shared_pools
from etmpc.experiments.leaderboard_page import (  # noqa: F401
    BEGIN,
    END,
    ORACLE_NOTE,
    check_readme,
    headline,
    page,
    table_in,
    with_table,
)
from etmpc.learning.base import shipped
from etmpc.learning.config import VALIDATION_ENTROPY
from etmpc.learning.jobs import mean_scores
from etmpc.loop.closed import cpu_clock
from etmpc.systems import distinct, folder_name, make_system, names, task_version
from etmpc.systems.base import require
from etmpc.views.figures import write_performance_profile_png

FORMAT = "etmpc-leaderboard"
WORK = Path("results") / "leaderboard"  # where finished rows are kept (make leaderboard runs from the checkout)
VALIDATION_EPISODES = 20  # training-distribution episodes that choose the best threshold
THRESHOLDS = np.linspace(-100.0, 200.0, 301)


@dataclass(frozen=True)
class Entry:
    """A row of the leaderboard: a name, what kind of trigger it is, and its spec on each task."""

    name: str
    kind: str  # reference | baseline | learned | meter | bound | submitted (a verified card's)
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


def row_names() -> list[str]:
    """The leaderboard's rows, in order (a shipped learner's only where its policies are shipped)."""
    return [*FIRST, *(name for name, *_ in shipped_learners()), *LAST]


def shipped_policy(task: str, file: str = "learned.json") -> Path | None:
    """A policy shipped for ``task`` in a checkout's ``policies/`` (``file`` there), if there is one."""
    path = data_root() / "policies" / folder_name(task) / file
    if not path.is_file():
        return None
    try:  # named from where the command runs (make leaderboard: the checkout), so the page names no machine's paths
        return path.relative_to(Path.cwd())
    except ValueError:
        return path


def best_threshold(task: str, workers: int, say: Callable[[str], None]) -> str:
    """The ``threshold:X`` of the task's grid with the best mean objective on training-distribution episodes."""
    system = make_system(task)
    require(system, "experiments", "the leaderboard's best threshold")
    specs = system.benchmark.threshold_specs()
    with make_backend("local", workers) as pool:
        means = mean_scores(pool, system.name, specs, VALIDATION_ENTROPY, VALIDATION_EPISODES)
    chosen = metrics.best(zip(specs, means), system.objective_sense, key=lambda pair: pair[1])[0]
    say(f"{task}: best threshold on {VALIDATION_EPISODES} training-distribution episodes: {chosen}")
    return chosen


def kept_threshold(task: str, work: Path | None, workers: int, say: Callable[[str], None]) -> str:
    """:func:`best_threshold`, kept in ``work`` (``best-threshold/<task>.choice.json``, sealed) for the grid,
    the validation episodes and the task's version it was chosen on: a run that continues does not choose
    again (one that changed any of them does)."""
    system = make_system(task)
    key = {
        "grid": system.benchmark.threshold_specs(),
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
    found += [
        Entry(
            LAST[0],
            "meter",
            {t: rollout_meter_spec(make_system(t), best[t]) for t in tasks},
            "one-step lookahead over sampled futures: a real policy",
        ),
        Entry(LAST[1], "bound", {t: references[t].oracle_spec for t in tasks}, ORACLE_NOTE),
    ]
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
    for path in sorted(Path(work).glob("*/*.json")):
        _read_kept(path)


def _provenance() -> dict:
    """:func:`~etmpc.common.provenance.commit_and_date`, with the machine and the software: what made the page."""
    return commit_and_date() | {
        "machine": {
            "processor": platform.processor() or platform.machine(),
            "system": platform.platform(),
            "cores": len(os.sched_getaffinity(0)),
        },
        "software": software(),
    }


def build(
    docs: Path,
    work: Path,
    tasks: list[str] | None = None,
    episodes: int | None = None,
    workers: int = 1,
    readme: Path | None = None,
    say: Callable[[str], None] = lambda line: None,
    cards: list[Path] = (),
) -> dict:
    """Score every entry on every task and write ``docs/leaderboard.{md,json}`` and the profile figure;
    with ``readme``, rewrite its headline table between the markers. Each of ``cards`` (an external
    scorecard, ``etmpc score --json``) is verified first (:mod:`etmpc.evaluation.verify`) and its triggers
    join as rows, not played here. Returns the JSON."""
    with shared_pools():  # one pool of workers for every row (a row is one evaluation)
        return _build(docs, work, distinct(tasks or names()), episodes, workers, readme, say, list(cards))


def submitted(
    cards: list[Path], tasks: list[str], episodes: int, workers: int, say: Callable[[str], None]
) -> tuple[list[Entry], dict[tuple[str, str], TaskScore]]:
    """Each card's triggers as entries, and their rows by (entry, task): a card must verify (a seeded
    sample of each row replayed bit for bit) and be scored on the leaderboard's tasks and episodes."""
    found, rows = [], {}
    for card in cards:
        verdict = verify(card, workers=workers)
        if not verdict.verified:
            raise EtmpcError(f"--card {card} does not verify ({verdict.mismatches[0]}; etmpc verify {card} lists all)")
        say(f"--card {card}: verified ({verdict.replayed} episodes replayed bit for bit)")
        data = read_card(card)
        card_rows = [TaskScore.from_json(r) for r in data["rows"]]  # verified: every row is a row
        if set(data["tasks"]) != set(tasks) or any(r.episodes != episodes for r in card_rows):
            raise EtmpcError(
                f"--card {card} scores {', '.join(data['tasks'])} on {card_rows[0].episodes} episodes; "
                f"the leaderboard has {', '.join(tasks)} on {episodes}: score every task on its whole test set"
            )
        for row in card_rows:
            name = f"{row.policy} (submitted)"
            if name not in [e.name for e in found]:
                found.append(Entry(name, "submitted", {}, f"from {Path(card).name}, verified by replaying a seeded sample"))
            next(e for e in found if e.name == name).specs[row.task] = row.policy
            rows[name, row.task] = row
    return found, rows


def _build(
    docs: Path,
    work: Path,
    tasks: list[str],
    episodes: int | None,
    workers: int,
    readme: Path | None,
    say: Callable[[str], None],
    cards: list[Path],
) -> dict:
    if readme is not None:
        check_readme(readme)
    check_kept(work)
    references = {task: stored(task, episodes) for task in tasks}
    extra, given = submitted(cards, tasks, episodes or min(r.episodes for r in references.values()), workers, say)
    for task in tasks:  # the shipped policies parse (and are the files shipped) before any row is played
        system = make_system(task)
        parse_policies(
            system,
            [f"{prefix}{path}" for _, file, prefix, _ in shipped_learners() if (path := shipped_policy(task, file)) is not None],
        )
    board = entries(tasks, references, workers, say, work) + extra
    n = episodes or min(r.episodes for r in references.values())
    result = []
    rows_all: list[TaskScore] = []
    played: dict[str, dict] = {}
    for entry in board:
        rows = []
        for task in [t for t in tasks if t in entry.specs]:
            if (entry.name, task) in given:  # a verified card's row: not played here
                rows.append(given[entry.name, task])
                continue
            row, at = _row(entry, task, references[task], work, n, workers, say)
            rows.append(row)
            played[f"{at['commit']}{' (with uncommitted changes)' if at['uncommitted_changes'] else ''}"] = at
        named = [replace(r, policy=entry.name) for r in rows]
        rows_all += named
        result.append(
            {
                "name": entry.name,
                "kind": entry.kind,
                "note": entry.note,
                "specs": entry.specs,
                "rows": [r.to_json() for r in rows],
                "aggregate": aggregate(named).to_json(),
            }
        )
    data = {
        "format": FORMAT,
        "suite_version": SUITE_VERSION,
        "tasks": tasks,
        "episodes": n,
        "task_versions": {t: task_version(t) for t in tasks},
        "references": {
            t: {
                "best_periodic": r.best,
                "oracle": r.oracle_spec,
                "gap": r.gap,
                "test_set_sha256": r.test_set_sha256,
                "recompute_price": r.recompute_price,
                "objective_sense": r.objective_sense,
                "failure_name": make_system(t).failure_name,  # what its rows count as failures (None: none)
            }
            for t, r in references.items()
        },
        "generated": _provenance() | {"rows_played_at": sorted(played)},
        "entries": result,
    }
    docs.mkdir(parents=True, exist_ok=True)
    card = Scorecard(tasks, {}, rows_all, [])
    write_performance_profile_png(docs / "leaderboard_profile.png", profiles(card, THRESHOLDS), THRESHOLDS, tasks)
    write_json(docs / "leaderboard.json", data)
    write_text(docs / "leaderboard.md", page(data))
    if readme is not None:
        write_text(Path(readme), with_table(Path(readme).read_text(), headline(data)))
    return data
