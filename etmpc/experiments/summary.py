"""The numbers of ``etmpc reproduce``'s report, from the evaluation JSONs alone: per task, the best
fixed policy, the learned policies against it (paired over test-set episodes, 95 % CIs), the default
learner and the headroom (rollout and the oracle)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from etmpc.common.documents import loads
from etmpc.evaluation.compare import paired, per_episode
from etmpc.evaluation import metrics
from etmpc.learning.config import TrainConfig
from etmpc.learning.train import curve_summary


def summarise_system(system, baselines: dict, learned: dict | None, curve: dict | None) -> dict:
    """The numbers of the report for one system, from the evaluation JSONs and the learning curve of
    the paper's learner (``learned`` and ``curve`` are None for a task the paper did not study)."""
    sense = system.objective_sense
    fixed = baselines["policies"]
    best = _best_fixed(fixed, sense)
    head = {
        "domain": system.domain,
        "task": system.task,
        "name": system.name,
        "objective_sense": sense,
        "episodes": baselines["policies"][best]["episodes"],
        "fixed": {spec: _row(s) for spec, s in fixed.items()},
        "best_fixed": dict(_row(fixed[best]), policy=best),
    }
    if learned is None:
        return head
    assert curve is not None  # the paper's learner is evaluated with its learning curve, or neither is
    per_seed = [s["objective_mean"] for s in learned["policies"].values()]
    # As evaluate does: a run that ended on a non-finite state is counted, never averaged in.
    learned_runs = [r for r in learned["runs"] if r["finite"]]
    # Paired over test-set episodes: the learned policy's mean over seeds and passes against the
    # best fixed policy on the same episode.
    by_episode: dict[int, list[float]] = {}
    for r in learned_runs:
        by_episode.setdefault(r["episode"], []).append(r["objective"])
    fixed_by_episode = {r["episode"]: r["objective"] for r in baselines["runs"] if r["policy"] == best and r["finite"]}
    episodes = sorted(set(by_episode) & set(fixed_by_episode))
    paired_runs = metrics.paired_differences(
        [np.mean(by_episode[e]) for e in episodes], [fixed_by_episode[e] for e in episodes], sense
    )
    learned_mean = float(np.mean([r["objective"] for r in learned_runs]))
    best_value = fixed[best]["objective_mean"]
    margin_percent = metrics.oriented(100.0 * (learned_mean - best_value) / abs(best_value), sense)  # > 0: learned better
    points = curve["points"]
    best_point = points[int(np.argmax(metrics.oriented([p["objective_mean"] for p in points], sense)))]
    return {
        **head,
        "learned": {
            "objective_mean": learned_mean,
            "objective_std_seeds": float(np.std(per_seed, ddof=1)) if len(per_seed) > 1 else 0.0,
            "control_objective_mean": float(np.mean([r["control_objective"] for r in learned_runs])),
            "recomputes_mean": float(np.mean([r["recomputes"] for r in learned_runs])),
            "solver_failures": int(sum(r["solver_failures"] for r in learned["runs"])),
            "nonfinite_episodes": len(learned["runs"]) - len(learned_runs),
            "per_seed": per_seed,
            "repeats": next(iter(learned["policies"].values()))["repeats"],
        },
        "paired": {
            "mean_difference": paired_runs["mean_difference"],
            "ci95": paired_runs["ci95"],
            "learned_better_episodes": paired_runs["better_episodes"],
            "episodes": paired_runs["episodes"],
        },
        "margin_percent": margin_percent,
        "curve": {"start": points[0], "best": best_point, "final": points[-1], "points": points},
    }


def summarise_default(system, baselines: dict, default: dict, state) -> dict:
    """The default learner's shipped policy on the test set, against the best fixed policy."""
    sense = system.objective_sense
    best = _best_fixed(baselines["policies"], sense)
    ((spec, row),) = default["policies"].items()
    hyper = loads(Path(spec[3:]).read_text())["hyperparameters"]
    return {
        "policy": spec,
        "seed": hyper["seed"],
        "validation_objective": hyper["validation_objective"],
        "validation": state.validation,
        "base": state.base,
        **_row(row),
        "paired": paired(per_episode(default), per_episode(baselines, {best}), sense),
        "curve": curve_summary(state)["points"],
    }


def summarise_headroom(
    system, best: str, baselines: dict, learned: dict | None, default: dict, rollout: dict, oracle: dict
) -> dict:
    """Every contender and the oracle against the best fixed policy, paired on the episodes the
    rollout policy played. Rows, in order: the oracle (a reference, not a policy), the rollout
    policy, the default learner, the paper's learner, the best fixed policy."""
    sense = system.objective_sense
    reference = per_episode(baselines, {best})
    episodes = sorted(per_episode(rollout))
    rows = {}
    for name, evaluation in (
        ("oracle", oracle),
        ("rollout", rollout),
        ("learned_default", default),
        ("learned_paper", learned),
        ("best_fixed", None),
    ):
        if name == "learned_paper" and learned is None:  # a task the paper did not study
            continue
        evaluation = evaluation or {"policies": {best: None}, "runs": [r for r in baselines["runs"] if r["policy"] == best]}
        runs = [r for r in evaluation["runs"] if r["episode"] in episodes and r["finite"]]
        rows[name] = dict(
            paired(per_episode(evaluation), reference, sense, episodes),
            policies=list(evaluation["policies"]),
            recomputes_mean=float(np.mean([r["recomputes"] for r in runs])) if runs else float("nan"),
        )
    cost = rollout.get("cost", {})
    steps = sum(r["steps"] for r in rollout["runs"])
    return {
        "reference": best,
        "episodes": len(episodes),
        "rows": rows,
        "rollout_cost": cost,
        # CPU seconds per step of the rollout policy (its decision and the step itself; the solve is a small part).
        "rollout_seconds_per_step": cost["wall_seconds"] * cost["workers"] / steps if cost and steps else None,
    }


