"""GPOMDP against exact gradients of a tiny MDP, computed by enumerating every action sequence."""

import itertools
import json

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


def test_the_advantage_scale_divides_the_step_by_the_earlier_advantages_rms():
    """Reference by hand: the first update's unit is its own advantages' RMS, each later one's the RMS of every earlier
    episode's advantages; the estimate is the paper's divided by it. A positive number fixed before the episode is
    drawn: in expectation the exact gradient (the enumerated tiny MDP's, by finite differences) over that number."""
    theta, gamma = np.array([0.4, -0.3, 0.2]), 0.9
    episodes = list(enumerate_episodes(theta))
    scaled = Learner.start(theta, Settings(discount=gamma, learning_rate=0.1, scale="advantage"), steps=4)
    seen: list[float] = []
    for _, rewards, feats, actions, keeps, steps in episodes[:5]:
        advantages = rewards_to_go(rewards, gamma)[steps]
        unit = np.sqrt(np.mean(np.square(seen if seen else advantages)))
        before = scaled.theta
        g = scaled.update(feats, actions, keeps, steps, rewards)
        paper = gradient(feats, actions, keeps, steps, rewards_to_go(rewards, gamma))
        np.testing.assert_allclose(g, paper / unit, rtol=1e-12)
        np.testing.assert_allclose(scaled.theta, before + 0.1 * paper / unit, rtol=1e-12)
        seen += list(advantages)
    assert scaled.advantage_count == len(seen)
    np.testing.assert_allclose(scaled.advantage_square_sum, np.sum(np.square(seen)), rtol=1e-12)
    # Once the unit is fixed (after the first episode), the expected estimate is the exact gradient over it.
    unit = np.sqrt(scaled.advantage_square_sum / scaled.advantage_count)
    expected = np.zeros(3)
    for p, rewards, feats, actions, keeps, steps in episodes:
        learner = Learner(
            theta.copy(),
            Settings(discount=1.0, scale="advantage"),
            np.zeros(4),
            1,
            None,
            None,
            scaled.advantage_count,
            scaled.advantage_square_sum,
        )
        expected += p * learner.update(feats, actions, keeps, steps, rewards)
    eps = 1e-6
    fd = np.array([(expected_return(theta + eps * e) - expected_return(theta - eps * e)) / (2 * eps) for e in np.eye(3)])
    np.testing.assert_allclose(expected, fd / unit, rtol=1e-6, atol=1e-9)


def test_the_scale_is_checked_and_the_paper_step_is_the_default():
    with pytest.raises(ValueError, match="scale"):
        Settings(scale="gradient")
    assert Settings().scale == "none"


# theta after 3 training episodes of battery/trading (seed 7), paper features, normalisation from 2 episodes, default
# settings and the state baseline: computed with etmpc.learning.jobs.train_block at commit 49d8583, before the scale.
BEFORE_THE_SCALE = {
    "none": [
        0.05543609686666476,
        0.08817074840596947,
        -0.056239933733519556,
        0.03567173191173148,
        0.09409736655487644,
        -0.0393363070696306,
        -2.901868770148478,
    ],
    "state": [
        0.05501192278067983,
        0.06639919886813099,
        -0.003989777349858725,
        0.056828626477036556,
        0.07710594440117458,
        -0.0068097653610420805,
        -2.9754061704276134,
    ],
}


@pytest.mark.parametrize("baseline", sorted(BEFORE_THE_SCALE))
def test_the_default_settings_train_the_same_parameters_as_before_the_scale(baseline):
    from etmpc.learning.jobs import _learner_to_json, normalisation_states, train_block
    from etmpc.policies.learned import LogisticPolicy, Normalisation

    task = "battery/trading"
    normalisation = Normalisation.fit(np.concatenate([normalisation_states(task, i, "paper") for i in range(2)]))
    policy = LogisticPolicy.initial(normalisation, task, {}, "paper")
    learner = Learner.start(policy.theta, Settings(baseline=baseline), 100)
    trained, _ = train_block(task, policy.to_json(), _learner_to_json(learner), 7, 0, 3)
    np.testing.assert_allclose(trained["theta"], BEFORE_THE_SCALE[baseline], rtol=1e-12, atol=1e-15)
    assert "advantage_count" not in trained  # the paper's runs keep what they kept


def test_a_scaled_learner_resumes_from_its_json_as_if_never_stopped():
    from etmpc.learning.jobs import _learner_from_json, _learner_to_json

    rng = np.random.default_rng(5)
    batches = [
        (
            rng.normal(size=(6, 3)),
            rng.integers(0, 2, 6),
            np.full(6, 0.4),
            np.sort(rng.choice(8, 6, replace=False)),
            rng.normal(size=8),
        )
        for _ in range(4)
    ]
    straight = Learner.start(np.zeros(3), Settings(scale="advantage", baseline="state"), steps=8)
    stopped = Learner.start(np.zeros(3), Settings(scale="advantage", baseline="state"), steps=8)
    for k, batch in enumerate(batches):
        straight.update(*batch)
        if k == 2:
            stopped = _learner_from_json(json.loads(json.dumps(_learner_to_json(stopped))))
        stopped.update(*batch)
    assert stopped.advantage_count == straight.advantage_count == 24
    np.testing.assert_array_equal(stopped.theta, straight.theta)
