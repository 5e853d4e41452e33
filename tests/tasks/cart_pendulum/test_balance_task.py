"""The cart pendulum's balance task as a dm-control environment: suite registration, specs, episode length,
seeding and stored episodes; and its failures, counted by hand from the pole's angles."""

from types import SimpleNamespace

import numpy as np
import pytest
from dm_control.rl import control

from etmpc import suite
from etmpc.evaluation.workers import play_test_episode
from etmpc.policies import parse_policy
from etmpc.systems import cart_pendulum
from etmpc.systems.cart_pendulum import task as cp_env
from etmpc.common.errors import UnknownNameError


def test_suite_returns_a_dm_control_environment():
    env = suite.load("cart_pendulum", "balance", task_kwargs={"random": 0})
    assert isinstance(env, control.Environment)
    assert env.control_timestep() == pytest.approx(0.1)
    assert env.physics.timestep() == pytest.approx(0.025)
    assert "balance" in cart_pendulum.SUITE.tagged("benchmarking")


def test_unknown_names_list_the_valid_ones():
    with pytest.raises(UnknownNameError, match="valid: cart_pendulum, battery"):
        suite.load("cartpole", "balance")
    with pytest.raises(UnknownNameError, match="valid: balance"):
        suite.load("cart_pendulum", "swingup")
    with pytest.raises(UnknownNameError, match="valid: mismatched, matched"):
        suite.load("cart_pendulum", "balance", task_kwargs={"plant": "ideal"})


def test_specs_match_what_it_returns_over_a_whole_episode():
    env = suite.load("cart_pendulum", "balance", task_kwargs={"random": 1})
    obs_spec, action_spec = env.observation_spec(), env.action_spec()
    assert list(obs_spec) == ["cart_position", "cart_velocity", "pole_angle", "pole_angular_velocity"]
    assert action_spec.shape == (1,) and action_spec.minimum[0] == -25 and action_spec.maximum[0] == 25
    timestep, steps = env.reset(), 0
    while not timestep.last():
        for name, spec in obs_spec.items():
            spec.validate(timestep.observation[name])
        timestep = env.step(action_spec.generate_value())
        steps += 1
        env.reward_spec().validate(np.asarray(timestep.reward))
        assert timestep.reward == pytest.approx(-(env.physics.pole_angle() ** 2))
    assert steps == cp_env.EPISODE_STEPS


def test_action_spec_bounds_the_force():
    env = suite.load("cart_pendulum", "balance", task_kwargs={"random": 0})
    env.reset()
    env.step([1e3])  # MuJoCo clamps to ctrlrange
    assert env.physics.data.actuator_force[0] == pytest.approx(25.0)


def _observations(env, steps=30):
    timestep = env.reset()
    rows = [list(timestep.observation.values())]
    for _ in range(steps):
        rows.append(list(env.step([0.5]).observation.values()))
    return np.array(rows)


def test_same_seed_same_episodes_different_seed_differs():
    a = suite.load("cart_pendulum", "balance", task_kwargs={"random": 7})
    b = suite.load("cart_pendulum", "balance", task_kwargs={"random": 7})
    c = suite.load("cart_pendulum", "balance", task_kwargs={"random": 8})
    for _ in range(2):  # successive episodes too
        obs_a = _observations(a)
        np.testing.assert_array_equal(obs_a, _observations(b))
        assert not np.array_equal(obs_a, _observations(c))


def test_stored_episode_replays_exactly(cart_testset, cart_system):
    episode = cart_system.episode_from_arrays(cart_testset.episode_arrays(3))
    env_a = cp_env.make_environment(random=1)
    env_b = cp_env.make_environment(random=2)
    env_a.task.use_episode(episode)
    env_b.task.use_episode(episode)
    obs_a, obs_b = _observations(env_a), _observations(env_b)
    np.testing.assert_array_equal(obs_a, obs_b)
    np.testing.assert_array_equal(obs_a[0], episode.initial_state)
    np.testing.assert_array_equal(env_a.task.episode.disturbance, episode.disturbance)


def test_initial_states_follow_the_spec(cart_testset):
    x0 = cart_testset.arrays["initial_state"]
    assert x0.shape == (100, 4) and np.all(x0[:, 0] == 0)
    assert np.all(np.abs(x0[:, 1]) <= 1) and np.all(np.abs(x0[:, 2]) <= 0.78) and np.all(np.abs(x0[:, 3]) <= 1)
    w = cart_testset.arrays["disturbance"]
    assert w.shape == (100, 100)
    assert abs(w.mean()) < 0.05 and abs(w.std() - 1.0) < 0.05  # N(0, 1), 10^4 draws


def test_non_finite_state_terminates():
    env = suite.load("cart_pendulum", "balance", task_kwargs={"random": 0})
    env.reset()
    env.physics.data.qvel[0] = np.nan
    assert env.task.get_termination(env.physics) == 0.0


# -- failures: steps off balance ---------------------------------------------------------------------------
def _off_balance_by_hand(angles) -> list[int]:
    """The failures so far after each step, from the pole's angle at each step's end: beyond 0.1 rad, but for
    the recovery from the initial tilt (the steps before the first within 0.1 rad, among the first ten)."""
    counts, count, settled = [], 0, False
    for k, beta in enumerate(angles):
        if abs(beta) <= 0.1:
            settled = True
        elif settled or k >= 10:
            count += 1
        counts.append(count)
    return counts


def _counted(system, angles) -> int:
    rewards = -(np.asarray(angles, dtype=float) ** 2)  # the task's reward: -beta^2 of the state a step leads to
    return system.failures(SimpleNamespace(rewards=np.append(rewards, np.nan), steps=len(rewards)), None)


@pytest.mark.parametrize(
    "angles",
    [
        [0.5, 0.3, 0.05, 0.2, 0.0, -0.12],  # the recovery's steps (0, 1) are not counted; steps 3 and 5 are
        [0.7] * 12,  # never within: from step 10 on every step counts
        [0.05, 0.5, 0.5],  # within at once: the recovery is over
        [],
    ],
)
def test_off_balance_steps_follow_the_rule(cart_system, angles):
    assert cart_system.failure_name == "off balance"
    by_hand = _off_balance_by_hand(angles)
    assert [_counted(cart_system, angles[: k + 1]) for k in range(len(angles))] == by_hand  # never decreasing
    assert _counted(cart_system, angles) == (by_hand[-1] if angles else 0)


@pytest.mark.parametrize("spec", ["always", "every:10", "never"])
def test_a_played_episodes_failures_are_its_pole_angles_counted_by_hand(cart_system, spec):
    played = play_test_episode("cart_pendulum", parse_policy(spec, cart_system), 0, 0, 34)  # a test episode a kept plan tips
    traj = played.trajectory
    by_hand = _off_balance_by_hand(traj.states[1 : traj.steps + 1, 2])
    assert cart_system.failures(traj, played.episode) == by_hand[-1]
    if spec == "never":  # a plan kept N steps lets the pole out; re-planning every step does not
        assert by_hand[-1] > 0
    if spec == "always":
        assert by_hand[-1] == 0
