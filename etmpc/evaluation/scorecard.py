"""The suite's scorecard: how good is a policy, on every task, against fixed reference points?

**Normalized score, per task.** On a task's test set, with costs ``c`` (the objective where lower is
better; a profit is negated), the task's references per episode ``e`` are its *best periodic
schedule* ``B_e`` (the ``every:T``, ``T = 1..N``, with the best mean objective on that test set) and
the *oracle* over that schedule ``O_e`` (``oracle:every:T``, the one-step lookahead with the stored
future). With the reference gap ``D = mean_e (B_e - O_e)``, a policy ``P`` scores

    score = 100 * mean_e (B_e - P_e) / D,

per episode ``s_e = 100 (B_e - P_e) / D`` (its mean is the score): 0 is the best periodic schedule,
100 the oracle, exactly. Dividing by the *mean* gap, not each episode's own, keeps an episode whose
two references nearly tie from dominating. Above 100 is possible: the oracle is a one-step lookahead
over that schedule, not a bound. The 95 % CI is ``1.96 sd(s_e) / sqrt(n)`` (as
``etmpc evaluate --against``). An episode that ends on a non-finite state leaves the task unscored.

**The suite's aggregate**, over the tasks scored, as rliable computes it (Agarwal et al. 2021) with
a task's episodes as its runs: the interquartile mean of every episode score of every task together
(``scipy.stats.trim_mean(scores, 0.25)``: the middle half of the episodes, so neither a few extreme
episodes nor one task decides it), and the probability of improvement over the best periodic schedule
(per task, the share of episodes where the policy's cost is lower, ties counting half; averaged over
tasks), each with a 95 % stratified bootstrap CI: episodes resampled within each task
(``scipy.stats.bootstrap`` over one sample per task, 2000 resamples, percentile intervals, seeded),
the references' gap held fixed.

**References** are stored with the tasks (``tasks/<domain>/<task>/references.json``): every periodic
schedule's and the oracle's objective per stored episode, with the suite's version, the test set's
sha256 and the software that computed them, so scoring a policy plays only that policy.
``etmpc score --references`` rebuilds them; on another test set they are computed for the run.

**Compute.** Beside the count of recomputes, each episode's measured CPU time of the MPC's solves,
the feedback (the LQR) and the policy's own decisions (a rollout's simulations included), so that a
saving is shown net of what the policy itself costs. These are wall-clock figures of this machine.

**Where.** The statistics are pure functions of score arrays in :mod:`etmpc.evaluation.metrics`; this
module holds the results (a :class:`TaskScore` per task and policy, an :class:`Aggregate` per policy, the
:class:`Scorecard`, each with its JSON) and plays the policies; :mod:`etmpc.evaluation.scoretable`
writes the card as text.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from etmpc.common.errors import EtmpcError
from etmpc.common.outputs import write_json
from etmpc.common.progress import Progress
from etmpc.evaluation import metrics
from etmpc.evaluation import testsets as ts_mod
from etmpc.common import checks
from etmpc.evaluation.arguments import check_policies, parse_policies
from etmpc.evaluation.evaluate import Evaluation, evaluate
from etmpc.evaluation.inputs import check_run_outputs, run_inputs
from etmpc.evaluation.metrics import BOOTSTRAP_RESAMPLES, BOOTSTRAP_SEED  # noqa: F401  (the card's statistics)
from etmpc.evaluation.references import References, build_references, references_path, stored
from etmpc.evaluation.card import (  # noqa: F401  (the card's records, here before they had their module)
    Aggregate,
    Scorecard,
    TaskScore,
    _nan,
    aggregate,
    by_policy,
    failed_task,
    profile,
    profiles,
)
from etmpc.evaluation.mainscript import UnguardedScript
from etmpc.evaluation.scoretable import format_scorecard  # noqa: F401  (the card as text)
from etmpc.evaluation.backends import shared_pools
from etmpc.systems import distinct, folder_name, make_system, names, system_key, task_version


# -- scores ----------------------------------------------------------------------------------------
def task_score(refs: References, evaluation: Evaluation | dict, spec: str) -> TaskScore:
    """``spec``'s score on ``refs``' task from ``evaluation`` on the references' test set: as played (an
    :class:`Evaluation`, whose runs carry their CPU time) or its JSON (``etmpc evaluate --json``,
    reproduce's files: no CPU time). A stochastic policy's passes are averaged per episode."""
    data = evaluation.to_json(cpu=True) if isinstance(evaluation, Evaluation) else evaluation
    by_episode: dict[int, list[float]] = {}
    failures: dict[int, list[int | None]] = {}
    recomputes: dict[int, list[int]] = {}
    solver_failures: dict[int, int] = {}
    nonfinite = 0
    runs = [r for r in data["runs"] if r["policy"] == spec]
    for r in runs:  # a non-finite episode's objective is null in strict JSON
        by_episode.setdefault(r["episode"], []).append(_nan(r["objective"]))
        failures.setdefault(r["episode"], []).append(r.get("failures"))
        recomputes.setdefault(r["episode"], []).append(r["recomputes"])
        solver_failures[r["episode"]] = solver_failures.get(r["episode"], 0) + int(r["solver_failures"])
        nonfinite += not r["finite"]
    if data["test_set"]["sha256"] != refs.test_set_sha256:
        raise EtmpcError(f"{refs.task}: {spec} was evaluated on another test set than the references'")
    cpu = [c for r, c in zip(data["runs"], data.get("cpu_seconds") or []) if r["policy"] == spec]
    parts = {k: 1e3 * float(np.mean([c[k] for c in cpu])) for k in ("solve", "feedback", "decide")} if cpu else {}
    episodes = sorted(by_episode)
    return _scored(
        refs,
        spec,
        episodes,
        [float(np.mean(by_episode[e])) for e in episodes],
        nonfinite,
        data["policies"][spec],
        parts | {"total": sum(parts.values())} if parts else {},
        _counted(failures, episodes),
        [_per_episode(recomputes[e]) for e in episodes],
        [solver_failures[e] for e in episodes],
    )


def _per_episode(values: Sequence[float]) -> float:
    """An episode's count, or its mean over a stochastic policy's passes."""
    return values[0] if len(values) == 1 else float(np.mean(values))


def _counted(failures: dict[int, list[int | None]], episodes: list[int]) -> list[float] | None:
    """Each episode's failures (:func:`_per_episode`), or None where a run did not count them (a task that
    does not count its failures)."""
    known = {e: [f for f in failures[e] if f is not None] for e in episodes}
    if any(len(known[e]) < len(failures[e]) for e in episodes):
        return None
    return [_per_episode(known[e]) for e in episodes]


def _scored(
    refs: References,
    spec: str,
    episodes: list[int],
    objectives: list[float],
    nonfinite: int,
    summary: dict,
    cpu_ms: dict,
    episode_failures: list[float] | None = None,
    episode_recomputes: list[float] | None = None,
    episode_solver_failures: list[int] | None = None,
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
        episode_objectives=[float(v) for v in objectives],
        episode_recomputes=episode_recomputes,
        episode_solver_failures=episode_solver_failures,
    )


# -- the command ------------------------------------------------------------------------------------
def score(
    policies: list,
    tasks: list[str] | None = None,
    test_set: str | None = None,
    workers: int | None = None,
    progress: bool = True,
    json_path: str | Path | None = None,
    say: Callable[[str], None] = lambda line: None,
    episodes: int | None = None,
    options=(),
) -> Scorecard:
    """Score every policy of ``policies`` (spec strings or policy objects, as :func:`etmpc.evaluate`
    takes) on every task of ``tasks`` (default: the whole suite), each on its stored test set at its
    own price, against the stored references (see the module's docstring). ``test_set``: another test
    set, for one task; its references are computed for the run. ``episodes``: the first N episodes
    only (each task's references then of those episodes: 0 and 100 stay exact; references computed for the run
    are played on those episodes only, the best schedule chosen there). ``options``: the tasks' options
    (:mod:`etmpc.systems.options`, a mapping or ``(name, value)`` pairs, the same for every task), under which
    the stored references do not hold: they are computed for the run, and the card keeps them per episode (for
    ``etmpc verify``) with the options. A policy that fails
    on a task has that task's row say so; the others are still scored (:attr:`Scorecard.complete` is
    then False, and ``json_path`` is not written: a card with a failed row never is).

    Every argument, every policy on every task, and the outputs are checked before any episode is
    played, with the command line's messages (:class:`EtmpcError`): a spec that does not parse, a
    policy given twice, an empty or repeated task, an output that is one of the run's inputs."""
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
    keys = {task: system_key(task, None, options) for task in tasks}  # each task with the options, checked
    given = next(iter(keys.values())).options  # as the keys write them (the same names and values for every task)
    if test_set is not None and len(tasks) != 1:
        raise EtmpcError("--test-set belongs to one task: give exactly one --task with it")
    if test_set is not None and not Path(test_set).is_file():
        raise EtmpcError(f"test set {test_set} not found")
    for key in keys.values():  # an option the stored episodes cannot feel: refused before any reference is played
        ts_mod.check_options_act(key, test_set)
    for task in tasks:  # each policy parsed (or checked) on each task: a bad one fails before any episode
        try:
            parse_policies(keys[task].make(), policies)
        except EtmpcError as exc:
            raise EtmpcError(f"{task}: {exc}") from None
    check_run_outputs({"--json": json_path}, inputs=run_inputs(policies, test_set))
    if test_set is None and not given:  # every task's references checked before any policy is played
        references = {task: stored(task, episodes) for task in tasks}
        shown: dict[str, dict[str, object]] = {
            task: {"stored": f"{folder_name(task)}/{references_path(task).name}"} for task in tasks
        }
    else:
        if test_set is not None:
            system = make_system(tasks[0])
            ts_mod.load(test_set, system.domain, system.task)  # a bad test set fails before the references are played
        references = {}
        shown = {}
        for task in tasks:
            why = f"test set {test_set}" if test_set is not None else f"its options ({', '.join(f'{n}={v}' for n, v in given)})"
            say(f"{task}: no stored references for {why}: computing them for this run")
            references[task] = build_references(keys[task], test_set, workers, progress, say, episodes, meter=False)
            shown[task] = {"stored": None}
            if given:  # what etmpc verify compares with the references it rebuilds, episode by episode
                kept = references[task]
                shown[task] |= {
                    "options": dict(keys[task].options),
                    "best_objectives": list(kept.periodic[kept.best]),
                    "oracle_objectives": list(kept.oracle),
                    "objective_sense": kept.objective_sense,
                }
    for task, refs in references.items():
        shown[task] |= {
            "best_periodic": refs.best,
            "oracle": refs.oracle_spec,
            "test_set_sha256": refs.test_set_sha256,
            "episodes": refs.episodes,
            "recompute_price": refs.recompute_price,
            "gap": refs.gap,
        }
    total = len(policies) * sum(refs.episodes for refs in references.values())  # the whole card's episodes, up front
    # each policy played on its own (a failing one fails its row only), one pool for all, one estimate for all
    with shared_pools(), Progress(total, enabled=progress, whole=True):
        rows = [
            play_and_score(keys[task], references[task], policy, test_set, workers, progress)
            for task in tasks
            for policy in policies
        ]
    card = Scorecard(tasks, shown, rows, [aggregate(r) for r in by_policy(rows).values()])
    if json_path is not None and card.complete:
        write_json(Path(json_path), card.to_json())
    return card


def _name(policy) -> str:
    return policy if isinstance(policy, str) else str(getattr(policy, "spec", type(policy).__name__))


def play_and_score(
    task, refs: References, policy, test_set: str | None = None, workers: int | None = None, progress: bool = True
) -> TaskScore:
    """``policy`` (a spec or an object) played on ``refs``' episodes of ``task`` (a name, or a
    :class:`~etmpc.systems.SystemKey` with options) and scored; a policy that fails (bad spec, its own error)
    gives a row that says so."""
    try:
        evaluation = evaluate(task, [policy], refs.episodes, workers=workers, test_set=test_set, progress=progress)
    except UnguardedScript:  # the script's error, not the policy's: no row can be played
        raise
    except EtmpcError as exc:  # the row says so (the table shows it): the command's own line says which rows failed
        return failed_task(refs.task, _name(policy), str(exc))
    return task_score(refs, evaluation, evaluation.summaries[0].policy)
