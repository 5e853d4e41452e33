"""Learners compared over training seeds: ``docs/results/learners.json`` and its page ``docs/results/learners.md``.

    etmpc study learners --work runs/learners                      # every task: hours on 2 cores
    etmpc study learners --work runs/learners --task cart_pendulum/kicks_levels
    etmpc study learners --page-only                               # the page again from learners.json
    etmpc study learners --task TASK --retrain --ship              # after TASK's version changed: every seed again

Per task, with the task's recipes (``policies/<task>/dpi.yml`` and ``ppo.yml``, which ``etmpc reproduce`` reads
too):

* **DPI** trained once over ``--dpi-seeds`` (default: the recipe's) in lockstep (``WORK/dpi/<task>``): every seed's own choice on
  validation episodes (``seed<S>/selected.json``) and the run's (``selected.json``, the shipped seed);
* **PPO** trained once per seed of ``--ppo-seeds`` (``WORK/ppo/<task>/seed<S>``); the shipped seed is the
  one with the best objective on the same validation episodes;
* every seed's policy, each learner's shipped one, the shipped ones under the task's shield (where it
  declares one) and the best fixed schedule played on the stored test set (``etmpc.score``; the oracle's
  and the rollout meter's rows are the stored references' own evaluations). Scores are paired with the best
  fixed schedule episode by episode (0 = it, 100 = the oracle over it), with 95 % CIs.

Training uses the test set for nothing but its learning curve (a look back); every choice is made on
training-distribution episodes. Every stage is kept in WORK: run again, the study continues where it was.
With ``--ship`` the chosen seeds' files are copied into ``policies/<task>/`` (then regenerate the
leaderboard: ``make leaderboard``).
"""

from __future__ import annotations

import argparse
import json
import shutil
from pathlib import Path

import numpy as np

from etmpc.common import outputs
from etmpc.evaluation.references import rollout_meter_spec, stored
from etmpc.evaluation.scorecard import score, task_score
from etmpc.experiments.studies import runner
from etmpc.experiments.studies.learner_runs import dpi_runs, ppo_runs, row
from etmpc.experiments.studies.learners_page import page
from etmpc.learning.config import parse_seeds
from etmpc.systems import folder_name, make_system, names


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
    system = make_system(task)
    refs = stored(task)
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
        outputs.write_text(card_path, json.dumps({"specs": specs, "rows": rows}) + "\n")
    bounds, bound_rows = bounds_of(system, refs)
    rows |= bound_rows
    result = {"task": task, "best_fixed": refs.best, "rows": rows, "bounds": bounds, "learners": {}, "shield": None}
    result["made"] = runner.made()  # each task's own: tasks are run (and continued) by separate invocations
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


def arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--work", type=Path, default=Path("runs/learners"), help="where runs, cards and costs are kept (resumable)"
    )
    parser.add_argument("--task", action="append", choices=names(), help="a task (repeatable; default: every task)")
    parser.add_argument("--dpi-seeds", type=parse_seeds, help="DPI's seeds (default: its dpi.yml's)")
    parser.add_argument("--ppo-seeds", type=parse_seeds, default=(0, 1, 2), help="PPO's seeds (default 0-2)")
    runner.options(parser)
    parser.add_argument("--ship", action="store_true", help="copy the chosen seeds' files into policies/<task>/")
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


def run(args: argparse.Namespace) -> None:
    clock = runner.Stopwatch()
    provenance = runner.made()  # the code that runs: the checkout as it starts
    results = runner.Results(args.out, "learners")
    document = results.kept(lambda: {"tasks": {}})
    document["tasks"] = {t: document["tasks"][t] for t in names() if t in document["tasks"]}
    if args.page_only:
        results.write_page(page, document)
        return
    if args.bounds_only:
        for task in args.task or list(document["tasks"]):
            bounds, rows = bounds_of(make_system(task), stored(task))
            result = document["tasks"][task]
            result["rows"] = {k: v for k, v in result["rows"].items() if k not in result["bounds"].values()} | rows
            result["bounds"] = bounds
        results.write(document, page)
        return
    for task in args.task or names():
        result = compare(task, args.work, args.dpi_seeds, args.ppo_seeds, args.workers, args.retrain)
        document["tasks"][task] = result
        if args.ship:
            ship(task, result)
        print(
            f"{task}: " + "; ".join(f"{n} seeds {l['seed_mean']:.1f} ± {l['seed_sd']:.1f}" for n, l in result["learners"].items())
        )
    document["tasks"] = {t: document["tasks"][t] for t in names() if t in document["tasks"]}
    document.update(provenance)
    document["machine"] = runner.machine(args.workers, cpu=True)
    document["seconds"] = clock.seconds()
    results.write(document, page)


def ship(task: str, result: dict) -> None:
    """Copy the chosen seeds' files of ``task`` into ``policies/<task>/``."""
    (Path("policies") / folder_name(task)).mkdir(parents=True, exist_ok=True)  # a new task's first policies
    for learner in result["learners"].values():
        for name, source in learner["files"].items():
            shutil.copyfile(source, Path("policies") / folder_name(task) / name)
