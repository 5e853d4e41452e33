"""The command line against files that are not what they seem: an output that lands on an input, a path that
is no regular file, and an argument refused only after the work it should have prevented.

Every case is refused as :mod:`tests.end_to_end.test_hostile`'s are (exit code 2, one line naming the problem,
no traceback, every file byte-identical, none new), and besides:

* before any work: nothing is played (the functions that play episodes, verify a card or train fail the test
  if called), so a check made only after playing fails here;
* without hanging: a command that opens a FIFO waits for a writer that never comes; an alarm ends the case.
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
from pathlib import Path

import pytest

from etmpc.cli import main
from tests.end_to_end.test_hostile import CART_POLICY, EV, _assert_one_line, _files, _setup, refused_in_one_line

MARKERS = "<!-- leaderboard:begin -->\n| a table |\n<!-- leaderboard:end -->\n"
LEADERBOARD = ["score", "--leaderboard", "--task", "battery", "--out", "lb"]
ROBUSTNESS = ["robustness", "--task", "cart_pendulum", "--episodes", "1", "--workers", "1"]
SMALL_TRAINING = ["--episodes", "2", "--eval-every", "2", "--eval-episodes", "1", "--seeds", "0", "--workers", "1"]


def _fifo(path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    os.mkfifo(path)


def _outputs_setup(kind: str, d: Path) -> None:
    """The files of a case: its own kinds here, the others :func:`tests.end_to_end.test_hostile._setup`'s."""
    if kind == "readme-in-out":  # a README with the leaderboard's markers, under the name the page is written to
        (d / "lb").mkdir()
        (d / "lb" / "leaderboard.md").write_text(f"# mine\n\n{MARKERS}")
    elif kind == "card-in-out":
        (d / "lb").mkdir()
        (d / "lb" / "leaderboard.json").write_text('{"mine": true}\n')
    elif kind == "policy-in-out":  # a user's policy saved under the name a robustness curve writes
        (d / "rob").mkdir()
        (d / "rob" / "robustness.json").write_bytes(CART_POLICY.read_bytes())
    elif kind == "settings-in-run":  # DPI's settings, kept in the run directory under a name the run writes
        (d / "run").mkdir()
        (d / "run" / "selected.json").write_text("{}\n")
    elif kind == "fifos":
        for name in ("fifo.md", "fifo.json", "fifo.yml", "fifo.rrd", "fifo.npz"):
            _fifo(d / name)
    elif kind == "sweep-settings-fifo":
        _fifo(d / "run" / "battery" / "trading" / "settings.json")
    elif kind == "reproduce-settings-fifo":
        _fifo(d / "run" / "settings.json")
    elif kind == "kept-row-fifo":
        _fifo(d / "results" / "leaderboard" / "always" / "battery" / "trading.json")
    else:
        _setup(kind, d)


CASES = [  # (id, setup, argv, what the one line must name)
    # an output on an input: a file a command writes inside its --out DIR is checked against what it reads
    ("leaderboard-page-on-its-readme", "readme-in-out", [*LEADERBOARD, "--readme", "lb/leaderboard.md"], "lb/leaderboard.md"),
    ("leaderboard-json-on-its-card", "card-in-out", [*LEADERBOARD, "--card", "lb/leaderboard.json"], "lb/leaderboard.json"),
    (
        "robustness-curve-on-its-policy",
        "policy-in-out",
        [*ROBUSTNESS, "--vary", "horizon=20;10", "--policy", "rl:rob/robustness.json", "--out", "rob"],
        "rob/robustness.json",
    ),
    (
        "train-run-on-its-settings",
        "settings-in-run",
        ["train", "--task", "battery", "--out", "run", "--settings", "run/selected.json", *SMALL_TRAINING],
        "run/selected.json",
    ),
    # a path that exists but is no regular file: refused before it is opened
    ("leaderboard-readme-a-fifo", "fifos", [*LEADERBOARD, "--readme", "fifo.md"], "fifo.md (--readme) is a FIFO"),
    ("leaderboard-readme-a-device", "none", [*LEADERBOARD, "--readme", "/dev/null"], "(--readme) is a character device"),
    ("leaderboard-card-a-fifo", "fifos", [*LEADERBOARD, "--card", "fifo.json"], "(--card fifo.json) is a FIFO"),
    ("leaderboard-kept-row-a-fifo", "kept-row-fifo", LEADERBOARD, "trading.json, a FIFO"),
    ("evaluate-policy-a-fifo", "fifos", [*EV, "--policy", "rl:fifo.json"], "fifo.json (policy rl:fifo.json) is a FIFO"),
    ("evaluate-test-set-a-fifo", "fifos", [*EV, "--policy", "always", "--test-set", "fifo.npz"], "fifo.npz (test set) is a FIFO"),
    ("evaluate-test-set-a-device", "none", [*EV, "--policy", "always", "--test-set", "/dev/null"], "a character device"),
    (
        "evaluate-json-a-fifo",
        "fifos",
        [*EV, "--policy", "always", "--episodes", "1", "--workers", "1", "--json", "fifo.json"],
        "--json fifo.json is a FIFO",
    ),
    ("train-settings-a-fifo", "fifos", ["train", "--task", "battery", "--out", "run", "--settings", "fifo.yml"], "fifo.yml"),
    ("verify-card-a-fifo", "fifos", ["verify", "fifo.json"], "fifo.json"),
    ("figure-evaluation-a-fifo", "fifos", ["figure", "bars", "fifo.json", "--out", "x.png"], "fifo.json"),
    ("replay-recording-a-fifo", "fifos", ["replay", "fifo.rrd"], "fifo.rrd (recording) is a FIFO"),
    ("sweep-settings-a-fifo", "sweep-settings-fifo", ["sweep", "--task", "battery", "--out", "run", "--quick"], "settings.json"),
    (
        "reproduce-settings-a-fifo",
        "reproduce-settings-fifo",
        ["reproduce", "--quick", "--task", "battery", "--out", "run"],
        "settings.json, a FIFO",
    ),
    (
        "robustness-out-a-fifo",
        "fifos",
        [*ROBUSTNESS, "--vary", "horizon=20;10", "--policy", "every:3", "--out", "fifo.md"],
        "--out fifo.md is a FIFO",
    ),
    # an argument refused only after the work it should have prevented
    (
        "robustness-out-an-existing-file",
        "file-parent",
        [*ROBUSTNESS, "--vary", "horizon=20;10", "--policy", "every:3", "--out", "afile"],
        "--out afile is not a directory",
    ),
    (
        "robustness-into-a-user-directory",
        "user-dir",
        [*ROBUSTNESS, "--vary", "horizon=20;10", "--policy", "every:3", "--out", "run"],
        "notes.txt",
    ),
    (
        "robustness-second-value-fails-when-made",
        "none",
        [*ROBUSTNESS, "--vary", "solver.block=4;50", "--policy", "every:3", "--out", "rob"],
        "solver.block=50",
    ),
    (  # a card of this suite scored on one task and 4 episodes: refused before any card is verified
        "leaderboard-card-of-other-tasks",
        "hostile-cards",
        [*LEADERBOARD, "--card", "as_it_is.json"],
        "as_it_is.json scores battery/trading on 4 episodes",
    ),
]


