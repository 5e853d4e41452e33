"""``etmpc discriminate``: its options and its command (the study is :mod:`etmpc.experiments.discriminate`'s,
imported when the command runs)."""

from __future__ import annotations

import time

from etmpc.cli.tasks import task_option
from etmpc.cli import types


def add_parser(sub, tasks: str) -> None:
    """The ``discriminate`` subcommand's options, on the command line's subparsers ``sub``."""
    di = sub.add_parser(
        "discriminate",
        help="can policies be told apart on a task? The event-triggered policies, the clairvoyant "
        "reference and the rollout policy against the periodic front at their rate",
    )
    task_option(di, tasks)
    di.add_argument(
        "--price",
        type=types.price,
        default=None,
        metavar="P",
        help="price of a recompute that chooses the best periodic schedule and prices the oracle and the "
        "rollout (default: the task's)",
    )
    di.add_argument("--episodes", type=types.positive_int, default=30, help="first N test-set episodes (default 30)")
    di.add_argument(
        "--workers",
        type=types.workers,
        default=None,
        help="worker processes (default: one for fewer than 32 episode runs, else one per core)",
    )
    di.add_argument(
        "--json",
        type=types.json_path,
        default=None,
        metavar="PATH",
        help="write the price, the best periodic schedule, both evaluations and every row as JSON",
    )


def run(args) -> None:
    from etmpc.common.outputs import write_json
    from etmpc.evaluation.inputs import check_run_outputs
    from etmpc.experiments.discriminate import discriminate, format_discrimination
    from etmpc.systems import check_name

    check_name(args.task)
    check_run_outputs({"--json": args.json})
    started = time.perf_counter()
    found = discriminate(args.task, args.price, args.episodes, args.workers, progress=True, options=args.options)
    print(format_discrimination(args.task, found, args.episodes, time.perf_counter() - started))
    if args.json is not None:
        write_json(args.json, found)
        print(f"wrote {args.json}")
