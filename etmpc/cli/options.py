"""The ``etmpc`` command line's options: the parser, and one argument type per kind of number.

Every type refuses bad input with a one-line message (argparse's errors become :class:`EtmpcError`).
"""

from __future__ import annotations

import argparse
from contextlib import contextmanager
from pathlib import Path

from etmpc.cli.tasks import task_option
from etmpc.cli import discriminate, figures, scoring, study, training, types
from etmpc.cli.output import LazyHelp, backend_arguments, run_arguments, task_prices
from etmpc.cli import suite
from etmpc.common.errors import EtmpcError
from etmpc.policies.specs import syntax
from etmpc.systems import names


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("etmpc")
    except PackageNotFoundError:
        return "(not installed)"


class _Parser(argparse.ArgumentParser):
    """etmpc's parser: an error is one line (exit code 2), and an argument marked ``shown_required`` (``--task``,
    which the older positional form may give instead) is shown as required, without brackets, in the usage."""

    def error(self, message: str):  # one line, exit code 2
        raise EtmpcError(message)

    def format_usage(self) -> str:
        with self._required_shown():
            return super().format_usage()

    def format_help(self) -> str:
        with self._required_shown():
            return super().format_help()

    @contextmanager
    def _required_shown(self):
        marked = [action for action in self._actions if getattr(action, "shown_required", False)]
        for action in marked:
            action.required = True
        try:
            yield
        finally:
            for action in marked:
                action.required = False


