"""Choose each safety task's shield rule on training-distribution episodes (``etmpc.learning.shields``).

    etmpc study shields                       # the tasks below, hours on 2 cores (1,000 episodes each)
    etmpc study shields --task quadrotor/waypoints --episodes 30
    etmpc study shields --from-tables         # choose again from shields.json's tables, and its page
    etmpc study shields --task quadrotor/waypoints --episodes 1000 --select certify --bound 0.05

For each task: its shipped DPI and PPO, unshielded and under every rule of the task's grid, and its best
fixed schedule, on the first ``--episodes`` validation episodes (never the test set), and a rule chosen by
``--select``: ``budget``, the safest rule within a cost budget (:func:`~etmpc.learning.shields.pick`), or
``certify``, the cheapest rule whose failures per episode, paired with the schedule's, are within ``--bound``
at 95 % for every learner (:func:`~etmpc.learning.shields.certify`), or the budget's choice where nothing is
(:func:`~etmpc.learning.shields.certify_or_budget`), said to be uncertified. Each task keeps how it was chosen. Writes
``docs/results/shields.json`` (what was chosen, and the whole table) and its page ``shields.md``, and
prints each task's rule as the line to declare in its system class (``shield = ShieldRule(...)``). The
test-set figures of the shielded policies are on the learner comparison page, the ``learners`` study's.
"""

from __future__ import annotations

import argparse
import math

from etmpc.common.errors import EtmpcError
from etmpc.common.progress import Progress
from etmpc.evaluation.backends import make_backend
from etmpc.evaluation.references import stored
from etmpc.experiments.leaderboard_rows import shipped_policy
from etmpc.experiments.studies import runner
from etmpc.learning.shields import BUDGET, SAFETY_BOUND, candidates, certify_or_budget, choose, pick, rules, select

#: Each task whose failures are safety events: its grid (maximum plan ages, margins in its unit, and deviations
#: from the plan beside a margin: |W (x - x_hat)|, the threshold trigger's measure). Falls are rare on the cart
#: pendulum (a few in a hundred episodes): a certified rule needs about a thousand episodes. The quadrotor's crashes
#: begin as a flip on a kept plan, while the margin to the ground is still wide: its grid reads the deviation. On
#: kicks_levels the deviations are the event trigger's levels (threshold:X:iterate), beside the margin once certified.
GRIDS: dict[str, tuple[tuple[int, ...], tuple[float | None, ...], tuple[float | None, ...]]] = {
    "cart_pendulum/kicks": ((5, 10, 20), (None, 0.6, 0.9, 1.0), (None,)),
    "cart_pendulum/kicks_late": ((3, 5, 10), (None, 0.9, 1.0, 1.1), (None,)),
    "cart_pendulum/kicks_levels": ((5, 10), (None, 1.1), (None, 0.2, 0.3, 0.5)),
    "cart_pendulum/kicks_noisy": ((5, 10, 20), (None, 0.6, 0.9, 1.0), (None,)),
    "quadrotor/waypoints": ((10, 15), (None, 0.25), (None, 0.5, 1.0, 2.0)),
    "quadrotor/waypoints_noisy": ((10, 15), (None, 0.25), (None, 0.5, 1.0, 2.0)),
}
EPISODES = 1000  # validation episodes per policy, unless --episodes


def shipped(task: str) -> list[str]:
    specs = []
    if (path := shipped_policy(task)) is not None:
        specs.append(f"rl:{path}")
    if (path := shipped_policy(task, "ppo.zip")) is not None:
        specs.append(f"sb3:{path}")
    return specs


