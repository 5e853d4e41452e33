"""Every ``etmpc …`` command line of the README and of docs/ is parsed by the real argument parser, so that a
command, a flag, a task or an option that stops existing fails here with its page and line, and a deprecated
form fails off the page that lists deprecations; the cheap ones (``options``, ``tasks``, ``--help``, a small
``testset``) are run as a new user runs them. What counts as a command line and how a synopsis is read:
:mod:`tests.end_to_end.doc_lines`."""

from __future__ import annotations

import dataclasses
import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests.conftest import REPO
from tests.end_to_end.doc_lines import (
    DEPRECATIONS_PAGE,
    LINES,
    Line,
    relax,
    argv,
    check_policies,
    check_tasks_and_options,
    command_lines,
    deprecated,
    parse,
)

CHEAP = ("options", "tasks")  # commands that answer in about a second, run in full


@pytest.fixture(scope="module")
def parser():
    from etmpc.cli import options

    return options.build_parser()


@pytest.fixture(scope="module")
def relaxed():
    from etmpc.cli import options

    return relax(options.build_parser())


def test_the_command_lines_are_found():
    pages = {line.page for line in LINES}
    assert {"README.md", "docs/using.md", "docs/getting-started.md", "docs/tasks/sensing.md"} <= pages
    assert sum(not line.fragment for line in LINES) >= 50 and sum(line.fragment for line in LINES) >= 100
    joined = [line for line in LINES if line.page == "docs/using.md" and "--record runs/cart_video.rrd" in line.text]
    assert joined and "--fps F" in joined[0].text  # a backslash's continuation is part of its line


@pytest.mark.parametrize("line", LINES, ids=[f"{line.page}:{line.line}" for line in LINES])
def test_the_command_line_parses_with_the_real_parser(line, parser, relaxed):
    if line.refused is not None:  # shown refused: it is, in the words the page shows
        with pytest.raises(AssertionError) as refusal:
            check_tasks_and_options(line, parse(line, parser)[0])
        assert line.refused in str(refusal.value), f"{line.where()}\n  the page says: {line.refused}\n{refusal.value}"
        return
    args, said = parse(line, relaxed if line.fragment else parser)
    old = deprecated(args, said)
    assert old is None or line.page == DEPRECATIONS_PAGE, f"{line.where()}\n  a deprecated form: {old}"
    if args is not None:
        check_tasks_and_options(line, args)
        check_policies(line, args)


def _cheap(line: Line, parser) -> bool:
    """Whether the line is a whole command (a fragment only if it parses as one) that answers in seconds."""
    try:
        words = argv(line, parser)
        if line.fragment:
            parse(dataclasses.replace(line, fragment=False), parser)
    except AssertionError:  # not whole; or refused, which the parsing test reports
        return False
    small_testset = words[:1] == ["testset"] and "--episodes" in words
    return bool(words) and (words[0] in CHEAP or "--help" in words or words == ["--version"] or small_testset)


@pytest.fixture(scope="module")
def cheap_lines(parser):
    return [line for line in LINES if _cheap(line, parser)]


def test_some_lines_are_cheap_enough_to_run(cheap_lines):
    assert any("options" in line.text for line in cheap_lines) and any("testset" in line.text for line in cheap_lines)


def test_the_cheap_command_lines_run_as_written(cheap_lines, parser, tmp_path):
    runs = {}  # each command once, under the first line that writes it
    for line in cheap_lines:
        runs.setdefault(tuple(argv(line, parser)), line)
    for i, (words, line) in enumerate(runs.items()):
        folder = tmp_path / str(i)
        folder.mkdir()
        done = subprocess.run(
            [sys.executable, "-m", "etmpc.cli", *words],
            cwd=folder,
            env=dict(os.environ, MUJOCO_GL="egl", PYTHONPATH=str(REPO)),
            capture_output=True,
            text=True,
            timeout=120,
        )
        assert done.returncode == 0 and "warning" not in done.stderr, f"{line.where()}\n{done.stderr[-2000:]}"
        assert done.stdout.strip(), line.where()


