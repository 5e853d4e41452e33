"""GPOMDP against exact gradients of a tiny MDP, computed by enumerating every action sequence."""

import itertools

import numpy as np
import pytest

from etmpc.gpomdp import Learner, Settings, gradient, rewards_to_go
from etmpc.learned import sigmoid

# A 4-step MDP with a scalar state; the policy decides at steps 0, 2 and 3 (step 1 is "forced":
# it recomputes whatever the policy says, like a plan that ran out).
DECIDES = (True, False, True, True)


def phi(s):
    return np.array([s, s * s, 1.0])


def step(s, recompute):
    return 0.6 * s + (0.2 if recompute else 0.9), -(s - 0.5) ** 2 - 0.1 * recompute


def enumerate_episodes(theta):
    """Every decision sequence with its probability, and what GPOMDP needs from it."""
    decided = [t for t in range(4) if DECIDES[t]]
    for actions in itertools.product((0, 1), repeat=len(decided)):
        s, prob, rewards, feats, keeps = 0.3, 1.0, [], [], []
        chosen = dict(zip(decided, actions))
        for t in range(4):
            a = chosen.get(t, 1)
            if DECIDES[t]:
                p_keep = sigmoid(theta @ phi(s))
                prob *= p_keep if a == 0 else 1.0 - p_keep
                feats.append(phi(s))
                keeps.append(p_keep)
            s, r = step(s, a)
            rewards.append(r)
        yield prob, np.array(rewards), np.array(feats), np.array(actions), np.array(keeps), np.array(decided)


def expected_return(theta):
    return sum(p * r.sum() for p, r, *_ in enumerate_episodes(theta))


def expected_estimate(theta, discount, baseline=None):
    total = np.zeros(3)
    for p, rewards, feats, actions, keeps, steps in enumerate_episodes(theta):
        total += p * gradient(feats, actions, keeps, steps, rewards_to_go(rewards, discount), baseline)
    return total


@pytest.mark.parametrize("theta", [np.array([0.0, 0.0, -3.0]), np.array([1.2, -0.7, 0.4])])
def test_undiscounted_estimate_is_the_exact_gradient(theta):
    eps = 1e-6
    fd = np.array([(expected_return(theta + eps * e) - expected_return(theta - eps * e)) / (2 * eps) for e in np.eye(3)])
    np.testing.assert_allclose(expected_estimate(theta, 1.0), fd, rtol=1e-6, atol=1e-9)
    assert np.linalg.norm(fd) > 1e-3  # the check is not trivially 0 = 0


def test_a_baseline_does_not_change_the_expected_gradient():
    theta = np.array([0.5, 0.3, -0.2])
    baseline = np.array([-0.4, 1.3, -0.2, 0.7])
    np.testing.assert_allclose(expected_estimate(theta, 0.9, baseline), expected_estimate(theta, 0.9), atol=1e-12)


def test_reordered_sum_equals_baxter_bartletts_eligibility_trace():
    rng = np.random.default_rng(0)
    T, steps = 30, np.array(sorted(rng.choice(30, 18, replace=False)))
    feats, actions, keeps = rng.normal(size=(18, 5)), rng.integers(0, 2, 18), rng.uniform(0.05, 0.95, 18)
    rewards, gamma = rng.normal(size=T), 0.975
    z, trace_estimate, decision = np.zeros(5), np.zeros(5), dict(zip(steps, range(18)))
    for t in range(T):
        z = gamma * z
        if t in decision:
            d = decision[t]
            z = z + ((1 - actions[d]) - keeps[d]) * feats[d]
        trace_estimate += rewards[t] * z
    np.testing.assert_allclose(gradient(feats, actions, keeps, steps, rewards_to_go(rewards, gamma)), trace_estimate, rtol=1e-12)


def test_learner_ascends_and_keeps_a_running_mean_baseline():
    learner = Learner.start(np.zeros(3), Settings(learning_rate=0.5, baseline="mean"), steps=4)
    first = learner.update(np.array([[1.0, 0.0, 1.0]]), np.array([0]), np.array([0.5]), np.array([0]), np.array([1.0, 0.0, 0.0, 1.0]))
    # no baseline yet: G_0 = 1 + 0.975^3; score (1 - 0 - 0.5) = 0.5
    np.testing.assert_allclose(first, 0.5 * (1 + 0.975**3) * np.array([1.0, 0.0, 1.0]))
    np.testing.assert_allclose(learner.theta, 0.5 * first)
    np.testing.assert_allclose(learner.baseline_mean, rewards_to_go(np.array([1.0, 0.0, 0.0, 1.0]), 0.975))
    second = learner.update(np.array([[1.0, 0.0, 1.0]]), np.array([0]), np.array([0.5]), np.array([0]), np.array([1.0, 0.0, 0.0, 1.0]))
    np.testing.assert_allclose(second, 0.0, atol=1e-15)  # the same return as the baseline: no push


def test_settings_are_checked():
    with pytest.raises(ValueError, match="baseline"):
        Settings(baseline="median")
    with pytest.raises(ValueError, match="discount"):
        Settings(discount=1.5)
