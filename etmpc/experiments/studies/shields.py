"""Choose each safety task's shield rule on training-distribution episodes (``etmpc.learning.shields``).

    etmpc study shields                       # the tasks below, about 40 min on 2 cores
    etmpc study shields --task quadrotor/waypoints --episodes 30
    etmpc study shields --from-tables         # choose again from shields.json's tables, and its page

For each task: its shipped DPI and PPO, unshielded and under every rule of the task's grid, and its best
fixed schedule, on the first ``--episodes`` validation episodes (never the test set). Writes
``docs/results/shields.json`` (what was chosen, and the whole table) and its page ``shields.md``, and
prints each task's rule as the line to declare in its system class (``shield = ShieldRule(...)``). The
test-set figures of the shielded policies are on the learner comparison page, the ``learners`` study's.
"""

from __future__ import annotations

import argparse

from etmpc.common.progress import Progress
from etmpc.evaluation.backends import make_backend
from etmpc.evaluation.references import stored
from etmpc.experiments.leaderboard_rows import shipped_policy
from etmpc.experiments.studies import runner
from etmpc.learning.shields import BUDGET, choose, pick, rules

#: Each task whose failures are safety events: its grid (maximum plan ages, margins in its unit) and how many
#: validation episodes (falls are rare on the cart pendulum: a few in a hundred episodes).
GRIDS = {
    "cart_pendulum/kicks": ((5, 10, 20), (None, 0.6, 0.9, 1.0), 200),
    "cart_pendulum/kicks_late": ((3, 5, 10), (None, 0.9, 1.0, 1.1), 200),
    "cart_pendulum/kicks_levels": ((3, 5, 10), (None, 0.9, 1.0, 1.1), 200),
    "quadrotor/waypoints": ((7, 10, 15), (None, 0.25, 0.5), 100),
}


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
        "beside the best fixed schedule. A shield is insurance bought with objective: among the rules that cost "
        f"the learners at most {100 * BUDGET:g} % of their unshielded mean objective (lower is better on these "
        "tasks), the chosen rule is the safest (the fewest failures per episode of the learner that fails most), "
        "then the cheapest; none if no rule within the budget is safer than no shield. What the shield is: "
        "[policies](../policies.md#shields-shield).",
        "",
    ]
    for task, result in document["tasks"].items():
        schedule = result["schedule"]
        unshielded = result["unshielded"]
        chosen = (
            "none (no rule within the budget is safer than no shield)"
            if result["chosen"] is None
            else f"**`shield:{result['chosen']}`**"
        )
        safety = "as safe as" if result["safe"] else "less safe than"
        lines += [
            f"## `{task}`",
            "",
            f"{result['episodes']} validation episodes, played at commit `{result.get('commit', document['commit'])}`; "
            f"margins in {result['margin_unit']}. "
            f"`{schedule['spec']}`: objective {schedule['objective']:.3f}, {schedule['failures']:.3f} failures per episode. "
            f"Chosen: {chosen} ({safety} `{schedule['spec']}` on these episodes).",
            "",
            "| rule | mean objective of the learners | failures per episode, the worse learner |",
            "|---|---|---|",
            f"| none | {unshielded['objective']:.3f} | {unshielded['worst_failures']:.3f} |",
        ]
        for row in result["rules"]:
            mark = " (chosen)" if row["rule"] == result["chosen"] else ""
            lines.append(f"| `{row['rule']}`{mark} | {row['objective']:.3f} | {row['worst_failures']:.3f} |")
        lines.append("")
    return "\n".join(lines)


def arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--task", action="append", choices=sorted(GRIDS), help="a task (repeatable; default: all)")
    parser.add_argument("--episodes", type=int, help="validation episodes per policy (default: the task's, 100 or 200)")
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
        document["tasks"] = {task: pick(result) for task, result in document["tasks"].items()}
        results.write(document, page)
        return
    clock = runner.Stopwatch()
    provenance = runner.made()  # the code that runs: the checkout as it starts
    played = results.kept(lambda: {"tasks": {}})["tasks"]  # the tasks not run again stay
    for task in args.task or list(GRIDS):
        played[task] = dict(rule(task, args.episodes, args.workers), commit=provenance["commit"], date=provenance["date"])
    document = {
        "commit": provenance["commit"],
        "date": provenance["date"],
        "machine": runner.machine(args.workers, cpu=True),
        "seconds": clock.seconds(),
        "tasks": {task: played[task] for task in GRIDS if task in played},
    }
    results.write(document, page)


def rule(task: str, episodes: int | None, workers: int) -> dict:
    """Play ``task``'s grid of rules (on its own number of validation episodes unless ``episodes``), and say which was
    chosen, as the line to declare in its system class."""
    ages, margins, default_episodes = GRIDS[task]
    episodes = episodes or default_episodes
    grid = rules(ages, margins)
    policies = shipped(task)
    jobs = (1 + len(policies) * (1 + len(grid))) * episodes
    with make_backend("local", workers) as pool, Progress(jobs, f"{task}: shield rules") as bar:
        result = choose(task, policies, stored(task).best, grid, episodes, pool, lambda job: bar.update())
    schedule = result["schedule"]
    unshielded = result["unshielded"]
    worst = unshielded["worst_failures"]
    print(f"{task}: {schedule['spec']} fails {schedule['failures']:.3f}/episode; unshielded learners at worst {worst:.3f}")
    for row in result["rules"]:
        print(f"  shield:{row['rule']:<8} objective {row['objective']:9.4f}  worst failures {row['worst_failures']:.3f}")
    if result["chosen"] is None:
        print("  chosen: none within the budget: shield = None")
        return result
    chosen = result["chosen"].split(":")
    declared = f"ShieldRule({chosen[0]}{', ' + chosen[1] if len(chosen) > 1 else ''})"
    verdict = "as safe as the schedule" if result["safe"] else "less safe than the schedule"
    print(f"  chosen: shield:{result['chosen']} ({verdict}): {declared}")
    return result
