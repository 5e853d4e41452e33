"""``etmpc score``: its options and its command (the scorecard, the stored references, the leaderboard).

See :mod:`etmpc.evaluation.scorecard` for what a score is and :mod:`etmpc.experiments.leaderboard`
for the leaderboard. This module sits with the command line, on top: it may import any floor.
"""

from __future__ import annotations

import argparse
import shlex
from pathlib import Path

from etmpc.cli.tasks import task_option
from etmpc.cli import types
from etmpc.cli.output import LazyHelp, distinct_policies as _distinct_policies, say as _say, warn
from etmpc.common.errors import EtmpcError
from etmpc.policies.specs import syntax

REFERENCES_OUT = Path("results") / "references"  # where --references writes, unless --out says
LEADERBOARD_OUT = Path("docs")
_OLD_POLICIES = "given_policies"  # where the older form's positional policies land


def _leaderboard_help() -> str:
    """``--leaderboard``'s help, naming the leaderboard's rows from :mod:`etmpc.experiments.leaderboard_rows` (made
    only when the help is shown: it is a heavy import)."""
    from etmpc.experiments.leaderboard_rows import row_names

    return (
        f"score every built-in policy ({', '.join(row_names())}; a shipped learner where policies/<task>/ holds it; "
        "the oracle is the clairvoyant reference, 100) and write DIR/leaderboard.md, .json and the profile figure "
        "(make leaderboard)"
    )


def add_parser(sub, tasks: str) -> None:
    """The ``score`` subcommand's options, on the command line's subparsers ``sub``."""
    sc = sub.add_parser("score", help="score policies on every task against the suite's fixed references: the scorecard")
    sc.add_argument(
        "--policy",
        action="append",
        default=None,
        metavar="SPEC",
        help=f"a policy to score (repeatable): {syntax()} (py:MODULE:NAME for your own)",
    )
    sc.add_argument(_OLD_POLICIES, nargs="*", default=None, metavar="SPEC", help=argparse.SUPPRESS)  # the older form
    task_option(sc, tasks, many=True, positional=False)
    sc.add_argument(
        "--test-set",
        default=None,
        metavar="PATH",
        help="another test set, for one --task: its references are computed for the run",
    )
    sc.add_argument(
        "--episodes",
        type=types.positive_int,
        default=None,
        help="first N test-set episodes (default: all); the references are then those episodes'",
    )
    sc.add_argument("--json", type=types.json_path, default=None, metavar="PATH", help="write the scorecard as JSON")
    sc.add_argument(
        "--figure",
        type=types.png_path,
        default=None,
        metavar="PATH.png",
        help="also draw the policies' performance profiles (share of episodes above each score)",
    )
    sc.add_argument(
        "--workers",
        type=types.workers,
        default=None,
        help="worker processes (default: one per task for fewer than 32 episodes, else one per core)",
    )
    sc.add_argument(
        "--leaderboard",
        action="store_true",
        help=LazyHelp(
            _leaderboard_help,
            "score every built-in policy and write DIR/leaderboard.md, .json and the profile figure (make leaderboard)",
        ),
    )
    sc.add_argument(
        "--out",
        type=Path,
        default=None,
        metavar="DIR",
        help=f"with --leaderboard: where the page goes (default {LEADERBOARD_OUT}); finished rows are kept in "
        f"results/leaderboard, so an interrupted run continues. With --references: where the rebuilt "
        f"files go (default {REFERENCES_OUT}; DIR/DOMAIN/TASK/references.json: copy one over the stored "
        "file to ship it)",
    )
    sc.add_argument(
        "--card",
        type=Path,
        action="append",
        default=None,
        metavar="CARD.json",
        help="with --leaderboard: add the policies of a score card made elsewhere (etmpc score --json, every "
        "task on its whole test set) as rows, once it verifies (etmpc verify; repeatable)",
    )
    sc.add_argument(
        "--readme",
        type=Path,
        default=None,
        metavar="PATH",
        help="with --leaderboard: also rewrite this README's table between its leaderboard markers",
    )
    sc.add_argument(
        "--references",
        action="store_true",
        help="rebuild the references of the tasks (every periodic schedule and the oracle on the stored "
        "test set; a maintainer's step after a task changes), into --out: never over the stored ones",
    )
    sc.add_argument(
        "--meter-only",
        action="store_true",
        help="with --references: play only the rollout meter again, the schedules and the oracle as stored "
        "(after a change to the meter itself, which moves no score)",
    )


