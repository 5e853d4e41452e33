"""The noisy variants: their base's episodes (paired), a sensor and a filter, the filter's features for learners,
and the base's learned policies playable on them."""

import numpy as np
import pytest

from etmpc.evaluation import testsets
from etmpc.loop import run_episode
from etmpc.policies import parse_policy
from etmpc.systems import make_system
from etmpc.systems.noisy import FILTER_FEATURES, filter_features

VARIANTS = {"cart_pendulum/kicks_noisy": "cart_pendulum/kicks", "quadrotor/waypoints_noisy": "quadrotor/waypoints"}


@pytest.mark.parametrize("task, base", VARIANTS.items())
def test_a_noisy_variant_plays_its_bases_episodes_through_a_filter(task, base):
    system, original = make_system(task), make_system(base)
    assert system.variant_of == base and system.estimator is not None and original.estimator is None
    mine = testsets.load(testsets.default_path(system.domain, system.task), system.domain, system.task)
    theirs = testsets.load(testsets.default_path(original.domain, original.task), original.domain, original.task)
    assert mine.episodes == theirs.episodes == 100
    for i in (0, 57, 99):  # the same episodes: scores pair with the base's episode by episode
        a, b = mine.episode_arrays(i), theirs.episode_arrays(i)
        assert a.keys() == b.keys() and all(np.array_equal(a[k], b[k]) for k in a)
    assert system.recompute_price == original.recompute_price
    assert system.exogenous_feature_names == (*original.exogenous_feature_names, *FILTER_FEATURES)


@pytest.mark.parametrize("task, base", VARIANTS.items())
def test_the_bases_learned_policy_plays_on_the_variant_and_sees_the_filter(task, base):
    system = make_system(task)
    testset = testsets.load(testsets.default_path(system.domain, system.task), system.domain, system.task)
    policy = parse_policy(f"rl:policies/{base}/learned.json", system)
    seen = []

    class Spy:
        spec, stochastic = policy.spec, policy.stochastic

        def decide(self, s, rng):
            seen.append(filter_features(s))
            return policy.decide(s, rng)

    traj = run_episode(system, system.make_env(), Spy(), None, system.episode_from_arrays(testset.episode_arrays(0)))
    assert traj.steps == system.episode_steps and np.isfinite(traj.estimates).all()
    seen = np.array(seen)
    assert (seen[:, 0] >= 0).all() and (seen[:, 1] > 0).all()  # a NIS, and the estimate's spread
    assert seen[:, 0].std() > 0  # the innovation changes with what the filter did not predict


def test_the_filter_features_are_zero_where_the_sensor_is_exact():
    class S:
        belief = None

    np.testing.assert_array_equal(filter_features(S()), [0.0, 0.0])


def test_the_estimates_spread_is_the_root_of_the_trace_and_never_nan():
    """``estimate_std`` is ``sqrt(trace P)`` for a covariance; for one a diverged filter rounded to a negative
    variance (as a tumbling quadrotor's did, at -1.48 on its roll) it is the root of the variances' sizes."""
    from etmpc.control.sensing import Belief

    nan = np.full(3, np.nan)
    a = np.random.default_rng(2).normal(size=(3, 3))
    for covariance, spread in ((a @ a.T, np.sqrt(np.trace(a @ a.T))), (np.diag([4.0, -1.5, 0.25]), np.sqrt(5.75))):

        class S:
            belief = Belief(np.zeros(3), covariance, nan, nan, 7.0)

        assert filter_features(S()).tolist() == [7.0, spread]
