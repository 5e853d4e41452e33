"""An option that cannot change a run on the stored test set (declared ``draws``: it acts only on newly drawn episodes)
is refused in one line before any work, by every command and API function that plays the stored test set, with the
way to draw a test set where it acts; with such a drawn test set it is accepted, and it acts."""

from __future__ import annotations

import shlex

import numpy as np
import pytest

import etmpc
from etmpc.cli import main
from etmpc.cli.tasks import TAKES_OPTIONS
from etmpc.common.errors import EtmpcError
from etmpc.evaluation import evaluate as evaluate_module
from etmpc.evaluation import testsets
from etmpc.systems import names, system_class, system_key
from etmpc.systems.options import described, settable

KICKS = "cart_pendulum/kicks"
RATE = ["--option", "disturbances.kicks_per_s=3"]
# every command that takes --option and plays a test set, as a user would call it with an option of the draws
PLAYING = {
    "evaluate": ["evaluate", "--task", KICKS, "--policy", "every:3", "--episodes", "1"],
    "score": ["score", "--policy", "every:3", "--task", KICKS, "--episodes", "1"],
    "render": ["render", "--task", KICKS, "--policy", "every:3", "--out", "x.mp4"],
    "robustness": ["robustness", "--task", KICKS, "--vary", "horizon=10;12", "--policy", "every:3", "--out", "rb"],
    "bench": ["bench", "--task", KICKS, "--episodes", "1"],
    "discriminate": ["discriminate", "--task", KICKS, "--episodes", "1"],
    "figure": ["figure", "trajectory", "--task", KICKS, "--policy", "every:3"],
    "sweep": ["sweep", "--task", KICKS, "--quick"],
}
# the commands that take --option and play no stored test set: they draw episodes, or list the options
DRAWING = ("testset", "train", "options")


def _drawing_options() -> list[tuple[str, str]]:
    """(task, option) for every option the registry's tasks declare as acting on newly drawn episodes only."""
    return [
        (task, name)
        for task in names()
        for name, (declared, _) in described(system_class(task).Config()).items()
        if declared.draws
    ]


@pytest.fixture
def nothing_played(monkeypatch):
    """Any episode played, or any test set loaded, fails the test: a refusal comes before any work."""

    def played(*args, **kwargs):
        raise AssertionError("work started before the refusal")

    monkeypatch.setattr(evaluate_module, "run_jobs", played)
    monkeypatch.setattr(testsets, "load", played)


def test_every_command_that_takes_options_is_either_checked_here_or_plays_no_stored_test_set():
    assert set(TAKES_OPTIONS) == set(PLAYING) | set(DRAWING)


@pytest.mark.parametrize("command", sorted(PLAYING))
def test_every_command_refuses_an_option_of_the_draws_on_the_stored_test_set_in_one_line(
    command, tmp_path, monkeypatch, capsys, nothing_played
):
    monkeypatch.chdir(tmp_path)
    assert main([*PLAYING[command], *RATE]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("etmpc: error: option disturbances.kicks_per_s"), err
    assert f"etmpc testset --task {KICKS} --option disturbances.kicks_per_s=3.0" in err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("task, option", _drawing_options())
def test_every_declared_option_of_the_draws_is_refused_on_the_stored_test_set(task, option, nothing_played):
    value = settable(system_class(task).Config())[option]  # even its default: the stored episodes were drawn once
    with pytest.raises(EtmpcError, match=f"option {option}: it acts only on newly drawn episodes") as refused:
        etmpc.evaluate(system_key(task, None, {option: value}), ["every:3"], 1, workers=1, progress=False)
    assert f"etmpc testset --task {task}" in str(refused.value)


def test_the_python_api_refuses_it_before_any_work(nothing_played):
    with pytest.raises(EtmpcError, match="disturbances.kicks_per_s: it acts only on newly drawn episodes"):
        etmpc.score(["every:3"], [KICKS], episodes=1, workers=1, progress=False, options={"disturbances.kicks_per_s": 3})


def test_the_test_set_the_refusal_names_is_drawn_with_the_option_and_is_then_accepted(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main([*PLAYING["evaluate"], *RATE]) == 2
    err = capsys.readouterr().err
    suggested = shlex.split(err[err.index("'etmpc testset") + 1 : err.index("', then")])
    assert main([*suggested[1:], "--episodes", "2"]) == 0  # the command it names, as written (fewer episodes)
    drawn = suggested[suggested.index("--out") + 1]
    with np.load(tmp_path / drawn, allow_pickle=False) as data:
        assert '"kicks_per_s": 3.0' in str(data["meta"])  # the test set was drawn at the rate asked
    capsys.readouterr()
    assert main([*PLAYING["evaluate"], *RATE, "--test-set", drawn, "--workers", "1"]) == 0
    assert "every:3" in capsys.readouterr().out


def test_training_which_draws_its_episodes_still_takes_such_an_option():
    """The learners build their episodes' system through the worker's context (and draw new episodes from it):
    the check belongs to what plays the stored test set, not there."""
    from etmpc.evaluation.workers import context

    key = system_key(KICKS, None, {"disturbances.kicks_per_s": 3})
    system, _, _ = context(key)
    assert system.config.disturbances.kicks_per_s == 3.0


def test_the_environment_draws_its_training_episodes_with_such_an_option_and_refuses_it_on_the_stored_test_set():
    from etmpc.envs.gym import TriggerEnv

    env = TriggerEnv(KICKS, options={"disturbances.kicks_per_s": 3})
    assert env.core.system.config.disturbances.kicks_per_s == 3.0
    env.reset(seed=0)  # a training episode, drawn at the rate asked
    with pytest.raises(EtmpcError, match="disturbances.kicks_per_s: it acts only on newly drawn episodes"):
        env.reset(options={"test_episode": 0})
