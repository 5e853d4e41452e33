"""How every command takes its task: ``--task TASK``, the task's id (``DOMAIN/TASK``, or ``DOMAIN`` alone for
its domain's first task; :func:`etmpc.systems.spec`). A command of one task requires it; a command that can
play several repeats it, every task by default.

An older etmpc took the task as the first word after the command (``etmpc evaluate cart_pendulum ...``); that
form still works for one release, with one deprecation line saying what to write instead."""

from __future__ import annotations

import argparse

from etmpc.cli.output import warn
from etmpc.common.errors import EtmpcError

_OLD = "given_task"  # where the older form's positional task lands


def task_option(parser, tasks: str, what: str = "the task", many: bool = False, positional: bool = True) -> None:
    """Add ``--task`` to ``parser`` (``many``: repeatable, default every task), and the older positional form
    where the command had one (``positional``)."""
    if many:
        every = f"only this task ({tasks}; repeatable; default: every task)"
        parser.add_argument("--task", action="append", default=None, metavar="TASK", help=every)
    else:
        given = parser.add_argument("--task", default=None, metavar="TASK", required=not positional, help=f"{what}: {tasks}")
        given.shown_required = positional  # shown required in the usage; the older form may give it instead (resolve)
    if positional:
        parser.add_argument(_OLD, nargs="*" if many else "?", default=None, metavar="TASK", help=argparse.SUPPRESS)
    parser.add_argument(
        "--option", action="append", default=None, metavar="NAME=VALUE", help=_option_help(parser.prog.split()[1])
    )
    parser.set_defaults(task_many=many)


def _option_help(command: str) -> str:
    if command == "options":
        return "set one of the task's options, to see what it is set to and what it may be (repeatable)"
    where = "`etmpc options --task TASK` lists them" + ("" if command in TAKES_OPTIONS else "; not taken by this command yet")
    return f"set one of the task's options (repeatable; e.g. horizon=15; {where})"


#: The commands that play a task with its options (``--option``); the others refuse them, saying so.
TAKES_OPTIONS = (
    "evaluate",
    "score",
    "render",
    "testset",
    "robustness",
    "options",
    "train",
    "bench",
    "discriminate",
    "figure",
    "sweep",
)


def resolve(args) -> None:
    """Put the task given in the older positional form into ``args.task``, with one deprecation line; refuse a
    task given both ways, and a one-task command without its task."""
    if not hasattr(args, "task_many"):
        return
    old = getattr(args, _OLD, None)
    given = bool(old) if args.task_many else old is not None
    if given:
        assert old is not None  # given: the task (or tasks) in the old form
        if args.task:
            raise EtmpcError("give the task once, as --task TASK")
        words = old if args.task_many else [old]
        new = " ".join(f"--task {word}" for word in words)
        warn(f"'etmpc {args.command} {' '.join(words)}' is deprecated: say 'etmpc {args.command} {new}'")
        args.task = list(words) if args.task_many else old
    if not args.task_many and args.task is None:
        raise EtmpcError(f"etmpc {args.command} needs --task TASK")
    args.options = _options(args)


def _options(args) -> tuple[tuple[str, str], ...]:
    """``--option NAME=VALUE``s as ``(name, value)`` pairs (checked against the task when its key is made)."""
    from etmpc.systems.options import split

    given = getattr(args, "option", None) or []
    if given and args.command not in TAKES_OPTIONS:
        raise EtmpcError(f"etmpc {args.command} does not take --option yet (etmpc {', '.join(TAKES_OPTIONS)} do)")
    return tuple(split(text) for text in given)
