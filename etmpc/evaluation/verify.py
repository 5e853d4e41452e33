"""``etmpc verify CARD``: check somebody's scorecard by rebuilding and replaying it.

A scorecard (``etmpc score --json``) holds, per task and policy, every episode's normalised score
against the task's references. Anyone with the policy can check it. Nothing a card carries is taken on
its word: it is evidence, read as a stranger's file (``docs/verify.md``).

1. **Every field is of its type** (:mod:`etmpc.evaluation.card_checks`): a field of another type, a
   row's per-episode list not of its episode count, an unknown word, is one line, before anything else.
2. **It is this suite's card**: the suite's version, each task's version and test set are this
   etmpc's, and it was scored against the stored references, or (a task scored with options) against
   references computed for it on the stored test set (a card scored on another test set is not a suite result).
3. **It runs no code the card alone names**: a row whose policy imports a Python module (``py:MODULE:NAME``,
   also within another spec: ``shield:py:m:T``) is replayed only if that exact spec was allowed
   (``--allow-code SPEC``); else verify refuses before playing anything. Only the registry's kinds are built;
   an ``rl:``, ``self:`` or ``sb3:`` file is read as data.
4. **Its references are this etmpc's**: a task's stored references are loaded and checked; those a card
   carries for a task scored with options are rebuilt in full from the task and its options on the card's
   episodes, as scoring built them (:mod:`etmpc.evaluation.carried`: every periodic schedule and the oracle,
   what scoring cost), and every number the card states of them is compared bit for bit with the rebuilt ones.
   The rows are checked against the stored or rebuilt references, never the card's.
5. **It holds together** (:mod:`etmpc.evaluation.consistency`): every number the card states follows from
   the episodes it carries, per row (each episode's score from its objective and the references, bit for
   bit; the means, totals, CI and shares; the CPU time's total from its parts: the CPU time itself is the
   scorer's machine's measurement, checked for consistency, never replayed), and the suite's aggregates
   from the rows.
6. **It replays**: a seeded sample of each row's episodes is played again with the policy the row names
   (an ``rl:PATH``, ``sb3:PATH`` must be readable here, an allowed ``py:`` module importable), and each
   episode's objective, recomputes, solver failures, failures and score must be the card's bit for bit (the
   loop's numbers do not depend on the number of workers, nor on the machine's kernels among x86-64 CPUs with
   fused multiply-add: ``docs/using.md``). Together: no number of a card can be changed without a line saying which.

Every mismatch is one line; :func:`verify` returns them (an empty list: the card verifies). A card that is
not a suite result, is malformed or names code not allowed raises :class:`EtmpcError` (one line).
"""

from __future__ import annotations

import math
import shlex
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from etmpc.common import checks
from etmpc.common.documents import read_document
from etmpc.common.errors import EtmpcError
from etmpc.common.provenance import LIBM_WORDS, libm_rounding
from etmpc.evaluation import carried as carry
from etmpc.evaluation import metrics
from etmpc.evaluation.card import TaskScore
from etmpc.evaluation.card_checks import check_card, check_row
from etmpc.evaluation.consistency import aggregate_mismatches, row_mismatches, same
from etmpc.evaluation.arguments import parse_policies
from etmpc.evaluation.evaluate import run_jobs
from etmpc.evaluation.references import SUITE_VERSION, References, stored
from etmpc.evaluation.workers import workers_for
from etmpc.policies.specs import find
from etmpc.systems import SystemKey, distinct, system_key, task_version

FORMAT = "etmpc-scorecard"
SAMPLE = 5  # episodes replayed per row by default
CODE_KIND = "py"  # the kind whose spec names a Python module to import: never run on a card's word


@dataclass(frozen=True)
class Verdict:
    """What :func:`verify` found: every mismatch (one line each), what it replayed and what it rebuilt."""

    card: str
    rows: int
    replayed: int  # episodes played again
    mismatches: list[str]
    caution: str | None = None  # this machine's C library rounds as the card's did not: say so beside the verdict
    rebuilt: tuple[str, ...] = ()  # the tasks (scored with options) whose references were rebuilt in full

    @property
    def verified(self) -> bool:
        return not self.mismatches


