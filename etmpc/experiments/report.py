"""``REPORT.md`` from ``results.json``'s content alone, and what it says about the software and machine."""

from __future__ import annotations

import os
import platform
from importlib import metadata
from pathlib import Path

from etmpc.systems import folder_name, same_task
from etmpc.experiments.clock import time_table
from etmpc.experiments import shipped as shipped_policies
from etmpc.evaluation.metrics import higher_or_lower, oriented
from etmpc.experiments.pareto import report_section

# The paper's headline figures (docs/paper.md, "The paper's headline results"), to set the results against.
PAPER = {"cart_pendulum/balance": {"margin_percent": 5.0}, "battery/trading": {"margin_percent": 7.0}}


def software_versions() -> dict:
    names = ("numpy", "scipy", "mujoco", "dm-control", "casadi", "control", "rerun-sdk", "ray", "matplotlib", "av")
    versions: dict[str, str | None] = {"python": platform.python_version()}
    for name in names:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = None
    versions["etmpc"] = metadata.version("etmpc")
    return versions


def machine() -> dict:
    cpu = platform.processor() or ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    try:
        memory = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 2**30
    except (ValueError, OSError):
        memory = float("nan")
    return {"platform": platform.platform(), "cpu": cpu, "cores": len(os.sched_getaffinity(0)), "memory_gib": round(memory, 1)}


def _f(x: float) -> str:
    return f"{x:.5f}"


def report(results: dict) -> str:
    """``REPORT.md`` from ``results.json``'s content alone."""
    s = results["settings"]
    lines = ["# etmpc: the paper's experiments, reproduced", ""]
    if s.get("smoke"):
        lines += [
            "**This is a smoke run (`--quick`): every size is far too small for a conclusion. It checks that "
            "every stage runs; it gives no verdicts.**",
            "",
        ]
    lines += [
        f"Settings: {len(s['seeds'])} seeds x {s['episodes']} training episodes, evaluated every {s['eval_every']}"
        f" on {s['eval_episodes'] or 'all'} test-set episodes; fixed policies and the final learned policies on "
        f"{s['test_episodes'] or 'all'} test-set episodes, the learned ones {s['repeats']} times.",
        "",
    ]
    for domain, r in results["systems"].items():
        sense = higher_or_lower(r["objective_sense"])
        unit = "profit, EUR" if sense == "higher" else "cost"
        lines += [
            f"## {domain}",
            "",
            f"Objective: {unit}, {sense} is better, mean over {r['episodes']} test-set episodes.",
            "",
            "| policy | objective | ± std over episodes | control | recomputes | solver failures |",
            "|---|---|---|---|---|---|",
        ]
        for spec, row in r["fixed"].items():
            mark = " **(best fixed)**" if spec == r["best_fixed"]["policy"] else ""
            lines.append(
                f"| `{spec}`{mark} | {_f(row['objective_mean'])} | {_f(row['objective_std'])} | "
                f"{_f(row['control_objective_mean'])} | {row['recomputes_mean']:.2f} | {row['solver_failures']} |"
            )
        if "learned" in r:  # the paper's learner, on the paper's own tasks
            lines += _paper_learner(r)
        else:
            lines += [
                "",
                f"![Figure 3]({r['files']['figure3']})",
                "",
                "A task beyond the paper: its learners are the default one (DPI), below, and PPO.",
                "",
            ]
        lines += (
            []
            + headroom_section(r, s.get("smoke", False))
            + learners_section(r)
            + [f"Files: {', '.join(f'`{v}`' for v in r['files'].values())}.", ""]
        )
    lines += scorecard_section(results)
    lines += shipped_policies.section(results["systems"])
    if results.get("sweep"):
        lines += ["# Beyond the paper: the trade-off curve", ""]
        for domain, pareto in results["sweep"].items():
            lines += report_section(pareto) + ["", f"![trade-off](sweep/{folder_name(domain)}/pareto.png)", ""]
    lines += ["## Against the paper", ""]
    lines += (["No verdicts in a smoke run."] if s.get("smoke") else against_the_paper(results)) + [""]
    lines += time_table(results["systems"])
    lines += ["## Software and machine", "", "| package | version |", "|---|---|"]
    lines += [f"| {k} | {v} |" for k, v in results["software"].items()]
    m = results["machine"]
    lines += ["", f"Machine: {m['cpu']}, {m['cores']} cores, {m['memory_gib']} GiB, {m['platform']}.", ""]
    if "provenance" in results:  # a run's stages may have been played by earlier invocations (a run continues)
        p = results["provenance"]
        lines += [
            f"Written at commit {p['commit']}{' (with uncommitted changes)' if p['uncommitted_changes'] else ''} on {p['date']}.",
            "",
        ]
    return "\n".join(lines)


