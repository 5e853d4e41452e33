"""Evaluation: results independent of the worker count, and equal to a direct run."""

import json

import numpy as np
import pytest

from etmpc.evaluation.evaluate import evaluate
from etmpc.loop import run_episode
from etmpc.policies import parse_policy

POLICIES = ["always", "every:5", "threshold:0.3"]


@pytest.fixture(scope="module")
def serial():
    return evaluate("cart_pendulum", POLICIES, episodes=4, workers=1, progress=False)


def test_same_numbers_for_any_worker_count(serial):
    parallel = evaluate("cart_pendulum", POLICIES, episodes=4, workers=2, progress=False)
    assert json.dumps(serial.to_json(), sort_keys=True) == json.dumps(parallel.to_json(), sort_keys=True)


def test_summary_equals_a_direct_run(serial, cart_system, cart_testset):
    env = cart_system.make_env()
    for summary in serial.summaries:
        policy = parse_policy(summary.policy, cart_system.error_weights)
        objectives, recomputes = [], []
        for e in range(4):
            traj = run_episode(cart_system, env, policy, None, cart_system.episode_from_arrays(cart_testset.episode_arrays(e)))
            beta = traj.states[1:101, 2]
            objectives.append(np.sum(beta**2) + 5e-5 * traj.recomputes)
            recomputes.append(traj.recomputes)
        assert summary.objective_mean == pytest.approx(np.mean(objectives), rel=1e-12)
        assert summary.objective_std == pytest.approx(np.std(objectives, ddof=1), rel=1e-9)
        assert summary.recomputes_mean == pytest.approx(np.mean(recomputes))
        assert summary.objective_sense == "min" and summary.episodes == 4 and summary.repeats == 1


def test_json_has_the_documented_fields(serial, cart_testset):
    data = serial.to_json()
    assert data["test_set"]["sha256"] == cart_testset.sha256
    for policy in POLICIES:
        entry = data["policies"][policy]
        for key in ("objective_mean", "objective_std", "objective_sense", "control_objective_mean", "recomputes_mean",
                    "solver_failures", "episodes", "repeats", "nonfinite_episodes"):
            assert key in entry
    assert len(data["runs"]) == 3 * 4