# -- the checker itself, on a small fake page ------------------------------------------------------------
def _fake(tmp_path: Path, body: str) -> list[Line]:
    (tmp_path / "docs").mkdir(exist_ok=True)
    page = tmp_path / "docs" / "page.md"
    page.write_text(body)
    return command_lines([page], tmp_path)


def test_a_flag_that_does_not_exist_fails_naming_page_and_line(tmp_path, parser):
    (line,) = _fake(tmp_path, "# A page\n\n```sh\netmpc evaluate --task cart_pendulum --policy every:3 --no-such-flag\n```\n")
    with pytest.raises(AssertionError, match=r"(?s)docs/page.md:4: etmpc evaluate .*unrecognized arguments: --no-such-flag"):
        parse(line, parser)


def test_a_synopsis_is_read_as_its_plainest_instance(tmp_path, parser):
    (line,) = _fake(
        tmp_path,
        "```sh\netmpc sweep [--task TASK ...] [--prices P1,P2,...] [--episodes N] \\\n    [--backend local|ray]  # all\n```\n",
    )
    assert argv(line, parser) == [
        "sweep",
        "--task",
        "cart_pendulum",
        "--prices",
        "0.001,0.01",
        "--episodes",
        "3",
        "--backend",
        "local",
    ]
    args, _ = parse(line, parser)
    assert args.task == ["cart_pendulum"] and args.prices == (0.001, 0.01) and args.backend == "local"


def test_an_unknown_placeholder_is_refused(tmp_path, parser):
    (line,) = _fake(tmp_path, "```sh\netmpc evaluate --task TASK --policy WHATEVER\n```\n")
    with pytest.raises(AssertionError, match="placeholder 'WHATEVER'"):
        argv(line, parser)


@pytest.mark.parametrize(
    "text", ["etmpc bench TASK", "etmpc sweep cart_pendulum --quick", "etmpc train-self --task battery --out x.json"]
)
def test_a_deprecated_form_is_found(tmp_path, relaxed, text):
    (line,) = _fake(tmp_path, f"Run `{text}`.\n")
    args, said = parse(line, relaxed)
    assert deprecated(args, said)


def test_an_option_the_task_does_not_have_is_refused(tmp_path, parser):
    (line,) = _fake(tmp_path, "```sh\netmpc evaluate --task cart_pendulum --policy every:3 --option sensor.noise_std=0.01\n```\n")
    args, _ = parse(line, parser)
    with pytest.raises(AssertionError, match="docs/page.md:2: .*sensor.noise_std"):
        check_tasks_and_options(line, args)
    (line,) = _fake(
        tmp_path, "```sh\netmpc evaluate --task cart_pendulum/kicks --policy every:3 --option sensor.noise_std=0.01\n```\n"
    )
    check_tasks_and_options(line, parse(line, parser)[0])


def test_an_unknown_task_is_refused(tmp_path, relaxed):
    (line,) = _fake(tmp_path, "`etmpc render --task cart_pendulum/swingup`\n")
    args, _ = parse(line, relaxed)
    with pytest.raises(AssertionError, match="unknown task"):
        check_tasks_and_options(line, args)


def test_a_policy_of_no_kind_or_a_bad_one_is_refused(tmp_path, parser):
    for spec, why in [("treshold:0.3", "unknown policy"), ("every:0", "every:0")]:
        (line,) = _fake(tmp_path, f"```sh\netmpc evaluate --task cart_pendulum/kicks --policy {spec}\n```\n")
        with pytest.raises(AssertionError, match=f"(?s)docs/page.md:2: .*policy {spec}: .*{why}"):
            check_policies(line, parse(line, parser)[0])
    (line,) = _fake(tmp_path, "```sh\netmpc evaluate --task cart_pendulum/kicks --policy rl:mine.json --policy every:3\n```\n")
    check_policies(line, parse(line, parser)[0])  # a file of the user's: its kind is enough
