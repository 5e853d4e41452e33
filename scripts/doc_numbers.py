"""Every number the README and docs/ quote by hand sits under a marker naming the results file or the code it
comes from:

    <!-- number: docs/leaderboard.json entries[name=DPI (shipped)].rows[task=battery].score | .1f -->32.1<!-- /number -->
    <!-- number: etmpc.systems.quadrotor.system:Config.angle_weight | g -->0.5<!-- /number -->

* the source: a JSON file, relative to the repository's root, then a space and a key;
* the key: dotted names into the JSON, ``[N]`` for a list's N-th item, ``[field=value]`` for the item of a
  list whose ``field`` is ``value`` (exactly one must be);
* or, with no space, ``MODULE:ATTRIBUTE``: a module of etmpc (``etmpc`` or ``etmpc.…``; any other is refused,
  never imported) and a dotted attribute path in it, ``[N]`` for a sequence's N-th item, ``[KEY]`` for a dict's
  item (``TEST_SET_SEEDS[kicks]``). A dataclass's
  field, read off its class, is its default (``Config.horizon``; a ``default_factory``'s value), and its property
  the default instance's (``Battery.trade_limit_kw``); a task's numbers
  live in its ``Config`` and task module, so a page quotes them from there;
* after ``|``, options, each ``name=value`` (a bare first one is the format):
  ``.1f`` (any Python format; one ending in ``%`` multiplies by 100 and prints ``11.36 %``),
  ``vs=KEY`` (the relative change against another key of the same file or module: ``(value - other) / |other|``),
  ``per=KEY`` (the ratio to another key of the same file or module: ``value / |other|``, a gap as a share of a mean),
  ``times=KEY`` (the product with another key of the same file or module: a horizon of N intervals in seconds),
  ``scale=X`` (multiplies, after ``vs``: ``scale=-1`` turns a cost's change into a gain, ``scale=100`` a share
  into a count of 100 episodes); in a table's row, where ``|`` would end the cell, ``\\|`` separates them.

    python scripts/doc_numbers.py            # check: one line per number that disagrees with its source
    python scripts/doc_numbers.py --write    # rewrite every marked number from its source

A list, a table or a count the registry holds (the tasks, their ids and versions, their prices) sits under a
marker of its own kind, naming a function of etmpc that takes no argument and returns the text
(:mod:`etmpc.systems.catalogue`'s):

    the suite has <!-- generated: etmpc.systems.catalogue:task_count -->ten<!-- /generated --> tasks

A text of several lines (a table) stands between the markers on lines of its own, with a blank line either side.

``tests/end_to_end/test_docs_numbers.py`` runs the check.
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib
import inspect
import json
import re
import sys
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MARKER = re.compile(r"<!-- number: (?P<spec>.*?) -->(?P<shown>.*?)<!-- /number -->")
GENERATED = re.compile(r"<!-- generated: (?P<spec>\S+) -->(?P<shown>.*?)<!-- /generated -->", flags=re.S)
_PART = re.compile(r"\[([^\]]*)\]|([^.\[\]]+)")
_PYTHON = re.compile(r"(?P<module>[^\s:]+):(?P<key>\S+)")  # MODULE:ATTRIBUTE, no space
_ETMPC_MODULE = re.compile(r"etmpc(?:\.[A-Za-z_][A-Za-z0-9_]*)*")  # the only modules a page may name


@dataclass(frozen=True)
class Number:
    """One marked number: where it is, what it names, what the page shows."""

    page: Path
    line: int
    source: str
    key: str
    options: dict[str, str]
    shown: str
    span: tuple[int, int]  # of the shown text in the page
    python: bool = False  # the source is a module of etmpc (MODULE:ATTRIBUTE), not a JSON file
    generated: bool = False  # a text a function of that module returns (``<!-- generated: ... -->``)

    def where(self) -> str:
        return f"{self.page}:{self.line}"

    def name(self) -> str:
        """The source and key as the marker writes them."""
        return f"{self.source}:{self.key}" if self.python else f"{self.source} {self.key}"


def parse(spec: str) -> tuple[str, str, dict[str, str], bool]:
    """``FILE KEY | fmt | name=value ...`` or ``MODULE:ATTRIBUTE | ...`` as (file or module, key, options,
    whether the source is a module). A module outside etmpc raises ``ValueError``: a page names no other."""
    head, *rest = [part.strip() for part in spec.replace("\\|", "|").split("|")]  # \| in a table's row
    python = _PYTHON.fullmatch(head)
    if python:
        source, key = python.group("module"), python.group("key")
        if not _ETMPC_MODULE.fullmatch(source):
            raise ValueError(f"a marker's module must be etmpc's (etmpc.…), not {source!r}: {spec!r}")
    else:
        source, _, key = head.partition(" ")
    if not source or not key.strip():
        raise ValueError(f"a marker needs a file and a key, or MODULE:ATTRIBUTE: {spec!r}")
    options: dict[str, str] = {}
    for i, option in enumerate(rest):
        name, eq, value = option.partition("=")
        if eq and name in ("fmt", "vs", "per", "times", "scale"):
            options[name] = value.strip()
        elif i == 0 and not eq:
            options["fmt"] = option
        else:
            raise ValueError(f"unknown option {option!r} in {spec!r} (fmt, vs=KEY, per=KEY, times=KEY, scale=X)")
    return source, key.strip(), options, bool(python)


def lookup(data, key: str):
    """The value at ``key`` (see the module's docstring) in ``data``."""
    value = data
    for index, name in _PART.findall(key):
        if name:
            if not isinstance(value, dict) or name not in value:
                raise KeyError(f"{key}: no {name!r}")
            value = value[name]
        elif "=" in index:
            field, _, wanted = index.partition("=")
            found = [item for item in value if isinstance(item, dict) and str(item.get(field)) == wanted]
            if len(found) != 1:
                raise KeyError(f"{key}: {len(found)} items with {field}={wanted!r}")
            value = found[0]
        else:
            value = value[int(index)]
    return value


def attribute(module, key: str):
    """The value at the dotted attribute path ``key`` (``[N]`` indexes a sequence, ``[KEY]`` a dict) in
    ``module``; a dataclass's field read off its class is its default."""
    value = module
    for index, name in _PART.findall(key):
        if name:
            if name.startswith("__"):
                raise KeyError(f"{key}: {name!r}: a marker reads no dunder attribute")
            value = _attribute(value, name, key)
        elif isinstance(value, Mapping) and "=" not in index:
            if index not in value:
                raise KeyError(f"{key}: no item {index!r}")
            value = value[index]
        elif re.fullmatch(r"-?[0-9]+", index):
            value = value[int(index)]
        else:
            raise KeyError(f"{key}: [{index}]: a Python value is indexed by a number, a dict by a key")
    return value


def _attribute(value, name: str, key: str):
    if isinstance(value, type) and dataclasses.is_dataclass(value):
        field = {f.name: f for f in dataclasses.fields(value)}.get(name)
        if field is not None:  # its default: a frozen dataclass keeps a plain one on the class, not a factory's
            if field.default is not dataclasses.MISSING:
                return field.default
            if field.default_factory is not dataclasses.MISSING:
                return field.default_factory()
            raise KeyError(f"{key}: {value.__name__}.{name} has no default")
        if isinstance(inspect.getattr_static(value, name, None), property):  # the default instance's
            return getattr(value(), name)
    if not hasattr(value, name):
        raise KeyError(f"{key}: no {name!r}")
    return getattr(value, name)


def module(name: str, root: Path = ROOT):
    """The module of etmpc ``name``, imported from ``root``'s ``etmpc/`` where it has one (so a worktree's
    check reads its own code, not an installed copy's); any other name raises ``ValueError`` unimported."""
    if not _ETMPC_MODULE.fullmatch(name):
        raise ValueError(f"not a module of etmpc: {name!r}")
    package = Path(root).resolve() / "etmpc"
    if package.is_dir() and "etmpc" not in sys.modules and str(package.parent) not in sys.path:
        sys.path.insert(0, str(package.parent))
    found = importlib.import_module(name)
    where = Path(getattr(found, "__file__", "") or "").resolve()
    if package.is_dir() and package not in where.parents:
        raise ImportError(f"{name} was imported from {where}, not from {package}")
    return found


def render(value, options: dict[str, str]) -> str:
    """The number as the page shows it (a generated text as it is, a text of several lines set apart by blank lines)."""
    if options.get("text"):
        return f"\n\n{value}\n\n" if "\n" in value else value
    fmt = options.get("fmt", "")
    if fmt.endswith("%"):
        return format(value * 100, fmt[:-1] + "f") + " %"
    return format(value, fmt)


def source_value(number: Number, root: Path = ROOT, cache: dict | None = None):
    cache = {} if cache is None else cache
    if number.generated:
        made = attribute(module(number.source, root), number.key)
        if not callable(made):
            raise TypeError(f"{number.name()} is not a function")
        return made()
    if number.python:
        data, read = module(number.source, root), attribute
    else:
        if number.source not in cache:
            cache[number.source] = json.loads((root / number.source).read_text())
        data, read = cache[number.source], lookup
    value = read(data, number.key)
    if "vs" in number.options:
        other = read(data, number.options["vs"])
        value = (value - other) / abs(other)
    if "per" in number.options:
        value = value / abs(read(data, number.options["per"]))
    if "times" in number.options:
        value = value * read(data, number.options["times"])
    if "scale" in number.options:
        value = value * float(number.options["scale"])
    return value


def numbers(page: Path, text: str | None = None) -> list[Number]:
    text = page.read_text() if text is None else text
    found = []
    for match in MARKER.finditer(text):
        source, key, options, python = parse(match.group("spec"))
        line = text.count("\n", 0, match.start()) + 1
        found.append(Number(page, line, source, key, options, match.group("shown"), match.span("shown"), python))
    for match in GENERATED.finditer(text):
        source, key, _, python = parse(match.group("spec"))
        if not python:
            raise ValueError(f"a generated text names a function of etmpc, MODULE:FUNCTION: {match.group('spec')!r}")
        line = text.count("\n", 0, match.start()) + 1
        shown, span = match.group("shown"), match.span("shown")
        found.append(Number(page, line, source, key, {"text": "1"}, shown, span, python=True, generated=True))
    return sorted(found, key=lambda n: n.span)


def pages(root: Path = ROOT) -> list[Path]:
    return [root / "README.md", *sorted((root / "docs").rglob("*.md"))]


def check(paths: list[Path], root: Path = ROOT) -> list[str]:
    """One message per marked number that disagrees with its source (or names a missing one)."""
    cache: dict = {}
    problems = []
    for page in paths:
        try:
            found = numbers(page)
        except ValueError as exc:
            problems.append(f"{page}: {exc}")
            continue
        for n in found:
            try:
                expected = render(source_value(n, root, cache), n.options)
            except (OSError, ImportError, KeyError, IndexError, TypeError, ValueError) as exc:
                problems.append(f"{n.where()}: {n.name()}: cannot be read ({exc})")
                continue
            if n.shown != expected:
                problems.append(f"{n.where()}: {n.name()} is {expected!r}, the page says {n.shown!r}")
    return problems


def write(paths: list[Path], root: Path = ROOT) -> list[Path]:
    """Rewrite every marked number from its source; returns the pages changed."""
    cache: dict = {}
    changed = []
    for page in paths:
        text = page.read_text()
        out, at = [], 0
        for n in numbers(page, text):
            out += [text[at : n.span[0]], render(source_value(n, root, cache), n.options)]
            at = n.span[1]
        new = "".join(out) + text[at:]
        if new != text:
            page.write_text(new)
            changed.append(page)
    return changed


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--write", action="store_true", help="rewrite every marked number from its source")
    args = parser.parse_args(argv)
    if args.write:
        for page in write(pages()):
            print(f"rewrote {page.relative_to(ROOT)}")
        return
    problems = check(pages())
    print("\n".join(problems) or f"every marked number agrees with its source ({sum(len(numbers(p)) for p in pages())})")
    sys.exit(1 if problems else 0)


if __name__ == "__main__":
    main()