def read_card(path: str | Path) -> dict:
    return read_document(
        path,
        FORMAT,
        missing=f"card {path} not found",
        unreadable=f"card {path} cannot be read ({{error}})",
        foreign=f"{path} is not an etmpc scorecard (format {FORMAT!r}): make one with etmpc score --json",
    )


def _suite(card: dict, where: str) -> tuple[dict[str, References], dict[str, SystemKey]]:
    """The stored references of each task of ``card`` scored without options, and the task with its options of
    each scored with them (whose references are rebuilt); :class:`EtmpcError` (one line) for a card of another
    suite, task version or test set, or with a field of another type."""
    if card.get("suite_version") != SUITE_VERSION:
        raise EtmpcError(
            f"{where} was made under suite version {card.get('suite_version')!r}; this etmpc's is "
            f"{SUITE_VERSION}: verify it with the etmpc it was made with"
        )
    check_card(card, where)
    try:
        distinct(card["tasks"])  # each a task of this etmpc, none twice under two names (counted twice in the aggregates)
    except EtmpcError as exc:
        raise EtmpcError(f"{where}: tasks: {exc}") from None
    references, keys = {}, {}
    for task in card["tasks"]:
        if card["task_versions"][task] != task_version(task):
            raise EtmpcError(
                f"{where} scored {task} at version {card['task_versions'][task]!r}; this etmpc's is {task_version(task)}"
            )
        ref = card["references"][task]
        if "options" in ref:  # scored with options: its references are rebuilt, never the card's taken
            keys[task] = carry.key_of(task, ref, where)
            continue
        if ref.get("stored") is None:
            raise EtmpcError(f"{where} scored {task} on another test set than the stored one: it is not a suite result")
        try:
            refs = stored(task, ref["episodes"])
        except EtmpcError as exc:  # more episodes than the stored references hold, or none stored here
            raise EtmpcError(f"{where}: references.{task}: {exc}") from None
        if ref["test_set_sha256"] != refs.test_set_sha256:
            raise EtmpcError(
                f"{where} scored {task} on test set {ref['test_set_sha256'][:12]}…, not the stored {refs.test_set_sha256[:12]}…"
            )
        references[task] = refs
    return references, keys


def _stated_references(card: dict, references: dict[str, References], keys: dict[str, SystemKey]) -> list[str]:
    """Which of the numbers the card states of each task's references are not the stored (or rebuilt) ones."""
    found = []
    for task, refs in references.items():
        stated = card["references"][task]
        own = {"best_periodic": refs.best, "oracle": refs.oracle_spec, "gap": refs.gap, "recompute_price": refs.recompute_price}
        whose = "rebuilt" if task in keys else "the stored"
        found += [
            f"{task}: references' {key} {stated.get(key)!r} in the card, {whose} {value!r}"
            for key, value in own.items()
            if not same(stated.get(key), value)
        ]
        if task in keys:
            found += carry.differences(task, stated, keys[task], refs)
    return found


def _rows(card: dict, where: str) -> list[TaskScore]:
    try:
        rows = [TaskScore.from_json(row) for row in card["rows"]]
    except (KeyError, TypeError, ValueError) as exc:  # a field of another type says which (BadValue); the rest as raised
        said = str(exc) if isinstance(exc, EtmpcError) else repr(exc)
        raise EtmpcError(f"{where} holds a row that is not a row ({said})") from None
    for index, row in enumerate(rows):
        check_row(row, index, where)
    failed = [f"{r.policy} on {r.task}" for r in rows if r.error is not None]
    if failed:
        raise EtmpcError(f"{where} holds a failed row ({failed[0]}): there is nothing to verify")
    foreign = [r.task for r in rows if r.task not in card["tasks"]]
    if foreign:
        raise EtmpcError(f"{where} holds a row of {foreign[0]!r}, which is not among its tasks")
    pairs = [(r.task, r.policy) for r in rows]
    twice = next((p for p in pairs if pairs.count(p) > 1), None)
    if twice is not None:
        raise EtmpcError(f"{where} holds two rows of {twice[1]} on {twice[0]}")
    return rows