def page(document: dict) -> str:
    """``docs/results/shields.md``: each task's table of rules, from ``shields.json``."""
    lines = [
        "# Shields: how each task's rule was chosen",
        "",
        runner.generated("shields", "docs/results/shields.json"),
        "",
        f"Last run at commit `{document['commit']}` ({document['date']}) on {document['machine']}, in "
        f"{document['seconds'] / 60:.0f} min (each task says the commit it was played at). Each rule played around "
        "the task's shipped DPI and PPO on validation episodes (the training distribution, never the test set), "
        "beside the best fixed schedule. A rule is chosen in one of two ways, and each task says which. By a "
        "budget: a shield is insurance bought with objective: among the rules that cost "
        f"the learners at most {100 * BUDGET:g} % of their unshielded mean objective (lower is better on these "
        "tasks), the chosen rule is the safest (the fewest failures per episode of the learner that fails most), "
        "then the cheapest; none if no rule within the budget is safer than no shield. By certification: safety "
        "as a constraint: a rule (or none) is certified when, for each learner, the upper end of the 95 % "
        "confidence interval of its failures per episode minus the schedule's, paired episode by episode, is "
        "within the bound, the interval widened for the number of rules tried (Bonferroni); the certified rule "
        "with the best mean objective is chosen; where nothing is certified, not even no shield, the budget "
        "chooses and the task says its rule is not certified. What the shield is: "
        "[policies](../policies.md#shields-shield).",
        "",
    ]
    for task, result in document["tasks"].items():
        lines += _task_section(task, result, result.get("commit", document["commit"]))
    return "\n".join(lines)


def _task_section(task: str, result: dict, commit: str) -> list[str]:
    """One task's paragraph and table of rules."""
    schedule = result["schedule"]
    selection = result.get("selection", {"by": "budget"})
    certified = selection["by"] == "certify"
    bounds = "upper_bounds" in selection  # certification was asked (and, where nothing passed, the budget chose)
    if certified:
        how = f"by certification, within {selection['bound']:g} failures per episode of `{schedule['spec']}`"
        none = "none (no shield is certified and cheapest)" if result["safe"] else "none (no rule is certified)"
        safety = "certified" if result["safe"] else "not certified"
    elif selection.get("uncertified"):
        how = (
            f"by a budget, as nothing (no shield included) is certified within {selection['bound']:g} failures per "
            f"episode of `{schedule['spec']}`"
        )
        none = "none (no rule within the budget is safer than no shield)"
        safety = "not certified"
    else:
        how = "by a budget"
        none = "none (no rule within the budget is safer than no shield)"
        safety = ("as safe as" if result["safe"] else "less safe than") + f" `{schedule['spec']}` on these episodes"
    chosen = none if result["chosen"] is None else f"**`shield:{result['chosen']}`**"
    header = "| rule | mean objective of the learners | failures per episode, the worse learner |"
    rule = "|---|---|---|"
    if bounds:
        header += " upper bound of the paired failure gap, the worse learner |"
        rule += "---|"
    lines = [
        f"## `{task}`",
        "",
        f"{result['episodes']} validation episodes, played at commit `{commit}`; a rule is `AGE[:MARGIN[:DEVIATION]]`, margins "
        f"in {result['margin_unit']}, deviations as `threshold:X` measures them. "
        f"`{schedule['spec']}`: objective {schedule['objective']:.3f}, {schedule['failures']:.3f} failures per episode. "
        f"Chosen {how}: {chosen} ({safety}).{_behind_schedule(result)}{_why_uncertified(result)}",
        "",
        header,
        rule,
    ]
    for row in candidates(result):
        name = "none" if row["rule"] == "none" else f"`{row['rule']}`"
        mark = " (chosen)" if row["rule"] == result["chosen"] else ""
        line = f"| {name}{mark} | {row['objective']:.3f} | {row['worst_failures']:.3f} |"
        if bounds:
            line += f" {selection['upper_bounds'][row['rule']]:.3f} |"
        lines.append(line)
    lines.append("")
    return lines


def _behind_schedule(result: dict) -> str:
    """The rules within the bound that certification passed over, as some learner under them loses to the schedule."""
    behind = result.get("selection", {}).get("behind_schedule", [])
    if not behind:
        return ""
    rows = {row["rule"]: row for row in candidates(result)}
    named = ", ".join(f"`{rule}` ({rows[rule]['objective']:.3f})" for rule in behind)
    return (
        f" Within the bound, but not certified because a learner under it does worse than `{result['schedule']['spec']}` "
        f"on mean objective (the learners' mean in brackets): {named}."
    )


def _why_uncertified(result: dict) -> str:
    """Where nothing was certified: how wide the spread of the paired gaps alone makes the interval."""
    selection = result.get("selection", {})
    if not selection.get("uncertified"):
        return ""
    rows = candidates(result)
    spreads = [p["failure_gap"]["sd"] for row in rows for p in row["policies"].values()]
    half = selection["z"] * min(spreads) / math.sqrt(result["episodes"])
    return (
        f" The paired gaps' standard deviations are {min(spreads):.2f} to {max(spreads):.2f} failures per episode, so "
        f"the interval's upper end is at least {half:.2f} above the mean gap, whatever the rule: rare, long failures "
        "(episodes that count tens of failures) decide it."
    )


def arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--task", action="append", choices=sorted(GRIDS), help="a task (repeatable; default: all)")
    parser.add_argument("--episodes", type=int, default=EPISODES, help=f"validation episodes per policy (default {EPISODES})")
    parser.add_argument(
        "--select",
        choices=("certify", "budget"),
        default="certify",
        help="certify: the cheapest rule within --bound of the schedule's failures (paired, 95 %%), or, where "
        f"nothing is, the budget's choice, said to be uncertified; budget: the safest rule costing at most "
        f"{100 * BUDGET:g} %% (default: certify)",
    )
    parser.add_argument(
        "--bound",
        type=float,
        default=SAFETY_BOUND,
        help=f"with --select certify: failures per episode a learner may add to the schedule's (default: {SAFETY_BOUND:g})",
    )
    runner.options(parser, page_only=False)
    parser.add_argument(
        "--from-tables",
        action="store_true",
        help="choose again from the tables in shields.json (no episode played) and write the page",
    )


def run(args: argparse.Namespace) -> None:
    results = runner.Results(args.out, "shields")
    if args.from_tables:
        document = results.read()
        document["tasks"] = {task: select(result) for task, result in document["tasks"].items()}
        results.write(document, page)
        return
    if args.episodes < 2:
        raise EtmpcError(f"--episodes must be at least 2 (a paired bound needs two), got {args.episodes}")
    if not 0 < args.bound < math.inf:
        raise EtmpcError(f"--bound must be a number of failures per episode > 0, got {args.bound}")
    clock = runner.Stopwatch()
    provenance = runner.made()  # the code that runs: the checkout as it starts
    played = results.kept(lambda: {"tasks": {}})["tasks"]  # the tasks not run again stay
    for task in args.task or list(GRIDS):
        result = rule(task, args.episodes, args.workers)
        result = certify_or_budget(result, args.bound) if args.select == "certify" else pick(result)
        played[task] = dict(result, commit=provenance["commit"], date=provenance["date"])
        report(result)
    document = {
        "commit": provenance["commit"],
        "date": provenance["date"],
        "machine": runner.machine(args.workers, cpu=True),
        "seconds": clock.seconds(),
        "tasks": {task: played[task] for task in GRIDS if task in played},
    }
    results.write(document, page)


def rule(task: str, episodes: int, workers: int) -> dict:
    """Play ``task``'s grid of rules on ``episodes`` validation episodes: the table a rule is chosen from."""
    grid = rules(*GRIDS[task])
    policies = shipped(task)
    jobs = (1 + len(policies) * (1 + len(grid))) * episodes
    with make_backend("local", workers) as pool, Progress(jobs, f"{task}: shield rules") as bar:
        result = choose(task, policies, stored(task).best, grid, episodes, pool, lambda job: bar.update())
    return result


def report(result: dict) -> None:
    """Print a task's table and its choice, as the line to declare in its system class."""
    schedule, unshielded = result["schedule"], result["unshielded"]
    worst = unshielded["worst_failures"]
    print(
        f"{result['task']}: {schedule['spec']} fails {schedule['failures']:.3f}/episode; unshielded learners at worst {worst:.3f}"
    )
    bounds = result["selection"].get("upper_bounds", {})
    for row in candidates(result):
        bound = f"  upper bound of the gap {bounds[row['rule']]:.3f}" if bounds else ""
        print(f"  shield:{row['rule']:<12} objective {row['objective']:9.4f}  worst failures {row['worst_failures']:.3f}{bound}")
    verdict = "certified" if result["selection"]["by"] == "certify" else "as safe as the schedule"
    verdict = verdict if result["safe"] else f"not {verdict}"
    if result["selection"].get("uncertified"):
        verdict = "nothing certified: the budget's choice, not certified"
    if result["chosen"] is None:
        print(f"  chosen: no shield ({verdict}): shield = None")
        return
    declared = f"ShieldRule({', '.join(result['chosen'].split(':'))})"
    print(f"  chosen: shield:{result['chosen']} ({verdict}): {declared}")
