"""``etmpc verify CARD``: check somebody's scorecard by replaying it.

A scorecard (``etmpc score --json``) holds, per task and trigger, every episode's normalised score
against the task's stored references. Anyone with the trigger can check it:

1. **It is this suite's card**: the suite's version, each task's version and test set are this
   etmpc's, and it was scored against the stored references (a card scored on another test set is
   not a suite result).
2. **It holds together**: per row, the episode count, the score (the mean of the episode scores),
   the confidence interval and the share of better episodes follow from its episode scores (the
   failures' mean and CI from its episodes' failure counts, where the card has them), and the
   suite's aggregates (IQM, probability of improvement, their bootstrap intervals) follow from the rows,
   as :mod:`etmpc.evaluation.scorecard` computes them (with :mod:`etmpc.evaluation.metrics`).
3. **It replays**: a seeded sample of each row's episodes is played again with the trigger the row
   names (its spec: the handed-in ``py:MODULE:NAME``, ``rl:PATH``, ``sb3:PATH`` must be importable or
   readable here), and each episode's score (and failure count) must be the card's bit for bit (the
   loop's numbers do not depend on the machine's kernels or the number of workers: ``docs/using.md``).

Every mismatch is one line; :func:`verify` returns them (an empty list: the card verifies).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from etmpc.common.documents import read_document
from etmpc.common.errors import EtmpcError
from etmpc.common.outputs import strict
from etmpc.evaluation import metrics
from etmpc.evaluation.evaluate import parse_policies, run_jobs
from etmpc.evaluation.references import SUITE_VERSION, References, stored
from etmpc.evaluation.card import TaskScore, aggregate, by_policy
from etmpc.evaluation.workers import workers_for
from etmpc.systems import system_key, task_version

FORMAT = "etmpc-scorecard"
SAMPLE = 5  # episodes replayed per row by default
TOLERANCE = 1e-9  # relative: a row's score against the mean of its episode scores (two summations)


@dataclass(frozen=True)
class Verdict:
    """What :func:`verify` found: every mismatch (one line each) and what it replayed."""

    card: str
    rows: int
    replayed: int  # episodes played again
    mismatches: list[str]

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


def _suite(card: dict, where: str) -> dict[str, References]:
    """The references each task of ``card`` was scored against (raises :class:`EtmpcError`, one line, for a
    card of another suite, task version or test set)."""
    if card.get("suite_version") != SUITE_VERSION:
        raise EtmpcError(
            f"{where} was made under suite version {card.get('suite_version')!r}; this etmpc's is "
            f"{SUITE_VERSION}: verify it with the etmpc it was made with"
        )
    tasks, versions, shown = card.get("tasks"), card.get("task_versions"), card.get("references")
    if not (isinstance(tasks, list) and tasks and isinstance(versions, dict) and isinstance(shown, dict)):
        raise EtmpcError(f"{where} names no tasks, task versions or references (made by an older etmpc?)")
    references = {}
    for task in tasks:
        if versions.get(task) != task_version(task):
            raise EtmpcError(f"{where} scored {task} at version {versions.get(task)!r}; this etmpc's is {task_version(task)}")
        ref = shown.get(task)
        if not isinstance(ref, dict) or not ref.get("stored"):
            raise EtmpcError(f"{where} scored {task} on another test set than the stored one: it is not a suite result")
        episodes = ref.get("episodes")
        if not (isinstance(episodes, int) and not isinstance(episodes, bool)):
            raise EtmpcError(f"{where} gives {task} {episodes!r} episodes, not a count")
        refs = stored(task, episodes)
        if ref.get("test_set_sha256") != refs.test_set_sha256:
            raise EtmpcError(
                f"{where} scored {task} on test set {str(ref.get('test_set_sha256'))[:12]}…, not the "
                f"stored {refs.test_set_sha256[:12]}…"
            )
        references[task] = refs
    return references


def _rows(card: dict, where: str) -> list[TaskScore]:
    try:
        rows = [TaskScore.from_json(row) for row in card["rows"]]
    except (KeyError, TypeError, ValueError) as exc:
        raise EtmpcError(f"{where} holds a row that is not a row ({exc!r})") from None
    failed = [f"{r.policy} on {r.task}" for r in rows if r.error is not None]
    if failed:
        raise EtmpcError(f"{where} holds a failed row ({failed[0]}): there is nothing to verify")
    foreign = [r.task for r in rows if r.task not in card["tasks"]]
    if foreign:
        raise EtmpcError(f"{where} holds a row of {foreign[0]!r}, which is not among its tasks")
    return rows


def _same(a, b) -> bool:
    """Equal as the card stores numbers: NaN (JSON's null) equals NaN."""
    return (isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b)) or a == b


def _complete(row: TaskScore, refs: References) -> bool:
    """``row`` has a score for each of the references' episodes (else nothing of it can be checked)."""
    return row.episodes == refs.episodes == len(row.episode_scores)