def read_checked(path: str | Path) -> tuple[dict, list[TaskScore]]:
    """The card at ``path`` and its rows, checked as :func:`verify` checks them before it builds or plays anything
    (this suite's, its stored references' test sets, every field of its type): for a reader that must refuse a
    card before any is verified (the leaderboard's ``--card``)."""
    where = f"card {path}"
    card = read_card(path)
    _suite(card, where)
    return card, _rows(card, where)


def runs_code(spec: str) -> bool:
    """Whether ``spec`` imports a Python module to build its policy: a ``py:`` spec, or one that holds one
    (``shield:py:m:T``, ``rollout:py:m:T:4``): any stretch of it after a colon written as a ``py:`` spec (whose
    kind, :func:`~etmpc.policies.specs.find`, is its text up to the next colon: each stretch is read once)."""
    return any((kind := find(stretch)) is not None and kind.name == CODE_KIND for stretch in spec.split(":"))


def _refuse_code(path, rows: list[TaskScore], allow_code: tuple[str, ...]) -> None:
    """One line, before anything is built or played, for the first row whose policy runs code not allowed."""
    for row in rows:
        if runs_code(row.policy) and row.policy not in allow_code:
            raise EtmpcError(
                f"card {path}: {row.policy} on {row.task} runs code (it imports a Python module), which verify never "
                f"does on a card's word: if you trust that module, allow the spec with --allow-code {shlex.quote(row.policy)}"
            )


def _policies(card: dict, rows: list[TaskScore], where: str) -> list[tuple[SystemKey, object]]:
    """Each row's task (with the card's options) and its policy, built by the registry's kinds."""
    built = []
    for row in rows:
        key = system_key(row.task, None, carry.options_of(card, row.task))
        try:
            (policy,) = parse_policies(key.make(), [row.policy]).values()
        except EtmpcError as exc:
            raise EtmpcError(f"{where}: cannot replay {row.policy} on {row.task}: {exc}") from None
        built.append((key, policy))
    return built


def _complete(row: TaskScore, refs: References) -> bool:
    """``row`` has a score for each of the references' episodes (else nothing of it can be checked)."""
    return row.episodes == refs.episodes == len(row.episode_scores)


def sample(episodes: int, size: int, seed: int, row: int) -> list[int]:
    """The episodes replayed of a row: ``size`` of ``episodes`` (0: all), drawn from ``seed`` and the row's index."""
    if size == 0 or size >= episodes:
        return list(range(episodes))
    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(row,)))
    return sorted(int(e) for e in rng.choice(episodes, size=size, replace=False))