def _pct(row: dict) -> str:
    return f"{row['gain_percent']:+.2f} % ± {row['gain_percent_ci95']:.2f} %"


def headroom_section(r: dict, smoke: bool) -> list[str]:
    """What any policy could gain over the best fixed policy, and what the learners reach."""
    h, d = r["headroom"], r["default_learner"]
    best = h["reference"]
    names = {
        "oracle": "a one-step lookahead over it that knows the episode's future: a reference, **not a policy**",
        "rollout": "rollout policy",
        "learned_default": "learned, default learner (DPI, error features)",
        "learned_paper": "learned, the paper's (GPOMDP, paper features)",
        "best_fixed": "best fixed",
    }
    lines = [
        f"### Headroom over `{best}`",
        "",
        f"Paired over test-set episodes 0–{h['episodes'] - 1} (the rollout policies are expensive); "
        "gain > 0 is better than the best fixed policy; 95 % CIs. The oracle is what a one-step lookahead "
        f"over `{best}` can gain knowing the future, not what every policy can: one that also saves recomputes can beat it.",
        "",
        "| | policies | recomputes | objective | gain over best fixed | gain % |",
        "|---|---|---|---|---|---|",
    ]
    for key, row in h["rows"].items():
        specs = ", ".join(f"`{p}`" for p in row["policies"]) if len(row["policies"]) <= 2 else f"{len(row['policies'])} seeds"
        gain = (
            ("reference", "reference")
            if key == "best_fixed"
            else (f"{oriented(row['mean_difference'], r['objective_sense']):+.5f} ± {row['ci95']:.5f}", _pct(row))
        )
        lines.append(
            f"| {names[key]} | {specs} | {row['recomputes_mean']:.1f} | {_f(row['objective_mean'])} | {gain[0]} | {gain[1]} |"
        )
    if h["rollout_seconds_per_step"] is not None:
        cost = h["rollout_cost"]
        lines += [
            "",
            f"The rollout policy cost {h['rollout_seconds_per_step'] * 1e3:.0f} ms of CPU per step (its decision "
            f"included): {cost['wall_seconds']:.0f} s for {h['episodes']} episodes on {cost['workers']} workers.",
        ]
    p = d["paired"]
    lines += [
        "",
        f"**The default learner on all {p['episodes']} test-set episodes** (`{d['policy']}`, seed {d['seed']}, "
        f"chosen among {len(d['validation'])} policies of {len({k.partition('@')[0] for k in d['validation']})} seeds on "
        "validation episodes, never the test set; iteration 0 rolled out "
        f"over `{d['base']}`): {_f(d['objective_mean'])} with {d['recomputes_mean']:.1f} recomputes; against "
        f"`{best}`: gain {_pct(p)}, better in {p['better_episodes']}/{p['episodes']} episodes.",
    ]
    if not smoke:
        ci_low = p["gain_percent"] - p["gain_percent_ci95"]
        lines.append(f"Its CI {'excludes' if ci_low > 0 else 'does not exclude'} 0.")
    return lines + [""]


