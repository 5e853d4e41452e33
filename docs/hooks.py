"""MkDocs hooks: the command-line reference, generated from etmpc's own argument parsers at build time,
so that the page cannot drift from the code (``docs/reference/cli.md``'s ``<!-- cli-reference -->``)."""

from __future__ import annotations

import argparse
import re
import os

MARKER = "<!-- cli-reference -->"
# scripts/doc_numbers.py's markers around a number or a generated text: an HTML comment that starts a line ends
# the paragraph it is in, so the site shows the text without them.
_SOURCE_MARKERS = re.compile(r"<!-- (?:number|generated): .*? -->|<!-- /(?:number|generated) -->")


def cli_reference() -> str:
    """Every command's ``--help``, as the terminal shows it at 100 columns."""
    os.environ["COLUMNS"] = "100"
    from etmpc.cli.options import build_parser

    parser = build_parser()
    parts = ["```text", parser.format_help().rstrip(), "```", ""]
    return "\n".join(parts + _commands(parser, "etmpc", "##"))


def _commands(parser: argparse.ArgumentParser, prefix: str, level: str) -> list[str]:
    """A section per command of ``parser`` (and one level down per kind of a command that has kinds, such
    as ``etmpc figure``'s), each with its ``--help``."""
    sub = next((a for a in parser._actions if isinstance(a, argparse._SubParsersAction)), None)
    if sub is None:
        return []
    summaries = {choice.dest: choice.help for choice in sub._choices_actions}
    parts = []
    for name, command in sub.choices.items():
        summary = summaries.get(name) or ""
        parts += [
            f"{level} {prefix} {name}",
            "",
            f"{summary[:1].upper()}{summary[1:]}.",
            "",
            "```text",
            command.format_help().rstrip(),
            "```",
            "",
        ]
        parts += _commands(command, f"{prefix} {name}", level + "#")
    return parts


def on_page_markdown(markdown: str, page, config, files) -> str:
    markdown = _SOURCE_MARKERS.sub("", markdown)
    if MARKER in markdown:
        return markdown.replace(MARKER, cli_reference())
    return markdown


_ROLE = re.compile(r":(?:class|func|meth|mod|attr|data|exc|obj):(<code>)~?")


def on_page_content(html: str, page, config, files) -> str:
    """Docstrings use Sphinx's roles (``:class:`Plan```); the API pages show the name alone, as code."""
    return _ROLE.sub(r"\1", html)
