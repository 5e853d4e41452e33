"""The trigger problem as an environment (etmpc.envs): the same loop as evaluate, bit for bit; gymnasium's
own checker; deterministic resets; clear errors; vectorised environments."""

import re

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import etmpc  # noqa: F401  (registers the environments)
from etmpc.envs.registration import env_id, register
from etmpc.common.errors import EtmpcError
from etmpc.envs.gym import TriggerEnv
from etmpc.envs.trigger import TriggerEnvironment
from etmpc.evaluation.evaluate import evaluate
from etmpc.evaluation.workers import play_test_episode
from etmpc.policies import parse_policy
from etmpc.systems import make_system, names

TASKS = list(names())


def test_every_task_is_registered_under_its_gymnasium_id():
    ids = register()
    assert ids == [env_id(t) for t in TASKS] and "etmpc/cart_pendulum-balance-v0" in ids
    assert all(i in gym.registry for i in ids)


@pytest.mark.parametrize("task", TASKS)
def test_gymnasiums_checker_passes(task):
    check_env(gym.make(env_id(task)).unwrapped, skip_render_check=True)


def _play(env: gym.Env, rule, test_episode: int):
    """Play a test-set episode through the gymnasium environment; ``rule(age) -> 0 or 1`` (keep or a full
    solve: the last action, 2, on a task with compute levels). ``recompute`` is each step's priced work;
    ``failures`` the episode's failures so far as ``info`` gives them, at the reset and after each step."""
    obs, info = env.reset(options={"test_episode": test_episode})
    rewards, control, recompute, forced, failures = [], [], [], [], [info["failures"]]
    solve = env.action_space.n - 1
    while True:
        obs, reward, terminated, truncated, info = env.step(solve * rule(env.unwrapped.core.loop.age))
        rewards.append(reward)
        control.append(info["control_reward"])
        recompute.append(info.get("work", info["recompute"]))
        forced.append(info["forced"])
        failures.append(info["failures"])
        if terminated or truncated:
            assert truncated and not terminated
            return np.array(rewards), np.array(control), np.array(recompute), np.array(forced), failures


RULES = {"always": lambda age: 1, "every:3": lambda age: int(age >= 3), "never": lambda age: 0}


@pytest.mark.parametrize("task", TASKS)
@pytest.mark.parametrize("spec", ["always", "every:3", "never"])
def test_an_agent_answering_like_a_fixed_policy_gets_what_evaluate_reports_bit_for_bit(task, spec):
    env = gym.make(env_id(task))
    system = make_system(task)
    episodes = [0, 7]
    result = evaluate(task, [spec], episodes=max(episodes) + 1, workers=1, progress=False).to_json()
    objectives = {r["episode"]: r["objective"] for r in result["runs"]}
    counted = {r["episode"]: r["failures"] for r in result["runs"]}  # every task counts its failures
    for e in episodes:
        rewards, control, recompute, forced, failures = _play(env, RULES[spec], e)
        played = play_test_episode(system.name, parse_policy(spec, system), 0, 0, e).trajectory
        # The loop is the same: the same rewards, computations and forced steps, to the last bit.
        np.testing.assert_array_equal(control, played.rewards[: played.steps])
        np.testing.assert_array_equal(recompute, played.work[: played.steps])
        np.testing.assert_array_equal(forced, played.forced[: played.steps])
        np.testing.assert_array_equal(rewards, control - system.recompute_price * recompute)
        # And the objective evaluate reports is these rewards' sum, as evaluate sums them.
        total = control.sum() - system.recompute_price * recompute.sum()
        assert (total if system.objective_sense == "max" else -total) == objectives[e]
        # info's failures so far: ints, 0 at the reset, never decreasing, and at the end what evaluate counts.
        assert all(type(f) is int for f in failures) and failures[0] == 0 and failures == sorted(failures)
        assert failures[-1] == counted[e]


def test_info_carries_the_failures_so_far_step_by_step():
    """On the balance task, counted by hand from the pole's angle after each step: beyond 0.1 rad, but for the
    recovery from the initial tilt (test episode 34, each plan kept as long as it lasts, tips the pole)."""
    env = TriggerEnvironment("cart_pendulum")
    timestep = env.reset(test_episode=34)
    shown, by_hand, settled = [env.info["failures"]], [0], False
    while not timestep.last():
        timestep = env.step(0)
        beta, k = abs(env.loop.x[2]), env.loop.step_index - 1
        by_hand.append(by_hand[-1] + (beta > 0.1 and (settled or k >= 10)))
        settled = settled or beta <= 0.1
        shown.append(env.info["failures"])
    assert shown == by_hand and shown[-1] > 0


