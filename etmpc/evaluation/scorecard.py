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
"""

from __future__ import annotations

import math
import platform
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from scipy import stats

from etmpc.common.errors import EtmpcError
from etmpc.common.outputs import write_json
from etmpc.evaluation import testsets as ts_mod
from etmpc.common import checks
from etmpc.evaluation.evaluate import Evaluation, check_policies, evaluate, parse_policies
from etmpc.evaluation.inputs import check_run_outputs, run_inputs
from etmpc.evaluation.references import (SUITE_VERSION, References, build_references, mean, references_path,
                                         software, stored)
from etmpc.evaluation.mainscript import UnguardedScript
from etmpc.evaluation.workers import shared_pools
from etmpc.systems import distinct, make_system, names, task_version

BOOTSTRAP_RESAMPLES = 2000
BOOTSTRAP_SEED = 0


# -- scores ----------------------------------------------------------------------------------------
@dataclass(frozen=True)
class TaskScore:
    """One trigger on one task."""

    task: str
    policy: str
    episodes: int
    objective_mean: float
    objective_sense: str
    recomputes_mean: float
    failures_mean: float | None  # the task's own failures (falls, ...), if it counts them
    solver_failures: int
    nonfinite_episodes: int
    score: float  # NaN when not scored (non-finite episodes, or an error)
    score_ci95: float
    episode_scores: list[float]  # s_e
    better_share: float  # share of episodes with a lower cost than the best periodic schedule (ties: half)
    cpu_ms: dict[str, float]  # mean per episode: solve, feedback, decide, total
    reference: str  # the best periodic schedule
    error: str | None = None
    task_version: int = 0  # the task's version it was scored on (docs/versioning.md)

    @classmethod
    def from_json(cls, data: dict) -> TaskScore:
        """A row as :func:`dataclasses.asdict` gave it and strict JSON kept it (a number not scored is
        ``null`` there, NaN here)."""
        nan = lambda v: math.nan if v is None else v  # noqa: E731
        fields = dict(data)
        for name in ("objective_mean", "recomputes_mean", "score", "score_ci95", "better_share"):
            fields[name] = nan(fields[name])
        fields["episode_scores"] = [nan(v) for v in fields["episode_scores"]]
        fields["cpu_ms"] = {k: nan(v) for k, v in dict(fields["cpu_ms"]).items()}
        return cls(**fields)


def task_score(refs: References, evaluation: Evaluation, spec: str) -> TaskScore:
    """``spec``'s score on ``refs``' task from ``evaluation`` (one run per episode, the references' test set)."""
    runs = sorted((r for r in evaluation.runs if r.policy == spec), key=lambda r: r.episode)
    cpu = [c for r, c in zip(evaluation.runs, evaluation.cpu or []) if r.policy == spec]
    summary = next(s for s in evaluation.summaries if s.policy == spec)
    parts = {k: 1e3 * float(np.mean([c[k] for c in cpu])) if cpu else math.nan for k in ("solve", "feedback", "decide")}
    return _scored(refs, spec, [r.episode for r in runs], [r.objective for r in runs], sum(not r.finite for r in runs),
                   asdict(summary), parts | {"total": sum(parts.values())})


def task_score_from_json(refs: References, evaluation: dict, spec: str) -> TaskScore:
    """The same from an evaluation's JSON (``etmpc evaluate --json``, reproduce's files), whose runs carry
    no CPU time; a stochastic policy's passes are averaged per episode."""
    by_episode: dict[int, list[float]] = {}
    nonfinite = 0
    for r in evaluation["runs"]:
        if r["policy"] == spec:  # a non-finite episode's objective is null in strict JSON
            by_episode.setdefault(r["episode"], []).append(math.nan if r["objective"] is None else r["objective"])
            nonfinite += not r["finite"]
    if evaluation["test_set"]["sha256"] != refs.test_set_sha256:
        raise EtmpcError(f"{refs.task}: {spec} was evaluated on another test set than the references'")
    episodes = sorted(by_episode)
    return _scored(refs, spec, episodes, [float(np.mean(by_episode[e])) for e in episodes], nonfinite,
                   evaluation["policies"][spec], {})


def _scored(refs: References, spec: str, episodes: list[int], objectives: list[float], nonfinite: int, summary: dict,
            cpu_ms: dict) -> TaskScore:
    if episodes != list(range(refs.episodes)):
        raise EtmpcError(f"{refs.task}: {spec} was not played on each of the references' {refs.episodes} episodes")
    best, costs, gap = refs.costs(refs.periodic[refs.best]), refs.costs(objectives), refs.gap
    if nonfinite:
        score = ci = better = math.nan
        per_episode: list[float] = []
    else:
        score = 100.0 * mean(best - costs) / gap
        per_episode = list(100.0 * (best - costs) / gap)
        ci = float(1.96 * np.std(per_episode, ddof=1) / math.sqrt(len(per_episode))) if len(per_episode) > 1 else math.nan
        better = float(np.mean((costs < best) + 0.5 * (costs == best)))
    return TaskScore(refs.task, spec, len(episodes), summary["objective_mean"], refs.objective_sense,
                     summary["recomputes_mean"], summary.get("failures_mean"), summary["solver_failures"], nonfinite,
                     score, ci, per_episode, better, cpu_ms, refs.best, task_version=task_version(refs.task))


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


def _iqm(*samples, axis=-1):
    """rliable's IQM: the 25 %-trimmed mean of every task's episode scores together."""
    return stats.trim_mean(np.concatenate(samples, axis=axis), 0.25, axis=axis)


def _mean_of_means(*samples, axis=-1):
    return np.mean(np.stack([np.mean(s, axis=axis) for s in samples], axis=-1), axis=-1)


def _interval(samples: list[np.ndarray], statistic) -> tuple[float, float]:
    if any(len(s) < 2 for s in samples):
        return (math.nan, math.nan)
    result = stats.bootstrap(tuple(samples), statistic, n_resamples=BOOTSTRAP_RESAMPLES, method="percentile",
                             vectorized=True, paired=False, rng=np.random.default_rng(BOOTSTRAP_SEED))
    return float(result.confidence_interval.low), float(result.confidence_interval.high)


def aggregate(rows: list[TaskScore]) -> Aggregate:
    """The IQM and the probability of improvement over the tasks of ``rows`` that were scored."""
    scored = [r for r in rows if math.isfinite(r.score)]
    policy = rows[0].policy if rows else ""
    if not scored:
        return Aggregate(policy, 0, math.nan, (math.nan, math.nan), math.nan, (math.nan, math.nan))
    scores = [np.asarray(r.episode_scores) for r in scored]
    improved = [(np.asarray(r.episode_scores) > 0) + 0.5 * (np.asarray(r.episode_scores) == 0) for r in scored]
    iqm = float(_iqm(*scores))
    improvement = float(np.mean([np.mean(x) for x in improved]))
    return Aggregate(policy, len(scored), iqm, _interval(scores, _iqm), improvement,
                     _interval([x.astype(float) for x in improved], _mean_of_means))


def profile(rows: list[TaskScore], thresholds: np.ndarray) -> np.ndarray:
    """The performance profile (rliable's): at each threshold ``tau``, the share of episodes whose
    score exceeds ``tau``, averaged over the tasks scored (each task weighs the same)."""
    scored = [np.asarray(r.episode_scores) for r in rows if math.isfinite(r.score)]
    if not scored:
        return np.full(len(thresholds), math.nan)
    return np.mean([(s[None, :] > np.asarray(thresholds)[:, None]).mean(axis=1) for s in scored], axis=0)


def profiles(card: Scorecard, thresholds: np.ndarray) -> dict[str, np.ndarray]:
    """Each trigger's :func:`profile` over the tasks it was scored on."""
    by_policy: dict[str, list[TaskScore]] = {}
    for row in card.rows:
        by_policy.setdefault(row.policy, []).append(row)
    return {policy: profile(rows, thresholds) for policy, rows in by_policy.items()}


# -- the command ------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Scorecard:
    tasks: list[str]
    references: dict[str, dict]  # task -> what it was scored against (best schedule, sha256, stored or computed)
    rows: list[TaskScore]
    aggregates: list[Aggregate]

    @property
    def complete(self) -> bool:
        """Every trigger was played on every task (none failed)."""
        return all(r.error is None for r in self.rows)

    def to_json(self) -> dict:
        return {"format": "etmpc-scorecard", "suite_version": SUITE_VERSION, "tasks": self.tasks,
                "task_versions": {task: task_version(task) for task in self.tasks},
                "references": self.references, "rows": [asdict(r) for r in self.rows],
                "aggregates": [asdict(a) for a in self.aggregates], "software": software(),
                "machine": {"processor": platform.processor() or platform.machine(), "system": platform.platform()}}


def score(policies: list, tasks: list[str] | None = None, test_set: str | None = None, workers: int | None = None,
          progress: bool = True, json_path: str | Path | None = None,
          say: Callable[[str], None] = lambda line: None, episodes: int | None = None) -> Scorecard:
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
        shown[task] |= {"best_periodic": refs.best, "oracle": refs.oracle_spec, "test_set_sha256": refs.test_set_sha256,
                        "episodes": refs.episodes, "recompute_price": refs.recompute_price, "gap": refs.gap}
    with shared_pools():  # each trigger played on its own (a failing one fails its row only), one pool for all
        rows = [play_and_score(task, references[task], policy, test_set, workers, progress)
                for task in tasks for policy in policies]
    by_policy: dict[str, list[TaskScore]] = {}
    for row in rows:
        by_policy.setdefault(row.policy, []).append(row)
    card = Scorecard(tasks, shown, rows, [aggregate(r) for r in by_policy.values()])
    if json_path is not None and card.complete:
        write_json(Path(json_path), card.to_json())
    return card


def _name(policy) -> str:
    return policy if isinstance(policy, str) else str(getattr(policy, "spec", type(policy).__name__))


def play_and_score(task: str, refs: References, policy, test_set: str | None = None, workers: int | None = None,
                   progress: bool = True) -> TaskScore:
    """``policy`` (a spec or an object) played on ``refs``' episodes of ``task`` and scored; a policy that
    fails (bad spec, its own error) gives a row that says so."""
    try:
        evaluation = evaluate(task, [policy], refs.episodes, workers=workers, testset_path=test_set, progress=progress)
    except UnguardedScript:  # the script's error, not the trigger's: no row can be played
        raise
    except EtmpcError as exc:  # the row says so (the table shows it): the command's own line says which rows failed
        return failed_task(task, _name(policy), str(exc))
    return task_score(refs, evaluation, evaluation.summaries[0].policy)


def format_scorecard(card: Scorecard) -> str:
    """The scorecard as text: per task and trigger, then the suite's aggregate per trigger."""
    width = max([18] + [len(r.policy) + 2 for r in card.rows])
    task_width = max([14] + [len(t) + 2 for t in card.tasks])
    head = (f"{'task':<{task_width}}{'policy':<{width}}{'objective':>11}{'computations':>14}{'failures':>10}"
            f"{'score':>9}{'± 95 % CI':>11}{'CPU ms/ep':>11}{'(solve':>9}{'feedback':>10}{'trigger)':>10}")
    lines = ["normalized score per task: 0 = its best periodic schedule, 100 = the oracle over it (a one-step "
             "lookahead: above 100 is possible); CPU: measured on this machine, per episode", head, "-" * len(head)]
    for r in card.rows:
        if r.error is not None:
            lines.append(f"{r.task:<{task_width}}{r.policy:<{width}}failed: {r.error}")
            continue
        failures = f"{r.failures_mean:.2f}" if r.failures_mean is not None else "-"
        score = f"{r.score:>9.1f}{r.score_ci95:>11.1f}" if math.isfinite(r.score) else \
            f"{'-':>9}{f'{r.nonfinite_episodes} non-finite':>11}"
        cpu = r.cpu_ms
        lines.append(f"{r.task:<{task_width}}{r.policy:<{width}}{r.objective_mean:>11.4f}{r.recomputes_mean:>14.2f}"
                     f"{failures:>10}{score}{cpu['total']:>11.1f}{cpu['solve']:>9.1f}{cpu['feedback']:>10.1f}"
                     f"{cpu['decide']:>10.1f}")
    lines += ["", "the suite: interquartile mean of every task's episode scores and probability of improvement over the best "
                  "periodic schedule, 95 % stratified bootstrap CIs",
              f"{'policy':<{width}}{'tasks':>6}{'IQM':>9}{'95 % CI':>18}{'P(improve)':>12}{'95 % CI':>16}"]
    for a in card.aggregates:
        lines.append(f"{a.policy:<{width}}{a.tasks:>6}{a.iqm:>9.1f}{f'[{a.iqm_ci95[0]:.1f}, {a.iqm_ci95[1]:.1f}]':>18}"
                     f"{a.probability_of_improvement:>12.2f}"
                     f"{f'[{a.probability_of_improvement_ci95[0]:.2f}, {a.probability_of_improvement_ci95[1]:.2f}]':>16}")
    refs = "; ".join(f"{t}: {r['best_periodic']} and {r['oracle']}" + ("" if r.get("stored") else " (computed)")
                     for t, r in card.references.items())
    lines.append(f"references: {refs}")
    return "\n".join(lines)
