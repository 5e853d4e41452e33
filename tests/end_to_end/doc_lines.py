"""The ``etmpc …`` command lines of the README and of docs/, found and read as the real argument parser
(:func:`etmpc.cli.options.build_parser`) reads them (``test_doc_commands.py`` parses every one and runs the
cheap ones; ``test_doc_names.py`` checks the ids, files and option names the pages write).

What counts as a command line:

* in a fenced block that is not Python, a line starting with ``etmpc`` (or ``$ etmpc``), joined with the
  lines its trailing backslashes continue; ``make`` and ``python`` lines are not etmpc lines. It is parsed as
  written: every required argument present;
* in the text, an inline ```etmpc …``` span: a fragment (``etmpc evaluate --json``), so the arguments it
  leaves out may be required ones; what it names must exist.

A synopsis is read as its plainest instance: ``[--quick]`` is given, ``a|b`` and ``{a,b}`` are their first
choice, ``...`` and ``…`` elide (a flag followed by one must exist, its value is not checked), and a
placeholder in capitals is given a value of its kind (:data:`PLACEHOLDERS`; one the test does not know
fails, asking to be added). A ``--task`` must name a task of the registry and each ``--option`` one of
that task's options with a value it takes, and each policy spec one of a registered kind (built for the task where
it reads no file). A deprecated form (the task as a positional word, ``train-self``,
``train``'s old flags) may appear only on the page that lists deprecations (:data:`DEPRECATIONS_PAGE`).
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import io
import re
import shlex
import warnings
from dataclasses import dataclass
from pathlib import Path

from tests.conftest import REPO

GENERATED = ("docs/results/", "docs/reference/")  # made from runs and the parsers: nothing typed there
DEPRECATIONS_PAGE = "docs/changelog.md"  # the one page that may show a deprecated form (CHANGELOG.md)
# The worked plugin of docs/adding-a-task.md (examples/etmpc_slider): a task once it is installed.
PLUGIN_TASKS = {"docs/adding-a-task.md": ("slider",)}
# A placeholder in capitals -> a value of its kind. ``NAME.ext`` (PATH.rrd, EVAL.json) becomes ``name.ext``.
PLACEHOLDERS = {
    "TASK": "cart_pendulum",
    "T": "cart_pendulum",
    "SPEC": "every:3",
    "N": "3",
    "R": "2",
    "W": "2",
    "S": "0",
    "SEED": "0",
    "I": "0",
    "K": "2",
    "F": "10",
    "P": "0.001",
    "P1,P2,...": "0.001,0.01",
    "ADDR": "auto",
    "PATH": "out.json",
    "FILE": "out.json",
    "DIR": "runs/docs",
    "PNG": "out.png",
    "ZIP": "model.zip",
    "NAME": "dpi",
    "KEY=VALUE": "episodes=3",
    "NAME=VALUE": "horizon=20",
    "X": "3",
}
ELISIONS = ("...", "…")


@dataclass(frozen=True)
class Line:
    """One etmpc command line of a page: where it is, how it is written, and whether it is a fragment."""

    page: str
    line: int
    text: str
    fragment: bool
    refused: str | None = None  # the page shows it refused: the ``etmpc: error:`` line under it, without the prefix

    def where(self) -> str:
        return f"{self.page}:{self.line}: {self.text}"


def doc_pages() -> list[Path]:
    pages = [REPO / "README.md", *sorted((REPO / "docs").rglob("*.md"))]
    return [p for p in pages if not p.relative_to(REPO).as_posix().startswith(GENERATED)]


def _fenced(name: str, text: str) -> list[Line]:
    found = []
    for block in re.finditer(r"^( *)```([^\n`]*)\n(.*?)^\1```", text, flags=re.S | re.M):
        if block.group(2).strip() in ("python", "toml", "bibtex", "yaml", "json"):
            continue
        first = text.count("\n", 0, block.start(3)) + 1
        rows = block.group(3).splitlines()
        i = 0
        while i < len(rows):
            start, joined = i, rows[i].strip()
            while joined.endswith("\\") and i + 1 < len(rows):
                i += 1
                joined = joined[:-1].rstrip() + " " + rows[i].strip()
            joined = joined.removeprefix("$ ")
            shown = rows[i + 1].strip() if i + 1 < len(rows) else ""
            refused = shown.removeprefix("etmpc: error: ") if shown.startswith("etmpc: error: ") else None
            if re.match(r"etmpc(\s|$)", joined):
                found.append(Line(name, first + start, joined, fragment=False, refused=refused))
            i += 1
    return found


def _inline(name: str, text: str) -> list[Line]:
    outside = re.sub(r"^( *)```.*?^\1```", lambda m: "\n" * m.group(0).count("\n"), text, flags=re.S | re.M)
    found = []
    for span in re.finditer(r"`(etmpc (?:[a-z-]+|--[a-z-]+)(?: [^`]*)?)`", outside):
        found.append(Line(name, outside.count("\n", 0, span.start()) + 1, span.group(1), fragment=True))
    return found


def command_lines(pages: list[Path] | None = None, root: Path = REPO) -> list[Line]:
    """Every etmpc command line of ``pages`` (the README and docs/, but the generated pages)."""
    found = []
    for page in doc_pages() if pages is None else pages:
        name, text = page.relative_to(root).as_posix(), page.read_text()
        found += _fenced(name, text) + _inline(name, text)
    return found


def _placeholder(word: str) -> str:
    stem, dot, ext = word.partition(".")
    if word in PLACEHOLDERS:
        return PLACEHOLDERS[word]
    if dot and re.fullmatch(r"[A-Z][A-Z0-9_]*", stem) and ext.isalnum():
        return f"{stem.lower()}.{ext}"
    if re.fullmatch(r"[A-Z][A-Z0-9_]*(=[A-Z0-9_]+)?", word):
        raise AssertionError(f"placeholder {word!r} has no value: add it to PLACEHOLDERS")
    return word


def argv(line: Line, parser) -> list[str]:
    """The line's arguments after ``etmpc``, its synopsis read as its plainest instance (module docstring)."""
    words = shlex.split(line.text, comments=True)[1:]
    plain: list[str] = []
    for word in words:
        word = word.strip("[]")
        if word.startswith("{") and word.endswith("}"):
            word = word[1:-1].split(",")[0]
        elif "|" in word:
            word = word.split("|")[0]
        if not word:
            continue
        if word not in PLACEHOLDERS and any(e in word for e in ELISIONS):  # an elided value, or an elided repetition
            if plain and plain[-1].startswith("--") and "=" not in plain[-1]:
                _check_flag(parser, plain, plain.pop(), line)
            continue
        plain.append(_placeholder(word))
    if line.fragment and len(plain) > 1 and plain[-1].startswith("--") and plain[-1] not in ("--help", "--version"):
        _check_flag(parser, plain, plain.pop(), line)  # `etmpc score --json`: the flag it discusses, with no value
    return plain