def build_parser() -> argparse.ArgumentParser:
    tasks = " | ".join(names())
    parser = _Parser(prog="etmpc", description="Event-triggered MPC benchmark.")
    parser.add_argument("--version", action="version", version=f"etmpc {_version()}")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)

    ev = sub.add_parser("evaluate", help="compare policies on a stored test set")
    task_option(ev, tasks, "the task to evaluate on")
    ev.add_argument(
        "--policy",
        action="append",
        required=True,
        metavar="SPEC",
        help=f"{syntax()} (repeatable; oracle:BASE knows each episode's future: a reference point, not a policy)",
    )
    ev.add_argument("--episodes", type=types.positive_int, default=None, help="first N test-set episodes (default: all)")
    ev.add_argument("--repeats", type=types.positive_int, default=1, help="passes over the test set (for stochastic policies)")
    ev.add_argument(
        "--workers",
        type=types.workers,
        default=None,
        help="worker processes (default: one for fewer than 32 episode runs, else one per core)",
    )
    ev.add_argument("--seed", type=types.seed, default=0, help="seed of the policies' own randomness")
    ev.add_argument(
        "--price",
        type=types.price,
        default=None,
        metavar="P",
        help=LazyHelp(lambda: f"price of a recompute in the objective (default: the task's own: {task_prices()})"),
    )
    ev.add_argument("--test-set", default=None, metavar="PATH", help="test set file (default: the stored one)")
    ev.add_argument("--json", type=types.json_path, default=None, metavar="PATH", help="write the results as JSON")
    ev.add_argument(
        "--against",
        default=None,
        metavar="SPEC",
        help="also print every policy against this one (one of --policy), paired per episode with 95 %% CIs",
    )
    ev.add_argument(
        "--record",
        type=types.recording,
        default=None,
        metavar="PATH.rrd|URL",
        help="write every episode into a Rerun recording (open it with `rerun PATH.rrd`), or stream it to the "
        "Rerun viewer at URL (rerun+http://HOST:PORT/proxy, as `rerun` prints it)",
    )
    ev.add_argument(
        "--spawn",
        action="store_true",
        help="stream every episode to a Rerun viewer started for the run (where there is a screen), besides any --record",
    )
    backend_arguments(ev)

    scoring.add_parser(sub, tasks)

    training.add_parser(sub, tasks)

    re_ = sub.add_parser("reproduce", help="the paper's experiments on every task, with REPORT.md and results.json")
    re_.add_argument("--quick", action="store_true", help="the same steps at small sizes (a few minutes)")
    task_option(re_, tasks, many=True, positional=False)
    re_.add_argument(
        "--sweep",
        action="store_true",
        help="also sweep the price of a recompute (etmpc sweep) and answer the equal-rate question in the "
        "report; on a finished run's directory only the sweeps run (make sweep)",
    )
    run_arguments(re_, "run directory (default results/reproduce, or results/reproduce-quick with --quick)")

    sw = sub.add_parser("sweep", help="the trade-off curve over prices of a recompute: pareto.json, pareto.png, SWEEP.md")
    task_option(sw, tasks, many=True)
    sw.add_argument(
        "--prices",
        type=types.prices,
        default=None,
        metavar="P1,P2,...",
        help="prices of a recompute (default: a log grid per task, up to where `never` wins)",
    )
    sw.add_argument(
        "--episodes",
        type=types.positive_int,
        default=None,
        help="first N test-set episodes for every policy (default 20, 3 with --quick)",
    )
    sw.add_argument("--quick", action="store_true", help="a smoke run: 3 episodes, half the thresholds, rollouts K=2 H=10")
    run_arguments(sw, "run directory, a folder per task (default results/sweep, or results/sweep-quick with --quick)")

    rn = sub.add_parser("render", help="render one test-set episode headless to an MP4 video (a task with a 3-D scene)")
    task_option(rn, tasks, "the task to render (one with a 3-D scene: a task without one, such as the battery, says so)")
    rn.add_argument("--policy", required=True, metavar="SPEC", help=f"the policy that plays it: {syntax()}")
    rn.add_argument("--episode", type=types.index, default=0, help="test-set episode (default 0)")
    rn.add_argument("--out", type=Path, required=True, metavar="FILE.mp4", help="the video to write (a new .mp4 file)")
    rn.add_argument("--seed", type=types.seed, default=0, help="seed of the policy's own randomness, as in evaluate")
    rn.add_argument("--width", type=types.positive_int, default=640, metavar="PIXELS", help="frame width (default 640)")
    rn.add_argument("--height", type=types.positive_int, default=480, metavar="PIXELS", help="frame height (default 480)")
    rn.add_argument("--fps", type=types.fps, default=None, help="frames per second (default: one frame per control interval)")
    rn.add_argument(
        "--record",
        type=types.recording,
        default=None,
        metavar="PATH.rrd|URL",
        help="also write the episode, frames included, into a Rerun recording, or stream it to the viewer at URL",
    )

    vf = sub.add_parser(
        "verify",
        help="check a scorecard (etmpc score --json) by replaying a seeded sample of its "
        "episodes bit for bit (and rebuilding the references of a task scored with options): one line per mismatch",
    )
    vf.add_argument("card", type=Path, metavar="CARD.json", help="the scorecard to check (etmpc score --json)")
    vf.add_argument(
        "--sample",
        type=types.non_negative_int,
        default=5,
        metavar="N",
        help="episodes replayed per row (default 5; 0: every episode)",
    )
    vf.add_argument("--seed", type=types.seed, default=0, help="the seed the sample is drawn from")
    vf.add_argument(
        "--allow-code",
        action="append",
        default=[],
        metavar="SPEC",
        help="replay a row whose policy imports a Python module (py:MODULE:NAME, also within another spec), "
        "given as its exact spec (repeatable): without it, verify refuses such a card before playing anything",
    )
    vf.add_argument(
        "--workers",
        type=types.workers,
        default=None,
        help="worker processes (default: one for fewer than 32 episodes to replay, else one per core)",
    )

    tst = sub.add_parser("testset", help="draw a test set: N episodes of a task from a seed, with its sha256 (for --test-set)")
    task_option(tst, tasks, "the task to draw episodes of")
    tst.add_argument("--seed", type=types.seed, required=True, help="the seed every draw comes from")
    tst.add_argument("--episodes", type=types.positive_int, default=100, help="episodes (default 100)")
    tst.add_argument("--out", type=Path, required=True, metavar="FILE.npz", help="a new file (never overwritten)")

    rp = sub.add_parser("replay", help="summarise a Rerun recording: objective, recomputes, prediction errors")
    rp.add_argument("recording", type=Path, metavar="PATH.rrd", help="a recording of etmpc evaluate --record")
    rp.add_argument("--per-episode", action="store_true", help="one line per episode, not only per policy")
    rp.add_argument("--json", type=types.json_path, default=None, metavar="PATH", help="write every episode's figures as JSON")

    be = sub.add_parser("bench", help="time the MPC solve, the rest of a step and whole episodes")
    task_option(be, tasks, many=True)
    be.add_argument("--episodes", type=types.positive_int, default=10, help="test-set episodes per measurement")
    be.add_argument("--json", type=types.json_path, default=None, metavar="PATH", help="write the figures as JSON")
    be.add_argument(
        "--no-reference",
        action="store_true",
        help="skip the reference solvers (do-mpc for cart_pendulum, scipy linprog for battery)",
    )

    rb = sub.add_parser(
        "robustness",
        help="score policies across a range of one of a task's options (noise, gusts): robustness.json, .png, ROBUSTNESS.md",
    )
    task_option(rb, tasks, "the task to play")
    rb.add_argument(
        "--vary",
        required=True,
        metavar="NAME=V1;V2;...",
        help="the option to vary and its values, separated by ';' (a value may be a list: 0.01,0,0.01,0)",
    )
    rb.add_argument("--policy", action="append", required=True, metavar="SPEC", help=f"{syntax()} (repeatable)")
    rb.add_argument("--against", default=None, metavar="SPEC", help="also each policy's paired improvement over this one")
    rb.add_argument("--episodes", type=types.positive_int, default=None, help="first N test-set episodes (default: all)")
    rb.add_argument("--workers", type=types.workers, default=None, help="worker processes (default: by the work)")
    rb.add_argument("--out", type=Path, required=True, metavar="DIR", help="where robustness.json, .png and ROBUSTNESS.md go")

    op = sub.add_parser("options", help="a task's options (--option NAME=VALUE) with their values: its defaults, or as set")
    task_option(op, tasks, "the task whose options to list")
    suite.add_parser(sub)
    discriminate.add_parser(sub, tasks)
    figures.add_parser(sub, tasks)
    study.add_parser(sub)
    return parser