def policies(args) -> list[str]:
    """The policies to score: ``--policy SPEC``s, or those given positionally as an older etmpc took them (for one
    release, with one deprecation line saying what to write instead); never both."""
    old = getattr(args, _OLD_POLICIES, None) or []
    if old and args.policy:
        raise EtmpcError("give the policies once, each as --policy SPEC")
    if old:
        new = " ".join(f"--policy {shlex.quote(spec)}" for spec in old)
        warn(f"'etmpc score {' '.join(shlex.quote(spec) for spec in old)}' is deprecated: say 'etmpc score {new}'")
    return list(args.policy or old)


def run(args) -> None:
    """``etmpc score``: the scorecard, ``--references`` or ``--leaderboard``."""
    args.policy = policies(args)
    from etmpc.evaluation.inputs import check_run_outputs, run_inputs
    from etmpc.evaluation.references import build_references, references_path, replay_meter, write_references
    from etmpc.evaluation.scorecard import format_scorecard, score
    from etmpc.systems import distinct, folder_name, names

    tasks = distinct(args.task or names())
    if args.options and (args.leaderboard or args.references):
        raise EtmpcError("--leaderboard and --references are the suite's own tasks: no --option with them")
    if args.meter_only and not args.references:
        raise EtmpcError("--meter-only is --references'")
    if args.leaderboard:
        return _leaderboard(args, tasks)
    if args.readme is not None or args.card is not None:
        raise EtmpcError("--readme and --card are --leaderboard's")
    if args.references:
        if args.policy or args.test_set is not None or args.json is not None or args.figure is not None:
            raise EtmpcError(
                "--references rebuilds the stored references only: no --policy, --test-set, --json or --figure with it"
            )
        out = args.out or REFERENCES_OUT
        files = [f"{folder_name(task)}/references.json" for task in tasks]  # every task's, checked before the first is built
        check_run_outputs({}, {"--out": out}, writes={"--out": files})
        for task in tasks:
            build = replay_meter if args.meter_only else build_references
            path = write_references(build(task, workers=args.workers, say=_say), out / folder_name(task) / "references.json")
            print(f"wrote {path} (to ship it: copy it over {references_path(task)})")
        return
    if args.out is not None:
        raise EtmpcError("--out is --leaderboard's and --references'")
    if not args.policy:
        raise EtmpcError("give at least one policy to score: --policy SPEC (such as every:3 or py:MODULE:NAME)")
    _distinct_policies(args.policy)
    check_run_outputs({"--json": args.json, "--figure": args.figure}, inputs=run_inputs(args.policy, args.test_set))
    if args.test_set is not None and not Path(args.test_set).is_file():
        raise EtmpcError(f"test set {args.test_set} not found")
    card = score(
        args.policy,
        tasks,
        args.test_set,
        args.workers,
        json_path=args.json,
        say=_say,
        episodes=args.episodes,
        options=args.options,
    )
    print(format_scorecard(card))
    if args.json is not None and card.complete:  # a card with a failed row is never written (below)
        print(f"wrote {args.json}")
    if args.figure is not None:
        import numpy as np

        from etmpc.evaluation.card import profiles
        from etmpc.views.figures import write_performance_profile_png

        thresholds = np.linspace(-100.0, 200.0, 301)
        write_performance_profile_png(args.figure, profiles(card, thresholds), thresholds, card.tasks)
        print(f"wrote {args.figure}")
    if not card.complete:
        failed = sorted({f"{r.policy} on {r.task}" for r in card.rows if r.error is not None})
        unwritten = "" if args.json is None else f"; {args.json} not written (a card with a failed row never is)"
        raise EtmpcError(f"not every policy could be scored on every task: {', '.join(failed)} (see its row){unwritten}")


def _leaderboard(args, tasks: list[str]) -> None:
    from etmpc.evaluation.workers import default_workers
    from etmpc.experiments.leaderboard import PAGE, WORK, build, check_files, headline

    if args.policy or args.references or args.test_set is not None or args.json is not None or args.figure is not None:
        raise EtmpcError(
            "--leaderboard scores the built-in policies on the stored test sets: no --policy, --references, "
            "--test-set, --json or --figure with it"
        )
    out = args.out or LEADERBOARD_OUT
    cards = args.card or []
    check_files(out, WORK, args.readme, cards)  # the page, the kept rows, the README and the cards: none on another
    for card in cards:
        if not card.is_file():
            raise EtmpcError(f"--card {card} not found")
    data = build(out, WORK, tasks, args.episodes, args.workers or default_workers(), args.readme, say=_say, cards=cards)
    print(headline(data))
    print(
        f"wrote {out}/{PAGE[0]}, {PAGE[1]} and {PAGE[2]}" + (f"; the table in {args.readme}" if args.readme is not None else "")
    )
