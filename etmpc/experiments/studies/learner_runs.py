"""The learners' runs from the tasks' recipes (``policies/<task>/dpi.yml`` and ``ppo.yml``), shared by the studies
that train them (``learners``, ``failure-cost``, ``levels``): DPI over seeds in lockstep, PPO one run per seed, each
kept in a work folder so that a study run again continues; and a score card's row as those studies keep it.
"""

from __future__ import annotations

import json
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np

from etmpc.learning import dpi_recipe, hyperparams
from etmpc.learning.config import TrainConfig
from etmpc.learning.ppo import train_ppo
from etmpc.learning.ppo_settings import PpoSettings, settings_json
from etmpc.experiments.stages import trained
from etmpc.learning.runner import cost_path, timed
from etmpc.systems import folder_name, make_system, system_class

EVAL_EPISODES = 10  # test-set episodes of DPI's learning curve (a look back, never a choice)


def recipe_folder(task: str) -> Path:
    """Where ``task``'s recipe is read: its shipped policies' folder, or, for a variant with none shipped yet (a
    noisy variant's first run), the folder of the task whose world it plays (``variant_of``)."""
    own = Path("policies") / folder_name(task)
    variant_of = getattr(system_class(task), "variant_of", None)
    return own if (own / "learned.json").exists() or variant_of is None else Path("policies") / folder_name(variant_of)


def shipped_recipe(task: str) -> TrainConfig:
    """The DPI run of ``task``'s recipe, ``policies/<task>/dpi.yml`` (:mod:`etmpc.learning.dpi_recipe`), with the
    learning curve's test-set episodes; a new variant's first run takes the task's whose world it plays."""
    return replace(dpi_recipe.recipe(task), eval_episodes=EVAL_EPISODES)


def dpi_runs(
    task: str, work: Path, seeds: tuple[int, ...] | None, workers: int, failure_cost: float | None = None, out: Path | None = None
) -> dict:
    """DPI over ``seeds`` (None: the recipe's) in lockstep with the task's recipe (``failure_cost``, if given, in
    place of the recipe's), in ``out`` (default ``WORK/dpi/<task>``)."""
    out = work / "dpi" / folder_name(task) if out is None else out
    if (out / "checkpoint.json").exists():  # a run already in WORK continues as it was set up
        config = TrainConfig.from_json(json.loads((out / "checkpoint.json").read_text())["config"])
    else:
        config = shipped_recipe(task)
        config = config if seeds is None else replace(config, seeds=seeds)
        if failure_cost is not None:
            config = replace(config, dpi=replace(config.dpi, failure_cost=failure_cost))

    with timed(out, workers):  # the first invocation that finishes the run keeps its wall time
        trained(config, out, {"workers": workers, "backend": "local", "address": None}, progress=True)
    cost = json.loads(cost_path(out).read_text())
    seeds = config.seeds
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
    chosen = (max if sense == "max" else min)(seeds, key=lambda seed: validation[seed])
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