class _Hung(BaseException):
    """The command still ran when the case's alarm rang: it waits on a FIFO."""


@contextlib.contextmanager
def _within(seconds: int):
    """Raise :class:`_Hung` in the block if it lasts ``seconds`` (a blocked ``open`` of a FIFO included)."""

    def ring(signum, frame):
        raise _Hung(f"still running after {seconds} s")

    previous = signal.signal(signal.SIGALRM, ring)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)


@pytest.fixture
def nothing_played(monkeypatch):
    """Every function that plays episodes, verifies a card or trains fails the test if called."""
    from etmpc.evaluation import evaluate
    from etmpc.experiments import leaderboard, leaderboard_rows, robustness
    from etmpc.learning import runner

    def played(*args, **kwargs):
        pytest.fail("work was done before the command refused its arguments")

    for module, name in [
        (evaluate, "evaluate"),
        (robustness, "evaluate"),
        (leaderboard_rows, "play_and_score"),
        (leaderboard_rows, "best_threshold"),
        (leaderboard, "verify"),
        (runner, "run"),
    ]:
        monkeypatch.setattr(module, name, played)


@pytest.mark.parametrize("setup, argv, names", [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_a_file_that_is_not_what_it_seems_is_refused_before_any_work(
    setup, argv, names, tmp_path, monkeypatch, capsys, nothing_played
):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "dont_write_bytecode", True)
    _outputs_setup(setup, tmp_path)
    refused_in_one_line(argv, names, tmp_path, capsys, _within(60))


def test_robustness_writes_into_an_empty_directory_and_over_its_own_curve(tmp_path, monkeypatch, capsys):
    """``--out DIR`` is a directory: an existing empty one is taken, and so is one that holds only an earlier
    curve's files (replaced), as a rerun leaves it."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "rob").mkdir()
    argv = ["robustness", "--task", "cart_pendulum/kicks", "--vary", "disturbances.kick_scale=0.5;2"]
    argv += ["--policy", "every:3", "--episodes", "1", "--workers", "1", "--out", "rob"]
    assert main(argv) == 0, capsys.readouterr().err
    first = _files(tmp_path / "rob")
    assert sorted(first) == ["ROBUSTNESS.md", "robustness.json", "robustness.png"]
    assert main(argv) == 0, capsys.readouterr().err
    assert sorted(_files(tmp_path / "rob")) == sorted(first)
    assert (tmp_path / "rob" / "ROBUSTNESS.md").read_bytes() == first["ROBUSTNESS.md"]


def test_bench_checks_every_tasks_episodes_before_timing_the_first(tmp_path, monkeypatch, capsys):
    from etmpc.common.errors import EtmpcError
    from etmpc.evaluation import bench

    checked = []

    def benched(key, episodes):
        checked.append(str(key))
        if len(checked) == 2:
            raise EtmpcError(f"--episodes {episodes}: the {key} test set has 3 episodes")

    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(bench, "benched", benched)
    monkeypatch.setattr(bench, "run_bench", lambda *a, **k: pytest.fail("a task was timed"))
    assert main(["bench", "--task", "battery", "--task", "cart_pendulum", "--episodes", "5", "--no-reference"]) == 2
    _assert_one_line(capsys.readouterr().err, "cart_pendulum/balance test set has 3 episodes")
    assert checked == ["battery/trading", "cart_pendulum/balance"]