def _paper_learner(r: dict) -> list[str]:
    """The paper's learner (GPOMDP, 5 seeds): its row, its margin over the best fixed policy, its curve."""
    le, p, c = r["learned"], r["paired"], r["curve"]
    return [
        f"| learned ({len(le['per_seed'])} seeds x {le['repeats']} passes) | {_f(le['objective_mean'])} | "
        f"± {_f(le['objective_std_seeds'])} over seeds | {_f(le['control_objective_mean'])} | "
        f"{le['recomputes_mean']:.2f} | {le['solver_failures']} |",
        "",
        f"**Learned minus best fixed (`{r['best_fixed']['policy']}`)**, paired over test-set episodes: "
        f"{p['mean_difference']:+.5f} ± {p['ci95']:.5f} (95 % CI); the learned policy is better in "
        f"{p['learned_better_episodes']}/{p['episodes']} episodes; margin {r['margin_percent']:+.2f} % "
        f"(positive: the learned policy is better).",
        "",
        f"**Learning curve** (test-set objective, mean ± std over seeds): start {_f(c['start']['objective_mean'])} "
        f"({c['start']['recomputes_mean']:.1f} recomputes), best {_f(c['best']['objective_mean'])} at "
        f"{c['best']['episodes']} episodes, final {_f(c['final']['objective_mean'])} ± {_f(c['final']['objective_std'])} "
        f"({c['final']['recomputes_mean']:.1f} recomputes).",
        "",
        f"![learning curve]({r['files']['curve']}) ![Figure 3]({r['files']['figure3']})",
        "",
    ]


