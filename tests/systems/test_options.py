"""A task's options: set by name from text, checked, written one way only, carried by the system's key."""

import re

import numpy as np
import pytest

from etmpc.common.checks import BadValue
from etmpc.common.errors import EtmpcError, UnknownNameError
from etmpc.control.sensing import Sensor
from etmpc.systems import SystemKey, system_key
from etmpc.systems.options import apply, canonical, settable, split

KICKS = "cart_pendulum/kicks"


def test_every_option_of_a_task_is_listed_with_its_default_and_the_price_is_not_one():
    options = settable(SystemKey(KICKS).make().config)
    assert options["horizon"] == 20
    assert options["sensor.noise_std"] == () and options["sensor.dropout"] == 0.0
    assert options["latency.intervals"] == 0
    assert "recompute_price" not in options


def test_options_set_nested_settings_from_text_by_the_fields_types():
    config = SystemKey(KICKS).make().config
    made = apply(config, {"sensor.noise_std": "0.01, 0, 0.02,0", "sensor.measured": "yes,no,true,0", "horizon": "15"})
    assert made.sensor == Sensor(noise_std=(0.01, 0.0, 0.02, 0.0), measured=(True, False, True, False))
    assert made.horizon == 15 and config.horizon == 20  # the default left as it was
    assert apply(config, {"sensor.dropout": 0.25}).sensor.dropout == 0.25  # a value, not text, from the API


def test_two_spellings_of_the_same_options_make_the_same_key():
    a = system_key(KICKS, None, {"sensor.noise_std": "0.010,0,0.02,0", "sensor.seed": "7"})
    b = system_key(KICKS, None, [("sensor.seed", "7"), ("sensor.noise_std", "1e-2,0.0,2e-2,0.")])
    assert a == b and hash(a) == hash(b)
    assert a.options == (("sensor.noise_std", "0.01,0.0,0.02,0.0"), ("sensor.seed", "7"))
    assert str(a) == f"{KICKS} --option sensor.noise_std=0.01,0.0,0.02,0.0 --option sensor.seed=7"
    assert a != SystemKey(KICKS) and str(SystemKey(KICKS)) == KICKS


def test_a_key_with_options_makes_a_system_that_has_them():
    system = system_key(KICKS, 0.2, {"sensor.noise_std": "0.01", "sensor.measured": "1,0,1,0"}).make()
    assert system.recompute_price == 0.2
    assert system.sensor.noise_std == (0.01,) and system.estimator is not None
    assert SystemKey(KICKS).make().estimator is None  # the default: the exact state, no filter


@pytest.mark.parametrize(
    "options, error, message",
    [
        ({"sensor.nois_std": "1"}, UnknownNameError, "unknown option 'sensor.nois_std'; valid: horizon, "),
        ({"recompute_price": "1"}, UnknownNameError, "--price"),
        ({"horizon.x": "1"}, UnknownNameError, "unknown option 'horizon.x'"),
        ({"solver.sqp_options": "1"}, UnknownNameError, "'solver.sqp_options' is not an option"),
        ({"horizon": "ten"}, BadValue, "option horizon: 'ten' is not a whole number"),
        ({"sensor.dropout": "nan"}, BadValue, "not a finite number"),
        ({"sensor.dropout": "1.5"}, BadValue, "option sensor.dropout: 1.5 is not a number in [0, 1)"),
        ({"sensor.measured": "maybe"}, BadValue, "'maybe' is not true or false"),
        ({"sensor.noise_std": "0.1,0.2"}, BadValue, "has 2 values, for a plant of 4 states"),
    ],
)
def test_a_bad_option_is_one_line_naming_it(options, error, message):
    with pytest.raises(error, match=re.escape(message)):
        system_key(KICKS, None, options).make()


def test_an_option_given_twice_or_not_as_name_value_is_refused():
    with pytest.raises(EtmpcError, match="option horizon is given twice"):
        system_key(KICKS, None, [("horizon", "10"), ("horizon", "12")])
    with pytest.raises(EtmpcError, match="NAME=VALUE"):
        split("sensor.noise_std")
    assert split("sensor.noise_std=0.1=x") == ("sensor.noise_std", "0.1=x")


def test_a_task_without_a_predictor_cannot_take_a_sensor():
    from etmpc.systems.battery.system import BatterySystem

    assert "sensor.noise_std" not in settable(BatterySystem.Config())  # the battery has no sensor to set


def test_canonical_text_reads_back_to_the_same_value():
    for value in (0.1, 1e-12, 3, True, "mismatched", (0.01, 0.0), (True, False)):
        kind = type(value) if not isinstance(value, tuple) else tuple[type(value[0]), ...]
        from etmpc.systems.options import parse

        assert parse(kind, canonical(value), "x") == value


def _played(key, episode, spec="every:3"):
    from etmpc.loop import run_episode
    from etmpc.policies import parse_policy

    system = key.make()
    return run_episode(system, system.make_env(), parse_policy(spec, system), None, episode)


@pytest.mark.parametrize(
    "task, option, field",
    [("cart_pendulum/kicks", "disturbances.kick_scale", "kick"), ("quadrotor/waypoints", "disturbances.gust_scale", "gust_peak")],
)
def test_a_disturbances_scale_plays_the_stored_episode_with_its_disturbances_scaled(task, option, field):
    """Independent truth: the same episode with its disturbance arrays doubled (or zeroed) by hand, played
    without the option, gives the same trajectory bit for bit (times 2 and 0 are exact)."""
    import dataclasses

    from etmpc.evaluation import testsets

    base = SystemKey(task)
    system = base.make()
    testset = testsets.load(testsets.default_path(system.domain, system.task), system.domain, system.task)
    episode = next(
        e
        for e in (system.episode_from_arrays(testset.episode_arrays(i)) for i in range(testset.episodes))
        if np.any(getattr(e, field))
    )
    for scale in (2.0, 0.0):
        scaled = _played(system_key(task, None, {option: scale}), episode)
        by_hand = _played(base, dataclasses.replace(episode, **{field: getattr(episode, field) * scale}))
        np.testing.assert_array_equal(scaled.states, by_hand.states)
        np.testing.assert_array_equal(scaled.rewards, by_hand.rewards)
    assert not np.array_equal(_played(base, episode).states, scaled.states)  # and the option does something


def test_a_disturbances_rate_changes_the_episodes_drawn_and_the_default_draws_as_before():
    from etmpc.evaluation import testsets

    kicks = SystemKey("cart_pendulum/kicks").make()
    arrays, meta = testsets.generate(kicks, 20261126, 20)
    stored = testsets.load(testsets.default_path(kicks.domain, kicks.task), kicks.domain, kicks.task)
    np.testing.assert_array_equal(arrays["kick"][:20], np.stack([stored.episode_arrays(i)["kick"] for i in range(20)]))
    stormy = system_key("cart_pendulum/kicks", None, {"disturbances.kicks_per_s": "3"}).make()
    more, meta = testsets.generate(stormy, 20261126, 20)
    assert meta["parameters"]["kicks_per_s"] == 3.0
    assert np.count_nonzero(more["kick"]) > 5 * np.count_nonzero(arrays["kick"])
