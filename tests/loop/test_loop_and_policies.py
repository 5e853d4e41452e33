"""Algorithm 1 with the fixed policies: recompute counts, the LQR path and policy parsing."""

import math
import time
from types import SimpleNamespace

import numpy as np
import pytest

from etmpc.common.errors import EtmpcError, UnknownNameError
from etmpc.loop import run_episode
from etmpc.policies import AugmentedState, parse_policy


@pytest.fixture(scope="module")
def episode(cart_system, cart_testset):
    return cart_system.episode_from_arrays(cart_testset.episode_arrays(2))


@pytest.fixture(scope="module")
def env(cart_system):
    return cart_system.make_env()


@pytest.mark.parametrize(
    "spec, expected",
    [("always", 100), ("never", 5), ("every:1", 100), ("every:3", 34), ("every:7", 15), ("every:20", 5), ("every:50", 5)],
)
def test_recompute_counts(cart_system, env, episode, spec, expected):
    traj = run_episode(cart_system, env, parse_policy(spec, cart_system), None, episode)
    assert traj.recomputes == expected
    period = {"always": 1, "never": 20}.get(spec) or int(spec.split(":")[1])
    assert traj.plan_age.max() == min(period, 20) - 1  # inputs applied at ages 0 .. T-1


def test_every_one_equals_always(cart_system, env, episode):
    a = run_episode(cart_system, env, parse_policy("always", cart_system), None, episode)
    b = run_episode(cart_system, env, parse_policy("every:1", cart_system), None, episode)
    np.testing.assert_array_equal(a.states, b.states)


class _Waits:
    """A trigger that keeps the plan after waiting 2 ms at each decision: asleep (wall time, no CPU) or
    spinning (2 ms of its thread's CPU)."""

    stochastic = False

    def __init__(self, spin: bool):
        self.spec, self.spin = ("spins" if spin else "sleeps"), spin

    def decide(self, s, rng):
        if self.spin:
            end = time.thread_time() + 0.002
            while time.thread_time() < end:
                pass
        else:
            time.sleep(0.002)
        return False


def test_the_loop_times_the_controllers_cpu_not_the_wall_clock(cart_system, env, episode):
    """A row's CPU column counts what the controller computed: a trigger that sleeps costs nothing, one that
    spins costs its spinning, whatever else shares the machine."""
    sleeps, spins = (run_episode(cart_system, env, _Waits(spin), None, episode) for spin in (False, True))
    asked = int((~sleeps.forced[: sleeps.steps]).sum())
    assert asked == 95  # every step but the 5 where the plan ran out
    assert sleeps.cpu_seconds()["decide"] < 0.1 * asked * 0.002  # the wall clock would count >= 190 ms
    assert spins.cpu_seconds()["decide"] >= asked * 0.002
    assert np.all(spins.decide_time_s[: spins.steps][~spins.forced[: spins.steps]] >= 0.002)


def test_applied_input_is_plan_plus_lqr_clipped(cart_system, env, episode):
    traj = run_episode(cart_system, env, parse_policy("never", cart_system), None, episode)
    expected = np.clip(traj.planned + traj.correction, -25, 25)
    np.testing.assert_array_equal(traj.applied, expected)
    kept = traj.plan_age > 0
    K = cart_system.feedback.gain
    np.testing.assert_allclose(traj.correction[kept, 0], -(traj.states[:100][kept] - traj.predicted[kept]) @ K[0])
    assert np.all(traj.correction[~kept] == 0)


def test_objective_is_the_sum_of_costs(cart_system, env, episode):
    traj = run_episode(cart_system, env, parse_policy("every:4", cart_system), None, episode)
    beta = traj.states[1:101, 2]
    assert -traj.policy_return(5e-5) == pytest.approx(np.sum(beta**2) + 5e-5 * 25, rel=1e-12)


def test_threshold_extremes(cart_system, env, episode):
    never = run_episode(cart_system, env, parse_policy("never", cart_system), None, episode)
    high = run_episode(cart_system, env, parse_policy("threshold:1e9", cart_system), None, episode)
    zero = run_episode(cart_system, env, parse_policy("threshold:0", cart_system), None, episode)
    np.testing.assert_array_equal(high.states, never.states)
    assert zero.recomputes == 100  # the disturbance always leaves some error
    mid = run_episode(cart_system, env, parse_policy("threshold:0.3", cart_system), None, episode)
    assert never.recomputes < mid.recomputes < 100


def test_threshold_uses_the_weighted_error_norm():
    weighted = SimpleNamespace(
        error_weights=np.array([0, 1, math.sqrt(10), math.sqrt(10)]), name="cart_pendulum", episode_steps=100
    )
    policy = parse_policy("threshold:1", weighted)
    s = lambda dx: AugmentedState(np.array(dx, float), np.zeros(4), 1, np.zeros(4))  # noqa: E731
    rng = np.random.default_rng(0)
    assert not policy.decide(s([100, 0, 0, 0]), rng)  # cart position has weight 0
    assert not policy.decide(s([0, 0.99, 0, 0]), rng)
    assert policy.decide(s([0, 0, 0.32, 0]), rng)  # sqrt(10) * 0.32 > 1


@pytest.mark.parametrize(
    "spec, error",
    [
        ("every:0", EtmpcError),
        ("every:-2", EtmpcError),
        ("every:x", EtmpcError),
        ("every:1.5", EtmpcError),
        ("threshold:-0.1", EtmpcError),
        ("threshold:nan", EtmpcError),
        ("threshold:inf", EtmpcError),
        ("threshold:", EtmpcError),
        ("always:3", EtmpcError),
        ("sometimes", UnknownNameError),
        ("rl:/nope.json", EtmpcError),
    ],
)
def test_bad_specs(spec, error):
    with pytest.raises(error):
        parse_policy(spec, "cart_pendulum")


def test_parse_policy_takes_the_system_or_its_name_and_the_old_form_warns(cart_system):
    shipped = "rl:policies/cart_pendulum/kicks/learned.json"
    # the task's name, as a figure script gives it: a kicks policy is the kicks task's, not the domain's
    assert parse_policy(shipped, "cart_pendulum/kicks").spec == "rl:cart_pendulum/kicks"  # a shipped policy, by its name
    with pytest.raises(EtmpcError, match="cart_pendulum/kicks"):
        parse_policy(shipped, cart_system)  # balance: a policy made for another task is refused
    assert parse_policy("every:3", cart_system).period == 3
    with pytest.warns(DeprecationWarning, match=r"parse_policy\(spec, system\)"):
        old = parse_policy("threshold:0.5", cart_system.error_weights, cart_system.name, cart_system.episode_steps)
    np.testing.assert_array_equal(old.weights, parse_policy("threshold:0.5", cart_system).weights)
