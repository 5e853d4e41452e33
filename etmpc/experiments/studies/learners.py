"""Learners compared over training seeds: ``docs/results/learners.json`` and its page ``docs/results/learners.md``.

    python scripts/learners.py --work runs/learners                      # every task: hours on 2 cores
    python scripts/learners.py --work runs/learners --task cart_pendulum/kicks_levels
    python scripts/learners.py --page-only                               # the page again from learners.json
    python scripts/learners.py --task TASK --retrain --ship              # after TASK's version changed: every seed again

Per task, with the recipe the shipped files record (``policies/<task>/learned.json``'s hyperparameters,
``ppo.yml``; :data:`RECIPES` says where this etmpc departs from it):

* **DPI** trained once over ``--dpi-seeds`` in lockstep (``WORK/dpi/<task>``): every seed's own choice on
  validation episodes (``seed<S>/selected.json``) and the run's (``selected.json``, the shipped seed);
* **PPO** trained once per seed of ``--ppo-seeds`` (``WORK/ppo/<task>/seed<S>``); the shipped seed is the
  one with the best objective on the same validation episodes;
* every seed's policy, each learner's shipped one, the shipped ones under the task's shield (where it
  declares one) and the best fixed schedule played on the stored test set (``etmpc.score``; the oracle's
  and the rollout meter's rows are the stored references' own evaluations). Scores are paired with the best
  fixed schedule episode by episode (0 = it, 100 = the oracle over it), with 95 % CIs.

Training uses the test set for nothing but its learning curve (a look back); every choice is made on
training-distribution episodes. Every stage is kept in WORK: run again, the script continues where it was.
With ``--ship`` the chosen seeds' files are copied into ``policies/<task>/`` (then regenerate the
leaderboard: ``make leaderboard``).
"""

from __future__ import annotations

import argparse
import json
import platform
import shutil
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from etmpc.common.provenance import commit_and_date
from etmpc.evaluation import metrics
from etmpc.evaluation.references import rollout_meter_spec, stored
from etmpc.evaluation.scorecard import score, task_score
from etmpc.learning import dpi, hyperparams
from etmpc.learning.config import TrainConfig, parse_seeds
from etmpc.learning.ppo import train_ppo
from etmpc.learning.ppo_settings import PpoSettings, settings_json
from etmpc.experiments.stages import trained
from etmpc.learning.runner import cost_path, timed
from etmpc.systems import folder_name, make_system, names, system_class

EVAL_EPISODES = 10  # test-set episodes of DPI's learning curve (a look back, never a choice)
DPI_KEYS = ("futures", "horizon", "states_per_episode", "ridge", "selection_episodes")
#: Where this etmpc's recipe departs from what the shipped file records. kicks_levels: DPI's first schedules
#: include the event-triggered real-time iteration under an age cap (shield:A:threshold:X:iterate), which does
#: better than the task's best fixed schedule iterate:1 on validation episodes; from iterate:1 and the default
#: schedules, DPI's policies did worse than iterate:1 there.
RECIPES = {
    "cart_pendulum/kicks_levels": {
        "episodes_per_seed": 60,  # the shipped policy is its run's first iteration (20 episodes); the run had 60
        "bases": (
            "iterate:1",
            "shield:5:threshold:0.2:iterate",
            "shield:8:threshold:0.2:iterate",
            "shield:8:threshold:0.1:iterate",
            "shield:8:threshold:0.3:iterate",
        ),
    }
}


def recipe_folder(task: str) -> Path:
    """Where ``task``'s recipe is read: its shipped policies' folder, or, for a variant with none shipped yet (a
    noisy variant's first run), the folder of the task whose world it plays (``variant_of``)."""
    own = Path("policies") / folder_name(task)
    variant_of = getattr(system_class(task), "variant_of", None)
    return own if (own / "learned.json").exists() or variant_of is None else Path("policies") / folder_name(variant_of)


