"""``etmpc figure forecasts | trajectory | bars``: its options and its command (the drawing is
:mod:`etmpc.experiments.figures`'s, imported when the command runs, so ``--help`` loads no matplotlib)."""

from __future__ import annotations

from pathlib import Path

from etmpc.cli.tasks import task_option
from etmpc.cli import types
from etmpc.cli.output import distinct_policies
from etmpc.common.wording import counted
from etmpc.policies.specs import syntax

KINDS = ("forecasts", "trajectory", "bars")


def add_parser(sub, tasks: str) -> None:
    """The ``figure`` subcommand and its three kinds, on the command line's subparsers ``sub``."""
    fg = sub.add_parser(
        "figure", help="draw the paper's figures: Figure 1 (forecasts), one episode (trajectory), Figure 3 (bars)"
    )
    kinds = fg.add_subparsers(dest="figure", required=True, parser_class=type(fg), metavar="{" + ",".join(KINDS) + "}")

    fc = kinds.add_parser(
        "forecasts",
        help="the paper's Figure 1: a battery test-set episode's true production and price "
        "with the forecasts each MPC solve was given, one column per policy",
    )
    fc.add_argument("--policy", action="append", default=None, metavar="SPEC", help=f"{syntax()} (repeatable; default every:20)")
    fc.add_argument("--episode", type=types.index, default=0, help="test-set episode (default 0)")
    fc.add_argument("--seed", type=types.seed, default=0, help="seed of a stochastic policy's draws (default 0)")
    fc.add_argument(
        "--out", type=types.png_path, default=None, metavar="PATH.png", help="default results/figure1_battery_forecasts.png"
    )

    tj = kinds.add_parser(
        "trajectory",
        help="one test-set episode played as evaluate plays it: every state with every "
        "plan's prediction, the recomputes, the inputs and the exogenous signals",
    )
    task_option(tj, tasks)
    tj.add_argument("--policy", required=True, metavar="SPEC", help=f"the policy that plays it: {syntax()}")
    tj.add_argument("--episode", type=types.index, default=0, help="test-set episode (default 0)")
    tj.add_argument("--seed", type=types.seed, default=0, help="seed of a stochastic policy's draws, as in evaluate (default 0)")
    tj.add_argument(
        "--out",
        type=types.png_path,
        default=None,
        metavar="PATH.png",
        help="default results/trajectory_<task>_<policy>_ep<I>.png",
    )

    br = kinds.add_parser(
        "bars",
        help="the paper's Figure 3: the mean objective per policy from evaluate --json documents "
        "of one task (error bars: std over repeats; a training run's seeds as one bar)",
    )
    br.add_argument("evaluations", nargs="+", type=Path, metavar="EVAL.json", help="etmpc evaluate --json output")
    br.add_argument("--out", type=types.png_path, default=None, metavar="PATH.png", help="default results/figure3_<task>.png")
    br.add_argument("--no-group", action="store_true", help="one bar per learned policy file, not one per training run")


def run(args) -> None:
    {"forecasts": _forecasts, "trajectory": _trajectory, "bars": _bars}[args.figure](args)


def _check(outputs: dict, inputs: dict) -> None:
    from etmpc.evaluation.inputs import check_run_outputs

    check_run_outputs(outputs, inputs=inputs)


def _forecasts(args) -> None:
    from etmpc.evaluation.inputs import run_inputs
    from etmpc.experiments import figures

    policies = args.policy or list(figures.FORECASTS_POLICIES)
    distinct_policies(policies)
    out = args.out or figures.FORECASTS_OUT
    _check({"--out": out}, run_inputs(policies))
    figures.forecasts(out, policies, args.episode, args.seed)
    print(f"wrote {out}")


def _trajectory(args) -> None:
    from etmpc.evaluation.inputs import run_inputs
    from etmpc.experiments import figures
    from etmpc.systems import check_name, system_key

    check_name(args.task)
    key = system_key(args.task, options=args.options)
    out = args.out or figures.trajectory_path(args.task, args.policy, args.episode)
    _check({"--out": out}, run_inputs([args.policy]))
    drawn = figures.trajectory(out, key, args.policy, args.episode, args.seed)
    print(
        f"{key}: episode {args.episode} under {args.policy}: objective {drawn.objective:.5f}, "
        f"{counted(drawn.recomputes, 'recompute')}, {counted(drawn.solver_failures, 'solver failure')}"
    )
    print(f"wrote {out}")


def _bars(args) -> None:
    from etmpc.experiments import figures

    sources = [str(path) for path in args.evaluations]
    docs = [figures.load_evaluation(path) for path in args.evaluations]
    out = args.out or figures.bars_path(docs, sources)
    _check({"--out": out}, {f"evaluation {path}": path for path in args.evaluations})
    figures.bars(out, docs, group_learned=not args.no_group, sources=sources)
    print(f"wrote {out}")