def _consistency(row: TaskScore, refs: References) -> list[str]:
    """What in a complete ``row`` does not follow from its own episode scores."""
    name = f"{row.task} {row.policy}"
    s = row.scores
    if row.reference != refs.best:
        return [f"{name}: scored against {row.reference}, the references' best schedule is {refs.best}"]
    if not np.all(np.isfinite(s)):
        return [f"{name}: an episode score is not a number"]
    found = []
    if not math.isclose(row.score, float(np.mean(s)), rel_tol=TOLERANCE, abs_tol=TOLERANCE):
        found.append(f"{name}: score {row.score!r} in the card, the mean of its episode scores is {float(np.mean(s))!r}")
    ci = metrics.mean_ci95(s)
    if not _same(row.score_ci95, ci):
        found.append(f"{name}: 95 % CI {row.score_ci95!r} in the card, {ci!r} from its episode scores")
    better = metrics.improvement_share(s)
    if not _same(row.better_share, better):
        found.append(f"{name}: better in {row.better_share!r} of the episodes in the card, {better!r} from its episode scores")
    return found + _failures_consistency(row, name)


def _failures_consistency(row: TaskScore, name: str) -> list[str]:
    """What of a row's failures (a card of an older etmpc has none) does not follow from its episodes' counts."""
    counts = row.episode_failures
    if counts is None:
        return []
    if len(counts) != row.episodes or not all(isinstance(c, (int, float)) and math.isfinite(c) for c in counts):
        return [f"{name}: {len(counts)} episode failure counts for {row.episodes} episodes, or one not a number"]
    found = []
    mean = float(np.mean(counts))
    if row.failures_mean is None or not math.isclose(row.failures_mean, mean, rel_tol=TOLERANCE, abs_tol=TOLERANCE):
        found.append(f"{name}: failures {row.failures_mean!r} per episode in the card, {mean!r} from its episodes")
    if not _same(row.failures_ci95, metrics.mean_ci95(counts)):
        found.append(
            f"{name}: failures' 95 % CI {row.failures_ci95!r} in the card, {metrics.mean_ci95(counts)!r} from its episodes"
        )
    return found


def _aggregates(card: dict, rows: list[TaskScore]) -> list[str]:
    """Which of the card's aggregates do not follow from its rows: each computed again and compared as the
    card stores it (strict JSON: a tuple a list, NaN null), where equal floats are equal bits."""
    given = {a.get("policy"): a for a in card.get("aggregates", []) if isinstance(a, dict)}
    found = []
    for policy, mine in by_policy(rows).items():
        stated = given.get(policy)
        if stated is None:
            found.append(f"{policy}: no aggregate in the card")
            continue
        for key, value in strict(aggregate(mine).to_json()).items():
            if stated.get(key) != value:
                found.append(f"{policy}: aggregate {key} {stated.get(key)!r} in the card, {value!r} from its rows")
    return found


def sample(episodes: int, size: int, seed: int, row: int) -> list[int]:
    """The episodes replayed of a row: ``size`` of ``episodes`` (0: all), drawn from ``seed`` and the row's index."""
    if size == 0 or size >= episodes:
        return list(range(episodes))
    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(row,)))
    return sorted(int(e) for e in rng.choice(episodes, size=size, replace=False))


def verify(path: str | Path, size: int = SAMPLE, seed: int = 0, workers: int | None = None, progress: bool = False) -> Verdict:
    """Check the card at ``path`` (see the module's docstring), replaying ``size`` episodes of each row
    (0: all of them) drawn from ``seed`` on ``workers`` processes (default: by the work,
    :func:`~etmpc.evaluation.workers.workers_for`). A card that is not a suite result raises
    :class:`EtmpcError`."""
    where = f"card {path}"
    card = read_card(path)
    references = _suite(card, where)
    rows = _rows(card, where)
    mismatches, replayable = [], []
    for index, row in enumerate(rows):
        if _complete(row, references[row.task]):
            mismatches += [f"{path}: {line}" for line in _consistency(row, references[row.task])]
            replayable.append(index)
        else:
            mismatches.append(
                f"{path}: {row.task} {row.policy}: {len(row.episode_scores)} episode scores for "
                f"{row.episodes} episodes; the references have {references[row.task].episodes}"
            )
    mismatches += [f"{path}: {line}" for line in _aggregates(card, rows)]
    jobs, expected = [], []
    for index in replayable:
        row, refs = rows[index], references[rows[index].task]
        key = system_key(row.task)
        try:
            (policy,) = parse_policies(key.make(), [row.policy]).values()
        except EtmpcError as exc:
            raise EtmpcError(f"{where}: cannot replay {row.policy} on {row.task}: {exc}") from None
        # The stored test set, which the references were checked against when loaded: workers check its digest.
        for episode in sample(refs.episodes, size, seed, index):
            jobs.append((key, None, refs.test_set_sha256, row.policy, policy, 0, episode, 0, False))
            expected.append((row, refs, episode))
    outcomes = run_jobs(jobs, workers or workers_for(len(jobs)), progress) if jobs else []
    for (result, _, _), (row, refs, episode) in zip(outcomes, expected):
        best, cost = refs.costs(refs.periodic[refs.best][episode]), refs.costs(result.objective)
        replayed = float(metrics.normalized_scores(cost, best, refs.gap)) if result.finite else math.nan
        if not _same(replayed, row.episode_scores[episode]):
            mismatches.append(
                f"{path}: {row.task} {row.policy} episode {episode}: score {row.episode_scores[episode]!r} "
                f"in the card, {replayed!r} replayed"
            )
        if row.episode_failures is not None and row.episode_failures[episode] != result.failures:
            mismatches.append(
                f"{path}: {row.task} {row.policy} episode {episode}: {row.episode_failures[episode]!r} failures "
                f"in the card, {result.failures!r} replayed"
            )
    return Verdict(str(path), len(rows), len(jobs), mismatches)
