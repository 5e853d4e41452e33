"""The suite's scorecard: how good is a trigger, on every task, against fixed reference points?

**Normalized score, per task.** On a task's test set, with costs ``c`` (the objective where lower is
better; a profit is negated), the task's references per episode ``e`` are its *best periodic
schedule* ``B_e`` (the ``every:T``, ``T = 1..N``, with the best mean objective on that test set) and
the *oracle* over that schedule ``O_e`` (``oracle:every:T``, the one-step lookahead with the stored
future). With the reference gap ``D = mean_e (B_e - O_e)``, a trigger ``P`` scores

    score = 100 * mean_e (B_e - P_e) / D,

per episode ``s_e = 100 (B_e - P_e) / D`` (its mean is the score): 0 is the best periodic schedule,
100 the oracle, exactly. Dividing by the *mean* gap, not each episode's own, keeps an episode whose
two references nearly tie from dominating. Above 100 is possible: the oracle is a one-step lookahead
over that schedule, not a bound on every trigger. The 95 % CI is ``1.96 sd(s_e) / sqrt(n)`` (as
``etmpc evaluate --against``). An episode that ends on a non-finite state leaves the task unscored.

**The suite's aggregate**, over the tasks scored, as rliable computes it (Agarwal et al. 2021) with
a task's episodes as its runs: the interquartile mean of every episode score of every task together
(``scipy.stats.trim_mean(scores, 0.25)``: the middle half of the episodes, so neither a few extreme
episodes nor one task decides it), and the probability of improvement over the best periodic schedule
(per task, the share of episodes where the trigger's cost is lower, ties counting half; averaged over
tasks), each with a 95 % stratified bootstrap CI: episodes resampled within each task
(``scipy.stats.bootstrap`` over one sample per task, 2000 resamples, percentile intervals, seeded),
the references' gap held fixed.

**References** are stored with the tasks (``tasks/<domain>/<task>_references.json``): every periodic
schedule's and the oracle's objective per stored episode, with the suite's version, the test set's
sha256 and the software that computed them, so scoring a trigger plays only that trigger.
``etmpc score --references`` rebuilds them; on another test set they are computed for the run.

**Compute.** Beside the count of computations, each episode's measured CPU time of the MPC's solves,
the feedback (the LQR) and the trigger's own decisions (a rollout's simulations included), so that a
saving is shown net of what the trigger itself costs. These are wall-clock figures of this machine.

**Where.** The statistics are pure functions of score arrays in :mod:`etmpc.evaluation.metrics`; this
module holds the results (a :class:`TaskScore` per task and trigger, an :class:`Aggregate` per trigger, the
:class:`Scorecard`, each with its JSON) and plays the triggers; :mod:`etmpc.evaluation.scoretable`
writes the card as text.
"""

from __future__ import annotations

import math
import platform
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from etmpc.common.errors import EtmpcError
from etmpc.common.outputs import write_json
from etmpc.evaluation import metrics
from etmpc.evaluation import testsets as ts_mod
from etmpc.common import checks
from etmpc.evaluation.evaluate import Evaluation, check_policies, evaluate, parse_policies
from etmpc.evaluation.inputs import check_run_outputs, run_inputs
from etmpc.evaluation.metrics import BOOTSTRAP_RESAMPLES, BOOTSTRAP_SEED  # noqa: F401  (the card's statistics)
from etmpc.evaluation.references import SUITE_VERSION, References, build_references, references_path, software, stored
from etmpc.evaluation.mainscript import UnguardedScript
from etmpc.evaluation.scoretable import format_scorecard  # noqa: F401  (the card as text)
from etmpc.evaluation.workers import shared_pools
from etmpc.systems import distinct, make_system, names, task_version


def _nan(value):
    """A number as strict JSON kept it: ``null`` (not scored) is NaN."""
    return math.nan if value is None else value


