"""Self-triggering policies (``self:PATH``): the loop keeps each plan exactly as long as announced
when it was made, the fit recovers a known rule, files are checked, training is deterministic."""

from __future__ import annotations

import json
import pickle
import re

import numpy as np
import pytest

from etmpc.learning import selftrigger as self_training
from etmpc.policies import selftrigger as st
from etmpc.common.errors import EtmpcError
from etmpc.policies import parse_policy
from etmpc.evaluation.workers import play_test_episode
from etmpc.systems import SystemKey


def _constant(domain: str, n: int, p: int) -> st.SelfTrigger:
    return st.SelfTrigger.constant("c.json", domain, st.CANDIDATES, n, p)


def _features(system) -> int:
    """The number of plan features of ``system``, from its first plan on test-set episode 0."""
    played = play_test_episode(system.domain, parse_policy("always", system), 0, 0, 0)
    env = system.make_env()
    env.task.use_episode(played.episode)
    timestep = env.reset()
    plan = system.plan(system.state(timestep), np.zeros(system.u_min.shape[0]), None, 0, timestep)
    return st.plan_features(plan).size


class _Spy(st.SelfTrigger):
    """A self-trigger that notes each announcement, with the step of the plan it was made for."""

    def announce(self, plan):
        n = super().announce(plan)
        self.__dict__.setdefault("announced", []).append(n)
        return n


@pytest.mark.parametrize("domain,n", [("cart_pendulum", 4), ("battery", 3)])
def test_a_constant_announcement_is_the_periodic_schedule_bit_for_bit(
    domain, n, cart_system, cart_testset, battery_system, battery_testset
):
    """Independent truth: ``every:n``, played by the loop's own periodic policy."""
    system, testset = (cart_system, cart_testset) if domain == "cart_pendulum" else (battery_system, battery_testset)
    policy = _constant(domain, n, _features(system))
    own = play_test_episode(domain, policy, 0, 0, 1).trajectory
    periodic = play_test_episode(domain, parse_policy(f"every:{n}", system), 0, 0, 1).trajectory
    np.testing.assert_array_equal(own.recompute, periodic.recompute)
    np.testing.assert_array_equal(own.states, periodic.states)
    np.testing.assert_array_equal(own.rewards, periodic.rewards)


def test_the_loop_keeps_each_plan_exactly_as_long_as_announced(cart_system, cart_testset):
    """A policy whose announcement depends on the plan (here on the sign of the pole angle it starts
    from): the gaps between recomputes are the announcements, in order."""
    p = _features(cart_system)
    theta = np.zeros((len(st.CANDIDATES), 1 + p))
    angle = 2  # x = (position, velocity, angle, angular velocity): feature 2 is the angle
    theta[st.CANDIDATES.index(2), 1 + angle] = 1.0  # a positive angle: keep 2 steps
    theta[st.CANDIDATES.index(6), 1 + angle] = -1.0  # a negative one: keep 6
    spy = _Spy("spy.json", "cart_pendulum", st.CANDIDATES, theta, np.zeros(p), np.ones(p))
    trajectory = play_test_episode("cart_pendulum", spy, 0, 0, 2).trajectory
    steps = np.flatnonzero(trajectory.recompute[: trajectory.steps])
    gaps = np.diff(steps)
    assert set(spy.announced) == {2, 6}  # both announcements happen in this episode
    # Every plan but the last (cut short by the episode's end) is kept exactly as announced.
    np.testing.assert_array_equal(gaps, spy.announced[: len(gaps)])
    assert trajectory.steps - steps[-1] <= spy.announced[len(gaps)]
    assert not trajectory.forced[1 : trajectory.steps].any()  # no plan ran out: every recompute was announced


def test_the_fit_recovers_a_rule_the_labels_follow():
    """Labels from a known rule (the best keep length is 1, 5 or 12 by which third feature 0 falls
    in): the fitted model's choice agrees with the rule on fresh features."""
    rng = np.random.default_rng(0)
    candidates = (1, 5, 12)

    def returns(z):
        best = np.digitize(z[:, 0], [-0.5, 0.5])  # 0, 1, 2
        q = rng.normal(0.0, 0.05, (len(z), 3))
        q[np.arange(len(z)), best] += 1.0
        return q

    z = rng.normal(size=(600, 3))
    theta = self_training.fit(z, returns(z), ridge=1e-3)
    fresh = rng.normal(size=(400, 3))
    fresh = fresh[np.abs(np.abs(fresh[:, 0]) - 0.5) > 0.1]  # away from the boundaries
    chosen = np.argmax(np.c_[np.ones(len(fresh)), fresh] @ theta.T, axis=1)
    assert np.mean(chosen == np.digitize(fresh[:, 0], [-0.5, 0.5])) > 0.97
    policy = st.SelfTrigger("p", "cart_pendulum", candidates, theta, np.zeros(3), np.ones(3))
    assert policy.candidates[int(np.argmax(theta @ np.r_[1.0, 2.0, 0.0, 0.0]))] == 12


