"""What a trigger that chooses how much to compute gains on ``cart_pendulum/kicks_levels``, and what a learner
could: ``docs/results/levels.{json,md}``.

    etmpc study levels --work runs/levels       # about 20 min on 2 cores
    etmpc study levels --page-only              # the page again from levels.json

Everything is played on validation episodes (the training distribution: the stream ``etmpc train`` validates on,
never the stored test set), paired episode by episode with the task's best fixed schedule ``iterate:1``:

1. event-triggered real-time iterations under an age cap, ``shield:A:threshold:X:iterate`` (one SQP iteration
   when the weighted prediction error exceeds ``X`` or the plan is ``A`` steps old, else keep), over a grid;
2. the shipped learners, and DPI trained with the shipped recipe (the ``learners`` study's) over seeds 0-2 on
   its ``error`` features and on the ``levels`` features (the same and ``unconverged``: whether the kept plan is
   a real-time iterate short of convergence), each seed's own choice;
3. two fixed baselines from the field (:func:`baselines`): the advanced-step RTI's extra SQP iterations at every
   interval (Frey, Nurkanovic and Diehl 2024; their level D, full SQP iterations, as ``iterate:1:K``), and an
   iteration budget per interval, as acados users set one with ``timeout_max_time``: as many SQP iterations as
   fit in one control interval on the task's target platform, stopping early when they converge, at every
   interval and at every second one;
4. on the first ``--rollout-episodes`` of them: the rollout policy over the best trigger of 1 (a one-step
   lookahead over sampled futures, with 4 and 16 futures: the policy DPI's classifier learns to imitate, with
   that trigger as its base) and the oracle over ``iterate:1`` (the same lookahead with each episode's future
   known: a reference, not a policy).

If the rollout policy does no better than its base, one step of policy improvement by simulation has nothing to
find there, and what separates the trigger from the oracle is what knowing the future gives.
"""

from __future__ import annotations

import argparse
import math
from dataclasses import replace
from pathlib import Path

import numpy as np

from etmpc.evaluation import metrics
from etmpc.evaluation.backends import make_backend
from etmpc.experiments.stages import trained
from etmpc.experiments.studies import runner
from etmpc.experiments.studies.learner_runs import shipped_recipe
from etmpc.learning.config import VALIDATION_ENTROPY
from etmpc.learning.jobs import episode_outcomes
from etmpc.systems import make_system

TASK = "cart_pendulum/kicks_levels"
BEST_FIXED = "iterate:1"
THRESHOLDS = (0.1, 0.2, 0.3, 0.5)
AGES = (5, 8, 12)
SHIPPED = {
    "DPI (shipped)": "rl:policies/cart_pendulum/kicks_levels/learned.json",
    "PPO (shipped)": "sb3:policies/cart_pendulum/kicks_levels/ppo.zip",
}
FEATURES = ("error", "levels")
SEEDS = (0, 1, 2)


def trigger(age: int, level: float) -> str:
    return f"shield:{age}:threshold:{level:g}:iterate"


def baselines(task: str = TASK) -> dict[str, str]:
    """Row name -> spec of the field's fixed baselines on ``task``: AS-RTI with one and two extra SQP iterations
    at every interval, and the iteration budget of one control interval on the task's platform (the iterations
    that fit in it, ``floor(interval / time per iteration)``), spent at every interval and at every second one."""
    system = make_system(task)
    latency = system.config.latency
    budget = math.floor(system.control_interval_s / latency.iteration_s + 1e-9)
    if budget < 1:
        raise ValueError(f"{task}: one SQP iteration takes longer than a control interval on {latency.platform}")
    names = {f"iterate:1:{1 + extra}": f"AS-RTI, {extra} extra iteration{'s' * (extra > 1)}" for extra in (1, 2)}
    for period in (1, 2):
        every = "every interval" if period == 1 else f"every {period} intervals"
        spec, name = f"iterate:{period}:{budget}", f"budget of {budget} iterations (one interval), {every}"
        names[spec] = f"{names[spec]} = {name}" if spec in names else name  # one schedule, played once
    return {name: spec for spec, name in names.items()}


