"""GPOMDP against exact gradients of a tiny MDP, computed by enumerating every action sequence."""

import itertools

import numpy as np
import pytest

from etmpc.learning.gpomdp import VALUE_RIDGE, Learner, Settings, gradient, rewards_to_go
from etmpc.policies.learned import sigmoid

# A 4-step MDP with a scalar state; the policy decides at steps 0, 2 and 3 (step 1 is "forced":
# it recomputes whatever the policy says, like a plan that ran out).
DECIDES = (True, False, True, True)


def phi(s):
    return np.array([s, s * s, 1.0])


def step(s, recompute):
    return 0.6 * s + (0.2 if recompute else 0.9), -((s - 0.5) ** 2) - 0.1 * recompute


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


def estimates(theta, discount, baseline=None):
    """Every episode's probability and GPOMDP estimate; ``baseline(steps, feats)`` gives b at each decision."""
    for p, rewards, feats, actions, keeps, steps in enumerate_episodes(theta):
        b = None if baseline is None else baseline(steps, feats)
        yield p, gradient(feats, actions, keeps, steps, rewards_to_go(rewards, discount), b)


def expected_estimate(theta, discount, baseline=None):
    return sum(p * g for p, g in estimates(theta, discount, baseline))


def estimate_variance(theta, discount, baseline=None):
    mean = expected_estimate(theta, discount, baseline)
    return sum(p * np.sum((g - mean) ** 2) for p, g in estimates(theta, discount, baseline))


@pytest.mark.parametrize("theta", [np.array([0.0, 0.0, -3.0]), np.array([1.2, -0.7, 0.4])])
def test_undiscounted_estimate_is_the_exact_gradient(theta):
    eps = 1e-6
    fd = np.array([(expected_return(theta + eps * e) - expected_return(theta - eps * e)) / (2 * eps) for e in np.eye(3)])
    np.testing.assert_allclose(expected_estimate(theta, 1.0), fd, rtol=1e-6, atol=1e-9)
    assert np.linalg.norm(fd) > 1e-3  # the check is not trivially 0 = 0


PER_STEP = np.array([-0.4, 1.3, -0.2, 0.7])


@pytest.mark.parametrize(
    "baseline",
    [
        lambda steps, feats: PER_STEP[steps],  # "mean": a number per step index
        lambda steps, feats: feats @ np.array([0.8, -1.1, 0.3]),  # "state": linear in phi(s_t)
    ],
    ids=["per-step", "state"],
)
def test_a_baseline_does_not_change_the_expected_gradient(baseline):
    theta = np.array([0.5, 0.3, -0.2])
    np.testing.assert_allclose(expected_estimate(theta, 0.9, baseline), expected_estimate(theta, 0.9), atol=1e-12)
    assert estimate_variance(theta, 0.9, baseline) != pytest.approx(estimate_variance(theta, 0.9))  # it did act


def test_the_fitted_state_baseline_reduces_the_variance():
    """w fitted to G_t by least squares over the exact distribution of decisions, as the learner does
    over sampled ones: the estimator's exact variance drops."""
    theta, gamma = np.array([0.5, 0.3, -0.2]), 0.9
    gram, target = np.zeros((3, 3)), np.zeros(3)
    for p, rewards, feats, _, _, steps in enumerate_episodes(theta):
        gram += p * feats.T @ feats
        target += p * feats.T @ rewards_to_go(rewards, gamma)[steps]
    w = np.linalg.solve(gram, target)
    fitted = estimate_variance(theta, gamma, lambda steps, feats: feats @ w)
    assert fitted < 0.5 * estimate_variance(theta, gamma)


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
    first = learner.update(
        np.array([[1.0, 0.0, 1.0]]), np.array([0]), np.array([0.5]), np.array([0]), np.array([1.0, 0.0, 0.0, 1.0])
    )
    # no baseline yet: G_0 = 1 + 0.975^3; score (1 - 0 - 0.5) = 0.5
    np.testing.assert_allclose(first, 0.5 * (1 + 0.975**3) * np.array([1.0, 0.0, 1.0]))
    np.testing.assert_allclose(learner.theta, 0.5 * first)
    np.testing.assert_allclose(learner.baseline_mean, rewards_to_go(np.array([1.0, 0.0, 0.0, 1.0]), 0.975))
    second = learner.update(
        np.array([[1.0, 0.0, 1.0]]), np.array([0]), np.array([0.5]), np.array([0]), np.array([1.0, 0.0, 0.0, 1.0])
    )
    np.testing.assert_allclose(second, 0.0, atol=1e-15)  # the same return as the baseline: no push


def test_settings_are_checked():
    with pytest.raises(ValueError, match="baseline"):
        Settings(baseline="median")
    with pytest.raises(ValueError, match="discount"):
        Settings(discount=1.5)


def test_state_baseline_is_ridge_least_squares_over_earlier_decisions():
    rng = np.random.default_rng(3)
    learner = Learner.start(np.zeros(4), Settings(learning_rate=0.1, baseline="state"), steps=10)
    rows, targets = [], []
    for _ in range(3):
        steps = np.sort(rng.choice(10, 6, replace=False))
        feats, rewards, actions = rng.normal(size=(6, 4)), rng.normal(size=10), rng.integers(0, 2, 6)
        before = learner.value_weights()
        g = learner.update(feats, actions, np.full(6, 0.3), steps, rewards)
        returns = rewards_to_go(rewards, 0.975)
        b = feats @ before if rows else None  # the first episode has no baseline yet
        np.testing.assert_allclose(g, gradient(feats, actions, np.full(6, 0.3), steps, returns, b), rtol=1e-12)
        if rows:
            assert not np.allclose(g, gradient(feats, actions, np.full(6, 0.3), steps, returns))
        rows.append(feats)
        targets.append(returns[steps])
    # Reference: the augmented least-squares problem [Phi; sqrt(lambda) I] w = [G; 0].
    design = np.vstack(rows + [np.sqrt(VALUE_RIDGE) * np.eye(4)])
    reference = np.linalg.lstsq(design, np.concatenate(targets + [np.zeros(4)]), rcond=None)[0]
    np.testing.assert_allclose(learner.value_weights(), reference, rtol=1e-10)
