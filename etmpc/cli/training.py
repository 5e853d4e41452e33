"""``etmpc train``: its options and its command. Any learner registered in :mod:`etmpc.learning.base`
(``--algorithm``: gpomdp, dpi, self, ppo and any other :class:`~etmpc.learning.base.Learner` with a name),
its settings from a file (``--settings``, :func:`~etmpc.learning.base.load_settings`) and the command line
(``--set KEY=VALUE``), trained by :func:`etmpc.learning.runner.run`. The old flags and ``etmpc train-self``
are :mod:`etmpc.cli.legacy`'s. This module sits with the command line, on top: it may import any floor.
"""

from __future__ import annotations

import dataclasses
import math
import typing
from pathlib import Path

from etmpc.cli.tasks import task_option
from etmpc.cli import legacy, types
from etmpc.cli.output import LazyHelp, backend_arguments, check_backend, say, warn
from etmpc.common.errors import EtmpcError

DEFAULT = "dpi"
# What the command line gives a learner that its settings do not say (as etmpc train did before --set, as
# the shipped PPO and etmpc reproduce were chosen), where its Settings' own default differs.
COMMAND_LINE = {"ppo": {"validation_episodes": 50}}


def _learners() -> dict:
    from etmpc.learning.base import learners

    return learners()


class _Registered:
    """``--algorithm``'s choices: the registry's names, read when first needed (importing every learner
    loads matplotlib, which another command's ``--help`` should not)."""

    def __contains__(self, name) -> bool:
        return name in _learners()

    def __iter__(self):
        return iter(_learners())


def _names(names: list[str]) -> str:
    return " and ".join([", ".join(names[:-1]), names[-1]] if len(names) > 1 else names)


_ALGORITHM = "the learner"
_SET = (
    "one setting, over --settings' or the defaults (repeatable): VALUE is read as YAML "
    "(4, 0.05, paper, [always, every:3], null); an unknown KEY says which are known."
)


def _algorithm_help() -> str:
    """``--algorithm``'s help, made when shown: every registered learner, and how many seeds each trains."""
    found = _learners()
    kinds = {"many": "several (in lockstep)", "one": "one", "none": "none"}
    seeds = ", ".join(
        f"{_names([n for n, c in found.items() if c.seeding == kind])} {what}"
        for kind, what in kinds.items()
        if any(c.seeding == kind for c in found.values())
    )
    return (
        f"{_ALGORITHM}: {', '.join(found)} (default {DEFAULT}; every Learner registered in etmpc.learning.base is "
        f"one, see docs/learning.md); --seeds: {seeds}"
    )


def _set_help() -> str:
    """``--set``'s help, made when shown: the settings of every registered learner."""
    known = "; ".join(
        f"{name}'s: {', '.join(f.name for f in dataclasses.fields(cls.Settings))}" for name, cls in _learners().items()
    )
    return f"{_SET} Settings by learner: {known}."


def add_parser(sub, tasks: str) -> None:
    """The ``train`` subcommand's options (and ``train-self``'s), on the command line's subparsers ``sub``."""
    tr = sub.add_parser(
        "train",
        help="train a policy with any registered learner: DPI (default), "
        "GPOMDP (the paper's), the self-trigger or PPO (Stable-Baselines3, the 'rl' extra)",
    )
    task_option(tr, tasks, "the task to train on")
    tr.add_argument(
        "--algorithm", choices=_Registered(), default=DEFAULT, metavar="NAME", help=LazyHelp(_algorithm_help, _ALGORITHM)
    )
    tr.add_argument(
        "--settings",
        type=Path,
        default=None,
        metavar="FILE",
        help="the learner's settings, a YAML or JSON file of its settings' names (PPO: an rl-zoo3 "
        "hyperparameter file, default the task's policies/<task>/ppo.yml); default: its defaults",
    )
    tr.add_argument(
        "--set", type=types.setting, action="append", default=None, metavar="KEY=VALUE", help=LazyHelp(_set_help, _SET)
    )
    tr.add_argument("--out", type=Path, required=True, metavar="DIR", help="run directory: its files, checkpoints, the policy")
    tr.add_argument(
        "--seeds",
        default=None,
        metavar="SEEDS",
        help="seeds: a range 0-4 or a list 0,2,5 (default: the learner's own, 0-4 for gpomdp and dpi, the "
        "settings' seed for ppo; how many each takes: --algorithm)",
    )
    legacy.training_price(tr)
    tr.add_argument("--workers", type=types.workers, default=None, help="worker processes (default: one per core)")
    backend_arguments(tr)
    tr.add_argument("--resume", action="store_true", help="continue the run in DIR from its last checkpoint")
    legacy.add_arguments(tr)
    legacy.add_self_parser(sub, tasks)