def _subparser(parser, words: list[str]):
    sub = next(a for a in parser._actions if a.dest == "command")
    command = next((w for w in words if not w.startswith("-")), None)
    return sub.choices.get(command)


def _check_flag(parser, words: list[str], flag: str, line: Line) -> None:
    sub = _subparser(parser, words)
    known = sub._option_string_actions if sub is not None else parser._option_string_actions
    assert flag in known, f"{line.where()}\n  {flag} is no option of this command"


def relax(parser):
    """``parser`` with no argument required (a fragment leaves out what it does not discuss)."""
    for action in parser._actions:
        if action.dest != "command":
            action.required = False
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                relax(sub)
    return parser


def parse(line: Line, parser):
    """``(args, what it said on stderr)``, or ``(None, the help)`` for ``--help``; refused input fails."""
    from etmpc.cli import tasks
    from etmpc.common.errors import EtmpcError

    words = argv(line, parser)
    said = io.StringIO()
    try:
        with contextlib.redirect_stderr(said), contextlib.redirect_stdout(io.StringIO()):
            args = parser.parse_args(words)
            tasks.resolve(args)
    except SystemExit as exc:  # --help, --version
        assert exc.code == 0, f"{line.where()}\n  exit {exc.code}: {said.getvalue()}"
        return None, ""
    except EtmpcError as exc:
        if line.fragment and "needs --task" in str(exc):
            return None, said.getvalue()
        raise AssertionError(f"{line.where()}\n  refused: {exc}") from None
    return args, said.getvalue()


def deprecated(args, said: str) -> str | None:
    """What is deprecated in the parsed line, or None."""
    from etmpc.cli import legacy

    if "deprecated" in said:
        return said.strip()
    if args is None:
        return None
    if args.command == "train-self":
        return "etmpc train-self"
    if getattr(args, "given_policies", None):  # score's older form: its policies as positional words
        return "etmpc score SPEC (now --policy SPEC)"
    old = [flag for flag in legacy.FLAGS if getattr(args, legacy._dest(flag), None) is not None]
    if getattr(args, "hyperparams", None) is not None:
        old.append("--hyperparams")
    return ", ".join(old) or None


def check_tasks_and_options(line: Line, args) -> None:
    """Each ``--task`` names a task of the registry, and each ``--option`` one of its options, with a value it takes."""
    from etmpc.systems import system_key

    given = getattr(args, "task", None)
    tasks = [] if given is None else given if isinstance(given, list) else [given]
    for task in tasks:
        if task in PLUGIN_TASKS.get(line.page, ()):
            continue
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # an older etmpc's task name is a deprecated form
            try:
                system_key(task, options=getattr(args, "options", ()) or ())
            except Exception as exc:  # noqa: BLE001 (whatever it is, the line does not work as written)
                raise AssertionError(f"{line.where()}\n  --task {task}: {exc}") from None


# A spec that reads a file (or imports a module) names its kind only: the file is the user's, made by another line.
READS_A_FILE = re.compile(r"(?:^|:)(?:rl|self|sb3|py):")


@functools.cache
def _system(task: str, options: tuple):
    from etmpc.systems import system_key

    return system_key(task, options=options).make()


def check_policies(line: Line, args) -> None:
    """Each policy the line plays (``--policy``, ``score``'s, ``--against``) is a spec of a registered kind, and
    one that reads no file is built for the line's task (its first; the cart pendulum where it names none)."""
    from etmpc.policies.specs import kind_of, parse_policy

    given = getattr(args, "policy", None)
    specs = [] if given is None else given if isinstance(given, list) else [given]
    specs += getattr(args, "given_policies", None) or []  # score's older form (refused off the changelog, by deprecated)
    specs += [args.against] if getattr(args, "against", None) else []
    tasks = getattr(args, "task", None) or ["cart_pendulum"]
    task = tasks if isinstance(tasks, str) else tasks[0]
    for spec in specs:
        try:
            kind_of(spec)
            if not READS_A_FILE.search(spec) and task not in PLUGIN_TASKS.get(line.page, ()):
                with warnings.catch_warnings():
                    warnings.simplefilter("error")  # a deprecated spec is a deprecated form
                    parse_policy(spec, _system(task, tuple(getattr(args, "options", ()) or ())))
        except Exception as exc:  # noqa: BLE001 (whatever it is, the line does not work as written)
            raise AssertionError(f"{line.where()}\n  policy {spec}: {exc}") from None


LINES = command_lines()  # the README's and docs/' own
