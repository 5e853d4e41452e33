"""``etmpc study NAME [OPTION ...]``: run one of the studies behind the results pages
(:mod:`etmpc.experiments.studies`), with the study's own options; ``etmpc study --list`` names them and
``etmpc study NAME --help`` gives a study's options. A study's module is imported when it runs."""

from __future__ import annotations

import argparse
from typing import NoReturn

from etmpc.common.errors import EtmpcError
from etmpc.experiments.studies import STUDIES, load


class _StudyParser(argparse.ArgumentParser):
    """A study's own options, under ``etmpc study NAME``: an error is one line (exit code 2), as the command's."""

    def error(self, message: str) -> NoReturn:  # raises instead of exiting: etmpc's one-line errors
        raise EtmpcError(message)


def add_parser(sub) -> None:
    """The ``study`` subcommand's options, on the command line's subparsers ``sub``."""
    st = sub.add_parser(
        "study",
        help="run a study behind a results page (its JSON and page into docs/results/): etmpc study --list names them",
        description="Run a study behind a results page. Each study has options of its own: etmpc study NAME --help.",
    )
    st.add_argument(
        "name", nargs="?", choices=sorted(STUDIES), metavar="NAME", help="the study to run (etmpc study --list names them)"
    )
    st.add_argument(
        "options", nargs=argparse.REMAINDER, metavar="OPTION", help="the study's own options (etmpc study NAME --help)"
    )
    st.add_argument("--list", action="store_true", help="list the studies, one line each, and exit")


def listing() -> str:
    """Every registered study, one line each: its name and what it makes."""
    width = max(map(len, STUDIES))
    return "\n".join(f"{name:<{width}}  {entry.summary}" for name, entry in sorted(STUDIES.items()))


def run(args: argparse.Namespace) -> None:
    if args.list:
        print(listing())
        return
    if args.name is None:
        raise EtmpcError(f"name a study (one of {', '.join(sorted(STUDIES))}), or --list")
    study = load(args.name)
    parser = _StudyParser(prog=f"etmpc study {args.name}", description=STUDIES[args.name].summary)
    study.arguments(parser)
    command = " ".join(["etmpc", "study", args.name, *args.options])  # what a study's JSON may record as its maker
    study.run(parser.parse_args(args.options, argparse.Namespace(command=command)))