def learners_section(r: dict) -> list[str]:
    """The learners side by side on every test-set episode, against the best fixed policy, with their cost
    and their sample-efficiency figure."""
    if "learners" not in r:
        return []
    le = r["learners"]
    names = {
        "dpi": "DPI (the default learner, `rl:`)",
        "gpomdp": "GPOMDP (the paper's, `rl:`, seeds pooled)",
        "ppo": "PPO (Stable-Baselines3, `sb3:`)",
    }
    lines = [
        f"### The learners against `{le['reference']}`, on every test-set episode",
        "",
        "| learner | recomputes | objective | gain over best fixed | better in | simulated steps per run | "
        "runs | training wall time |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for key in ("dpi", "gpomdp", "ppo"):
        if key not in le:
            continue
        row, cost = le[key], le[key]["training"]
        simulated = cost.get("simulated_steps_per_seed")
        wall = f"{cost['wall_seconds'] / 60:.1f} min on {cost['workers']} workers" if "wall_seconds" in cost else "not timed"
        lines.append(
            f"| {names[key]} | {row['recomputes_mean']:.1f} | {_f(row['objective_mean'])} | {_pct(row)} | "
            f"{row['better_episodes']}/{row['episodes']} | {'—' if simulated is None else f'{simulated:,}'} | "
            f"{cost.get('seeds', 1)} | {wall} |"
        )
    lines += [
        "",
        "Simulated steps count every control interval a run (one seed) simulated: its own episodes, the "
        "rollouts that label DPI's decisions, PPO's reward baseline. DPI ships the best of its seeds on "
        "validation episodes; GPOMDP's row pools its seeds' policies; PPO is one seed, its checkpoint chosen on "
        "validation episodes. The wall time is the whole training stage, every seed.",
    ]
    if "ppo" not in le:
        lines += ["", "PPO did not run: it needs the 'rl' extra (`pip install 'etmpc[rl]'`)."]
    if "efficiency" in r.get("files", {}):
        lines += ["", f"![sample efficiency]({r['files']['efficiency']})"]
    return lines + [""]


def of_task(systems: dict, task: str) -> dict | None:
    """A run's results for ``task``, whichever name the run gave it (an older run's ``battery``, a newer one's
    ``battery/trading``); None if it has none."""
    return next((r for name, r in systems.items() if same_task(name, task)), None)


def against_the_paper(results: dict) -> list[str]:
    """Each headline claim of the paper (docs/paper.md), and whether it holds here, with the numbers."""
    out = []
    systems = results["systems"]
    for domain, r in systems.items():
        claim = next((c for task, c in PAPER.items() if same_task(domain, task)), None)
        if claim is None:  # a task beyond the paper: no claim of the paper to hold it against
            continue
        paper = claim["margin_percent"]
        holds = (
            r["margin_percent"] > 0
            and r["paired"]["mean_difference"] != 0
            and r["paired"]["ci95"] < abs(r["paired"]["mean_difference"])
        )
        out.append(
            f"- *The learned policy is the best on {domain}, about {paper:g} % better than the second best.* "
            f"{'Holds' if holds else 'Does not hold'} here: learned {_f(r['learned']['objective_mean'])} against "
            f"the best fixed `{r['best_fixed']['policy']}` {_f(r['best_fixed']['objective_mean'])}, a margin of "
            f"{r['margin_percent']:+.2f} % (paired difference {r['paired']['mean_difference']:+.5f} ± "
            f"{r['paired']['ci95']:.5f})."
        )
    if (r := of_task(systems, "cart_pendulum/balance")) is not None:
        always = r["fixed"]["always"]
        le = r["learned"]
        cheap = {
            spec: row
            for spec, row in r["fixed"].items()
            if row["recomputes_mean"] <= 25.0 and row["control_objective_mean"] <= always["control_objective_mean"] * 1.01
        }
        holds = le["recomputes_mean"] < 25.0 and le["control_objective_mean"] <= always["control_objective_mean"] * 1.01
        out.append(
            "- *On the cart pendulum the learned policy reaches virtually the control performance of standard MPC "
            "(`always`) with less than a quarter of its recomputes.* "
            f"{'Holds' if holds else 'Does not hold'} for the learned policy: control {_f(le['control_objective_mean'])} "
            f"with {le['recomputes_mean']:.1f} recomputes, against `always` {_f(always['control_objective_mean'])} with "
            f"100. Fixed policies that do (control within 1 % of `always`, at most 25 recomputes): "
            + (
                ", ".join(f"`{s}` ({_f(v['control_objective_mean'])}, {v['recomputes_mean']:.0f})" for s, v in cheap.items())
                or "none"
            )
            + "."
        )
    if (r := of_task(systems, "battery/trading")) is not None:
        best = r["best_fixed"]
        always = r["fixed"]["always"]
        out.append(
            "- *On the battery the saving comes from keeping larger parts of one plan, not from the energy its "
            f"recomputes draw.* Here the best policy is `{best['policy']}` ({_f(best['objective_mean'])}, "
            f"{best['recomputes_mean']:.0f} recomputes); `always` earns {_f(always['objective_mean'])} and `never` "
            f"{_f(r['fixed']['never']['objective_mean'])}. "
            + (
                "Keeping plans does not pay on this benchmark's forecast model: a new plan trades at the true current "
                "price, a kept one at a forecast."
                if best["policy"] == "always"
                else "Keeping plans pays here."
            )
        )
    return out


def scorecard_section(results: dict) -> list[str]:
    """What the run trained, on the suite's scorecard (``etmpc score``): each task's normalized score
    (0: its best periodic schedule, 100: the oracle over it) and the interquartile mean of its episode scores."""
    from etmpc.evaluation.card import TaskScore, aggregate

    cards = {task: r.get("scorecard", {}) for task, r in results["systems"].items()}
    tasks = [task for task, card in cards.items() if "rows" in card]
    lines = ["## The scorecard", ""]
    missing = [f"{task}: {card['unavailable']}" for task, card in cards.items() if "unavailable" in card]
    if not tasks:
        return lines + ["No task could be scored." + (f" ({'; '.join(missing)})" if missing else ""), ""]
    names: list[str] = []
    for task in tasks:
        names += [name for name in cards[task]["rows"] if name not in names]
    lines += [
        "Each task's normalized score on the run's test-set episodes, against the suite's stored references "
        "(0: the task's best periodic schedule, 100: the oracle over it; ± 95 % CI), as `etmpc score` gives it; "
        "the IQM of every episode score of the tasks a row was scored on, with its stratified bootstrap CI. CPU times are "
        "`etmpc score`'s, not measured here.",
        "",
        "| trained | " + " | ".join(tasks) + " | IQM [95 % CI] |",
        "|---|" + "---:|" * (len(tasks) + 1),
    ]
    for name in names:
        rows = [cards[t]["rows"].get(name) for t in tasks]
        cells = ["-" if r is None else f"{r['score']:.1f} ± {r['score_ci95']:.1f}" for r in rows]
        a = aggregate([TaskScore.from_json(r) for r in rows if r is not None])
        lines.append(f"| {name} | " + " | ".join(cells) + f" | {a.iqm:.1f} [{a.iqm_ci95[0]:.1f}, {a.iqm_ci95[1]:.1f}] |")
    refs = "; ".join(f"{t}: `{cards[t]['references']['best_periodic']}`, `{cards[t]['references']['oracle']}`" for t in tasks)
    lines += ["", f"References: {refs}." + (f" Not scored: {'; '.join(missing)}." if missing else ""), ""]
    return lines
