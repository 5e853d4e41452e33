"""What the commands of the ``etmpc`` command line share: progress lines and warnings on stderr, the
check that a policy is named once, the ``--backend`` and ``--address`` options with their check, and the run
directory and workers of a study."""

from __future__ import annotations

import sys
from pathlib import Path
from collections.abc import Callable

from etmpc.cli import types
from etmpc.common import progress
from etmpc.common.errors import EtmpcError


def say(line: str) -> None:
    """Progress of a long stage, on stderr (stdout keeps the results), above the progress bar if one shows."""
    progress.say(line)


def warn(line: str) -> None:
    """A warning (a deprecated option), one line on stderr."""
    print(f"etmpc: warning: {line}", file=sys.stderr, flush=True)


class LazyHelp(str):
    """A help text made only when the help is shown (argparse expands it with ``%``): ``make()`` may read the
    registry and import the tasks, which ``etmpc --help`` and every command's parsing must not."""

    make: Callable[[], str]  # the text, made when the help is shown

    def __new__(cls, make: Callable[[], str], plain: str = "(made when shown)") -> LazyHelp:
        """``make``: the text, made when the help is shown; ``plain``: what the help is as a plain string."""
        text = super().__new__(cls, plain)
        text.make = make
        return text

    def __mod__(self, params):
        return self.make().replace("%", "%%") % params


def task_prices() -> str:
    """Each task's own price of a recompute, from the registry: ``5e-05 on cart_pendulum/balance; 0.1 on ...``."""
    from etmpc.systems.catalogue import entries

    by_price: dict[float, list[str]] = {}
    for entry in entries():
        by_price.setdefault(entry.recompute_price, []).append(entry.spec.id)
    return "; ".join(f"{price:g} on {', '.join(tasks)}" for price, tasks in by_price.items())


def backend_arguments(parser) -> None:
    from etmpc.evaluation.backends import BACKENDS

    parser.add_argument(
        "--backend",
        choices=BACKENDS,
        default="local",
        help="where the work runs: local processes, or Ray (the 'ray' extra); results are the same",
    )
    parser.add_argument(
        "--address",
        default=None,
        metavar="ADDR",
        help="Ray cluster to join, e.g. auto or ray://HOST:10001 (with --backend ray; "
        "default: start a local Ray instance of --workers CPUs)",
    )


def run_arguments(parser, out_help: str) -> None:
    """A study's run directory (``--out DIR``, described by ``out_help``; default None: the command's own),
    its worker processes (one per core by default) and where they run (:func:`backend_arguments`): the
    options that ``etmpc reproduce`` and ``etmpc sweep`` share, declared once."""
    parser.add_argument("--out", type=Path, default=None, metavar="DIR", help=out_help)
    parser.add_argument("--workers", type=types.workers, default=None, help="worker processes (default: one per core)")
    backend_arguments(parser)


def check_backend(args) -> None:
    if args.address is not None and args.backend != "ray":
        raise EtmpcError("--address needs --backend ray")


def distinct_policies(specs: list[str]) -> None:
    seen = set()
    for spec in specs:
        if spec in seen:
            raise EtmpcError(f"policy {spec} is given twice")
        seen.add(spec)
