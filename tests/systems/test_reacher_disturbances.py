"""The reacher's target jumps as options (``disturbances.jumps_per_s``, ``disturbances.target_radius_m``): the default
draws the stored test set's episodes bit for bit, and each option changes the draws as it says, counted on the drawn
arrays themselves."""

import numpy as np
import pytest

from etmpc.cli import main
from etmpc.common.checks import BadValue
from etmpc.evaluation import testsets
from etmpc.systems import SystemKey, system_key
from etmpc.systems.reacher import TEST_SET_SEEDS
from etmpc.systems.reacher import task as reacher_task
from etmpc.systems.reacher.physics import load_model

TASK = "reacher/jumps"
EPISODES = 20


def _jumps(target: np.ndarray) -> int:
    """How many times the target changes from one interval to the next, over a (episodes, steps, 2) array."""
    return int(np.count_nonzero(np.any(target[:, 1:] != target[:, :-1], axis=-1)))


@pytest.fixture(scope="module")
def default_draws():
    system = SystemKey(TASK).make()
    return testsets.generate(system, TEST_SET_SEEDS["jumps"], EPISODES)


def test_the_default_draws_the_stored_test_sets_episodes_and_metadata_exactly(default_draws):
    arrays, meta = default_draws
    stored = testsets.load(testsets.default_path("reacher", "jumps"), "reacher", "jumps")
    assert stored.meta["seed"] == TEST_SET_SEEDS["jumps"]
    for name in ("initial_state", "target"):
        expected = np.stack([stored.episode_arrays(i)[name] for i in range(EPISODES)])
        np.testing.assert_array_equal(arrays[name], expected)
    assert meta["parameters"] == stored.meta["parameters"]  # same keys, same values


def test_more_jumps_per_second_draw_many_more_jumps_and_the_metadata_says_so(default_draws):
    arrays, _ = default_draws
    system = system_key(TASK, None, {"disturbances.jumps_per_s": "2"}).make()
    more, meta = testsets.generate(system, TEST_SET_SEEDS["jumps"], EPISODES)
    assert meta["parameters"]["jump_probability"] == pytest.approx(0.2)
    # 20 episodes of 99 chances: about 79 jumps at 0.04 an interval, about 396 at 0.2
    assert _jumps(more["target"]) > 3 * _jumps(arrays["target"]) > 0
    assert abs(_jumps(more["target"]) / (EPISODES * 99) - 0.2) < 0.05
    for i in range(EPISODES):  # and they are episodes the task plays
        system.world.check_stored(system.episode_from_arrays({name: more[name][i] for name in more}))


def test_a_radius_range_draws_targets_within_it_and_the_rollouts_future_too(default_draws):
    system = system_key(TASK, None, {"disturbances.target_radius_m": "0.5,0.6"}).make()
    arrays, meta = testsets.generate(system, TEST_SET_SEEDS["jumps"], EPISODES)
    assert meta["parameters"]["target_radius_m"] == [0.5, 0.6]
    radius = np.hypot(arrays["target"][..., 0], arrays["target"][..., 1])
    assert radius.min() >= 0.5 - 1e-12 and radius.max() <= 0.6 + 1e-12
    assert radius.max() - radius.min() > 0.05  # spread over the range, not one radius
    default_radius = np.hypot(default_draws[0]["target"][..., 0], default_draws[0]["target"][..., 1])
    assert default_radius.min() < 0.5 or default_radius.max() > 0.6  # the default draws outside it
    # a rollout's redrawn future keeps to the options too (at 10 jumps per second: a new target every interval)
    both = system_key(TASK, None, {"disturbances.target_radius_m": "0.5,0.6", "disturbances.jumps_per_s": "10"}).make()
    episode = system.episode_from_arrays({name: arrays[name][0] for name in arrays})
    future = both.sample_future(episode, 10, np.random.default_rng(0))
    np.testing.assert_array_equal(future.target[:11], episode.target[:11])
    assert _jumps(future.target[None, 10:]) == 89
    assert np.all(np.abs(np.hypot(*future.target.T) - 0.55) <= 0.05 + 1e-12)
    stored = testsets.load(testsets.default_path("reacher", "jumps"), "reacher", "jumps")
    stored.check_playable(system, system.world)  # the stored test set is still one this task plays
    wide = system_key(TASK, None, {"disturbances.target_radius_m": "0.9,1"}).make()
    drawn, _ = testsets.generate(wide, TEST_SET_SEEDS["jumps"], 5)
    assert np.abs(drawn["target"]).max() > reacher_task.TARGET_RADIUS_M[1]
    for i in range(5):  # targets beyond the default's 0.95 m, accepted by the task with the option
        wide.world.check_stored(wide.episode_from_arrays({name: drawn[name][i] for name in drawn}))


def test_the_arms_reach_bounds_the_radius_and_the_plants_arm_reaches_as_far():
    root = load_model()
    forearm = np.linalg.norm(root.find("body", "forearm").pos)
    fingertip = np.linalg.norm(root.find("site", "fingertip").pos)
    assert forearm + fingertip == pytest.approx(reacher_task.REACH_M) and reacher_task.REACH_M == 1.0
    assert reacher_task.Disturbances(target_radius_m=(0.0, 1.0)).target_radius_m == (0.0, 1.0)  # the reach itself


def test_etmpc_options_lists_the_two_disturbances(capsys):
    assert main(["options", "--task", TASK]) == 0
    out = capsys.readouterr().out
    assert "  disturbances.jumps_per_s = 0.4\n" in out
    assert "  disturbances.target_radius_m = 0.3,0.95\n" in out
    assert main(["options", "--task", "reacher/jumps_late", "--option", "disturbances.jumps_per_s=1"]) == 0
    assert "  disturbances.jumps_per_s = 1.0   (as set)\n" in capsys.readouterr().out


@pytest.mark.parametrize(
    "option, value, message",
    [
        ("disturbances.jumps_per_s", "11", "option disturbances.jumps_per_s: 11.0 is not a number in [0, 10]"),
        ("disturbances.jumps_per_s", "-0.1", "option disturbances.jumps_per_s: -0.1 is not a number in [0, 10]"),
        ("disturbances.target_radius_m", "0.5,1.2", "target_radius_m: (0.5, 1.2) is not a pair (low, high), low <= high, each"),
        ("disturbances.target_radius_m", "0.6,0.5", "target_radius_m: (0.6, 0.5) is not a pair (low, high), low <= high"),
        ("disturbances.target_radius_m", "-0.1,0.5", "target_radius_m: (-0.1, 0.5) is not a pair (low, high), low <= high"),
        ("disturbances.target_radius_m", "0.5", "target_radius_m: (0.5,) has 1 values; it is a pair (low, high)"),
        ("disturbances.target_radius_m", "0.3,inf", "not a finite number"),
    ],
)
def test_a_bad_value_is_one_line_naming_the_option(capsys, option, value, message):
    with pytest.raises(BadValue, match=message.replace("(", r"\(").replace(")", r"\)").replace("[", r"\[").replace(".", r"\.")):
        system_key(TASK, None, {option: value}).make()
    assert main(["options", "--task", TASK, "--option", f"{option}={value}"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("etmpc: error:") and message in err, err
