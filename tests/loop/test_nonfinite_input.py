"""A controller that gives a non-finite input ends its episode as a plant that diverged does (counted
non-finite, excluded from the means) on every plant, in both of the loop's modes, instead of stopping the
whole evaluation (each plant refused it with a ValueError that stopped every other run too)."""

import numpy as np
import pytest

import etmpc.loop.closed as closed
from etmpc.evaluation.evaluate import evaluate
from etmpc.loop import ClosedLoop, Snapshot, play_on, run_episode
from etmpc.policies import parse_policy
from etmpc.systems import make_system

AT = 5  # the control interval whose input is NaN


@pytest.fixture
def nan_at_step(monkeypatch):
    """The loop's input at control interval AT of each episode (its 6th call in that episode) is NaN."""
    original, calls = closed._input, {"n": 0}

    def _input(system, plan, age, x):
        u, *rest = original(system, plan, age, x)
        calls["n"] += 1
        return (np.full_like(u, np.nan) if calls["n"] == AT + 1 else u), *rest

    monkeypatch.setattr(closed, "_input", _input)
    return calls


@pytest.mark.parametrize("task", ["cart_pendulum/kicks", "battery/trading", "reacher/jumps", "quadrotor/waypoints"])
def test_a_nan_input_ends_the_episode_as_non_finite_and_keeps_what_it_played(task, nan_at_step):
    system = make_system(task)
    env, twin, every = system.make_env(), system.make_env(), parse_policy("every:3", system)
    episode = system.draw_episode(np.random.default_rng(3))
    traj = run_episode(system, env, every, None, episode)
    assert traj.nonfinite and traj.steps == AT
    assert np.isfinite(traj.states[: AT + 1]).all() and np.isfinite(traj.applied[:AT]).all()

    loop = ClosedLoop(system, env).reset(episode)  # the light mode (rollouts, the oracle) from step 1 on
    loop.step(True)
    snapshot = Snapshot.take(loop.observed_state(context=True).context)
    nan_at_step["n"] = 0
    assert play_on(system, twin, snapshot, every, None, True) == -np.inf  # a failed play


def test_an_evaluation_with_such_an_episode_completes_and_counts_it(nan_at_step):
    result = evaluate("quadrotor/waypoints", ["every:7"], episodes=2, workers=1, progress=False)
    (summary,) = result.summaries
    assert summary.nonfinite_episodes == 1  # the first episode's interval AT; the second plays to its end
    assert [r.finite for r in result.runs] == [False, True]