@pytest.mark.parametrize("task", TASKS)
def test_a_reward_against_a_baseline_is_the_agents_reward_minus_the_baselines_on_the_same_episode(task):
    # The baseline's rewards are those evaluate's loop gives the baseline on the same test-set episode,
    # step for step and to the last bit; the agent's own stay as they were.
    system = make_system(task)
    env = TriggerEnv(task, reward_baseline="every:4")
    rewards, control, recompute, _, _ = _play(env, RULES["every:3"], 2)
    baseline = play_test_episode(system.name, parse_policy("every:4", system), 0, 0, 2).trajectory
    own = play_test_episode(system.name, parse_policy("every:3", system), 0, 0, 2).trajectory
    np.testing.assert_array_equal(control, own.rewards[: own.steps])
    paid = baseline.rewards[: baseline.steps] - system.recompute_price * baseline.work[: baseline.steps]
    np.testing.assert_array_equal(rewards, (control - system.recompute_price * recompute) - paid)
    # Its return is still the task's own, and both simulations are counted.
    assert env.unwrapped.core.episode_return == own.policy_return(system.recompute_price)
    assert env.unwrapped.core.simulated_steps == own.steps + baseline.steps


@pytest.mark.parametrize(
    "bad, error",
    [("threshold:0.1", ValueError), ("every:0", ValueError), ("rl:x.json", ValueError), ("bogus", ValueError), (3, TypeError)],
)
def test_a_reward_baseline_must_be_a_fixed_schedule(bad, error):
    """A bad argument to the API is an EtmpcError (one line on the command line) and the error Python's own
    would be: a ValueError for a bad value, a TypeError for a wrong type."""
    with pytest.raises(EtmpcError, match="reward_baseline: a fixed schedule") as raised:
        gym.make("etmpc/cart_pendulum-balance-v0", reward_baseline=bad)
    assert isinstance(raised.value, error)


def test_reset_with_a_seed_replays_the_same_episode_and_other_seeds_differ():
    env = gym.make("etmpc/battery-trading-v1")
    first = [env.reset(seed=3)[0]] + [env.step(0)[0] for _ in range(5)]
    again = [env.reset(seed=3)[0]] + [env.step(0)[0] for _ in range(5)]
    other = [env.reset(seed=4)[0]] + [env.step(0)[0] for _ in range(5)]
    np.testing.assert_array_equal(np.array(first), np.array(again))
    assert not np.array_equal(np.array(first), np.array(other))
    assert first[0].dtype == np.float32 and not first[0].any()  # before the first plan: zeros


def test_the_observation_is_the_error_features_and_their_squares():
    env = gym.make("etmpc/cart_pendulum-balance-v0").unwrapped
    env.reset(options={"test_episode": 0})
    for _ in range(4):
        obs, *_ = env.step(0)
    loop = env.core.loop
    error = loop.x - loop.plan.state_at(loop.age)
    expected = np.concatenate([error, [loop.age]])
    np.testing.assert_array_equal(obs, np.concatenate([expected, expected**2]).astype(np.float32))
    assert env.observation_names[:5] == (
        "error_cart_position",
        "error_cart_velocity",
        "error_pole_angle",
        "error_pole_angular_velocity",
        "plan_age",
    )
    battery = gym.make("etmpc/battery-trading-v1").unwrapped
    assert "price_error_eur_kwh" in battery.observation_names and len(battery.observation_names) == 2 * (1 + 1 + 10)


BAD_ACTIONS = [
    2,
    -1,
    0.5,
    "1",
    [0, 1],
    [1],
    (1,),
    None,
    np.float64(1.0),
    np.array([1]),
    np.array([[0]]),
    np.array(1.0),
    np.bool_(True),
    np.array(True),
    b"\x01",
]
GOOD_ACTIONS = [0, 1, True, False, np.int64(1), np.uint8(0), np.int32(1), np.array(0), np.array(1, dtype=np.int8)]


@pytest.mark.parametrize("action", BAD_ACTIONS, ids=repr)
def test_an_action_outside_the_space_is_a_clear_value_error(action):
    env = gym.make("etmpc/cart_pendulum-balance-v0").unwrapped
    env.reset(seed=0)
    with pytest.raises(ValueError, match="0 .keep the plan. or 1 .recompute."):
        env.step(action)
    assert not env.action_space.contains(action)  # exactly what the space holds: gymnasium's own answer agrees
    assert env.core.loop.step_index == 0  # nothing was played


def test_every_form_the_action_space_holds_is_taken_as_its_integer():
    env = gym.make("etmpc/cart_pendulum-balance-v0").unwrapped
    env.reset(options={"test_episode": 0})
    for action in GOOD_ACTIONS:
        assert env.action_space.contains(action)
        *_, info = env.step(action)
        assert info["recompute"] == (int(action) == 1 or info["forced"])


@pytest.mark.parametrize("index", [1.5, 2.0, True, "3", np.float64(1.0), [1], None])
def test_a_test_episode_must_be_an_integer_index(index):
    env = gym.make("etmpc/battery-trading-v1").unwrapped
    if index is None:  # None means: draw a training episode
        env.reset(options={"test_episode": index})
        return
    with pytest.raises(ValueError, match="test_episode must be an integer index"):
        env.reset(options={"test_episode": index})
    obs, _ = env.reset(options={"test_episode": np.int16(3)})  # a numpy integer is an index
    again, _ = env.reset(options={"test_episode": 3})
    np.testing.assert_array_equal(obs, again)