def dpi_runs(work: Path, workers: int) -> dict[str, str]:
    """DPI with the shipped recipe on each feature set (kept in WORK): row name -> each seed's chosen policy."""
    found = {}
    for features in FEATURES:
        out = work / f"dpi_{features}"
        config = replace(shipped_recipe(TASK), seeds=SEEDS, features=features)
        trained(config, out, {"workers": workers, "backend": "local", "address": None}, progress=True)
        for seed in SEEDS:
            found[f"DPI, {features} features, seed {seed}"] = f"rl:{out / f'seed{seed}' / 'selected.json'}"
    return found


def played(specs: dict[str, str], episodes: int, workers: int) -> dict[str, np.ndarray]:
    """name -> ``(episodes, 3)``: objective, failures and recomputes on the first ``episodes`` validation episodes."""
    with make_backend("local", workers) as pool:
        rows = episode_outcomes(pool, TASK, list(specs.values()), VALIDATION_ENTROPY, episodes)
    return dict(zip(specs, rows))


def gain(rows: np.ndarray, reference: np.ndarray) -> tuple[float, float]:
    """The paired gain of ``rows`` over ``reference`` (objectives, lower is better) as a share of the reference's
    mean objective, in percent, and its 95 % CI."""
    difference = metrics.paired_differences(rows[:, 0], reference[:, 0], "min")
    scale = float(np.mean(reference[:, 0]))
    return 100.0 * metrics.oriented(difference["mean_difference"], "min") / scale, 100.0 * difference["ci95"] / scale


def summary(rows: np.ndarray, reference: np.ndarray, spec: str, trigger_rows: np.ndarray | None = None) -> dict:
    share, ci = gain(rows, reference)
    found = {
        "spec": spec,
        "episodes": len(rows),
        "objective": float(np.mean(rows[:, 0])),
        "failures": float(np.mean(rows[:, 1])),
        "recomputes": float(np.mean(rows[:, 2])),
        "gain": share,
        "gain_ci95": ci,
        "episode_objectives": rows[:, 0].tolist(),
    }
    if trigger_rows is not None:  # and over the best trigger, on the same episodes
        found["gain_over_trigger"], found["gain_over_trigger_ci95"] = gain(rows, trigger_rows)
    return found


def study(work: Path, episodes: int, rollout_episodes: int, workers: int) -> dict:
    triggers = [trigger(a, x) for a in AGES for x in THRESHOLDS]
    specs = {BEST_FIXED: BEST_FIXED, **{t: t for t in triggers}, **SHIPPED, **dpi_runs(work, workers)}  # row name -> spec
    field = baselines()
    specs.update(field)
    main = played(specs, episodes, workers)
    best = min(triggers, key=lambda name: float(np.mean(main[name][:, 0])))
    lookahead = {
        BEST_FIXED: BEST_FIXED,
        best: best,
        f"rollout over {best}, 4 futures": f"rollout:{best}:4:10",
        f"rollout over {best}, 16 futures": f"rollout:{best}:16:10",
        "oracle": f"oracle:{BEST_FIXED}",
    }
    short = played(lookahead, rollout_episodes, workers)
    return {
        "task": TASK,
        "made": runner.made(),
        "validation_episodes": episodes,
        "rollout_episodes": rollout_episodes,
        "best_trigger": best,
        "rows": {name: summary(rows, main[BEST_FIXED], specs[name]) for name, rows in main.items() if name not in field},
        "baselines": {name: summary(main[name], main[BEST_FIXED], spec) for name, spec in field.items()},
        "iteration_s": make_system(TASK).config.latency.iteration_s,
        "lookahead": {name: summary(rows, short[BEST_FIXED], lookahead[name], short[best]) for name, rows in short.items()},
    }


def table(rows: dict, trigger: str | None = None) -> list[str]:
    extra = f" gain over `{trigger}` |" if trigger else ""
    lines = [
        f"| | spec | objective | gain over `iterate:1` |{extra} recomputes | failures / episode |",
        "|---|---|---:|---:|" + ("---:|" if trigger else "") + "---:|---:|",
    ]
    for name, r in rows.items():
        over = f" {r['gain_over_trigger']:+.1f} % ± {r['gain_over_trigger_ci95']:.1f} |" if trigger else ""
        lines.append(
            f"| {name} | `{r['spec']}` | {r['objective']:.3f} | {r['gain']:+.1f} % ± {r['gain_ci95']:.1f} |{over} "
            f"{r['recomputes']:.1f} | {r['failures']:.2f} |"
        )
    return lines


