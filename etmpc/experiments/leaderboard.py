"""``etmpc score --leaderboard``: every built-in policy scored on the suite, written as a generated page.

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
  lookahead ``H``: a real policy (on a noisy variant each future also starts from a state drawn from the filter's
  belief), and the costliest to run (its CPU column shows it);
* **oracle**: ``oracle:BEST`` (its reference: 100), the clairvoyant reference: a one-step lookahead over the best
  periodic schedule with each episode's future known. Not a policy, and not a bound: a policy that saves
  recomputes the oracle's lookahead spends can score above 100 (the page says, per task, where and why).

The rollout meter's and the oracle's rows are scored from the runs the task's sealed references kept when they
were built (:meth:`References.kept_evaluation`), not played again: they are the two costliest rows, and the
same runs (a test plays them again and compares).

Each (entry, task) is scored by :mod:`etmpc.evaluation.scorecard` and kept in the work directory as it
finishes, so an interrupted run continues where it stopped. A kept row is sealed with the SHA-256 of its
content: one edited by hand is refused in one line, never published; one of an older etmpc (no seal, or
no failures counted, wall-clock times) or of other policy files is played again. The page (``docs/leaderboard.md``), its
JSON and the performance profiles are written at the end, with the commit, date, machine and
software that produced them; the README's headline table is the page's, rewritten between its markers.

The entries and the kept rows are :mod:`etmpc.experiments.leaderboard_rows`'; the page's text
:mod:`etmpc.experiments.leaderboard_page`'s; this module plays the rows and writes the files.
"""

from __future__ import annotations

import os
import platform
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

from etmpc.common.errors import EtmpcError
from etmpc.common.outputs import write_json, write_text
from etmpc.common.progress import Progress
from etmpc.common.provenance import commit_and_date
from etmpc.evaluation.references import SUITE_VERSION, software, stored
from etmpc.evaluation.evaluate import parse_policies
from etmpc.evaluation.inputs import check_run_outputs
from etmpc.evaluation.scorecard import Scorecard, TaskScore, aggregate, profiles
from etmpc.evaluation.verify import read_card, read_checked, verify
from etmpc.evaluation.backends import shared_pools
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
from etmpc.experiments.leaderboard_rows import Entry, _row, check_kept, entries, shipped_learners, shipped_policy
from etmpc.systems import distinct, make_system, names, task_version
from etmpc.views.figures import write_performance_profile_png

FORMAT = "etmpc-leaderboard"
WORK = Path("results") / "leaderboard"  # where finished rows are kept (make leaderboard runs from the checkout)
PAGE = ("leaderboard.md", "leaderboard.json", "leaderboard_profile.png")  # what it writes into its --out
THRESHOLDS = np.linspace(-100.0, 200.0, 301)


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
    cards: Sequence[Path] = (),
) -> dict:
    """Score every entry on every task and write ``docs/leaderboard.{md,json}`` and the profile figure;
    with ``readme``, rewrite its headline table between the markers. Each of ``cards`` (an external
    scorecard, ``etmpc score --json``) is verified first (:mod:`etmpc.evaluation.verify`) and its policies
    join as rows, not played here. Returns the JSON."""
    with shared_pools():  # one pool of workers for every row (a row is one evaluation)
        return _build(docs, work, distinct(tasks or names()), episodes, workers, readme, say, list(cards))


def check_files(docs: Path, work: Path, readme: Path | None = None, cards=()) -> None:
    """Raise, before any row is played, unless the page's files (:data:`PAGE` in ``docs``), the kept rows
    (``work``) and the README whose table is rewritten in place can be written without landing on one
    another or on a card read, none is a FIFO or a device, none lies in etmpc's data folders, and the
    README has its markers (:func:`check_readme`)."""
    check_run_outputs(
        {},
        {"--out": docs, "the kept rows' directory": work},
        {f"--card {card}": card for card in cards},
        writes={"--out": PAGE, "the kept rows' directory": lambda name: True},  # every kept row is read back
        edits={"--readme": readme},
    )
    if readme is not None:
        check_readme(readme)


def _scored_as_asked(card: Path, tasks: list[str], episodes: int) -> None:
    """Raise unless ``card`` scores ``tasks`` on ``episodes`` each, read and checked field by field as
    :func:`~etmpc.evaluation.verify.verify` checks it, before any card is verified (which replays episodes)."""
    data, rows = read_checked(card)
    counts = list(dict.fromkeys(row.episodes for row in rows))
    if set(data["tasks"]) != set(tasks) or counts != [episodes]:
        raise EtmpcError(
            f"--card {card} scores {', '.join(data['tasks'])} on {counts[0]} episodes; "
            f"the leaderboard has {', '.join(tasks)} on {episodes}: score every task on its whole test set"
        )


def submitted(
    cards: list[Path], tasks: list[str], episodes: int, workers: int, say: Callable[[str], None]
) -> tuple[list[Entry], dict[tuple[str, str], TaskScore]]:
    """Each card's policies as entries, and their rows by (entry, task): a card must be scored on the
    leaderboard's tasks and episodes (every card checked before any is verified) and verify (a seeded
    sample of each row replayed bit for bit)."""
    for card in cards:
        _scored_as_asked(card, tasks, episodes)
    found: list[Entry] = []
    rows: dict[tuple[str, str], TaskScore] = {}
    for card in cards:
        verdict = verify(card, workers=workers)
        if not verdict.verified:
            raise EtmpcError(f"--card {card} does not verify ({verdict.mismatches[0]}; etmpc verify {card} lists all)")
        say(f"--card {card}: verified ({verdict.replayed} episodes replayed bit for bit)")
        card_rows = [TaskScore.from_json(r) for r in read_card(card)["rows"]]  # verified: every row is a row
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
    check_files(docs, work, readme, cards)
    check_kept(work)
    references = {task: stored(task, episodes) for task in tasks}
    for task in tasks:  # the shipped policies parse (and are the files shipped) before any card or row is played
        system = make_system(task)
        parse_policies(
            system,
            [f"{prefix}{path}" for _, file, prefix, _ in shipped_learners() if (path := shipped_policy(task, file)) is not None],
        )
    extra, given = submitted(cards, tasks, episodes or min(r.episodes for r in references.values()), workers, say)
    board = entries(tasks, references, workers, say, work) + extra
    n = episodes or min(r.episodes for r in references.values())
    result = []
    rows_all: list[TaskScore] = []
    played: dict[str, dict] = {}
    to_play = [(entry, task) for entry in board for task in tasks if task in entry.specs and (entry.name, task) not in given]
    with Progress(n * len(to_play), whole=True) as bar:  # every row's episodes: one estimate for the whole table
        for entry in board:
            rows = []
            for task in [t for t in tasks if t in entry.specs]:
                if (entry.name, task) in given:  # a verified card's row: not played here
                    rows.append(given[entry.name, task])
                    continue
                before = bar.n
                row, at = _row(entry, task, references[task], work, n, workers, say)
                if bar.n == before:  # kept, or from the references: no episode played, none to estimate from
                    bar.skip(n)
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
    markdown, json_file, figure = (docs / name for name in PAGE)
    write_performance_profile_png(figure, profiles(card, THRESHOLDS), THRESHOLDS, tasks)
    write_json(json_file, data)
    write_text(markdown, page(data))
    if readme is not None:
        write_text(Path(readme), with_table(Path(readme).read_text(), headline(data)))
    return data
