"""Safety in learning, its weight chosen on validation episodes: ``docs/results/failure_cost.{json,md}``.

    etmpc study failure-cost --work runs/failure_cost                       # quadrotor/waypoints: ~40 min
    etmpc study failure-cost --work runs/failure_cost --task cart_pendulum/kicks_levels --costs 0,3,10
    etmpc study failure-cost --work runs/failure_cost --learner ppo --task quadrotor/waypoints_noisy
    etmpc study failure-cost --page-only                                    # the page again from the JSON

For each failure cost ``c`` of ``--costs`` (DPI's ``failure_cost``: each of the task's failures in a labelling
rollout costs ``c`` on top of its reward; PPO's: each failure costs ``c`` in its training environments' reward),
the learner is trained with the recipe the task ships (DPI: its ``dpi.yml``,
the ``learners`` study's; PPO: ``ppo.yml``), over the same seeds, in ``WORK/<task>/cost_<c>`` (PPO:
``WORK/ppo/<task>/cost_<c>/seed<s>``); each cost's run ships the seed it chose on its own validation episodes. The
cost is then chosen on ``--validation`` training-distribution episodes (the stream ``etmpc train`` validates on,
never the stored test set), safety first: among the costs whose mean objective there is tied with the best one's
(the paired difference's 95 % CI spans 0), the fewest failures per episode, then the better objective.
Every cost's policy is scored on the stored test set beside the best fixed schedule (paired, 95 % CIs), so the
page shows what the choice gave and what the others would have. Every stage is kept in WORK: run again, the
study continues where it stopped.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from etmpc.evaluation.backends import make_backend
from etmpc.evaluation.references import stored
from etmpc.evaluation.scorecard import score
from etmpc.experiments.studies import runner
from etmpc.experiments.studies.learner_runs import dpi_runs, ppo_runs, row
from etmpc.learning.config import VALIDATION_ENTROPY
from etmpc.learning.jobs import episode_outcomes
from etmpc.systems import folder_name, make_system


def runs(task: str, work: Path, costs: list[float], seeds: tuple[int, ...], workers: int, learner: str) -> dict[float, dict]:
    """One run of ``learner`` per cost (kept in WORK; the ``learners`` study's runs, over ``seeds``): its chosen
    policy, seed and training cost (DPI: the run's; PPO: the mean per seed)."""
    done = {}
    for cost in costs:
        if learner == "ppo":
            run = ppo_runs(task, work, seeds, workers, cost, work / "ppo" / folder_name(task) / f"cost_{cost:g}")
            policy = f"sb3:{run['seeds'][run['chosen']]}"
        else:
            run = dpi_runs(task, work, seeds, workers, cost, work / folder_name(task) / f"cost_{cost:g}")
            policy = f"rl:{run['files']['learned.json']}"
        done[cost] = {"policy": policy, "seed": run["chosen"], "wall_seconds": run["cost"]["wall_seconds"]}
    return done


def validate(task: str, specs: list[str], episodes: int, workers: int) -> list[dict]:
    """Each spec's objective and failures per episode on the validation stream (the same episodes for every spec)."""
    with make_backend("local", workers) as pool:
        outcomes = episode_outcomes(pool, task, specs, VALIDATION_ENTROPY, episodes)
    return [
        {
            "objective": float(np.mean(o[:, 0])),
            "failures": float(np.mean(o[:, 1])),
            "failures_ci95": float(1.96 * np.std(o[:, 1], ddof=1) / np.sqrt(len(o))),
            "recomputes": float(np.mean(o[:, 2])),
            "episode_objectives": o[:, 0].tolist(),
        }
        for o in outcomes
    ]


def choose(costs: list[float], validation: dict, sense: str) -> tuple[float, list[float]]:
    """Safety first: among the costs whose validation objective is tied with the best one's (their paired
    difference's 95 % CI spans 0), the fewest failures, then the better objective. Returns it and the tied costs."""
    sign = 1.0 if sense == "min" else -1.0
    best = min(costs, key=lambda c: sign * validation[c]["objective"])
    tied = []
    for c in costs:
        gap = sign * (np.asarray(validation[c]["episode_objectives"]) - validation[best]["episode_objectives"])
        if c == best or gap.mean() <= 1.96 * gap.std(ddof=1) / np.sqrt(len(gap)):
            tied.append(c)
    return min(tied, key=lambda c: (validation[c]["failures"], sign * validation[c]["objective"])), tied


def study(task: str, work: Path, costs: list[float], seeds, episodes: int, workers: int, learner: str = "dpi") -> dict:
    system = make_system(task)
    refs = stored(task)
    trained_runs = runs(task, work, costs, seeds, workers, learner)
    specs = [refs.best] + [trained_runs[c]["policy"] for c in costs]
    checked = validate(task, specs, episodes, workers)
    schedule = checked[0]
    validation = dict(zip(costs, checked[1:]))
    chosen, tied = choose(costs, validation, system.objective_sense)
    card = score(specs, [task], workers=workers)
    rows = {r.policy: row(r) for r in card.rows}
    return {
        "task": task,
        "made": runner.made(),
        "best_fixed": refs.best,
        "seeds": list(seeds),
        "validation_episodes": episodes,
        "schedule": {"validation": schedule, "test": rows[refs.best]},
        "costs": {
            f"{c:g}": {**trained_runs[c], "validation": validation[c], "test": rows[trained_runs[c]["policy"]]} for c in costs
        },
        "chosen": f"{chosen:g}",
        "tied": [f"{c:g}" for c in tied],
    }


SECTIONS = {"dpi": ("tasks", "DPI"), "ppo": ("ppo_tasks", "PPO")}  # the learner -> its key in the JSON, its name


def page(document: dict) -> str:
    lines = [
        "# A failure cost in learning",
        "",
        runner.generated("failure-cost", "docs/results/failure_cost.json"),
        "",
        "With a failure cost `c` (`etmpc train --set failure_cost=c`) every failure of the task (a fall, a step "
        "outside the geofence) costs `c` more than the reward charges for it, so that learning weighs safety: in DPI's "
        "labels (each decision is labelled by rollouts, keep or recompute, over sampled futures) or in PPO's reward "
        "(its training environments', `TriggerEnv(failure_cost=c)`). The cost is "
        "chosen on validation episodes of the training distribution (never the stored test set), safety first: among "
        "the costs whose validation objective is tied with the best one's (the paired difference's 95 % CI spans 0), "
        "the fewest failures, then the better objective. Each cost's run ships the seed it chose on its own validation "
        "episodes. The test columns are the "
        "stored test set's (100 episodes): score 0 = the best fixed schedule, 100 = the oracle over it, ± a 95 % CI, "
        "paired episode by episode.",
        "",
    ]
    for key, name in SECTIONS.values():
        lines += section(document, key, name)
    return "\n".join(lines)


def section(document: dict, key: str, name: str) -> list[str]:
    lines = []
    for task, t in document.get(key, {}).items():
        made = t["made"]
        dirty = " with uncommitted changes" if made.get("uncommitted_changes") else ""
        lines += [
            f"## {name}: `{task}`",
            "",
            f"Made at commit `{made['commit']}`{dirty} ({made['date']}) on {document['machine']}; seeds "
            f"{', '.join(map(str, t['seeds']))}; {t['validation_episodes']} validation episodes. Tied on validation: "
            f"{', '.join(t.get('tied', []))}; chosen cost: **{t['chosen']}**.",
            "",
            "| | validation: objective | validation: failures / episode | test: score | test: failures / episode "
            "| recomputes | training (min) |",
            "|---|---:|---:|---:|---:|---:|---:|",
        ]
        s = t["schedule"]
        lines.append(
            f"| best fixed `{t['best_fixed']}` | {s['validation']['objective']:.4g} | {s['validation']['failures']:.2f} | "
            f"0 | {s['test']['failures']:.2f} ± {s['test']['failures_ci95']:.2f} | {s['test']['recomputes']:.1f} | |"
        )
        for cost, c in t["costs"].items():
            mark = " (chosen)" if cost == t["chosen"] else ""
            lines.append(
                f"| {name}, failure cost {cost}{mark} | {c['validation']['objective']:.4g} | {c['validation']['failures']:.2f} "
                f"| {c['test']['score']:.1f} ± {c['test']['score_ci95']:.1f} | {c['test']['failures']:.2f} ± "
                f"{c['test']['failures_ci95']:.2f} | {c['test']['recomputes']:.1f} | {c['wall_seconds'] / 60:.1f} |"
            )
        lines.append("")
    return lines


def arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--work", type=Path, default=Path("runs/failure_cost"), help="where the runs are kept (resumable)")
    parser.add_argument("--task", action="append", default=None, help="a task (repeatable; default: quadrotor/waypoints)")
    parser.add_argument("--costs", default="0,3,10", help="failure costs to try, comma-separated (default 0,3,10)")
    parser.add_argument("--seeds", default="0,1,2", help="the learner's seeds, comma-separated (default 0,1,2)")
    parser.add_argument("--learner", choices=sorted(SECTIONS), default="dpi", help="the learner trained (default dpi)")
    parser.add_argument(
        "--validation", type=int, default=300, help="validation episodes that choose the cost (failures are rare)"
    )
    runner.options(parser)


def run(args: argparse.Namespace) -> None:
    results = runner.Results(args.out, "failure_cost")
    if args.page_only:
        results.write_page(page)
        return
    document = results.kept(lambda: {"tasks": {}})
    costs = [float(c) for c in args.costs.split(",")]
    seeds = tuple(int(s) for s in args.seeds.split(","))
    clock = runner.Stopwatch()
    for task in args.task or ["quadrotor/waypoints"]:
        section = document.setdefault(SECTIONS[args.learner][0], {})
        section[task] = study(task, args.work, costs, seeds, args.validation, args.workers, args.learner)
    document["machine"] = runner.machine(args.workers)
    document["seconds"] = clock.seconds()
    results.write(document, page)
