"""``RerunLogger``: any episode of any etmpc Gymnasium environment into a Rerun recording, read back by
``etmpc replay`` with the steps, recomputes and objective the environment reported while it was played."""

from __future__ import annotations

import json

import gymnasium as gym
import pytest

import etmpc  # noqa: F401 (registers the environments)
from etmpc.cli import main
from etmpc.common.errors import EtmpcError
from etmpc.views import RerunLogger


def play(env, test_episode: int, steps: int | None = None) -> dict:
    """Play a stored episode, recomputing every fourth step (to its end, or ``steps`` steps): what the
    environment reported of it."""
    env.reset(options={"test_episode": test_episode})
    played, recomputes, done = 0, 0, False
    while not done and (steps is None or played < steps):
        _, _, terminated, truncated, info = env.step(int(played % 4 == 0))
        played, recomputes, done = played + 1, recomputes + int(info["recompute"]), terminated or truncated
    return {"steps": played, "recomputes": recomputes, "return": env.unwrapped.core.episode_return}


def test_a_wrapped_environments_episodes_replay_with_what_the_environment_reported(tmp_path, capsys):
    path = tmp_path / "episodes.rrd"
    env = RerunLogger(gym.make("etmpc/cart_pendulum-kicks-v0"), path, policy="every fourth")
    reported = [play(env, 0), play(env, 3, steps=10)]  # the second is cut short by close
    env.close()
    assert path.is_file() and env.logged == 2
    main(["replay", str(path), "--json", str(tmp_path / "replayed.json")])
    replayed = json.loads((tmp_path / "replayed.json").read_text())["episodes"]
    assert reported[0]["steps"] == gym.spec("etmpc/cart_pendulum-kicks-v0").max_episode_steps
    assert [(e["policy"], e["episode"]) for e in replayed] == [("every fourth", 0), ("every fourth", 1)]
    for live, back in zip(reported, replayed):
        assert (back["steps"], back["recomputes"]) == (live["steps"], live["recomputes"])
        assert back["objective"] == pytest.approx(-live["return"], rel=1e-12)  # a cost: the return's opposite
    assert "every fourth" in capsys.readouterr().out


def test_rerun_logger_refuses_what_is_not_an_etmpc_environment_and_a_bad_recording(tmp_path):
    with pytest.raises(EtmpcError, match="logs an etmpc environment"):
        RerunLogger(gym.make("CartPole-v1"), tmp_path / "x.rrd")
    with pytest.raises(EtmpcError, match="a recording is a .rrd file"):
        RerunLogger(gym.make("etmpc/cart_pendulum-balance-v0"), tmp_path / "x.mp4")