def shipped_recipe(task: str) -> TrainConfig:
    """The DPI run the shipped ``learned.json`` records (its hyperparameters; its base task's for a new variant)."""
    data = json.loads((recipe_folder(task) / "learned.json").read_text())
    h = dict(data["hyperparameters"], **RECIPES.get(task, {}))
    return TrainConfig(
        task,
        episodes=h.get("episodes_per_seed", h["episodes"]),  # "episodes": the policy's own (an iteration's, if chosen so)
        eval_every=h.get("eval_every", 20),  # one DPI iteration per phase; files before it was written: 20
        eval_episodes=EVAL_EPISODES,
        normalisation_episodes=h["normalisation_episodes"],
        features=h["features"],
        algorithm="dpi",
        dpi=dpi.Settings(**{k: h[k] for k in DPI_KEYS}, bases=tuple(h["bases"]), failure_cost=h.get("failure_cost", 0.0)),
        validation_episodes=h["validation_episodes"],
    )


def dpi_runs(
    task: str, work: Path, seeds: tuple[int, ...], workers: int, failure_cost: float | None = None, out: Path | None = None
) -> dict:
    """DPI over ``seeds`` in lockstep with the shipped recipe (``failure_cost``, if given, in place of the recipe's),
    in ``out`` (default ``WORK/dpi/<task>``)."""
    out = work / "dpi" / folder_name(task) if out is None else out
    if (out / "checkpoint.json").exists():  # a run already in WORK continues as it was set up
        config = TrainConfig.from_json(json.loads((out / "checkpoint.json").read_text())["config"])
        seeds = config.seeds
    else:
        config = replace(shipped_recipe(task), seeds=seeds)
        if failure_cost is not None:
            config = replace(config, dpi=replace(config.dpi, failure_cost=failure_cost))

    with timed(out, workers):  # the first invocation that finishes the run keeps its wall time
        trained(config, out, {"workers": workers, "backend": "local", "address": None}, progress=True)
    cost = json.loads(cost_path(out).read_text())
    per_seed = {s: out / f"seed{s}" / "selected.json" for s in seeds}
    validation = {s: json.loads(p.read_text())["hyperparameters"]["validation_objective"] for s, p in per_seed.items()}
    return {
        "seeds": {s: str(p) for s, p in per_seed.items()},
        "validation": validation,
        "chosen": json.loads((out / "selected.json").read_text())["hyperparameters"]["seed"],
        "files": {"learned.json": out / "selected.json"},
        "cost": {"wall_seconds": cost["wall_seconds"], "workers": cost["workers"], "seeds_in_lockstep": len(seeds)},
    }


def ppo_runs(
    task: str,
    work: Path,
    seeds: tuple[int, ...],
    workers: int,
    failure_cost: float | None = None,
    folder: Path | None = None,
    retrain: bool = False,
) -> dict:
    """PPO, one run per seed, with the task's shipped ``ppo.yml`` (``failure_cost``, if given, in place of its own), in
    ``folder/seed<S>`` (default ``WORK/ppo/<task>``); the shipped network stands for its own seed's run, unless
    ``retrain`` (the task changed since it was trained: every seed is trained again)."""
    folder = work / "ppo" / folder_name(task) if folder is None else folder
    shipped = Path("policies") / folder_name(task)
    # the shipped network (its seed's run, not made again), if it is this task's; a new variant's recipe is its
    # own ppo.yml (the base task's, with the variant's id), trained at every seed
    made = json.loads((shipped / "ppo.json").read_text()) if (shipped / "ppo.json").exists() else None
    made = made if made is not None and made.get("task") == task and not retrain else None
    validation_episodes = (made or json.loads((recipe_folder(task) / "ppo.json").read_text()))["settings"]["validation_episodes"]
    base = hyperparams.shipped(task, PpoSettings(validation_episodes=validation_episodes))
    base = base if failure_cost is None else replace(base, failure_cost=failure_cost)
    paths, validation, costs = {}, {}, []
    for seed in seeds:
        out = folder / f"seed{seed}"
        kept = (out / "selected.zip").exists() and (out / "selected.json").exists()  # a finished run (or a copy of one)
        if not kept and made is not None and made["settings"] == json.loads(json.dumps(settings_json(replace(base, seed=seed)))):
            paths[seed], validation[seed] = shipped / "ppo.zip", made["validation_objective"]  # the shipped seed's run
            continue
        if not kept:
            if out.exists():
                shutil.rmtree(out)  # a stopped run starts again
            train_ppo(task, out, replace(base, seed=seed), workers, progress=True)
        if (out / "training.json").exists():  # its cost (a copy of a shipped run has none)
            costs.append(json.loads((out / "training.json").read_text()))
        paths[seed] = out / "selected.zip"
        validation[seed] = json.loads((out / "selected.json").read_text())["validation_objective"]
    sense = make_system(task).objective_sense
    chosen = (max if sense == "max" else min)(seeds, key=validation.get)
    out = folder / f"seed{chosen}"
    files = {"ppo.zip": out / "selected.zip", "ppo.json": out / "selected.json"} if paths[chosen].parent == out else {}
    return {
        "seeds": {s: str(p) for s, p in paths.items()},
        "validation": validation,
        "chosen": chosen,
        "files": files,  # nothing to ship when the shipped network stays the chosen one
        "cost": None
        if not costs
        else {  # per seed trained here (the shipped one's was not timed here)
            "wall_seconds": float(np.mean([c["wall_seconds"] for c in costs])),
            "workers": costs[0]["workers"],
            "environment_steps": costs[0]["environment_steps"],
            "simulated_steps": costs[0]["simulated_steps"],
        },
    }


