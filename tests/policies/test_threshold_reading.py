"""``threshold:X:reading``: the classic output-error trigger, on the sensor's latest readings instead of the filter's
estimate: it fires exactly where the weighted error of the entries read exceeds X (the norm written out here), and
on a task whose sensor is exact (the state is read whole) it is ``threshold:X``, decision for decision."""

import numpy as np
import pytest

from etmpc.common.errors import EtmpcError
from etmpc.control.sensing import Belief
from etmpc.control.timing import ITERATE, KEEP
from etmpc.loop import run_episode
from etmpc.policies import AugmentedState, parse_policy
from etmpc.systems import make_system


def test_it_fires_exactly_where_the_error_of_the_entries_read_exceeds_the_threshold():
    system = make_system("cart_pendulum/kicks_noisy")
    read = np.array([True, False, True, False])  # the cart's position and the pole's angle
    policy = parse_policy("threshold:0.2:reading", system)
    assert policy.spec == "threshold:0.2:reading"
    rng, fired_seen = np.random.default_rng(5), set()
    for _ in range(300):
        estimate, predicted, y = (rng.normal(scale=0.2, size=4) for _ in range(3))
        reading = np.where(read, y, np.nan)
        belief = Belief(estimate, np.eye(4), reading - np.where(read, estimate, np.nan), reading)
        s = AugmentedState(estimate, np.zeros(4), 2, predicted, belief=belief)
        fired = np.sqrt(np.sum((system.error_weights[read] * (y[read] - predicted[read])) ** 2)) > 0.2
        assert policy.decide(s, None) == fired
        fired_seen.add(fired)
    assert fired_seen == {True, False}


def test_with_nothing_read_this_step_it_keeps():
    system = make_system("cart_pendulum/kicks_noisy")
    nothing = np.full(4, np.nan)
    s = AugmentedState(np.ones(4), np.zeros(4), 3, np.zeros(4), belief=Belief(np.ones(4), np.eye(4), nothing, nothing))
    assert parse_policy("threshold:0:reading", system).decide(s, None) is False  # a dropped reading is no evidence


@pytest.mark.parametrize(
    ("task", "spec"), [("cart_pendulum/kicks", "threshold:0.2"), ("cart_pendulum/kicks_levels", "threshold:0.1:iterate")]
)
def test_on_an_exact_sensor_it_is_the_plain_threshold(task, spec):
    system = make_system(task)
    episode = system.draw_episode(np.random.default_rng(2))
    plain = run_episode(system, system.make_env(), parse_policy(spec, system), None, episode)
    reading = run_episode(system, system.make_env(), parse_policy(spec + ":reading", system), None, episode)
    assert reading.steps == plain.steps and reading.recomputes == plain.recomputes > 0
    assert np.array_equal(reading.states, plain.states) and np.array_equal(reading.rewards, plain.rewards)


def test_it_answers_an_iteration_with_levels():
    system = make_system("cart_pendulum/kicks_levels")
    policy = parse_policy("threshold:0.2:iterate:reading", system)
    assert policy.spec == "threshold:0.2:iterate:reading"
    x = np.array([0.0, 0.0, 1.0, 0.0])
    assert policy.decide(AugmentedState(x, x, 1, np.zeros(4)), None) == ITERATE
    assert policy.decide(AugmentedState(x, x, 1, x), None) == KEEP


@pytest.mark.parametrize("spec", ["threshold:0.2:reading:iterate", "threshold:0.2:estimate", "threshold:0.2:reading:reading"])
def test_bad_orders_and_words_are_one_line(spec):
    with pytest.raises(EtmpcError, match="may follow"):
        parse_policy(spec, make_system("cart_pendulum/kicks_levels"))
