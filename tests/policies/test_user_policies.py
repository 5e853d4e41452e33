"""Triggers of your own: policy objects in etmpc.evaluate and py:MODULE:NAME on the command line, with the
same parallel, paired, deterministic results as the built-in ones, and one line for whatever is wrong."""

import json
import subprocess
import sys
from dataclasses import dataclass

import pytest

import etmpc
from etmpc.cli import main
from etmpc.common.errors import EtmpcError

from tests.conftest import REPO


@dataclass(frozen=True)
class EveryThird:
    """The rule of every:3, written as a user would."""

    spec: str = "mine:every-third"
    stochastic: bool = False

    def decide(self, s, rng) -> bool:
        return s.age >= 3


@dataclass(frozen=True)
class Coin:
    """A stochastic rule: its draws come from the generator evaluate gives it."""

    spec: str = "mine:coin"
    stochastic: bool = True

    def decide(self, s, rng) -> bool:
        return bool(rng.random() < 0.3)


def test_a_policy_object_plays_exactly_as_the_same_built_in_rule_on_any_number_of_workers():
    one = etmpc.evaluate("cart_pendulum", ["every:3", EveryThird()], episodes=6, workers=1, progress=False).to_json()
    two = etmpc.evaluate("cart_pendulum", ["every:3", EveryThird()], episodes=6, workers=2, progress=False).to_json()
    assert one == two
    runs = {
        p: [(r["episode"], r["objective"], r["recomputes"]) for r in one["runs"] if r["policy"] == p]
        for p in ("every:3", "mine:every-third")
    }
    assert runs["every:3"] == runs["mine:every-third"] and len(runs["every:3"]) == 6


def test_a_stochastic_policy_object_draws_the_same_numbers_for_any_number_of_workers():
    one = etmpc.evaluate("battery", [Coin()], episodes=3, repeats=2, workers=1, progress=False).to_json()
    two = etmpc.evaluate("battery", [Coin()], episodes=3, repeats=2, workers=2, progress=False).to_json()
    assert one["runs"] == two["runs"]
    assert len({r["recomputes"] for r in one["runs"]}) > 1  # it does draw


def test_a_policy_object_is_checked_before_any_work():
    with pytest.raises(EtmpcError, match="is not a policy.*a bool `stochastic`.*decide"):
        etmpc.evaluate("cart_pendulum", [object()], episodes=1, workers=1, progress=False)
    with pytest.raises(EtmpcError, match="given twice"):
        etmpc.evaluate("cart_pendulum", [EveryThird(), EveryThird()], episodes=1, workers=1, progress=False)
    with pytest.raises(EtmpcError, match="a built-in policy's"):  # nor can it pass for one (tests/end_to_end/test_integrity.py)
        etmpc.evaluate("cart_pendulum", ["every:3", EveryThird(spec="every:3")], episodes=1, workers=1, progress=False)


MODULE = """
from dataclasses import dataclass

@dataclass(frozen=True)
class Late:
    spec: str = "late"
    stochastic: bool = False
    def decide(self, s, rng):
        return s.age >= 5

def factory():
    return Late()

class Raises:
    spec, stochastic = "raises", False
    def decide(self, s, rng):
        raise ZeroDivisionError("my bug")

class Answers:
    spec, stochastic = "answers", False
    def decide(self, s, rng):
        return "yes"

class Two:
    spec, stochastic = "two", False
    def decide(self, s, rng):
        return 2

class Broken:
    def __init__(self):
        raise RuntimeError("cannot build")

class NotAPolicy:
    spec = "no"

import_error = None
"""


@pytest.fixture
def here(tmp_path, monkeypatch):
    (tmp_path / "mytriggers.py").write_text(MODULE)
    monkeypatch.chdir(tmp_path)
    monkeypatch.syspath_prepend(str(tmp_path))
    yield tmp_path
    sys.modules.pop("mytriggers", None)


@pytest.mark.parametrize("target", ["py:mytriggers:Late", "py:mytriggers:factory"])
def test_py_targets_evaluate_like_the_same_rule(here, target, capsys):
    assert (
        main(
            [
                "evaluate",
                "--task",
                "battery",
                "--policy",
                "every:5",
                "--policy",
                target,
                "--episodes",
                "3",
                "--workers",
                "2",
                "--json",
                "out.json",
            ]
        )
        == 0
    )
    data = json.loads((here / "out.json").read_text())
    runs = {p: [(r["episode"], r["objective"]) for r in data["runs"] if r["policy"] == p] for p in data["policies"]}
    assert runs["every:5"] == runs[target]


@pytest.mark.parametrize(
    "target, message",
    [
        ("py:nosuchmodule:X", "cannot import nosuchmodule"),
        ("py:mytriggers:Missing", "mytriggers has no Missing"),
        ("py:mytriggers:NotAPolicy", "is not a policy"),
        ("py:mytriggers:Broken", "Broken() raised RuntimeError: cannot build"),
        ("py:mytriggers:Raises", "decide raised ZeroDivisionError: my bug"),
        ("py:mytriggers:Answers", "decide must return a bool"),
        (
            "py:mytriggers:Two",  # a compute level on a task that has none: it was taken as a full solve
            "policy py:mytriggers:Two: decide must return a bool (True: recompute), or 0 or 1 (keep, a full solve) "
            "on a task without compute levels; it returned int 2",
        ),
        ("py:mytriggers", "use py:MODULE:NAME"),
    ],
)
def test_a_bad_py_target_is_one_line_exit_2_and_writes_nothing(here, target, message, capsys):
    code = main(
        ["evaluate", "--task", "cart_pendulum", "--policy", target, "--episodes", "1", "--workers", "1", "--json", "out.json"]
    )
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and message in err and "Traceback" not in err
    assert not (here / "out.json").exists()


def test_the_examples_trigger_runs_and_its_table_is_etmpc_evaluates(tmp_path):
    examples = REPO / "examples"
    script = subprocess.run(
        [sys.executable, "my_trigger.py", "--episodes", "4", "--workers", "2"],
        cwd=examples,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert script.returncode == 0, script.stderr
    cli = subprocess.run(
        [
            sys.executable,
            "-m",
            "etmpc.cli",
            "evaluate",
            "--task",
            "cart_pendulum",
            "--policy",
            "every:3",
            "--policy",
            "threshold:0.3",
            "--policy",
            "py:my_trigger:AngleOrAge",
            "--against",
            "every:3",
            "--episodes",
            "4",
            "--workers",
            "1",
        ],
        cwd=examples,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert cli.returncode == 0, cli.stderr
    rows = lambda text: [line for line in text.splitlines() if line.startswith(("every:3", "threshold:0.3", "py:"))]  # noqa: E731
    assert rows(script.stdout) == rows(cli.stdout) and len(rows(cli.stdout)) == 5