def verify(
    path: str | Path,
    size: int = SAMPLE,
    seed: int = 0,
    workers: int | None = None,
    progress: bool = False,
    allow_code: tuple[str, ...] | list[str] = (),
    say: Callable[[str], None] = lambda line: None,
) -> Verdict:
    """Check the card at ``path`` (see the module's docstring), replaying ``size`` episodes of each row
    (0: all of them) drawn from ``seed`` on ``workers`` processes (default: by the work,
    :func:`~etmpc.evaluation.workers.workers_for`). ``allow_code``: the exact specs of rows whose policy
    imports a Python module (``py:``) that may be replayed. ``say``: where to tell that a task's references are
    being rebuilt (it costs what scoring them cost). A card that is not a suite result, is malformed or
    names code not allowed raises :class:`EtmpcError`."""
    size = checks.argument("size", lambda v: checks.at_least(checks.whole(v), 0), size)
    seed = checks.argument("seed", checks.seed, seed)
    if workers is not None:
        checks.argument("workers", checks.workers, workers)
    if not (isinstance(allow_code, (list, tuple)) and all(isinstance(s, str) for s in allow_code)):
        raise checks.BadType(f"allow_code: a list of policy specs is needed, got {allow_code!r}")
    where = f"card {path}"
    card = read_card(path)
    references, keys = _suite(card, where)
    rows = _rows(card, where)
    _refuse_code(path, rows, tuple(allow_code))
    built = _policies(card, rows, where)  # every policy built before any episode is played
    for task, key in keys.items():
        options = ", ".join(f"{name}={value}" for name, value in key.options)
        say(
            f"{task}: rebuilding the references the card scored it against ({options}) on its "
            f"{card['references'][task]['episodes']} episodes: every periodic schedule and the oracle, as scoring did"
        )
        references[task] = carry.rebuild(key, card["references"][task]["episodes"], workers, progress, say)
    references = {task: references[task] for task in card["tasks"]}
    mismatches, replayable = [], []
    for index, row in enumerate(rows):
        if _complete(row, references[row.task]):
            version = card["task_versions"][row.task]
            mismatches += [f"{path}: {line}" for line in row_mismatches(row, references[row.task], version)]
            replayable.append(index)
        else:
            mismatches.append(
                f"{path}: {row.task} {row.policy}: {len(row.episode_scores)} episode scores for "
                f"{row.episodes} episodes; the references have {references[row.task].episodes}"
            )
    found = _stated_references(card, references, keys) + aggregate_mismatches(card, rows)
    mismatches += [f"{path}: {line}" for line in found]
    jobs, expected = [], []
    for index in replayable:
        row, refs, (key, policy) = rows[index], references[rows[index].task], built[index]
        # The stored test set, which the references were checked against: workers check its digest.
        for episode in sample(refs.episodes, size, seed, index):
            jobs.append((key, None, refs.test_set_sha256, row.policy, policy, 0, episode, 0, False))
            expected.append((row, refs, episode))
    outcomes = run_jobs(jobs, workers or workers_for(len(jobs)), progress) if jobs else []
    for (result, _, _), (row, refs, episode) in zip(outcomes, expected):
        mismatches += [f"{path}: {line}" for line in _replayed(row, refs, episode, result)]
    return Verdict(str(path), len(rows), len(jobs), mismatches, _caution(card), tuple(keys))


def _replayed(row: TaskScore, refs: References, episode: int, result) -> list[str]:
    """What of ``row``'s ``episode`` is not as its replay ``result`` gave it, bit for bit."""
    name = f"{row.task} {row.policy} episode {episode}"
    best, cost = refs.costs(refs.periodic[refs.best][episode]), refs.costs(result.objective)
    replayed = float(metrics.normalized_scores(cost, best, refs.gap)) if result.finite else math.nan
    found = []
    if not same(replayed, row.episode_scores[episode]):
        found.append(f"{name}: score {row.episode_scores[episode]!r} in the card, {replayed!r} replayed")
    replayed_numbers = {
        "objective": (row.episode_objectives, result.objective),
        "recomputes": (row.episode_recomputes, result.recomputes),
        "solver failures": (row.episode_solver_failures, result.solver_failures),
        "failures": (row.episode_failures, result.failures),
    }
    for what, (carried, value) in replayed_numbers.items():
        if carried is not None and not same(carried[episode], value):
            found.append(f"{name}: {what} {carried[episode]!r} in the card, {value!r} replayed")
    return found


def _caution(card: dict) -> str | None:
    """A line, if this machine's libm rounds otherwise than the card's (a card of an older etmpc: otherwise
    than an x86-64 CPU with FMA): then a replay of the kicks tasks, the reacher or the quadrotor may differ
    in its last bits from the card's, and the quadrotor's by more, with nothing wrong in the card."""
    machine = card.get("machine")
    theirs = machine.get("libm") if isinstance(machine, dict) else None
    mine = libm_rounding()
    if mine == (theirs if theirs in LIBM_WORDS else "fma"):
        return None
    return (
        f"this machine's C library rounds sin, cos, exp and log as {LIBM_WORDS[mine]}; the card's was "
        f"{LIBM_WORDS.get(theirs or '', 'not recorded (an older etmpc)')}: replays of the kicks tasks, the reacher and "
        "the quadrotor may differ from the card's with nothing wrong in it; verify it on a machine like the card's"
    )
