"""The balance task's angular disturbance as options (``disturbances.angular_std_rad_s2``,
``disturbances.disturbance_scale``): the default draws and plays the stored test set's episodes as before, the
scale plays a stored episode as if its disturbances were multiplied by hand, and the standard deviation changes
the draws as it says, measured on the drawn arrays themselves."""

import dataclasses

import numpy as np
import pytest

from etmpc.cli import main
from etmpc.common.checks import BadValue
from etmpc.evaluation import testsets
from etmpc.systems import SystemKey, system_key
from etmpc.systems.cart_pendulum import TEST_SET_SEEDS
from etmpc.systems.cart_pendulum import task as balance_task

TASK = "cart_pendulum/balance"
EPISODES = 20


@pytest.fixture(scope="module")
def stored():
    return testsets.load(testsets.default_path("cart_pendulum", "balance"), "cart_pendulum", "balance")


@pytest.fixture(scope="module")
def default_draws(stored):
    return testsets.generate(SystemKey(TASK).make(), stored.meta["seed"], EPISODES)


def _played(key, episode, spec="every:3"):
    from etmpc.loop import run_episode
    from etmpc.policies import parse_policy

    system = key.make()
    return run_episode(system, system.make_env(), parse_policy(spec, system), None, episode)


def test_a_disturbance_scale_plays_the_stored_episode_with_its_disturbances_scaled_by_hand(stored):
    """Independent truth: the same episode with its disturbance array doubled (or zeroed) by hand, played
    without the option, gives the same trajectory bit for bit (times 2 and 0 are exact)."""
    base = SystemKey(TASK)
    episode = base.make().episode_from_arrays(stored.episode_arrays(0))
    assert np.any(episode.disturbance)
    unscaled = _played(base, episode)
    for scale in (2.0, 0.0):
        key = system_key(TASK, None, {"disturbances.disturbance_scale": scale})
        assert key.make().episode_parameters()["disturbance_scale"] == scale
        scaled = _played(key, episode)
        by_hand = _played(base, dataclasses.replace(episode, disturbance=episode.disturbance * scale))
        np.testing.assert_array_equal(scaled.states, by_hand.states)
        np.testing.assert_array_equal(scaled.rewards, by_hand.rewards)
        assert not np.array_equal(unscaled.states, scaled.states)  # and the option does something


def test_the_default_draws_the_stored_test_sets_episodes_and_metadata_exactly(stored, default_draws):
    arrays, meta = default_draws
    assert stored.meta["seed"] == TEST_SET_SEEDS["balance"]
    for name in ("initial_state", "disturbance"):
        expected = np.stack([stored.episode_arrays(i)[name] for i in range(EPISODES)])
        np.testing.assert_array_equal(arrays[name], expected)
    assert meta["parameters"] == stored.meta["parameters"]  # same keys, same values: no disturbance_scale at 1
    assert "disturbance_scale" not in meta["parameters"]
    system = SystemKey(TASK).make()
    stored.check_playable(system, system.world)  # within the default's ranges


def test_a_larger_std_draws_larger_disturbances_that_the_task_plays_and_redraws_alike(stored, default_draws):
    arrays, _ = default_draws
    system = system_key(TASK, None, {"disturbances.angular_std_rad_s2": "2"}).make()
    wider, meta = testsets.generate(system, stored.meta["seed"], EPISODES)
    assert meta["parameters"]["disturbance_std_rad_s2"] == 2.0
    assert np.std(wider["disturbance"]) == pytest.approx(2 * np.std(arrays["disturbance"]), rel=0.1)
    assert np.std(wider["disturbance"]) == pytest.approx(2.0, rel=0.1)  # 2000 draws: the sample std within 10 %
    np.testing.assert_array_equal(wider["initial_state"], arrays["initial_state"])  # only the disturbance changes
    for i in range(EPISODES):  # episodes the task plays, and the stored ones still are
        system.world.check_stored(system.episode_from_arrays({name: wider[name][i] for name in wider}))
    stored.check_playable(system, system.world)
    # a rollout's redrawn future: the past kept, the rest drawn with the option's std
    episode = system.episode_from_arrays(stored.episode_arrays(0))
    futures = [system.sample_future(episode, 40, np.random.default_rng(seed)) for seed in range(40)]
    np.testing.assert_array_equal(futures[0].disturbance[:40], episode.disturbance[:40])
    assert np.std([f.disturbance[40:] for f in futures]) == pytest.approx(2.0, rel=0.1)


def test_etmpc_options_lists_the_two_disturbances(capsys):
    assert main(["options", "--task", TASK]) == 0
    out = capsys.readouterr().out
    assert "  disturbances.angular_std_rad_s2 = 1.0\n" in out
    assert "  disturbances.disturbance_scale = 1.0\n" in out


@pytest.mark.parametrize("name", ["disturbances.angular_std_rad_s2", "disturbances.disturbance_scale"])
def test_a_negative_value_is_one_line_naming_the_option(capsys, name):
    field = name.split(".")[1]
    with pytest.raises(BadValue, match=rf"^option {name}: -1.0 is not a number in \[0, 100\] \("):
        system_key(TASK, None, {name: "-1"}).make()
    assert main(["options", "--task", TASK, "--option", f"{name}=-1"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("etmpc: error:") and field in err, err


def test_disturbances_refuse_what_is_not_a_finite_number_at_least_0():
    assert balance_task.Disturbances() == balance_task.Disturbances(balance_task.DISTURBANCE_STD_RAD_S2, 1.0)
    assert balance_task.Disturbances(angular_std_rad_s2=0.0, disturbance_scale=0.0).disturbance_scale == 0.0
    for bad in (-0.5, 100.5, float("inf"), float("nan")):
        with pytest.raises(BadValue, match=r"^Disturbances.angular_std_rad_s2: .* is not a number in \[0, 100\]"):
            balance_task.Disturbances(angular_std_rad_s2=bad)
        with pytest.raises(BadValue, match=r"^Disturbances.disturbance_scale: .* is not a number in \[0, 100\]"):
            balance_task.Disturbances(disturbance_scale=bad)
