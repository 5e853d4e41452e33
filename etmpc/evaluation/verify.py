"""``etmpc verify CARD``: check somebody's scorecard by replaying it.

A scorecard (``etmpc score --json``) holds, per task and policy, every episode's normalised score
against the task's stored references. Anyone with the policy can check it:

1. **It is this suite's card**: the suite's version, each task's version and test set are this
   etmpc's, and it was scored against the stored references (a card scored on another test set is
   not a suite result).
2. **It holds together**: every number the card states follows from the episodes it carries. Per
   row: each episode's score from its objective and the references (bit for bit); the objective's and
   the recomputes' means, the solver failures' total, the score (the mean of the episode scores), its
   confidence interval and the share of better episodes, the failures' mean and CI from its episodes;
   the episode count, task version, objective sense, best schedule and no non-finite episode; the CPU
   time's total from its parts (the CPU time itself is the scorer's machine's measurement: it is checked
   for consistency, never replayed). Per task, the references the card says it was scored against (best
   schedule, oracle, gap, price, test set) are the stored ones. The suite's aggregates (IQM, probability of
   improvement, their bootstrap intervals, the tasks counted) follow from the rows, as
   :mod:`etmpc.evaluation.scorecard` computes them (with :mod:`etmpc.evaluation.metrics`).
3. **It replays**: a seeded sample of each row's episodes is played again with the policy the row
   names (its spec: the handed-in ``py:MODULE:NAME``, ``rl:PATH``, ``sb3:PATH`` must be importable or
   readable here), and each episode's objective, recomputes, solver failures, failures and score must
   be the card's bit for bit (the loop's numbers do not depend on the number of workers, nor on the
   machine's kernels among x86-64 CPUs with fused multiply-add: ``docs/using.md``). Together: no number
   of a card can be changed without a line saying which.

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
from etmpc.common.provenance import LIBM_WORDS, libm_rounding
from etmpc.evaluation import metrics
from etmpc.evaluation.evaluate import parse_policies, run_jobs
from etmpc.evaluation import carried as carry
from etmpc.evaluation.references import SUITE_VERSION, References, stored
from etmpc.evaluation.card import TaskScore, aggregate, by_policy
from etmpc.evaluation.workers import workers_for
from etmpc.systems import system_key, task_version

FORMAT = "etmpc-scorecard"
SAMPLE = 5  # episodes replayed per row by default
TOLERANCE = 1e-9  # relative: a row's score against the mean of its episode scores (two summations)
CPU_PARTS = ("solve", "feedback", "decide", "total")


@dataclass(frozen=True)
class Verdict:
    """What :func:`verify` found: every mismatch (one line each) and what it replayed."""

    card: str
    rows: int
    replayed: int  # episodes played again
    mismatches: list[str]
    caution: str | None = None  # this machine's C library rounds as the card's did not: say so beside the verdict

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
        if isinstance(ref, dict) and not ref.get("stored") and ref.get("options"):
            references[task] = carry.carried(task, ref, where)  # a task with options: its references are the card's
            continue
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


def _stated_references(card: dict, references: dict[str, References]) -> list[str]:
    """Which of the numbers the card states of each task's references are not the stored references' own."""
    found = []
    for task, refs in references.items():
        stated = card["references"][task]
        own = {"best_periodic": refs.best, "oracle": refs.oracle_spec, "gap": refs.gap, "recompute_price": refs.recompute_price}
        for key, value in own.items():
            if not _same(stated.get(key), value):
                whose = "the stored" if stated.get("stored") else "from its episodes"
                found.append(f"{task}: references' {key} {stated.get(key)!r} in the card, {whose} {value!r}")
    return found


def _rows(card: dict, where: str) -> list[TaskScore]:
    try:
        rows = [TaskScore.from_json(row) for row in card["rows"]]
    except (KeyError, TypeError, ValueError) as exc:  # a field of another type says which (BadValue); the rest as raised
        said = str(exc) if isinstance(exc, EtmpcError) else repr(exc)
        raise EtmpcError(f"{where} holds a row that is not a row ({said})") from None
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


def _same(a, b) -> bool:
    """Equal as the card stores numbers: NaN (JSON's null) equals NaN."""
    return (isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b)) or a == b