def page(document: dict) -> str:
    made = document["made"]
    dirty = " with uncommitted changes" if made.get("uncommitted_changes") else ""
    rows, look, best = document["rows"], document["lookahead"], document["best_trigger"]
    learned = {name: r for name, r in rows.items() if name.startswith(("DPI", "PPO"))}
    triggers = {name: r for name, r in rows.items() if name not in learned}
    rollouts = {name.rpartition(", ")[2]: r for name, r in look.items() if name.startswith("rollout")}
    lines = [
        "# Compute levels: what a trigger gains, and what is left to learn",
        "",
        runner.generated("levels", "docs/results/levels.json"),
        "",
        f"Made at commit `{made['commit']}`{dirty} ({made['date']}) on {document['machine']}, in "
        f"{document['seconds'] / 60:.0f} min. On `{document['task']}` ([the task](../tasks/timing.md)) a decision is "
        "keep, one SQP iteration or a full solve. Every row is played on validation episodes (the training "
        "distribution, never the stored test set), paired episode by episode with the best fixed schedule "
        "`iterate:1`; a gain is a share of its objective (lower is better), ± a 95 % CI.",
        "",
        f"## Event triggers and learners ({document['validation_episodes']} validation episodes)",
        "",
        *table(triggers),
        "",
        *table(learned),
        "",
        *_baselines_section(document),
        f"## One step of lookahead ({document['rollout_episodes']} validation episodes)",
        "",
        f"The rollout policy over the best trigger above, `{best}`, simulates each answer over sampled futures and "
        "then plays the trigger: the policy DPI's classifier learns to imitate when the trigger is its base. "
        "The oracle does the same over `iterate:1` with each episode's own future.",
        "",
        *table(look, best),
        "",
        "What one step of improvement by simulation adds to the trigger, paired on these episodes: "
        + ", ".join(f"{r['gain_over_trigger']:+.1f} % ± {r['gain_over_trigger_ci95']:.1f} with {n}" for n, r in rollouts.items())
        + f"; what knowing the future adds: {look['oracle']['gain_over_trigger']:+.1f} % ± "
        f"{look['oracle']['gain_over_trigger_ci95']:.1f} (the oracle over the trigger).",
        "",
    ]
    return "\n".join(lines)


def _baselines_section(document: dict) -> list[str]:
    """The field's fixed baselines, on the same validation episodes (absent from a document made before them)."""
    field = document.get("baselines")
    if not field:
        return []
    best = max(field, key=lambda name: field[name]["gain"])
    return [
        f"## Baselines from the field ({document['validation_episodes']} validation episodes)",
        "",
        "`iterate:T:K` makes up to `K` SQP iterations from the shifted plan when the plan is `T` steps old, stopping "
        "early when they converge; each iteration is priced and takes "
        f"{1000 * document['iteration_s']:g} ms on the task's platform. The advanced-step RTI (Frey, Nurkanović and "
        "Diehl 2024) adds iterations to each real-time iteration: these rows are its level D (full SQP iterations); "
        "its levels A-C, which iterate on a QP with the last linearisation, are not modelled. The budget rows spend "
        "the iterations that fit in one control interval, as an acados user's `timeout_max_time` would.",
        "",
        *table(field),
        "",
        f"The best of them, {best}, gains {field[best]['gain']:+.1f} % ± {field[best]['gain_ci95']:.1f} over `iterate:1`.",
        "",
    ]


def arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--work", type=Path, default=Path("runs/levels"), help="where DPI's runs are kept (resumable)")
    parser.add_argument("--episodes", type=int, default=200, help="validation episodes of the triggers and learners")
    parser.add_argument("--rollout-episodes", type=int, default=20, help="validation episodes of the lookahead rows")
    runner.options(parser)


def run(args: argparse.Namespace) -> None:
    results = runner.Results(args.out, "levels")
    if args.page_only:
        results.write_page(page)
        return
    clock = runner.Stopwatch()
    document = study(args.work, args.episodes, args.rollout_episodes, args.workers)
    document["machine"] = runner.machine(args.workers)
    document["seconds"] = clock.seconds()
    results.write(document, page)
