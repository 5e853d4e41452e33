"""The names the README and docs/ write exist: every Gymnasium id is registered, every ``self:`` policy file
is one a training line of the docs writes, every dotted option name is an option of some task."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from tests.conftest import REPO
from tests.end_to_end.doc_lines import LINES, doc_pages, parse


@pytest.fixture(scope="module")
def parser():
    from etmpc.cli import options

    return options.build_parser()


# -- the Gymnasium ids the pages name ----------------------------------------------------------------------
VERSIONS_PAGE = "docs/versioning.md"  # names a task's older ids, to say they are refused


def test_every_gymnasium_id_the_docs_name_is_registered():
    from etmpc.systems import registry

    ids = {spec.gym_id for spec in registry.specs()}
    for page in doc_pages():
        name, text = page.relative_to(REPO).as_posix(), page.read_text()
        template = re.search(r"etmpc/<\w+>-<\w+>-v\d", text)  # every task at one version: none is
        assert template is None, f"{name}: {template.group(0)}: the version is each task's own (-vN)"
        for match in re.finditer(r"etmpc/([a-z_]+-[a-z_]+)-v(\d+)", text):
            line = text.count("\n", 0, match.start()) + 1
            if match.group(0) in ids:
                continue
            older = any(s.slug == match.group(1) and int(match.group(2)) < s.version for s in registry.specs())
            assert older and name == VERSIONS_PAGE, f"{name}:{line}: {match.group(0)} is no registered id"


def test_every_self_policy_file_the_docs_play_is_one_a_training_line_of_the_docs_writes(parser):
    """``self:DIR/selected.json`` in a page is what ``etmpc train --algorithm self --out DIR`` writes: the pages
    agree on where the self-triggering policy lands."""
    written = set()
    for line in LINES:
        if line.fragment or not line.text.startswith("etmpc train "):
            continue
        args, _ = parse(line, parser)
        if args is not None and args.algorithm == "self":
            written.add(f"{Path(args.out).as_posix()}/selected.json")
    assert written
    for line in LINES:
        for path in re.findall(r"self:(runs/\S+)", line.text):
            assert path in written, f"{line.where()}\n  self:{path} is written by no training line of the docs ({written})"


# -- the option names the pages write -----------------------------------------------------------------------
def test_every_dotted_option_name_the_docs_write_is_an_option_of_a_task():
    """```sensor.noise_std```, ```latency.intervals=2```: a name under one of the settings options live in
    (``sensor.``, ``latency.``, ...) is an option of some task of the registry (a file, ```market.py```, is not one)."""
    from etmpc.systems import catalogue

    names = {name for entry in catalogue.entries() for name in entry.options}
    heads = sorted({name.split(".")[0] for name in names if "." in name})
    written = re.compile(rf"`((?:{'|'.join(heads)})\.[A-Za-z_.]+?)(=[^`]*)?`")
    for page in doc_pages():
        name, text = page.relative_to(REPO).as_posix(), page.read_text()
        for match in written.finditer(text):
            option = match.group(1)
            if re.search(r"\.(py|md|json|npz|xml|png|yml|toml)$", option):
                continue
            line = text.count("\n", 0, match.start()) + 1
            assert option in names, f"{name}:{line}: {match.group(0)} is no task's option (etmpc tasks lists them)"
