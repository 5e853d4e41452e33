"""Every number the README and docs/ quote by hand sits under a marker naming the results file it comes from:

    <!-- number: docs/leaderboard.json entries[name=DPI (shipped)].rows[task=battery].score | .1f -->32.1<!-- /number -->

* the source: a JSON file, relative to the repository's root;
* the key: dotted names into the JSON, ``[N]`` for a list's N-th item, ``[field=value]`` for the item of a
  list whose ``field`` is ``value`` (exactly one must be);
* after ``|``, options, each ``name=value`` (a bare first one is the format):
  ``.1f`` (any Python format; one ending in ``%`` multiplies by 100 and prints ``11.36 %``),
  ``vs=KEY`` (the relative change against another key of the same file: ``(value - other) / |other|``),
  ``per=KEY`` (the ratio to another key of the same file: ``value / |other|``, a gap as a share of a mean),
  ``scale=X`` (multiplies, after ``vs``: ``scale=-1`` turns a cost's change into a gain, ``scale=100`` a share
  into a count of 100 episodes).

    python scripts/doc_numbers.py            # check: one line per number that disagrees with its source
    python scripts/doc_numbers.py --write    # rewrite every marked number from its source

``tests/end_to_end/test_docs_numbers.py`` runs the check.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MARKER = re.compile(r"<!-- number: (?P<spec>.*?) -->(?P<shown>.*?)<!-- /number -->")
_PART = re.compile(r"\[([^\]]*)\]|([^.\[\]]+)")


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

    def where(self) -> str:
        return f"{self.page}:{self.line}"


def parse(spec: str) -> tuple[str, str, dict[str, str]]:
    """``FILE KEY | fmt | name=value ...`` as (file, key, options)."""
    head, *rest = [part.strip() for part in spec.split("|")]
    source, _, key = head.partition(" ")
    if not source or not key.strip():
        raise ValueError(f"a marker needs a file and a key: {spec!r}")
    options: dict[str, str] = {}
    for i, option in enumerate(rest):
        name, eq, value = option.partition("=")
        if eq and name in ("fmt", "vs", "per", "scale"):
            options[name] = value.strip()
        elif i == 0 and not eq:
            options["fmt"] = option
        else:
            raise ValueError(f"unknown option {option!r} in {spec!r} (fmt, vs=KEY, per=KEY, scale=X)")
    return source, key.strip(), options


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


def render(value, options: dict[str, str]) -> str:
    """The number as the page shows it."""
    fmt = options.get("fmt", "")
    if fmt.endswith("%"):
        return format(value * 100, fmt[:-1] + "f") + " %"
    return format(value, fmt)


def source_value(number: Number, root: Path = ROOT, cache: dict | None = None):
    cache = {} if cache is None else cache
    if number.source not in cache:
        cache[number.source] = json.loads((root / number.source).read_text())
    data = cache[number.source]
    value = lookup(data, number.key)
    if "vs" in number.options:
        other = lookup(data, number.options["vs"])
        value = (value - other) / abs(other)
    if "per" in number.options:
        value = value / abs(lookup(data, number.options["per"]))
    if "scale" in number.options:
        value = value * float(number.options["scale"])
    return value


def numbers(page: Path, text: str | None = None) -> list[Number]:
    text = page.read_text() if text is None else text
    found = []
    for match in MARKER.finditer(text):
        source, key, options = parse(match.group("spec"))
        found.append(
            Number(page, text.count("\n", 0, match.start()) + 1, source, key, options, match.group("shown"), match.span("shown"))
        )
    return found


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
            except (OSError, KeyError, IndexError, TypeError, ValueError) as exc:
                problems.append(f"{n.where()}: {n.source} {n.key}: cannot be read ({exc})")
                continue
            if n.shown != expected:
                problems.append(f"{n.where()}: {n.source} {n.key} is {expected!r}, the page says {n.shown!r}")
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
