"""The page of the ``gpomdp`` study (``docs/results/gpomdp.md``), made from its JSON alone."""

from __future__ import annotations

from etmpc.experiments.studies import runner

PAPER = {"features": "paper", "baseline": "none", "learning_rate": 0.05, "discount": 0.975, "scale": "none"}


def page(document: dict) -> str:
    lines = [
        "# Why the paper's learner loses",
        "",
        runner.generated("gpomdp", "docs/results/gpomdp.json"),
        "",
        "GPOMDP (`etmpc train --algorithm gpomdp`), the paper's learner, on the paper's two tasks: first how its "
        "gradient estimate and its steps compare with the policy's parameters and the reward at the start of training, "
        "then an ablation, one factor at a time from the paper's settings (features `paper`, no baseline, "
        "α = 0.05, γ = 0.975, 1500 episodes), and the fix: a step in units of the advantages' spread "
        "(`scale=advantage`). Every row is trained over 5 seeds as `etmpc train` trains, and scored on validation "
        "episodes of the training distribution (never the stored test set), paired episode by episode with the task's "
        "best fixed schedule: gain in % of the schedule's objective, positive when the learner is better, ± a 95 % CI.",
        "",
        f"Played on {document['machine']}, in {document['seconds'] / 60:.0f} min in all.",
        "",
    ]
    for task, entry in document["tasks"].items():
        lines += task_section(task, entry)
    return "\n".join(lines)


def task_section(task: str, entry: dict) -> list[str]:
    made = entry.get("made", {})
    dirty = " with uncommitted changes" if made.get("uncommitted_changes") else ""
    lines = [f"## `{task}`", ""]
    if made:
        lines += [f"Made at commit `{made['commit']}`{dirty} ({made['date']}).", ""]
    if "diagnosis" in entry:  # measured first (a stopped study may have no more)
        lines += diagnosis_lines(entry["diagnosis"])
    if entry.get("rows"):
        lines += ablation_lines(task, entry)
        lines += movement_lines(entry)
    return lines


def diagnosis_lines(diagnosis: dict) -> list[str]:
    first = next(iter(diagnosis.values()))
    reward = first["reward"]
    lines = [
        "### The gradient at the start",
        "",
        f"{first['episodes']} episodes of the training distribution at the initial policy (keep probability "
        f"{reward['keep']:.3f}: it recomputes at {100 * (1 - reward['keep']):.0f} % of its decisions), of each feature "
        f"set. The return per episode is {reward['return_mean']:.4g} ± {reward['return_sd']:.3g} (mean ± sd over "
        f"episodes), {reward['per_step']:.3g} per step; a recompute costs {reward['recompute_price']:.3g}. One GPOMDP "
        "estimate per episode for each estimator (discount γ, baseline cross-fitted: each episode's from the others). "
        "*Step*: α = 0.05 times the root mean square of |g|, against the initial parameters' norm of 3 (the keep "
        "logit's bias). *Walk*: the spread of θ's random walk over 1500 updates at α = 0.05 (α √1500 times the "
        "estimates' total sd); *bias: drift, noise*: how far the keep logit's bias moves over those updates from the "
        "mean estimate, and the random walk's spread there; *z > 3*: the parameters whose mean estimate is more than "
        "3 standard errors from 0 (the signal an estimate of this many episodes finds). *Scaled* rows are in units "
        "of α (`scale=advantage`).",
        "",
        "| features | estimator | step per update | walk over 1500 | bias: drift | bias: noise | z > 3 |",
        "|---|---|---:|---:|---:|---:|---|",
    ]
    for features, d in diagnosis.items():
        for e in d["estimators"]:
            name = e["name"]
            lines.append(
                f"| {features} | {name} | {e['step']:.3g} | {e['walk']:.3g} | {e['bias_drift']:+.3g} | "
                f"{e['bias_noise']:.3g} | {significant(e)} |"
            )
    lines.append("")
    return lines


def significant(s: dict) -> str:
    return ", ".join(f"`{z['name']}` ({z['z']:+.1f})" for z in s["significant"]) or "none"


def changed(settings: dict) -> str:
    """What a row's settings change from the paper's, as ``--set`` pairs."""
    values = dict(PAPER, episodes=1500)
    diff = [
        f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}" for k in values if (v := settings.get(k, values[k])) != values[k]
    ]
    return ", ".join(f"`{d}`" for d in diff) or "the paper's"


def ablation_lines(task: str, entry: dict) -> list[str]:
    fixed = entry["fixed"]
    lines = [
        "### The ablation",
        "",
        f"Against `{fixed['spec']}` (objective {fixed['objective']:.5g} on the same {fixed['episodes']} validation "
        "episodes). *Seeds*: the mean gain over the 5 seeds ± their sd. *Shipped seed*: the seed a run would ship "
        "(chosen on 50 other validation episodes, as `etmpc train` chooses), its gain ± 95 % CI; *greedy*: the same "
        "policy deciding its likelier answer at each step instead of drawing it.",
        "",
        "| row | settings | seeds: gain % | recomputes | shipped seed: gain % | recomputes | greedy: gain % | recomputes "
        "| training (min) |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for name, row in entry["rows"].items():
        chosen, greedy = row["seeds"][str(row["chosen"])], row["greedy"]
        lines.append(
            f"| {name} | {changed(row['settings'])} | {row['mean']:+.2f} ± {row['sd']:.2f} | {row['recomputes']:.1f} | "
            f"{chosen['gain']:+.2f} ± {chosen['ci95']:.2f} (seed {row['chosen']}) | {chosen['recomputes']:.1f} | "
            f"{greedy['gain']:+.2f} ± {greedy['ci95']:.2f} | {greedy['recomputes']:.1f} | {row['minutes']:.1f} |"
        )
    best = max(entry["rows"], key=lambda r: entry["rows"][r]["mean"])
    row = entry["rows"][best]
    sets = " ".join(f"--set {k}={v}" for k, v in row["settings"].items() if v != dict(PAPER, episodes=1500)[k])
    lines += [
        "",
        f"Best on validation (mean over seeds): **{best}**, {row['mean']:+.2f} % ± {row['sd']:.2f} "
        f"(its shipped seed {row['seeds'][str(row['chosen'])]['gain']:+.2f} % ± "
        f"{row['seeds'][str(row['chosen'])]['ci95']:.2f}); its recipe: "
        f"`etmpc train --task {task} --algorithm gpomdp{' ' + sets if sets else ''}`.",
        "",
    ]
    return lines


def movement_lines(entry: dict) -> list[str]:
    lines = [
        "### How far training moves the policy",
        "",
        "Per row, mean over seeds, the first and the last block of 250 episodes: the length of one update "
        "|θ' − θ| (root mean square), the net move of θ over the block against the path its updates walked (1 is a "
        "straight line, 1/√250 = 0.06 a random walk), and the keep probability at the policy's decisions.",
        "",
        "| row | step: first | step: last | net / path: first | net / path: last | keep: first | keep: last |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    for name, row in entry["rows"].items():
        first, last = row["log"][0], row["log"][-1]
        lines.append(
            f"| {name} | {first['step']:.3g} | {last['step']:.3g} | {first['drift'] / first['path']:.2f} | "
            f"{last['drift'] / last['path']:.2f} | {first['keep']:.3f} | {last['keep']:.3f} |"
        )
    lines.append("")
    return lines