# -- scores ----------------------------------------------------------------------------------------
@dataclass(frozen=True)
class TaskScore:
    """One trigger on one task. Its JSON (:meth:`to_json`, :meth:`from_json`) is a card's row."""

    task: str
    policy: str
    episodes: int
    objective_mean: float
    objective_sense: str  # the objective's, for display: the scores are higher-is-better whatever it is
    recomputes_mean: float
    failures_mean: float | None  # the task's own failures (falls, ...), if it counts them
    solver_failures: int
    nonfinite_episodes: int
    score: float  # NaN when not scored (non-finite episodes, or an error)
    score_ci95: float
    episode_scores: list[float]  # s_e
    better_share: float  # share of episodes with a lower cost than the best periodic schedule (ties: half)
    cpu_ms: dict[str, float]  # mean per episode: solve, feedback, decide, total ({}: not measured)
    reference: str  # the best periodic schedule
    error: str | None = None
    task_version: int = 0  # the task's version it was scored on (docs/versioning.md)
    # The task's failures, if it counts them (None: it does not, or a row of an older etmpc): the 95 % CI of
    # failures_mean, 1.96 sd / sqrt(n) over the episodes (NaN below two), and each episode's count, in the
    # order of episode_scores, so that two triggers' failures can be paired episode by episode.
    failures_ci95: float | None = None
    episode_failures: list[float] | None = None

    @property
    def scores(self) -> np.ndarray:
        """The episode scores as an array, for :mod:`etmpc.evaluation.metrics`."""
        return np.asarray(self.episode_scores, dtype=float)

    @property
    def scored(self) -> bool:
        return math.isfinite(self.score)

    def to_json(self) -> dict:
        """The row as a card stores it (a number not scored is NaN here, ``null`` once written)."""
        return asdict(self)

    @classmethod
    def from_json(cls, data: dict) -> TaskScore:
        """A row as :meth:`to_json` gave it and strict JSON kept it (a number not scored is ``null``
        there, NaN here)."""
        fields = dict(data)
        for name in ("objective_mean", "recomputes_mean", "score", "score_ci95", "better_share"):
            fields[name] = _nan(fields[name])
        fields["episode_scores"] = [_nan(v) for v in fields["episode_scores"]]
        fields["cpu_ms"] = {k: _nan(v) for k, v in dict(fields["cpu_ms"]).items()}
        if fields.get("episode_failures") is not None:  # the row counted failures: null is a number not known
            fields["failures_mean"], fields["failures_ci95"] = _nan(fields["failures_mean"]), _nan(fields.get("failures_ci95"))
        return cls(**fields)


def task_score(refs: References, evaluation: Evaluation | dict, spec: str) -> TaskScore:
    """``spec``'s score on ``refs``' task from ``evaluation`` on the references' test set: as played (an
    :class:`Evaluation`, whose runs carry their CPU time) or its JSON (``etmpc evaluate --json``,
    reproduce's files: no CPU time). A stochastic policy's passes are averaged per episode."""
    data = evaluation.to_json(cpu=True) if isinstance(evaluation, Evaluation) else evaluation
    by_episode: dict[int, list[float]] = {}
    failures: dict[int, list[int | None]] = {}
    nonfinite = 0
    runs = [r for r in data["runs"] if r["policy"] == spec]
    for r in runs:  # a non-finite episode's objective is null in strict JSON
        by_episode.setdefault(r["episode"], []).append(_nan(r["objective"]))
        failures.setdefault(r["episode"], []).append(r.get("failures"))
        nonfinite += not r["finite"]
    if data["test_set"]["sha256"] != refs.test_set_sha256:
        raise EtmpcError(f"{refs.task}: {spec} was evaluated on another test set than the references'")
    cpu = [c for r, c in zip(data["runs"], data.get("cpu_seconds") or []) if r["policy"] == spec]
    parts = {k: 1e3 * float(np.mean([c[k] for c in cpu])) for k in ("solve", "feedback", "decide")} if cpu else {}
    episodes = sorted(by_episode)
    counted = all(f is not None for e in episodes for f in failures[e])  # by a task that counts them
    return _scored(
        refs,
        spec,
        episodes,
        [float(np.mean(by_episode[e])) for e in episodes],
        nonfinite,
        data["policies"][spec],
        parts | {"total": sum(parts.values())} if parts else {},
        # an episode's count, or its mean over a stochastic policy's passes
        [f[0] if len(f) == 1 else float(np.mean(f)) for f in map(failures.get, episodes)] if counted else None,
    )


def _scored(
    refs: References,
    spec: str,
    episodes: list[int],
    objectives: list[float],
    nonfinite: int,
    summary: dict,
    cpu_ms: dict,
    episode_failures: list[float] | None = None,
) -> TaskScore:
    if episodes != list(range(refs.episodes)):
        raise EtmpcError(f"{refs.task}: {spec} was not played on each of the references' {refs.episodes} episodes")
    best, costs, gap = refs.costs(refs.periodic[refs.best]), refs.costs(objectives), refs.gap
    if nonfinite:
        score = ci = better = math.nan
        per_episode: list[float] = []
    else:
        score = metrics.normalized_score(costs, best, gap)
        per_episode = list(metrics.normalized_scores(costs, best, gap))
        ci = metrics.mean_ci95(per_episode)
        better = metrics.improvement_share(best - costs)
    return TaskScore(
        refs.task,
        spec,
        len(episodes),
        summary["objective_mean"],
        refs.objective_sense,
        summary["recomputes_mean"],
        summary.get("failures_mean"),
        summary["solver_failures"],
        nonfinite,
        score,
        ci,
        per_episode,
        better,
        cpu_ms,
        refs.best,
        task_version=task_version(refs.task),
        failures_ci95=None
        if episode_failures is None
        else _nan(summary.get("failures_ci95", metrics.mean_ci95(episode_failures))),
        episode_failures=episode_failures,
    )