def row(card_row) -> dict:
    return {
        "policy": card_row.policy,
        "score": card_row.score,
        "score_ci95": card_row.score_ci95,
        "failures": card_row.failures_mean,
        "failures_ci95": card_row.failures_ci95,
        "recomputes": card_row.recomputes_mean,
        "objective": card_row.objective_mean,
        "episode_scores": list(card_row.episode_scores),
    }


def bounds_of(system, refs) -> tuple[dict, dict]:
    """The oracle's and the rollout meter's specs by name, and their rows, from the stored references' own runs."""
    bounds = {"oracle": refs.oracle_spec}
    if (meter := rollout_meter_spec(system, refs.best)) is not None and refs.kept_evaluation(meter) is not None:
        bounds["rollout meter"] = meter
    rows = {}
    for spec in bounds.values():
        evaluation = refs.kept_evaluation(spec)
        rows[spec] = row(task_score(refs, evaluation, spec)) if evaluation is not None else None
    return bounds, rows


def compare(task: str, work: Path, dpi_seeds, ppo_seeds, workers: int, retrain: bool = False) -> dict:
    system, refs = make_system(task), stored(task)
    learners = {"DPI": dpi_runs(task, work, dpi_seeds, workers), "PPO": ppo_runs(task, work, ppo_seeds, workers, retrain=retrain)}
    kinds = {"DPI": "rl", "PPO": "sb3"}
    shielded = system.shield is not None
    specs = [refs.best]
    for name, run in learners.items():
        specs += [f"{kinds[name]}:{path}" for path in run["seeds"].values()]
        if shielded:
            chosen = f"{kinds[name]}:{run['seeds'][run['chosen']]}"
            specs.append(f"shield:{system.shield.text}:{chosen}")
    card_path = work / "cards" / f"{folder_name(task)}.json"
    if card_path.exists() and json.loads(card_path.read_text()).get("specs") == specs:
        rows = json.loads(card_path.read_text())["rows"]
    else:
        card = score(specs, [task], workers=workers)
        rows = {r.policy: row(r) for r in card.rows}
        card_path.parent.mkdir(parents=True, exist_ok=True)
        card_path.write_text(json.dumps({"specs": specs, "rows": rows}) + "\n")
    bounds, bound_rows = bounds_of(system, refs)
    rows |= bound_rows
    result = {"task": task, "best_fixed": refs.best, "rows": rows, "bounds": bounds, "learners": {}, "shield": None}
    result["made"] = commit_and_date()  # each task's own: tasks are run (and continued) by separate invocations
    if shielded:
        result["shield"] = {"rule": system.shield.text, "unit": system.margin_unit}
    for name, run in learners.items():
        seeds = {s: rows[f"{kinds[name]}:{path}"] for s, path in run["seeds"].items()}
        scores = np.array([r["score"] for r in seeds.values()])
        result["learners"][name] = {
            "seeds": {str(s): r["policy"] for s, r in seeds.items()},
            "validation": {str(s): v for s, v in run["validation"].items()},
            "chosen": run["chosen"],
            "chosen_policy": f"{kinds[name]}:{run['seeds'][run['chosen']]}",
            "seed_scores": scores.tolist(),
            "seed_mean": float(scores.mean()),
            "seed_sd": float(scores.std(ddof=1)) if len(scores) > 1 else float("nan"),
            "cost": run["cost"],
            "files": {k: str(v) for k, v in run["files"].items()},
        }
    return result