def _best_fixed(fixed: dict, sense: str) -> str:
    """The fixed policy with the best mean objective (the first of a tie)."""
    return metrics.best(fixed, sense, key=lambda spec: fixed[spec]["objective_mean"])


def _row(s: dict) -> dict:
    keys = ("objective_mean", "objective_std", "control_objective_mean", "recomputes_mean", "solver_failures")
    return {k: s[k] for k in keys}


def summarise_learners(
    system,
    baselines: dict,
    learned: dict | None,
    default: dict,
    ppo: dict | None,
    ppo_run: dict | None,
    settings: dict,
    dpi_config: TrainConfig,
    costs: dict | None = None,
    curves: dict | None = None,
) -> dict:
    """Each learner's policy on every test-set episode against the best fixed policy (paired, 95 % CI),
    with what its training cost: the default learner (DPI), the paper's (GPOMDP) and, if it ran, PPO.
    ``costs``: each training stage's ``cost.json`` (wall seconds, workers); ``curves``: the learners'
    sample-efficiency curves (:mod:`etmpc.experiments.efficiency`), whose last point gives the steps one
    run (one seed) simulated."""
    sense = system.objective_sense
    best = _best_fixed(baselines["policies"], sense)
    reference = per_episode(baselines, {best})
    steps = system.episode_steps
    dpi_episodes = len(dpi_config.seeds) * dpi_config.episodes
    labelling = dpi_config.dpi.states_per_episode * dpi_config.dpi.futures * 2 * dpi_config.dpi.horizon
    rows = {
        "dpi": (
            default,
            {
                "seeds": len(dpi_config.seeds),
                "episodes": dpi_episodes,
                "environment_steps": dpi_episodes * steps,
                "simulated_steps_at_most": dpi_episodes * labelling,
            },
        )
    }
    if learned is not None:
        rows["gpomdp"] = (
            learned,
            {
                "seeds": len(settings["seeds"]),
                "episodes": len(settings["seeds"]) * settings["episodes"],
                "environment_steps": len(settings["seeds"]) * settings["episodes"] * steps,
            },
        )
    if ppo is not None:
        assert ppo_run is not None  # PPO's evaluation and its run come together (stages._ppo)
        rows["ppo"] = (
            ppo,
            {
                "seeds": 1,
                "environment_steps": ppo_run["environment_steps"],
                "wall_seconds": ppo_run["wall_seconds"],
                "workers": ppo_run["workers"],
            },
        )
    out: dict[str, object] = {"reference": best}
    for name, (evaluation, cost) in rows.items():
        runs = [r for r in evaluation["runs"] if r["finite"]]
        stage = (costs or {}).get(name)
        if stage is not None:
            cost = dict(cost, wall_seconds=stage["wall_seconds"], workers=stage["workers"])
        curve = (curves or {}).get(name)
        if curve:
            cost = dict(cost, simulated_steps_per_seed=curve[-1]["simulated_steps"])
        out[name] = dict(
            paired(per_episode(evaluation), reference, sense),
            policies=list(evaluation["policies"]),
            recomputes_mean=float(np.mean([r["recomputes"] for r in runs])) if runs else float("nan"),
            training=cost,
        )
    return out


def summarise_scorecard(system, evaluations: dict[str, tuple[dict | None, str]]) -> dict:
    """The scorecard of what a run trained (:mod:`etmpc.evaluation.scorecard`), from its evaluation JSONs:
    ``evaluations`` maps a row's name to ``(evaluation JSON, spec)`` (a None JSON: no such row). Returns
    ``{"references": ..., "rows": {name: TaskScore as JSON}}``, or ``{"unavailable": why}`` when the
    stored references do not fit the run (another test set, or too few episodes)."""
    from etmpc.common.errors import EtmpcError
    from etmpc.evaluation.references import load_references
    from etmpc.evaluation.scorecard import task_score

    first = next(data for data, _ in evaluations.values() if data is not None)
    try:
        refs = load_references(system.name, first["test_set"]["sha256"])
        episodes = len({r["episode"] for r in first["runs"]})
        refs = refs.head(episodes) if episodes < refs.episodes else refs
        rows = {
            name: task_score(refs, data, spec).to_json()
            for name, (data, spec) in evaluations.items()
            if data is not None and spec in data["policies"]
        }
    except EtmpcError as exc:
        return {"unavailable": str(exc)}
    return {"references": {"best_periodic": refs.best, "oracle": refs.oracle_spec, "episodes": refs.episodes}, "rows": rows}
