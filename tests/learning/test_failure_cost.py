"""A failure cost in learning (DPI's ``failure_cost``): a play's return loses exactly the cost times the failures the
same continuation has in the dm_env loop's own trajectory (counted by the task's ``failures``), DPI's labels carry
it, and a task whose failures are not read off its rewards refuses it before any work."""

import copy

import numpy as np
import pytest

from etmpc.cli import main
from etmpc.learning import dpi
from etmpc.loop import play_on, run_episode
from etmpc.policies import parse_policy
from etmpc.policies.rollout import q_values
from etmpc.systems import system_key
from etmpc.systems.capabilities import RewardFailures, offers
from tests.loop.test_rollout import SnapshotAt

STORMY = system_key("cart_pendulum/kicks", None, {"disturbances.kick_scale": "3"})  # kicks strong enough to fell it


def _fallen_episode(system):
    """The first episode (drawn from seed 0, 1, ...) in which ``never`` lets the pole fall after step 25."""
    for seed in range(20):
        episode = system.draw_episode(np.random.default_rng(seed))
        spy = SnapshotAt(parse_policy("never", system), 25)
        traj = run_episode(system, system.make_env(), spy, None, episode)
        if system.failures_in_rewards(traj.rewards[25 : traj.steps]) > 0:
            return traj, spy
    raise AssertionError("no fall in 20 episodes")


def test_a_plays_return_loses_the_cost_of_each_failure_the_loop_counts():
    system = STORMY.make()
    traj, spy = _fallen_episode(system)
    twin, never = system.make_env(), parse_policy("never", system)
    plain = play_on(system, twin, spy.snapshot, never, None, spy.decision)
    costly = play_on(system, twin, spy.snapshot, never, None, spy.decision, failure_cost=7.0)
    falls = system.failures(traj, None) - system.failures(_truncated(traj, 25), None)  # the continuation's, by the loop
    assert falls >= 1 and costly == pytest.approx(plain - 7.0 * falls, rel=1e-12)


def _truncated(traj, steps):
    short = copy.copy(traj)
    short.steps = steps
    return short


@pytest.mark.parametrize("task", ["cart_pendulum/kicks", "quadrotor/waypoints", "reacher/jumps"])
def test_failures_read_off_rewards_are_the_tasks_count(task):
    system = system_key(task).make()
    assert offers(system, RewardFailures)
    episode = system.draw_episode(np.random.default_rng(4))
    traj = run_episode(system, system.make_env(), parse_policy("every:8", system), None, episode)
    assert system.failures_in_rewards(traj.rewards[: traj.steps]) == system.failures(traj, episode)


class LabelsAt:
    """``never``, and at step 25 what DPI's labels would be there, with and without a failure cost (the same futures)."""

    simulates, spec, stochastic = True, "never", False

    def __init__(self, system):
        self.twin, self.runs = system.make_env(), {}

    def decide(self, s, rng):
        if s.context.step == 25:
            never = parse_policy("never", s.context.system)
            for cost in (0.0, 5.0):
                self.runs[cost] = q_values(s.context, never, 3, np.random.default_rng(1), self.twin, 15, failure_cost=cost)
        return False


def test_dpis_labels_carry_the_cost_and_none_is_as_before():
    system = STORMY.make()
    for seed in range(20):
        spy = LabelsAt(system)
        run_episode(system, system.make_env(), spy, None, system.draw_episode(np.random.default_rng(seed)))
        falls = (spy.runs[0.0] - spy.runs[5.0]) / 5.0  # per answer and future: the falls in it, whole numbers
        assert np.allclose(falls, np.round(falls), atol=1e-9) and np.all(np.round(falls) >= 0)
        if falls.max() >= 1:
            break
    else:
        raise AssertionError("no labelling future with a fall in 20 episodes")
    assert dpi.Settings().failure_cost == 0.0
    with pytest.raises(ValueError, match="failure cost must be >= 0"):
        dpi.Settings(failure_cost=-1.0)


def test_a_task_without_reward_failures_refuses_the_cost_in_one_line(tmp_path, capsys):
    assert main(["train", "--task", "battery", "--set", "failure_cost=2", "--out", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "DPI's failure_cost needs reward failures" in err and not (tmp_path / "run").exists()