def failed_task(task: str, spec: str, error: str) -> TaskScore:
    nan = math.nan
    return TaskScore(task, spec, 0, nan, "", nan, None, 0, 0, nan, nan, [], nan, {}, "", error, task_version(task))


@dataclass(frozen=True)
class Aggregate:
    """A trigger over the suite's tasks scored (see the module's docstring)."""

    policy: str
    tasks: int
    iqm: float
    iqm_ci95: tuple[float, float]
    probability_of_improvement: float
    probability_of_improvement_ci95: tuple[float, float]

    def to_json(self) -> dict:
        return asdict(self)

    @classmethod
    def from_json(cls, data: dict) -> Aggregate:
        pair = lambda v: tuple(_nan(x) for x in v)  # noqa: E731
        return cls(
            data["policy"],
            data["tasks"],
            _nan(data["iqm"]),
            pair(data["iqm_ci95"]),
            _nan(data["probability_of_improvement"]),
            pair(data["probability_of_improvement_ci95"]),
        )


def aggregate(rows: list[TaskScore]) -> Aggregate:
    """The IQM and the probability of improvement over the tasks of ``rows`` that were scored."""
    scored = [r.scores for r in rows if r.scored]
    policy = rows[0].policy if rows else ""
    if not scored:
        return Aggregate(policy, 0, math.nan, (math.nan, math.nan), math.nan, (math.nan, math.nan))
    return Aggregate(
        policy,
        len(scored),
        metrics.iqm(scored),
        metrics.iqm_ci95(scored),
        metrics.probability_of_improvement(scored),
        metrics.probability_of_improvement_ci95(scored),
    )


def profile(rows: list[TaskScore], thresholds: np.ndarray) -> np.ndarray:
    """The performance profile (:func:`~etmpc.evaluation.metrics.performance_profile`) over the tasks
    of ``rows`` that were scored."""
    return metrics.performance_profile([r.scores for r in rows if r.scored], thresholds)


def by_policy(rows: list[TaskScore]) -> dict[str, list[TaskScore]]:
    """``rows`` grouped by trigger, in the order the triggers first appear."""
    groups: dict[str, list[TaskScore]] = {}
    for row in rows:
        groups.setdefault(row.policy, []).append(row)
    return groups


def profiles(card: Scorecard, thresholds: np.ndarray) -> dict[str, np.ndarray]:
    """Each trigger's :func:`profile` over the tasks it was scored on."""
    return {policy: profile(rows, thresholds) for policy, rows in by_policy(card.rows).items()}


# -- the command ------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Scorecard:
    """The card: its rows and aggregates, and what each task was scored against. Its JSON
    (:meth:`to_json`, :meth:`from_json`) is what ``etmpc score --json`` writes."""

    tasks: list[str]
    references: dict[str, dict]  # task -> what it was scored against (best schedule, sha256, stored or computed)
    rows: list[TaskScore]
    aggregates: list[Aggregate]

    @property
    def complete(self) -> bool:
        """Every trigger was played on every task (none failed)."""
        return all(r.error is None for r in self.rows)

    def to_json(self) -> dict:
        return {
            "format": "etmpc-scorecard",
            "suite_version": SUITE_VERSION,
            "tasks": self.tasks,
            "task_versions": {task: task_version(task) for task in self.tasks},
            "references": self.references,
            "rows": [r.to_json() for r in self.rows],
            "aggregates": [a.to_json() for a in self.aggregates],
            "software": software(),
            "machine": {"processor": platform.processor() or platform.machine(), "system": platform.platform()},
        }

    @classmethod
    def from_json(cls, data: dict) -> Scorecard:
        """A card as :meth:`to_json` wrote it (its versions, software and machine are the JSON's to check)."""
        return cls(
            list(data["tasks"]),
            dict(data["references"]),
            [TaskScore.from_json(r) for r in data["rows"]],
            [Aggregate.from_json(a) for a in data["aggregates"]],
        )