def fmt(value, digits=1) -> str:
    return "–" if value is None or not np.isfinite(value) else f"{value:.{digits}f}"


def cell(r, key="score") -> str:
    if r is None:
        return "–"
    if key == "failures":
        return "–" if r["failures"] is None else f"{r['failures']:.2f} ± {fmt(r['failures_ci95'], 2)}"
    return f"{fmt(r['score'])} ± {fmt(r['score_ci95'])}"


def made(document: dict) -> str:
    """Which commit made which tasks (each task's own, else the document's), with the dates."""
    by_commit: dict[tuple[str, str], list[str]] = {}
    for task, result in document["tasks"].items():
        when = result.get("made") or {"commit": document["commit"], "date": document["date"]}
        commit = when["commit"] + (" with uncommitted changes" if when.get("uncommitted_changes") else "")
        by_commit.setdefault((commit, when["date"]), []).append(task)
    return "; ".join(
        f"commit `{commit}` ({date}) for {', '.join(f'`{t}`' for t in tasks)}" for (commit, date), tasks in by_commit.items()
    )


def page(document: dict) -> str:
    lines = [
        "# Learners compared over training seeds",
        "",
        "<!-- Generated by scripts/learners.py from docs/results/learners.json: do not edit by hand. -->",
        "",
        f"Made on {document['machine']}: {made(document)}. On each task's stored test set (100 episodes), "
        "scores are paired with the best fixed schedule episode by episode: 0 is the best fixed schedule, 100 the "
        "oracle over it; ± is a 95 % CI. A learner is a distribution of runs: each of its training seeds is scored, "
        "and the shipped seed is the one chosen on validation episodes (training distribution), never on these. "
        "Failures are the task's own (falls, steps outside the geofence, ...) per episode. The rollout meter and "
        "the oracle simulate the future at every decision (the oracle knows it): they are what a policy could "
        "reach, not policies one could ship.",
        "",
        "| task | learner | shipped seed: score | failures / episode | seeds: mean ± sd [min, max] | training cost |",
        "|---|---|---|---|---|---|",
    ]
    for task, result in document["tasks"].items():
        rows = result["rows"]
        best = rows[result["best_fixed"]]
        lines.append(f"| `{task}` | best fixed `{result['best_fixed']}` | 0 | {cell(best, 'failures')} | | |")
        for name, learner in result["learners"].items():
            shipped = rows[learner["chosen_policy"]]
            scores = learner["seed_scores"]
            cost = learner["cost"]
            spent = "–" if cost is None else f"{cost['wall_seconds'] / 60:.0f} min on {cost['workers']} workers"
            if cost is not None and "environment_steps" in cost:
                spent += f", {cost['environment_steps']} environment steps per seed"
            elif cost is not None:
                spent += f", {cost['seeds_in_lockstep']} seeds together"
            lines.append(
                f"| | {name} (seed {learner['chosen']} of {len(scores)}) | {cell(shipped)} | {cell(shipped, 'failures')} | "
                f"{fmt(learner['seed_mean'])} ± {fmt(learner['seed_sd'])} [{fmt(min(scores))}, {fmt(max(scores))}] | {spent} |"
            )
            if result["shield"] is not None:
                rule = result["shield"]["rule"]
                spec = f"shield:{rule}:{learner['chosen_policy']}"
                lines.append(f"| | {name} + shield `{rule}` | {cell(rows[spec])} | {cell(rows[spec], 'failures')} | | |")
        for name, spec in result["bounds"].items():
            lines.append(f"| | {name} `{spec}` | {cell(rows[spec])} | {cell(rows[spec], 'failures')} | | |")
    missing = [task for task in names() if task not in document["tasks"]]
    if missing:
        listed = ", ".join(f"`{task}`" for task in missing)
        lines += ["", f"Not run yet: {listed} (`python scripts/learners.py --task TASK`)."]
    lines += ["", "## Across the tasks above", ""]
    lines += [
        "The interquartile mean (rliable's IQM, over every task's episode scores) of each learner's shipped seed, "
        "and of every seed pooled, with 95 % stratified bootstrap intervals:",
        "",
        "| learner | IQM, shipped seed | IQM, all seeds |",
        "|---|---|---|",
    ]
    for name in ("DPI", "PPO"):
        shipped = [r["rows"][r["learners"][name]["chosen_policy"]]["episode_scores"] for r in document["tasks"].values()]
        pooled = [
            np.concatenate([r["rows"][p]["episode_scores"] for p in r["learners"][name]["seeds"].values()])
            for r in document["tasks"].values()
        ]
        low, high = metrics.iqm_ci95(shipped)
        plow, phigh = metrics.iqm_ci95(pooled)
        one, every = metrics.iqm(shipped), metrics.iqm(pooled)
        lines.append(f"| {name} | {one:.1f} [{low:.1f}, {high:.1f}] | {every:.1f} [{plow:.1f}, {phigh:.1f}] |")
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--work", type=Path, default=Path("runs/learners"), help="where runs, cards and costs are kept (resumable)"
    )
    parser.add_argument("--task", action="append", choices=names(), help="a task (repeatable; default: every task)")
    parser.add_argument("--dpi-seeds", type=parse_seeds, default=(0, 1, 2, 3, 4))
    parser.add_argument("--ppo-seeds", type=parse_seeds, default=(0, 1, 2))
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--out", type=Path, default=Path("docs/results"))
    parser.add_argument("--ship", action="store_true", help="copy the chosen seeds' files into policies/<task>/")
    parser.add_argument("--page-only", action="store_true", help="only write the page again from learners.json")
    parser.add_argument(
        "--retrain",
        action="store_true",
        help="train PPO's every seed again, the shipped network's too (after the task's version changed)",
    )
    parser.add_argument(
        "--bounds-only",
        action="store_true",
        help="take the oracle's and the rollout meter's rows again from the stored references (after they were played "
        "again), the learners' as they are in learners.json, and write the page again",
    )
    args = parser.parse_args()
    started, provenance = time.perf_counter(), commit_and_date()  # the code that runs: the checkout as it starts
    path = args.out / "learners.json"
    document = json.loads(path.read_text()) if path.exists() else {"tasks": {}}
    document["tasks"] = {t: document["tasks"][t] for t in names() if t in document["tasks"]}
    if args.page_only:
        (args.out / "learners.md").write_text(page(document))
        return
    if args.bounds_only:
        for task in args.task or list(document["tasks"]):
            bounds, rows = bounds_of(make_system(task), stored(task))
            result = document["tasks"][task]
            result["rows"] = {k: v for k, v in result["rows"].items() if k not in result["bounds"].values()} | rows
            result["bounds"] = bounds
        return write(document, args.out)
    for task in args.task or names():
        result = compare(task, args.work, args.dpi_seeds, args.ppo_seeds, args.workers, args.retrain)
        document["tasks"][task] = result
        if args.ship:
            (Path("policies") / folder_name(task)).mkdir(parents=True, exist_ok=True)  # a new task's first policies
            for learner in result["learners"].values():
                for name, source in learner["files"].items():
                    shutil.copyfile(source, Path("policies") / folder_name(task) / name)
        print(
            f"{task}: " + "; ".join(f"{n} seeds {l['seed_mean']:.1f} ± {l['seed_sd']:.1f}" for n, l in result["learners"].items())
        )
    document["tasks"] = {t: document["tasks"][t] for t in names() if t in document["tasks"]}
    document.update(provenance)
    document["machine"] = f"{platform.machine()}, {platform.processor() or platform.system()}, {args.workers} workers"
    document["seconds"] = time.perf_counter() - started
    write(document, args.out)


def write(document: dict, out: Path) -> None:
    """learners.json and its page into ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    (out / "learners.json").write_text(json.dumps(document, indent=1) + "\n")
    (out / "learners.md").write_text(page(document))
    print(f"wrote {out / 'learners.json'} and {out / 'learners.md'}")


if __name__ == "__main__":
    main()
