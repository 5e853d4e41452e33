"""The noisy variants' filters, chosen on training episodes: ``docs/results/estimators.json`` and its page.

    etmpc study estimators                  # both noisy tasks, 20 training episodes each (a few minutes)
    etmpc study estimators --page-only      # the page again from estimators.json

For each noisy task, the filter's process noise (``estimator.process_std``, the task's shape times a factor)
is tried on training episodes (drawn from ``--seed``, never the stored test set) under the base task's best
periodic schedule, and the factor with the best mean objective is the one to ship; its
shipped value is the default of the base task's Config (``estimator``; its noisy variant takes it). Run again
after a change, the factor chosen is 1 if the shipped value is still the best. Each row also gives the
estimate's RMS error per measured and unmeasured state against the plant's, and the filter's mean normalised
innovation squared beside the number of entries read (equal when the filter's model of the noise holds).

Then what the filter buys an event trigger: on each noisy task and its base, the best ``threshold:X`` (on the
filter's estimate; on the base, the exact state) and the best ``threshold:X:reading`` (on the raw readings), each
chosen from the task's grid on the leaderboard's validation episodes (training distribution), are scored on the
stored test set, with the score's change from the base's best threshold paired episode by episode.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np

from etmpc.evaluation import testsets
from etmpc.evaluation.scorecard import score
from etmpc.experiments.leaderboard_rows import VALIDATION_EPISODES, best_threshold
from etmpc.experiments.studies import runner
from etmpc.loop import run_episode
from etmpc.policies import parse_policy
from etmpc.systems import system_key

#: task -> the base's best periodic schedule (its stored references' best)
TASKS = {"cart_pendulum/kicks_noisy": "every:3", "quadrotor/waypoints_noisy": "every:7"}
FACTORS = (0.0625, 0.125, 0.25, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0)  # powers of 2 around the shipped value


def tune(task: str, schedule: str, episodes: int, seed: int) -> dict:
    base = system_key(task).make()
    shape = np.asarray(base.config.estimator.process_std, dtype=float)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "training.npz"
        testsets.draw(base, seed, episodes, path)
        training = testsets.load(path, base.domain, base.task)
        drawn = [base.episode_from_arrays(training.episode_arrays(i)) for i in range(episodes)]
    rows: list[dict] = []
    for factor in FACTORS:
        process = ",".join(repr(float(v)) for v in shape * factor)
        system = system_key(task, None, {"estimator.process_std": process}).make()
        policy = parse_policy(schedule, system)
        costs: list[float] = []
        errors = []
        nis: list[float] = []
        for episode in drawn:
            traj = run_episode(system, system.make_env(), policy, None, episode)
            assert traj.estimates is not None and traj.nis is not None  # a noisy task's loop keeps its filter's
            n = traj.steps
            rewards = traj.rewards[:n] - system.recompute_price * traj.work[:n]
            costs.append(-float(np.sum(rewards)) if system.objective_sense == "min" else float(np.sum(rewards)))
            errors.append(np.sqrt(np.mean((traj.estimates[: n + 1] - traj.states[: n + 1]) ** 2, axis=0)))
            nis.append(float(np.mean(traj.nis[1 : n + 1])))
        rows.append(
            {
                "factor": factor,
                "process_std": [float(v) for v in shape * factor],
                "objective": float(np.mean(costs)),
                "objective_ci95": float(1.96 * np.std(costs, ddof=1) / np.sqrt(len(costs))),
                "rms_error": [float(v) for v in np.mean(errors, axis=0)],
                "nis": float(np.mean(nis)),
            }
        )
        print(f"{task} x{factor:g}: objective {rows[-1]['objective']:.4f}, NIS {rows[-1]['nis']:.2f}")
    best = min(rows, key=lambda r: r["objective"])
    return {
        "schedule": schedule,
        "episodes": episodes,
        "seed": seed,
        "state_names": list(base.state_names),
        "measured": [bool(v) for v in base.sensor.arrays(len(base.state_names))[3]],
        "rows": rows,
        "chosen": best["factor"],
        "shipped": [float(v) for v in shape],
    }


def readings(task: str, base: str, workers: int) -> list[dict]:
    """The best threshold on the base, and on ``task`` the best on its estimate and on its readings (each chosen as the
    leaderboard chooses its best threshold): test-set rows."""
    grid = system_key(task).make().benchmark.threshold_specs()
    picks = [(base, "the state (exact)", best_threshold(base, workers, print, grid))]
    picks += [(task, "the filter's estimate", best_threshold(task, workers, print, grid))]
    picks += [(task, "the readings", best_threshold(task, workers, print, [f"{spec}:reading" for spec in grid]))]
    rows = []
    reference = None
    for name, reads, spec in picks:
        row = score([spec], tasks=[name], workers=workers, progress=False).rows[0]
        scores = np.asarray(row.episode_scores)
        reference = scores if reference is None else reference
        change = scores - reference
        rows.append(
            {
                "task": name,
                "reads": reads,
                "policy": spec,
                "score": row.score,
                "score_ci95": row.score_ci95,
                "recomputes": row.recomputes_mean,
                "failures": row.failures_mean,
                "change": float(np.mean(change)),
                "change_ci95": float(1.96 * np.std(change, ddof=1) / np.sqrt(len(change))) if len(change) > 1 else 0.0,
            }
        )
        print(f"{name}: {spec}: score {row.score:.1f} ± {row.score_ci95:.1f}")
    return rows


def page(document: dict) -> str:
    lines = [
        "# The noisy variants' filters",
        "",
        runner.generated("estimators", "docs/results/estimators.json"),
        "",
        f"Made at commit `{document['commit']}` ({document['date']}) on {document['machine']}, in "
        f"{document['seconds'] / 60:.0f} min. Each task's filter (an extended Kalman filter on the MPC's own predictor) "
        "was tried with its process noise scaled by each factor, on training episodes drawn from their own seed (never "
        "the stored test set), under the base task's best periodic schedule. The objective is the closed loop's (lower "
        "is better), ± a 95 % CI over the episodes; RMS error is the estimate's against the plant's state, per state "
        "(unmeasured states in italics); NIS is the mean normalised innovation squared, which equals the number of "
        "entries read when the filter's model of the noise holds.",
        "",
    ]
    for task, t in document["tasks"].items():
        names = [n if m else f"*{n}*" for n, m in zip(t["state_names"], t["measured"])]
        lines += [
            f"## `{task}`",
            "",
            f"{t['episodes']} training episodes (seed {t['seed']}) under `{t['schedule']}`; "
            f"entries read per step: {sum(t['measured'])}. Chosen: factor {t['chosen']:g}; shipped process noise: "
            f"{', '.join(f'{v:g}' for v in t['shipped'])}.",
            "",
            "| factor | objective | NIS | RMS error: " + ", ".join(names) + " |",
            "|---:|---:|---:|---|",
        ]
        for r in t["rows"]:
            mark = " (chosen)" if r["factor"] == t["chosen"] else ""
            errors = ", ".join(f"{v:.3g}" for v in r["rms_error"])
            lines.append(
                f"| {r['factor']:g}{mark} | {r['objective']:.4f} ± {r['objective_ci95']:.4f} | {r['nis']:.2f} | {errors} |"
            )
        lines.append("")
    if document.get("readings"):
        lines += [
            "## What a threshold trigger reads",
            "",
            "The best `threshold:X` on each noisy task's filter estimate and the best `threshold:X:reading` on its raw "
            "readings (the classic output-error trigger), each chosen from the task's grid on the leaderboard's "
            f"{document['validation_episodes']} validation episodes (training distribution), against the base task's "
            "best threshold on the exact state; scored on the stored test set (0: the task's own best periodic "
            "schedule, 100: the oracle over it), ± a 95 % CI over its episodes. *Change* is the score's change from "
            "the base's best threshold, paired episode by episode (the variants play their base's episodes).",
            "",
            "| task | the trigger reads | chosen | score | change from the base | recomputes | failures / episode |",
            "|---|---|---|---:|---:|---:|---:|",
        ]
        for rows in document["readings"].values():
            for r in rows:
                change = "—" if r is rows[0] else f"{r['change']:+.1f} ± {r['change_ci95']:.1f}"
                lines.append(
                    f"| `{r['task']}` | {r['reads']} | `{r['policy']}` | {r['score']:.1f} ± {r['score_ci95']:.1f} | "
                    f"{change} | {r['recomputes']:.1f} | {r['failures']:.2f} |"
                )
        lines.append("")
    return "\n".join(lines)


def arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--episodes", type=int, default=20, help="training episodes per task and factor (default 20)")
    parser.add_argument("--seed", type=int, default=1, help="the training episodes' seed (the stored test sets' are others)")
    runner.options(parser, workers=None)
    parser.add_argument("--workers", type=int, default=2, help="worker processes for the triggers' part (default 2)")


def run(args: argparse.Namespace) -> None:
    results = runner.Results(args.out, "estimators")
    if args.page_only:
        results.write_page(page)
        return
    clock = runner.Stopwatch()
    document = runner.made() | {"tasks": {}}
    for task, schedule in TASKS.items():
        document["tasks"][task] = tune(task, schedule, args.episodes, args.seed)
    document["validation_episodes"] = VALIDATION_EPISODES
    document["readings"] = {task: readings(task, system_key(task).make().variant_of, args.workers) for task in TASKS}
    document["machine"] = f"{runner.host()}, 1 process (the triggers' part: {args.workers})"
    document["seconds"] = clock.seconds()
    results.write(document, page)