def score(
    policies: list,
    tasks: list[str] | None = None,
    test_set: str | None = None,
    workers: int | None = None,
    progress: bool = True,
    json_path: str | Path | None = None,
    say: Callable[[str], None] = lambda line: None,
    episodes: int | None = None,
) -> Scorecard:
    """Score every trigger of ``policies`` (spec strings or policy objects, as :func:`etmpc.evaluate`
    takes) on every task of ``tasks`` (default: the whole suite), each on its stored test set at its
    own price, against the stored references (see the module's docstring). ``test_set``: another test
    set, for one task; its references are computed for the run. ``episodes``: the first N episodes
    only (each task's references then of those episodes: 0 and 100 stay exact). A trigger that fails
    on a task has that task's row say so; the others are still scored (:attr:`Scorecard.complete` is
    then False, and ``json_path`` is not written: a card with a failed row never is).

    Every argument, every trigger on every task, and the outputs are checked before any episode is
    played, with the command line's messages (:class:`EtmpcError`): a spec that does not parse, a
    trigger given twice, an empty or repeated task, an output that is one of the run's inputs."""
    check_policies(policies)
    if tasks is not None and (isinstance(tasks, (str, bytes)) or not isinstance(tasks, (list, tuple))):
        raise EtmpcError(f"tasks: a list of task names is needed, got {type(tasks).__name__} {tasks!r}")
    if tasks is not None and not tasks:
        raise EtmpcError("tasks: the list is empty; give at least one task, or None for every task of the suite")
    if episodes is not None:
        checks.argument("episodes", lambda v: checks.at_least(checks.whole(v), 1), episodes)
    if workers is not None:
        checks.argument("workers", checks.workers, workers)
    if test_set is not None and not isinstance(test_set, (str, Path)):
        raise EtmpcError(f"test_set: a file path is needed, got {type(test_set).__name__} {test_set!r}")
    tasks = distinct(names() if tasks is None else tasks)
    if test_set is not None and len(tasks) != 1:
        raise EtmpcError("--test-set belongs to one task: give exactly one --task with it")
    if test_set is not None and not Path(test_set).is_file():
        raise EtmpcError(f"test set {test_set} not found")
    for task in tasks:  # each trigger parsed (or checked) on each task: a bad one fails before any episode
        try:
            parse_policies(make_system(task), policies)
        except EtmpcError as exc:
            raise EtmpcError(f"{task}: {exc}") from None
    check_run_outputs({"--json": json_path}, inputs=run_inputs(policies, test_set))
    if test_set is None:  # every task's references checked before any trigger is played
        references = {task: stored(task, episodes) for task in tasks}
        shown = {task: {"stored": references_path(task).name} for task in tasks}
    else:
        (task,) = tasks
        system = make_system(task)
        ts_mod.load(test_set, system.domain, system.task)  # a bad test set fails before the references are played
        say(f"{task}: no stored references for test set {test_set}: computing them for this run")
        refs = build_references(task, test_set, workers, progress, say)
        references = {task: refs if episodes is None else refs.head(episodes)}
        shown = {task: {"stored": None}}
    for task, refs in references.items():
        shown[task] |= {
            "best_periodic": refs.best,
            "oracle": refs.oracle_spec,
            "test_set_sha256": refs.test_set_sha256,
            "episodes": refs.episodes,
            "recompute_price": refs.recompute_price,
            "gap": refs.gap,
        }
    with shared_pools():  # each trigger played on its own (a failing one fails its row only), one pool for all
        rows = [
            play_and_score(task, references[task], policy, test_set, workers, progress) for task in tasks for policy in policies
        ]
    card = Scorecard(tasks, shown, rows, [aggregate(r) for r in by_policy(rows).values()])
    if json_path is not None and card.complete:
        write_json(Path(json_path), card.to_json())
    return card


def _name(policy) -> str:
    return policy if isinstance(policy, str) else str(getattr(policy, "spec", type(policy).__name__))


def play_and_score(
    task: str, refs: References, policy, test_set: str | None = None, workers: int | None = None, progress: bool = True
) -> TaskScore:
    """``policy`` (a spec or an object) played on ``refs``' episodes of ``task`` and scored; a policy that
    fails (bad spec, its own error) gives a row that says so."""
    try:
        evaluation = evaluate(task, [policy], refs.episodes, workers=workers, testset_path=test_set, progress=progress)
    except UnguardedScript:  # the script's error, not the trigger's: no row can be played
        raise
    except EtmpcError as exc:  # the row says so (the table shows it): the command's own line says which rows failed
        return failed_task(task, _name(policy), str(exc))
    return task_score(refs, evaluation, evaluation.summaries[0].policy)
