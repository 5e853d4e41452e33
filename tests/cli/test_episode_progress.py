"""A single long episode says where it is on stderr (finding 6 of #75: a rollout ran a minute in silence): after
10 s of the episode, a line every 30 s with its step and the time left; a short one says nothing. The episode's
clock is made to run one second per step here, so the lines are checked against the steps the episode played."""

from __future__ import annotations

import functools
import json
import re

from etmpc.cli import main
from etmpc.common import progress
from etmpc.loop import play

ARGV = ["evaluate", "--task", "cart_pendulum/kicks", "--policy", "every:3", "--episodes", "1", "--workers", "1"]


def _one_second_per_read():
    ticks = iter(range(10**9))
    return lambda: float(next(ticks))


def test_a_long_episode_reports_its_steps_every_30_s_after_the_first_10_s(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(play, "EpisodeSteps", functools.partial(progress.EpisodeSteps, clock=_one_second_per_read()))
    assert main([*ARGV, "--json", str(tmp_path / "e.json")]) == 0
    steps = json.loads((tmp_path / "e.json").read_text())["runs"][0]["steps"]
    lines = re.findall(r"etmpc evaluate: episode 0 of every:3: step (\d+)/(\d+), (\S+) elapsed", capsys.readouterr().err)
    assert lines, "a long episode said nothing"
    done = [int(n) for n, _, _ in lines]
    assert {int(total) for _, total, _ in lines} == {steps}  # the steps the episode played
    assert done[0] == progress.FIRST_LINE_AFTER and all(b - a == progress.EVERY for a, b in zip(done, done[1:]))
    assert done[-1] < steps and len(done) == 1 + (steps - 1 - progress.FIRST_LINE_AFTER) // progress.EVERY


def test_a_short_episode_says_nothing(capsys):
    assert main(ARGV) == 0
    assert "step" not in capsys.readouterr().err
