"""Why the paper's learner loses, measured: ``docs/results/gpomdp.{json,md}``.

    etmpc study gpomdp --work runs/gpomdp --workers 1     # both tasks, every row: about 90 min on one core
    etmpc study gpomdp --work runs/gpomdp --rows paper,fix --task cart_pendulum/balance
    etmpc study gpomdp --page-only                        # the page again from the JSON

GPOMDP (:mod:`etmpc.learning.gpomdp`) on the paper's two tasks, one factor at a time from the paper's settings
(:data:`ROWS`: the features, the baseline, the step size, and the fix, a step in units of the advantages' spread),
then the fix with the best of each factor (``fix + best``, chosen on validation). Each row is trained over 5 seeds
as ``etmpc train --algorithm gpomdp`` trains (the same streams and updates: :mod:`.gpomdp_probe`), logged block by
block (how far each update moves the parameters, the keep probability). Each seed's final policy is scored on
validation episodes (``VALIDATION_ENTROPY``, the training distribution; never the stored test set), paired with the
task's best fixed schedule on the same episodes: episodes ``0..SELECT-1`` choose the seed a run ships (as ``etmpc
train`` chooses ``selected.json``), the next ``--validation`` score every seed. Before any training, the gradient's
spread at the initial policy is measured under each baseline on episodes of the study's own stream.
Every run is kept in WORK after each block, and the JSON after each row: run again, the study continues.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np

from etmpc.common import outputs
from etmpc.evaluation.backends import make_backend
from etmpc.evaluation.references import stored
from etmpc.experiments.studies import runner
from etmpc.experiments.studies.gpomdp_page import page
from etmpc.experiments.studies.gpomdp_probe import diagnosis_episode, gradient_spread, train_logged
from etmpc.learning import gpomdp
from etmpc.learning.config import VALIDATION_ENTROPY
from etmpc.learning.jobs import _call, _learner_to_json
from etmpc.policies.learned import LogisticPolicy, Normalisation
from etmpc.systems import folder_name, make_system

TASKS = ("cart_pendulum/balance", "battery/trading")
SEEDS = (0, 1, 2, 3, 4)
EPISODES = 1500  # the paper's
BLOCK = 250  # episodes per logged block (and per save)
SELECT = 50  # validation episodes that choose a run's seed (etmpc train's validation_episodes)
DIAGNOSIS = 200  # episodes of the gradient's spread
PAPER: dict[str, Any] = {"features": "paper", "baseline": "none", "learning_rate": 0.05, "discount": 0.975, "scale": "none"}
#: Each row: what it changes from the paper's settings, in the order they are played (the most telling first). The
#: fix's alpha: at the initial policy, once the advantages are in units of their RMS, the bias's random walk over
#: 1500 updates is about 80 alpha on both tasks (the diagnosis); alpha = 0.005 keeps it near 0.4 of the keep logit.
ROWS: dict[str, dict] = {
    "paper": {},
    "features error": {"features": "error"},
    "short discount": {"discount": 0.7},
    "baseline state": {"baseline": "state"},
    "fix + best": {"scale": "advantage", "learning_rate": 0.005},  # and each factor's best level (chosen)
    "alpha x10": {"learning_rate": 0.5},
    "alpha x10 for 3000 episodes": {"learning_rate": 0.5, "episodes": 3000},  # the alpha 0.5 run, continued
    "fix": {"scale": "advantage", "learning_rate": 0.005},
    "baseline mean": {"baseline": "mean"},
    "alpha /10": {"learning_rate": 0.005},
}
FACTORS = {
    "features": ("paper", "features error"),
    "baseline": ("paper", "baseline mean", "baseline state"),
    "discount": ("paper", "short discount"),
}


def settings_of(row: str, rows: dict) -> dict:
    """The full settings of ``row``; ``fix + best`` takes each factor's level from the row that scored best on
    validation among those played (``rows``, this task's)."""
    settings = dict(PAPER, **ROWS[row])
    if row == "fix + best":
        for factor, candidates in FACTORS.items():
            played = [r for r in candidates if r in rows]
            best = max(played, key=lambda r: rows[r]["mean"])
            settings[factor] = rows[best]["settings"][factor]
    return settings


def run_key(settings: dict) -> str:
    s = settings  # not its episodes: a longer row continues the run
    return f"{s['features']}-{s['baseline']}-a{s['learning_rate']:g}-g{s['discount']:g}-{s['scale']}"


def initial_policy(task: str, features: str, pool) -> LogisticPolicy:
    """The run's initial policy, as ``etmpc train`` sets it up (the same normalisation episodes)."""
    states = pool.map(_call, [("normalisation", (task, i, features)) for i in range(20)])
    hyper = {"algorithm": "gpomdp", "features": features, "normalisation_episodes": 20}
    return LogisticPolicy.initial(Normalisation.fit(np.concatenate(states)), task, hyper, features)


def train(task: str, settings: dict, work: Path, pool) -> dict:
    """The run of ``settings`` on ``task`` over :data:`SEEDS` to its ``episodes`` (default :data:`EPISODES`; kept in WORK
    after each block): its initial policy, each seed's latest parameters (and ``snapshots``, each seed's at every
    count a longer row went past), and the log of each block (per seed). A longer row continues the shorter one's run."""
    episodes = settings.get("episodes", EPISODES)
    path = work / folder_name(task) / f"{run_key(settings)}.json"
    state = json.loads(path.read_text()) if path.exists() else None
    if state is None:
        policy = initial_policy(task, settings["features"], pool)
        own = gpomdp.Settings(**{k: settings[k] for k in ("discount", "learning_rate", "baseline", "scale")})
        learner = _learner_to_json(gpomdp.Learner.start(policy.theta, own, make_system(task).episode_steps))
        state = {"policy": policy.to_json(), "learners": {str(s): learner for s in SEEDS}, "log": [], "done": 0, "seconds": 0.0}
    clock = runner.Stopwatch()
    while state["done"] < episodes:
        snapshots = state.setdefault("snapshots", {})
        snapshots[str(state["done"])] = {s: learner["theta"] for s, learner in state["learners"].items()}
        start, stop = state["done"], min(state["done"] + BLOCK, episodes)
        jobs = [(task, state["policy"], state["learners"][str(s)], s, start, stop) for s in SEEDS]
        results = pool.map(_train, jobs)
        state["learners"] = {str(s): learner for s, (learner, _) in zip(SEEDS, results)}
        state["log"].append({str(s): log for s, (_, log) in zip(SEEDS, results)})
        state["done"], state["seconds"] = stop, state["seconds"] + clock.seconds()
        clock = runner.Stopwatch()
        outputs.write_text(path, json.dumps(state) + "\n")
        print(f"{task} {run_key(settings)}: {stop}/{episodes} episodes per seed, {state['seconds'] / 60:.1f} min")
    return state


def _train(args: tuple):
    return train_logged(*args)


def outcomes(pool, task: str, policies: list, first: int, count: int) -> list[np.ndarray]:
    """Each policy's ``(objective, failures, recomputes)`` on validation episodes ``first..first+count-1``."""
    jobs = [("outcome", (task, p, VALIDATION_ENTROPY, i)) for p in policies for i in range(first, first + count)]
    values = np.array(pool.map(_call, jobs), dtype=float)
    return [values[k * count : (k + 1) * count] for k in range(len(policies))]


def paired(policy: np.ndarray, fixed: np.ndarray, sense: str) -> dict:
    """The policy against the fixed schedule on the same episodes: the gain in % of the schedule's mean objective
    (positive: the policy is better), its 95 % CI, and the recomputes."""
    gain = (fixed[:, 0] - policy[:, 0]) if sense == "min" else (policy[:, 0] - fixed[:, 0])
    unit = 100.0 / abs(float(fixed[:, 0].mean()))
    return {
        "gain": float(gain.mean()) * unit,
        "ci95": float(1.96 * gain.std(ddof=1) / np.sqrt(len(gain))) * unit,
        "recomputes": float(policy[:, 2].mean()),
        "objective": float(policy[:, 0].mean()),
    }


def score(task: str, state: dict, fixed: dict, episodes: int, pool, trained: int = EPISODES) -> dict:
    """Every seed's final policy on the validation episodes: the seed chosen on the first :data:`SELECT` (the one a
    run ships), every seed scored on the next ``episodes`` against the fixed schedule, and the chosen seed's
    policy also played greedily (its likelier decision at each step)."""
    initial = LogisticPolicy.from_json(state["policy"])
    thetas = at(state, trained)
    policies = [initial.with_theta(np.asarray(thetas[str(s)])).to_json() for s in SEEDS]
    sense = make_system(task).objective_sense
    chooser = outcomes(pool, task, policies, 0, SELECT)
    pick = (min if sense == "min" else max)(range(len(SEEDS)), key=lambda k: chooser[k][:, 0].mean())
    scored = outcomes(pool, task, policies + [dict(policies[pick], decision="greedy")], SELECT, episodes)
    seeds = {str(s): paired(o, fixed["scoring"], sense) for s, o in zip(SEEDS, scored)}
    gains = [seeds[str(s)]["gain"] for s in SEEDS]
    return {
        "seeds": seeds,
        "mean": float(np.mean(gains)),
        "sd": float(np.std(gains, ddof=1)),
        "recomputes": float(np.mean([seeds[str(s)]["recomputes"] for s in SEEDS])),
        "chosen": SEEDS[pick],
        "greedy": paired(scored[-1], fixed["scoring"], sense),
        "theta": thetas,
    }


def at(state: dict, episodes: int) -> dict[str, list]:
    """Each seed's parameters after ``episodes`` training episodes (its latest, or a snapshot a longer run kept)."""
    if state["done"] == episodes:
        return {str(s): state["learners"][str(s)]["theta"] for s in SEEDS}
    return state["snapshots"][str(episodes)]


def summary_log(state: dict, episodes: int = EPISODES) -> list[dict]:
    """Each block's log up to ``episodes``, averaged over the seeds."""
    blocks = [b for b in state["log"] if next(iter(b.values()))["episodes"] <= episodes]
    return [{k: float(np.mean([seed[k] for seed in block.values()])) for k in next(iter(block.values()))} for block in blocks]


def diagnose(task: str, pool) -> dict:
    """The gradient's spread at the initial policy of each feature set, under each estimator (:func:`gradient_spread`)."""
    result = {}
    for features in FACTOR_LEVELS["features"]:
        policy = initial_policy(task, features, pool).to_json()
        episodes = pool.map(_call_diagnosis, [(task, policy, i) for i in range(DIAGNOSIS)])
        result[features] = dict(gradient_spread(task, features, episodes, PAPER["learning_rate"], EPISODES), episodes=DIAGNOSIS)
    return result


FACTOR_LEVELS = {"features": ("paper", "error")}


def _call_diagnosis(args: tuple) -> dict:
    return diagnosis_episode(*args)


def study_task(task: str, rows: list[str], document: dict, work: Path, episodes: int, pool, save) -> None:
    """Play ``rows`` on ``task`` into ``document["tasks"][task]`` (rows already there stay), saving after each."""
    entry = document["tasks"].setdefault(task, {"rows": {}})
    if "diagnosis" not in entry:
        entry["diagnosis"] = diagnose(task, pool)
        save()
    best = stored(task).best
    if entry.get("fixed", {}).get("episodes") != episodes:
        played = outcomes(pool, task, [best], SELECT, episodes)[0]
        entry["fixed"] = {"spec": best, "episodes": episodes, "objective": float(played[:, 0].mean()), "scoring": played.tolist()}
        save()
    fixed = {"scoring": np.asarray(entry["fixed"]["scoring"])}
    for row in rows:
        if row in entry["rows"] and entry["rows"][row].get("episodes") == episodes:
            continue
        settings = settings_of(row, entry["rows"])
        state = train(task, settings, work, pool)
        trained = settings.get("episodes", EPISODES)
        result = score(task, state, fixed, episodes, pool, trained)
        entry["rows"][row] = dict(
            result,
            settings=settings,
            run=run_key(settings),
            episodes=episodes,
            log=summary_log(state, trained),
            minutes=state["seconds"] / 60,
        )
        entry["made"] = runner.made()
        save()


def arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--work", type=Path, default=Path("runs/gpomdp"), help="where the runs are kept (resumable)")
    parser.add_argument("--task", action="append", choices=TASKS, help="a task (repeatable; default: both)")
    parser.add_argument("--rows", default=",".join(ROWS), help=f"rows to play, comma-separated (default: all, {', '.join(ROWS)})")
    parser.add_argument("--validation", type=int, default=100, help="validation episodes that score each seed (default 100)")
    runner.options(parser, workers=1)


def run(args: argparse.Namespace) -> None:
    results = runner.Results(args.out, "gpomdp")
    if args.page_only:
        results.write_page(page)
        return
    rows = [r.strip() for r in args.rows.split(",")]
    unknown = [r for r in rows if r not in ROWS]
    if unknown:
        raise SystemExit(f"unknown row {unknown[0]!r}; known: {', '.join(ROWS)}")
    document = results.kept(lambda: {"tasks": {}})
    clock = runner.Stopwatch()
    seconds = document.get("seconds", 0.0)

    def save() -> None:
        for entry in document["tasks"].values():  # the rows in the order of ROWS, however they were played
            entry["rows"] = {r: entry["rows"][r] for r in ROWS if r in entry["rows"]}
        document.update(machine=runner.machine(args.workers), seconds=seconds + clock.seconds())
        results.write(document, page)

    with make_backend("local", args.workers) as pool:
        for row in rows:  # row by row over both tasks, so a stopped study has each row on both
            for task in args.task or TASKS:
                study_task(task, [row], document, args.work, args.validation, pool, save)
    save()