def configure(cls, path: Path | None, task: str, values: dict):
    """``cls``'s settings: its settings file's (or its defaults), then :data:`COMMAND_LINE`'s, then
    ``values`` (name -> value): an unknown name is refused listing the known ones, a value out of range
    with the settings' own message."""
    from etmpc.learning.base import load_settings

    settings = load_settings(cls, path, task)
    defaults = cls.Settings()
    hints = typing.get_type_hints(cls.Settings)
    known = [f.name for f in dataclasses.fields(cls.Settings)]
    unknown = [name for name in values if name not in known]
    if unknown:
        raise EtmpcError(f"unknown setting {unknown[0]!r} for {cls.name}; known: {', '.join(known)}")
    own = {k: v for k, v in COMMAND_LINE.get(cls.name, {}).items() if getattr(settings, k) == getattr(defaults, k)}
    converted = {}
    for name, value in values.items():
        hint = str(hints.get(name))
        if isinstance(value, list) and "tuple" in hint:
            value = tuple(value)
        elif isinstance(value, str) and ("float" in hint or "int" in hint) and "str" not in hint and _numeral(value):
            value = float(value)  # YAML 1.1 reads 3e-4 as text
        converted[name] = value
    try:
        return dataclasses.replace(settings, **{**own, **converted})
    except (ValueError, TypeError) as exc:
        raise EtmpcError(" ".join(str(exc).split())) from None


def _numeral(text: str) -> bool:
    try:
        return math.isfinite(float(text))
    except ValueError:
        return False


def _seeds(text: str | None, cls) -> tuple[int, ...] | None:
    from etmpc.learning.config import parse_seeds

    if text is None:
        return None
    if cls.seeding == "none":
        raise EtmpcError(f"--algorithm {cls.name} takes no --seeds (its draws are one fixed stream)")
    seeds = parse_seeds(text)
    if cls.seeding == "one" and len(seeds) != 1:
        raise EtmpcError(f"--algorithm {cls.name} trains one seed at a time: give --seeds S, got {text}")
    return seeds


def run(args) -> None:
    """``etmpc train``: check everything, train, say what was written and how to evaluate it."""
    from etmpc.evaluation.inputs import check_run_outputs
    from etmpc.evaluation.workers import default_workers
    from etmpc.learning.base import learner_class
    from etmpc.learning.runner import run as train
    from etmpc.systems import check_name, system_key
    from etmpc.views.curves import write_curve_png
    from etmpc.views.recording import Recorder

    check_name(args.task)
    check_backend(args)
    cls = learner_class(args.algorithm)
    values, notes = legacy.given(args, cls.name, {f.name for f in dataclasses.fields(cls.Settings)})
    path = args.settings if args.settings is not None else args.hyperparams
    check_run_outputs({}, {"--out": args.out}, {"--settings": path})  # before the settings are read: no FIFO, no device
    key = system_key(args.task, args.price, args.options)
    seeds = _seeds(args.seeds, cls)
    settings = configure(cls, path, key.task, {**values, **dict(args.set or [])})
    learner = cls(settings)
    # and, now that the learner says which files of the run's directory are its, none of them is the settings file
    check_run_outputs({}, {"--out": args.out}, {"--settings": path}, writes={"--out": learner.owns})
    workers = args.workers or default_workers()
    # recorder and curve_png: what the run's recordings and curve are drawn with (views, a floor above learning)
    done = train(
        learner,
        key,
        args.out,
        seeds,
        workers,
        args.resume,
        args.backend,
        args.address,
        say=say,
        recorder=Recorder,
        curve_png=write_curve_png,
    )
    for note in notes:
        warn(note)
    learner = done.learner
    run_state = getattr(learner, "run_state", None)
    if run_state is not None:  # gpomdp, dpi: the test-set curve
        from etmpc.learning.train import format_summary

        print(format_summary(run_state))
    result = getattr(learner, "result", None)
    if isinstance(result, dict) and "checkpoints" in result:  # ppo
        print(
            f"PPO on {result['task']}: {result['environment_steps']} environment steps in {result['wall_seconds']:.0f} s; "
            f"kept {result['selected']} (best of {len(result['checkpoints'])} on {learner.settings.validation_episodes} "
            "validation episodes)"
        )
    written = sorted(f"{p.name}/" if p.is_dir() else p.name for p in Path(args.out).iterdir())
    price = "" if args.price is None else f" --price {args.price:g}"
    price += "".join(f" --option {name}={value}" for name, value in key.options)
    evaluate = f"etmpc evaluate --task {args.task} --policy {done.policy}{price}"
    print(f"wrote {args.out}: {', '.join(written)} (evaluate it with: {evaluate})")
