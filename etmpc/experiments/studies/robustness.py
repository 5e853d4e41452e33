"""The robustness curves of the docs: ``docs/results/robustness.md``, its figures and JSON.

    etmpc study robustness                 # both curves (minutes on 2 cores)
    etmpc study robustness --episodes 10   # a quick look

Two curves, each on a task's stored test set (the same episodes at every value: paired), of the built-in
triggers (the task's best fixed schedule, its best threshold, the shipped DPI and PPO) against one option (``etmpc
robustness``): the noisy cart pendulum against its sensor's noise, and the quadrotor against the strength of its
gusts. Each curve's JSON and figure go to ``docs/results/robustness/<task>/``. Every number comes from
``etmpc.experiments.robustness``; this study only names the curves and writes the page, with the commit and the
machine.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from etmpc.common import outputs
from etmpc.experiments.robustness import markdown, robustness, write
from etmpc.experiments.studies import runner

#: (task, option, values): the triggers are the task's best fixed schedule and best threshold on the leaderboard
#: (docs/leaderboard.json: make leaderboard first) and its shipped DPI and PPO
CURVES = (
    ("cart_pendulum/kicks_noisy", "sensor.noise_std", ("0.0025", "0.005", "0.01", "0.02")),
    ("quadrotor/waypoints", "disturbances.gust_scale", ("0", "0.5", "1", "1.5", "2")),
)


def triggers(task: str, leaderboard: dict) -> list[str]:
    """The task's best fixed schedule and best threshold (the leaderboard's), then its shipped DPI and PPO."""
    specs = {entry["name"]: entry.get("specs") or {} for entry in leaderboard["entries"]}
    return [specs[name][task] for name in ("best periodic", "best threshold", "DPI (shipped)", "PPO (shipped)")]


def arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--episodes", type=int, default=50, help="test-set episodes per value (default 50)")
    runner.options(parser, page_only=False)


def run(args: argparse.Namespace) -> None:
    made = runner.made()
    sections = []
    leaderboard = json.loads(Path("docs/leaderboard.json").read_text())
    for task, option, values in CURVES:
        policies = triggers(task, leaderboard)
        document = robustness(task, option, values, policies, policies[0], args.episodes, args.workers, say=print)
        folder = args.out / "robustness" / task.replace("/", "-")
        write(document, folder, table=False)  # the table is this page's
        image = f"robustness/{folder.name}/robustness.png"
        sections += [markdown(document), f"![{task} against {option}]({image})", ""]
    path = runner.Results(args.out, "robustness").page
    outputs.write_text(path, page(made, runner.machine(args.workers), sections))
    print(f"wrote {path}")


def page(made: dict, machine: str, sections: list[str]) -> str:
    """The page: what made it, then each curve's section (its table and figure)."""
    lines = [
        "# Triggers against noise and disturbances",
        "",
        runner.generated("robustness"),
        "",
        f"Made at commit `{made['commit']}` ({made['date']}) on {machine}, "
        "with `etmpc robustness` (any task, option and triggers: `etmpc robustness --help`). "
        "Each curve plays the same stored test-set episodes at every value of its option, so a trigger's points and "
        "two triggers at one point are paired. The baseline of the improvement is the first trigger, the task's best "
        "fixed schedule at its default options.",
        "",
        *sections,
    ]
    return "\n".join(lines)