def _complete(row: TaskScore, refs: References) -> bool:
    """``row`` has a score for each of the references' episodes (else nothing of it can be checked)."""
    return row.episodes == refs.episodes == len(row.episode_scores)


def _consistency(row: TaskScore, refs: References, version) -> list[str]:
    """What in a complete ``row`` does not follow from its own episodes (``version``: the card's task version)."""
    name = f"{row.task} {row.policy}"
    s = row.scores
    if row.reference != refs.best:
        return [f"{name}: scored against {row.reference}, the references' best schedule is {refs.best}"]
    if not np.all(np.isfinite(s)):
        return [f"{name}: an episode score is not a number"]
    found = [
        f"{name}: {what} {mine!r} in the row, {theirs!r} {whose}"
        for what, mine, theirs, whose in (
            ("task version", row.task_version, version, "in the card's task versions"),
            ("objective sense", row.objective_sense, refs.objective_sense, "the task's"),
            ("non-finite episodes", row.nonfinite_episodes, 0, "in a row that was scored"),
        )
        if mine != theirs
    ]
    found += _episodes_consistency(row, refs, name) + _cpu_consistency(row, name)
    if not math.isclose(row.score, float(np.mean(s)), rel_tol=TOLERANCE, abs_tol=TOLERANCE):
        found.append(f"{name}: score {row.score!r} in the card, the mean of its episode scores is {float(np.mean(s))!r}")
    ci = metrics.mean_ci95(s)
    if not _same(row.score_ci95, ci):
        found.append(f"{name}: 95 % CI {row.score_ci95!r} in the card, {ci!r} from its episode scores")
    better = metrics.improvement_share(s)
    if not _same(row.better_share, better):
        found.append(f"{name}: better in {row.better_share!r} of the episodes in the card, {better!r} from its episode scores")
    return found + _failures_consistency(row, name)


def _mean_differs(stated, values) -> bool:
    return not (
        isinstance(stated, (int, float)) and math.isclose(stated, float(np.mean(values)), rel_tol=TOLERANCE, abs_tol=TOLERANCE)
    )


def _episodes_consistency(row: TaskScore, refs: References, name: str) -> list[str]:
    """What of a row's objective, recomputes, solver failures and episode scores does not follow from the
    objectives, recomputes and solver failures it carries per episode."""
    carried = {
        "episode_objectives": row.episode_objectives,
        "episode_recomputes": row.episode_recomputes,
        "episode_solver_failures": row.episode_solver_failures,
    }
    for key, values in carried.items():
        if values is None:
            return [f"{name}: no {key} (a row of an older etmpc): score the policy again to verify its numbers"]
        if len(values) != row.episodes:
            return [f"{name}: {len(values)} {key} for {row.episodes} episodes"]
    objectives = np.asarray(row.episode_objectives, dtype=float)
    if not np.all(np.isfinite(objectives)):
        return [f"{name}: an episode objective is not a number in a row that was scored"]
    best = refs.costs(refs.periodic[refs.best])
    expected = [float(v) for v in metrics.normalized_scores(refs.costs(objectives), best, refs.gap)]
    found = [
        f"{name} episode {e}: score {row.episode_scores[e]!r} in the card, {v!r} from its objective {float(objectives[e])!r}"
        for e, v in enumerate(expected)
        if row.episode_scores[e] != v
    ]
    if _mean_differs(row.objective_mean, objectives):
        found.append(f"{name}: objective {row.objective_mean!r} in the card, {float(np.mean(objectives))!r} from its episodes")
    if _mean_differs(row.recomputes_mean, row.episode_recomputes):
        mean = float(np.mean(row.episode_recomputes))
        found.append(f"{name}: recomputes {row.recomputes_mean!r} per episode in the card, {mean!r} from its episodes")
    if row.solver_failures != sum(row.episode_solver_failures):
        total = sum(row.episode_solver_failures)
        found.append(f"{name}: {row.solver_failures!r} solver failures in the card, {total!r} from its episodes")
    return found