def test_an_environment_cannot_be_pickled_and_says_what_to_do_instead():
    import copy
    import pickle

    for env in (gym.make("etmpc/battery-trading-v1"), TriggerEnvironment("battery")):
        with pytest.raises(TypeError, match=r"cannot be pickled .*gymnasium.make\('etmpc/battery-trading-v1'\)"):
            pickle.dumps(env)
        with pytest.raises(TypeError, match="cannot be pickled"):
            copy.deepcopy(env)


def test_unknown_reset_options_and_bad_test_episodes_are_refused():
    env = gym.make("etmpc/cart_pendulum-balance-v0").unwrapped
    with pytest.raises(ValueError, match="unknown reset options"):
        env.reset(options={"episode": 3})
    for options in ("test_episode", [("test_episode", 3)], 3):
        with pytest.raises(ValueError, match="reset options are a dict"):
            env.reset(options=options)
    with pytest.raises(EtmpcError, match="unknown reset options"):  # a ValueError, and one line on the command line
        env.reset(options={"episode": 3})
    from etmpc.common.errors import TestSetError

    with pytest.raises(TestSetError, match="out of range"):
        env.reset(options={"test_episode": 1000})


def test_a_test_set_holding_what_its_task_cannot_draw_is_refused_when_the_environment_reads_it(tmp_path):
    from etmpc.common.errors import TestSetError
    from etmpc.evaluation import testsets

    stored = testsets.load(testsets.default_path("cart_pendulum", "balance"), "cart_pendulum", "balance")
    arrays = {name: np.array(values[:2]) for name, values in stored.arrays.items()}
    arrays["disturbance"][1, 7] = 1e6
    path = tmp_path / "mine.npz"
    testsets.write(path, arrays, dict(stored.meta, episodes=2))
    env = TriggerEnvironment("cart_pendulum", test_set=str(path))
    with pytest.raises(TestSetError, match=re.escape("episode 1: disturbance: 1000000.0 at [7] is outside the task's range")):
        env.reset(test_episode=0)  # any episode: the whole set is checked when first read


def test_a_dm_env_environment_underneath():
    env = TriggerEnvironment("battery", seed=0)
    timestep = env.reset()
    assert timestep.first() and env.observation_spec().shape == timestep.observation.shape
    steps = 0
    while not timestep.last():
        timestep = env.step(1)
        steps += 1
    assert steps == 100 and timestep.discount == 1.0  # a time limit, not a failure


def test_vectorised_environments_work():
    envs = gym.vector.AsyncVectorEnv([lambda: gym.make("etmpc/cart_pendulum-balance-v0")] * 2)
    try:
        obs, info = envs.reset(seed=[0, 1])
        assert obs.shape == (2, 10) and obs.dtype == np.float32
        for _ in range(5):
            obs, reward, terminated, truncated, info = envs.step(np.array([1, 0]))
        assert reward.shape == (2,) and np.all(np.isfinite(reward)) and not terminated.any()
        assert info["recompute"][0] and np.all(info["forced"] == [False, False])
    finally:
        envs.close()


@pytest.mark.parametrize(
    "kwargs, says, error",
    [
        ({"task": 3}, "task: a task name", TypeError),
        ({"task": "cartpole"}, "unknown task 'cartpole'", KeyError),
        ({"recompute_price": -1.0}, "recompute_price: a price of a recompute is a finite number >= 0", ValueError),
        ({"recompute_price": "0.1"}, "recompute_price: '0.1' is not a number", ValueError),
        ({"seed": -1}, "seed: a seed is a whole number", ValueError),
        ({"seed": 1.5}, "seed: 1.5 is not a whole number", ValueError),
        ({"test_set": 3}, "test_set: a file path is needed", TypeError),
        ({"reward_baseline": "always:3"}, "reward_baseline: a fixed schedule", ValueError),
    ],
)
def test_a_bad_argument_to_an_environment_is_one_clear_error(kwargs, says, error):
    """Both an EtmpcError (one line on the command line) and the error Python's own would be."""
    from etmpc.common.errors import EtmpcError

    with pytest.raises(EtmpcError, match=re.escape(says)) as raised:
        TriggerEnvironment(**({"task": "battery"} | kwargs))
    assert isinstance(raised.value, error)


def test_an_older_version_of_a_tasks_id_points_at_the_current_one():
    """The battery's observation grew (0b5a03e): its environment is version 1, and gymnasium answers the old
    id with the new one, in one line."""
    from gymnasium.error import DeprecatedEnv

    assert env_id("battery") == "etmpc/battery-trading-v1" and env_id("cart_pendulum") == "etmpc/cart_pendulum-balance-v0"
    with pytest.raises(DeprecatedEnv, match="Please use `etmpc/battery-trading-v1` instead"):
        gym.make("etmpc/battery-trading-v0")
