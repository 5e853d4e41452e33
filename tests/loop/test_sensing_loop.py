"""The loop with a sensor: the controller, the feedback and the policy see the filter's estimate, the plant's state
is what is recorded and judged, the same episode reads the same noise, and the light loop replays it exactly."""

import copy
import dataclasses

import numpy as np
import pytest

from etmpc.loop import Snapshot, play_on, run_episode
from etmpc.evaluation import testsets
from etmpc.policies import parse_policy
from etmpc.policies.rollout import q_values
from etmpc.systems import SystemKey, system_key

NOISY = {"sensor.noise_std": "0.01,0,0.01,0", "sensor.measured": "1,0,1,0"}  # position and angle, 1 cm and 10 mrad


@pytest.fixture(scope="module")
def noisy():
    system = system_key("cart_pendulum/kicks", None, NOISY).make()
    testset = testsets.load(testsets.default_path(system.domain, system.task), system.domain, system.task)
    return system, [system.episode_from_arrays(testset.episode_arrays(i)) for i in range(3)]


class Spy:
    """A policy that keeps what it was shown, and snapshots the loop at one step."""

    simulates = True

    def __init__(self, inner, step: int = -1):
        self.inner, self.step, self.seen, self.snapshot = inner, step, [], None
        self.spec, self.stochastic = inner.spec, inner.stochastic

    def decide(self, s, rng):
        self.seen.append((s.context.step, np.array(s.x), s.belief))
        decision = self.inner.decide(s, rng)
        if s.context.step == self.step:
            self.snapshot, self.decision, self.context = Snapshot.take(s.context), decision, s.context
        return decision


def test_an_exact_sensor_hands_the_policy_the_state_itself(cart_system, cart_testset):
    kicks = SystemKey("cart_pendulum/kicks").make()
    testset = testsets.load(testsets.default_path(kicks.domain, kicks.task), kicks.domain, kicks.task)
    spy = Spy(parse_policy("every:3", kicks))
    traj = run_episode(kicks, kicks.make_env(), spy, None, kicks.episode_from_arrays(testset.episode_arrays(0)))
    assert traj.estimates is None and traj.measurements is None
    for step, x, belief in spy.seen:
        assert belief is None
        np.testing.assert_array_equal(x, traj.states[step])


def test_the_policy_sees_the_estimate_and_the_plant_state_is_recorded(noisy):
    system, episodes = noisy
    spy = Spy(parse_policy("threshold:0.3", system))
    traj = run_episode(system, system.make_env(), spy, None, episodes[0])
    n = traj.steps
    assert n == system.episode_steps
    for step, x, belief in spy.seen:
        np.testing.assert_array_equal(x, traj.estimates[step])
        np.testing.assert_array_equal(x, belief.mean)
        assert np.all(np.linalg.eigvalsh(belief.covariance) > 0)
    assert np.isnan(traj.measurements[: n + 1, [1, 3]]).all()  # the velocities are not measured
    read = traj.measurements[: n + 1, [0, 2]] - traj.states[: n + 1, [0, 2]]
    assert 0.007 < np.std(read) < 0.013  # the readings carry the noise asked for
    # the filter's angle is closer to the truth than the reading it is made from
    error = traj.estimates[: n + 1, 2] - traj.states[: n + 1, 2]
    assert np.sqrt(np.mean(error**2)) < np.sqrt(np.mean(read[:, 1] ** 2))
    # the velocities, never read, are estimated: within a fraction of their own spread
    for j in (1, 3):
        error = traj.estimates[: n + 1, j] - traj.states[: n + 1, j]
        assert np.sqrt(np.mean(error**2)) < 0.5 * np.std(traj.states[: n + 1, j])


def test_the_same_episode_reads_the_same_noise_and_another_seed_other_noise(noisy):
    system, episodes = noisy
    policy = parse_policy("every:2", system)
    first = run_episode(system, system.make_env(), policy, None, episodes[1])
    again = run_episode(system, system.make_env(), policy, None, episodes[1])
    np.testing.assert_array_equal(first.measurements, again.measurements)
    np.testing.assert_array_equal(first.states, again.states)
    other = system_key("cart_pendulum/kicks", None, NOISY | {"sensor.seed": "1"}).make()
    third = run_episode(other, other.make_env(), parse_policy("every:2", other), None, episodes[1])
    assert not np.array_equal(first.measurements[0], third.measurements[0])


@pytest.mark.parametrize("spec, step", [("every:3", 31), ("threshold:0.3", 47)])
def test_the_light_loop_continues_a_noisy_episode_bit_for_bit(noisy, spec, step):
    system, episodes = noisy
    inner = parse_policy(spec, system)
    spy = Spy(inner, step)
    original = run_episode(system, system.make_env(), spy, np.random.default_rng(3), episodes[2])
    assert spy.snapshot is not None and spy.snapshot.belief is not None
    np.testing.assert_array_equal(spy.snapshot.seen, original.estimates[step])
    twin = system.make_env()
    total = play_on(system, twin, spy.snapshot, inner, copy.deepcopy(np.random.default_rng(3)), spy.decision)
    expected = 0.0
    for reward, work in zip(original.rewards[step : original.steps], original.recompute[step : original.steps]):
        expected += reward - system.recompute_price * work
    assert total == expected
    np.testing.assert_array_equal(twin.physics.state(), original.states[original.steps])


def test_the_rollout_meter_knows_the_plant_only_through_the_filters_belief(noisy, monkeypatch):
    """Move the plant's true state and leave the filter none the wiser: the meter's returns do not change
    (its futures start from states drawn from the belief); DPI's privileged labels, from the true state, do."""
    system, episodes = noisy
    base = parse_policy("every:3", system)
    spy = Spy(base, 31)
    run_episode(system, system.make_env(), spy, None, episodes[1])
    true = spy.snapshot
    twin = system.make_env()
    twin.physics.restore(true.physics)
    moved_x = true.x + np.array([0.05, 0.2, 0.05, 0.2])
    twin.physics.set_state_vector(moved_x)
    twin.physics.forward()
    moved = dataclasses.replace(true, physics=twin.physics.snapshot(), x=moved_x)

    def returns(snapshot, from_belief):
        monkeypatch.setattr(Snapshot, "take", lambda context: snapshot)
        rng = np.random.default_rng(7)
        return q_values(spy.context, base, 3, rng, system.make_env(), 15, from_belief=from_belief)

    np.testing.assert_array_equal(returns(true, True), returns(moved, True))
    assert not np.array_equal(returns(true, False), returns(moved, False))
    assert not np.array_equal(returns(true, True), returns(true, False))


def test_a_play_resumed_at_the_plants_own_state_is_the_play_itself(noisy):
    system, episodes = noisy
    inner = parse_policy("every:3", system)
    spy = Spy(inner, 40)
    run_episode(system, system.make_env(), spy, None, episodes[0])
    snapshot = spy.snapshot
    plain = play_on(system, system.make_env(), snapshot, inner, None, True)
    started = play_on(system, system.make_env(), snapshot, inner, None, True, start=np.array(snapshot.x))
    assert started == plain