def _cpu_consistency(row: TaskScore, name: str) -> list[str]:
    """What of a row's CPU time per episode (the scorer's measurement, not replayed) does not hold together:
    the four parts, each a finite number >= 0, the total their sum (none at all: not measured)."""
    cpu = row.cpu_ms
    if not cpu:
        return []
    if sorted(cpu) != sorted(CPU_PARTS):
        return [f"{name}: CPU time of {', '.join(sorted(cpu))} in the card; a row measures {', '.join(CPU_PARTS)}"]
    if not all(isinstance(v, (int, float)) and math.isfinite(v) and v >= 0 for v in cpu.values()):
        return [f"{name}: a CPU time in the card is not a finite number >= 0 ({cpu})"]
    parts = cpu["solve"] + cpu["feedback"] + cpu["decide"]
    if not math.isclose(cpu["total"], parts, rel_tol=TOLERANCE, abs_tol=TOLERANCE):
        return [f"{name}: CPU total {cpu['total']!r} ms in the card, its parts sum to {parts!r}"]
    return []


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
    found = [f"{policy}: an aggregate in the card, but no rows of it" for policy in given if policy not in by_policy(rows)]
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
            version = card["task_versions"][row.task]
            mismatches += [f"{path}: {line}" for line in _consistency(row, references[row.task], version)]
            replayable.append(index)
        else:
            mismatches.append(
                f"{path}: {row.task} {row.policy}: {len(row.episode_scores)} episode scores for "
                f"{row.episodes} episodes; the references have {references[row.task].episodes}"
            )
    mismatches += [f"{path}: {line}" for line in _stated_references(card, references) + _aggregates(card, rows)]
    jobs, expected = [], []
    for index in replayable:
        row, refs = rows[index], references[rows[index].task]
        key = system_key(row.task, None, carry.options_of(card, row.task))
        try:
            (policy,) = parse_policies(key.make(), [row.policy]).values()
        except EtmpcError as exc:
            raise EtmpcError(f"{where}: cannot replay {row.policy} on {row.task}: {exc}") from None
        # The stored test set, which the references were checked against when loaded: workers check its digest.
        for episode in sample(refs.episodes, size, seed, index):
            jobs.append((key, None, refs.test_set_sha256, row.policy, policy, 0, episode, 0, False))
            expected.append((row, refs, episode))
    # the references a card carries (a task scored with options): replayed too, each sampled as a row after the card's
    checked = carry.reference_jobs(card, references, lambda episodes, k: sample(episodes, size, seed, len(rows) + k))
    jobs += [job for job, _ in checked]
    outcomes = run_jobs(jobs, workers or workers_for(len(jobs)), progress) if jobs else []
    for (result, _, _), (_, (task, spec, episode, stated)) in zip(outcomes[len(expected) :], checked):
        if not _same(stated, result.objective):
            mismatches.append(
                f"{path}: {task} references' {spec} episode {episode}: objective {stated!r} in the card, "
                f"{result.objective!r} replayed"
            )
    outcomes = outcomes[: len(expected)]
    for (result, _, _), (row, refs, episode) in zip(outcomes, expected):
        best, cost = refs.costs(refs.periodic[refs.best][episode]), refs.costs(result.objective)
        replayed = float(metrics.normalized_scores(cost, best, refs.gap)) if result.finite else math.nan
        if not _same(replayed, row.episode_scores[episode]):
            mismatches.append(
                f"{path}: {row.task} {row.policy} episode {episode}: score {row.episode_scores[episode]!r} "
                f"in the card, {replayed!r} replayed"
            )
        replayed_numbers = {
            "objective": (row.episode_objectives, result.objective),
            "recomputes": (row.episode_recomputes, result.recomputes),
            "solver failures": (row.episode_solver_failures, result.solver_failures),
            "failures": (row.episode_failures, result.failures),
        }
        for what, (carried, value) in replayed_numbers.items():
            if carried is not None and not _same(carried[episode], value):
                mismatches.append(
                    f"{path}: {row.task} {row.policy} episode {episode}: {what} {carried[episode]!r} in the card, "
                    f"{value!r} replayed"
                )
    return Verdict(str(path), len(rows), len(jobs), mismatches, _caution(card))


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
        f"{LIBM_WORDS.get(theirs, 'not recorded (an older etmpc)')}: replays of the kicks tasks, the reacher and "
        "the quadrotor may differ from the card's with nothing wrong in it; verify it on a machine like the card's"
    )
