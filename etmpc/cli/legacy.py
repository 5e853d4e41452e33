"""``etmpc train``'s options from before ``--settings`` and ``--set``, and ``etmpc train-self``: deprecated,
kept for one release so that scripts keep working.

Each old flag sets one setting of the learners it was an option of (:data:`FLAGS`), as ``--set`` does, so
a run gives the same files either way; ``--hyperparams FILE`` is ``--settings FILE``, and ``etmpc
train-self TASK --out FILE`` is ``etmpc train --task TASK --algorithm self`` writing its policy to FILE. A run
that used one ends with a line on stderr that says what replaces it (at the end: a refused command
stays one line).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TypedDict

from etmpc.cli.tasks import task_option
from etmpc.cli import types
from etmpc.cli.output import backend_arguments, check_backend, say, warn
from etmpc.common.errors import EtmpcError
from etmpc.learning.gpomdp import BASELINES
from etmpc.policies.features import FEATURE_SETS


class _Keywords(TypedDict, total=False):
    """An old flag's argparse keywords."""

    type: Callable[[str], object]
    metavar: str
    choices: Sequence[str]


_N = _Keywords(type=types.positive_int, metavar="N")
# the old flag -> (the setting it sets, the learners it was an option of, its argparse keywords)
FLAGS: dict[str, tuple[str, tuple[str, ...], _Keywords]] = {
    "--episodes": ("episodes", ("gpomdp", "dpi", "self"), _N),
    "--eval-every": ("eval_every", ("gpomdp", "dpi"), _N),
    "--eval-episodes": ("eval_episodes", ("gpomdp", "dpi"), _N),
    "--features": ("features", ("gpomdp", "dpi"), dict(choices=FEATURE_SETS)),
    "--validation-episodes": ("validation_episodes", ("gpomdp", "dpi", "self", "ppo"), _N),
    "--record": ("record_episodes", ("gpomdp", "dpi"), dict(type=types.index, metavar="N")),
    "--baseline": ("baseline", ("gpomdp",), dict(choices=BASELINES)),
    "--learning-rate": ("learning_rate", ("gpomdp",), dict(type=float, metavar="ALPHA")),
    "--discount": ("discount", ("gpomdp",), dict(type=float, metavar="GAMMA")),
    "--futures": ("futures", ("dpi", "self"), dict(type=types.positive_int, metavar="K")),
    "--horizon": ("horizon", ("dpi",), dict(type=types.positive_int, metavar="H")),
    "--labels": ("states_per_episode", ("dpi",), dict(type=types.positive_int, metavar="D")),
    "--timesteps": ("timesteps", ("ppo",), _N),
}
# etmpc train-self's options -> the self learner's settings
SELF_FLAGS = {
    "--episodes": "episodes",
    "--solves": "solves_per_episode",
    "--futures": "futures",
    "--validation-episodes": "validation_episodes",
}


def _dest(flag: str) -> str:
    return "old_" + flag[2:].replace("-", "_")


def add_arguments(parser) -> None:
    """The old flags, on ``etmpc train``'s parser, in a group of their own."""
    group = parser.add_argument_group(
        "deprecated options",
        "kept for one release: each is the --set shown (for the learners named), and a run that uses one says so at its end",
    )
    for flag, (name, owners, keywords) in FLAGS.items():
        group.add_argument(flag, dest=_dest(flag), default=None, help=f"--set {name}=… ({', '.join(owners)})", **keywords)
    group.add_argument("--hyperparams", type=Path, default=None, metavar="FILE", help="--settings FILE")


def given(args, learner: str, known) -> tuple[dict, list[str]]:
    """The settings the old flags in ``args`` give ``learner`` (whose settings are ``known``), and the notes
    that say what replaces each; a flag that was not an option of ``learner`` is refused."""
    values, notes = {}, []
    for flag, (name, owners, _) in FLAGS.items():
        value = getattr(args, _dest(flag))
        if value is None:
            continue
        if learner not in owners:
            own = f" (or {learner}'s own {name}: --set {name}=…)" if name in known else ""
            raise EtmpcError(
                f"{flag} is a setting of {' and '.join(owners)} only, not of {learner}: add --algorithm {owners[0]}{own}"
            )
        values[name] = value
        notes.append(f"{flag} is deprecated: use --set {name}={value}")
    if args.hyperparams is not None:
        if args.settings is not None:
            raise EtmpcError("--hyperparams is --settings' old name: give --settings alone")
        notes.append(f"--hyperparams is deprecated: use --settings {args.hyperparams}")
    return values, notes


def add_self_parser(sub, tasks: str) -> None:
    ts = sub.add_parser(
        "train-self",
        help="deprecated: etmpc train --task TASK --algorithm self (a self-triggering policy, "
        "self:PATH: at each solve, how long to keep the plan)",
    )
    task_option(ts, tasks, "the task to train on")
    ts.add_argument(
        "--out", type=types.json_path, required=True, metavar="FILE", help="the policy file to write (use it as self:FILE)"
    )
    training_price(ts)
    ts.add_argument("--episodes", type=types.positive_int, default=None, help="labelled training episodes (default 40)")
    ts.add_argument("--solves", type=types.positive_int, default=None, help="labelled solves per episode (default 8)")
    ts.add_argument(
        "--futures", type=types.positive_int, default=None, metavar="K", help="sampled futures per labelled solve (default 2)"
    )
    ts.add_argument(
        "--validation-episodes",
        type=types.positive_int,
        default=None,
        help="training-distribution episodes that choose among the fits and the base (default 20)",
    )
    ts.add_argument("--workers", type=types.workers, default=None, help="worker processes (default: one per core)")
    backend_arguments(ts)


def run_self(args) -> None:
    """``etmpc train-self``: the self learner, its policy written to ``--out`` (as before), and a note."""
    from dataclasses import replace

    from etmpc.evaluation.inputs import check_run_outputs
    from etmpc.evaluation.workers import default_workers
    from etmpc.learning.selftrigger import SelfSettings, train_self
    from etmpc.systems import check_name, system_key

    check_name(args.task)
    check_backend(args)
    check_run_outputs({"--out": args.out})
    values = {name: getattr(args, flag[2:].replace("-", "_")) for flag, name in SELF_FLAGS.items()}
    values = {name: value for name, value in values.items() if value is not None}
    train_self(
        system_key(args.task, args.price),
        args.out,
        replace(SelfSettings(), **values),
        args.workers or default_workers(),
        args.backend,
        args.address,
        say=say,
        progress=True,
    )
    price = "" if args.price is None else f" --price {args.price:g}"
    sets = "".join(f" --set {name}={value}" for name, value in values.items())
    warn(
        f"etmpc train-self is deprecated: use etmpc train --task {args.task} --algorithm self --out DIR{price}{sets} "
        "(it writes DIR/selected.json)"
    )
    print(f"wrote {args.out} (evaluate it with: etmpc evaluate --task {args.task} --policy self:{args.out}{price})")


def training_price(parser) -> None:
    """``--price``, as ``train`` and ``train-self`` take it."""
    parser.add_argument(
        "--price",
        type=types.price,
        default=None,
        metavar="P",
        help="train for this price of a recompute (default: the task's; see evaluate --price)",
    )