def _write(tmp_path, **change):
    p = 3
    data = _constant("cart_pendulum", 3, p).to_json()
    data.update(change)
    path = tmp_path / "p.json"
    path.write_text(json.dumps(data))
    return str(path)


@pytest.mark.parametrize(
    "change,message",
    [
        ({"format": "etmpc-logistic-policy"}, "not a self-trigger policy"),
        ({"domain": "battery"}, "is for 'battery'"),
        ({"theta": [[0.0] * 3] * 11}, "inconsistent"),
        ({"scale": [1.0, 0.0, 1.0]}, re.escape("scale[1] is 0.0, below the 1e-12 it may be")),
        ({"theta": [[1e308] * 4] * 11}, re.escape("self-trigger policy ") + ".*" + re.escape(": theta[0][0] is 1e+308, beyond")),
        ({"mean": [10**400, 0.0, 0.0]}, re.escape("mean[0] is 10000000000000000000..., not a finite number")),
        ({"candidates": [0] + list(st.CANDIDATES[1:])}, "inconsistent"),
        ({"candidates": [1, 1] + list(st.CANDIDATES[2:])}, "inconsistent"),
        ({"theta": "many"}, re.escape("theta is not a list of numbers (str)")),
    ],
)
def test_bad_files_are_one_clear_error(tmp_path, change, message):
    path = _write(tmp_path, **change)
    with pytest.raises(EtmpcError, match=message):
        parse_policy(f"self:{path}", "cart_pendulum")


def test_a_file_round_trips_and_a_policy_pickles_without_its_episode_memory(tmp_path, cart_system):
    path = _write(tmp_path)
    policy = parse_policy(f"self:{path}", cart_system)
    assert policy.spec == f"self:{path}" and policy.candidates == st.CANDIDATES
    np.testing.assert_array_equal(policy.theta, _constant("cart_pendulum", 3, 3).theta)
    policy._plan, policy._keep = object(), 7
    copy = pickle.loads(pickle.dumps(policy))
    assert copy._plan is None and copy._keep == 0


def test_a_non_finite_score_is_an_error_not_a_choice(cart_system):
    class Plan:
        states = np.zeros((3, 4))
        inputs = np.zeros((2, 1))
        forecasts = {}

    p = st.plan_features(Plan()).size
    theta = np.zeros((len(st.CANDIDATES), 1 + p))
    theta[0, 0] = np.inf
    theta[1, 0] = -np.inf
    with pytest.raises(EtmpcError, match="non-finite"):
        st.SelfTrigger("p", "cart_pendulum", st.CANDIDATES, theta, np.zeros(p), np.ones(p)).announce(Plan())


TINY = self_training.SelfSettings(
    bases=("every:3", "every:8"),
    selection_episodes=2,
    episodes=2,
    solves_per_episode=3,
    futures=1,
    horizon=2,
    ridges=(0.1,),
    validation_episodes=2,
)


def test_training_is_the_same_on_one_or_two_workers_and_never_worse_than_its_base_on_validation(tmp_path):
    one = self_training.train_self(SystemKey("cart_pendulum", 0.0005), tmp_path / "one.json", TINY, workers=1)
    two = self_training.train_self(SystemKey("cart_pendulum", 0.0005), tmp_path / "two.json", TINY, workers=2)
    np.testing.assert_array_equal(one.theta, two.theta)
    a, b = (json.loads((tmp_path / n).read_text()) for n in ("one.json", "two.json"))
    assert a["hyperparameters"] == b["hyperparameters"] and a["theta"] == b["theta"]
    hyper = a["hyperparameters"]
    assert hyper["recompute_price"] == 0.0005 and hyper["labelled_solves"] == 6
    # The base is the better of the two on the selection episodes, as their scores say.
    assert hyper["base"] == min(hyper["base_selection"], key=hyper["base_selection"].get)
    # What is kept is the best on validation, and the base itself (as a constant) was a candidate.
    validation = hyper["validation"]
    assert hyper["chosen"] == min(validation, key=validation.get)
    assert any(name.startswith("constant") for name in validation)


def test_settings_refuse_nonsense():
    with pytest.raises(EtmpcError, match="episodes"):
        self_training.SelfSettings(episodes=0)
    with pytest.raises(EtmpcError, match="ridges"):
        self_training.SelfSettings(ridges=(0.0,))
