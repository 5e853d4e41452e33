"""dm-control parity: our tasks load, seed, limit, flatten, validate and render as the suite's do.

The independent truth here is dm-control itself: ``dm_env.test_utils.EnvironmentTestMixin`` (the
dm_env contract), ``dm_control.suite`` (names, ``load``'s signature, what an unknown name raises)
and MuJoCo's own clamping of a limited actuator.
"""

import inspect
import math

import numpy as np
import pytest
from absl.testing import absltest
from dm_control import suite as dm_suite
from dm_env import test_utils

from etmpc import suite
from etmpc.systems import domains, make_system
from etmpc.systems.battery import task as battery_env
from etmpc.systems.cart_pendulum import task as cp_env

# A time limit of a few control intervals per task (from the task's own interval), so that episodes end in the tests.
STEPS = {task: 5 for task in suite.ALL_TASKS}
SHORT = {(d, t): 5 * make_system(f"{d}/{t}").control_interval_s for d, t in suite.ALL_TASKS}


class _ContractTest(test_utils.EnvironmentTestMixin):
    """dm_env's contract, with an action sequence long enough to cross two episode ends."""

    domain: str
    task: str

    def make_object_under_test(self):
        kwargs = {"random": 0, "time_limit": SHORT[self.domain, self.task]}
        return suite.load(self.domain, self.task, task_kwargs=kwargs)

    def make_action_sequence(self):
        spec, rng = self.environment.action_spec(), np.random.default_rng(1)
        for _ in range(2 * STEPS[self.domain, self.task] + 3):
            yield rng.uniform(spec.minimum, spec.maximum)


# dm_env's contract for every task of the suite: a test class per (domain, task).
for _domain, _task in suite.ALL_TASKS:
    _name = "".join(part.title() for part in f"{_domain}_{_task}".split("_")) + "ContractTest"
    globals()[_name] = type(_name, (_ContractTest, absltest.TestCase), {"domain": _domain, "task": _task})


def test_suite_containers_list_every_task_as_dm_control_suite_does():
    assert suite.ALL_TASKS == tuple((d, t) for d, package in domains().items() for t in package.TASKS)  # the registry's
    built_in = {
        "cart_pendulum": ("balance", "kicks", "kicks_late", "kicks_levels", "kicks_noisy"),
        "battery": ("trading",),
        "reacher": ("jumps", "jumps_late"),
        "quadrotor": ("waypoints", "waypoints_noisy"),
    }
    assert suite.TASKS_BY_DOMAIN.items() >= built_in.items()
    assert set(suite.BENCHMARKING) == set(suite.ALL_TASKS)
    # The same container types as the suite's.
    assert isinstance(suite.ALL_TASKS, type(dm_suite.ALL_TASKS)) and isinstance(suite.ALL_TASKS[0], tuple)
    assert isinstance(suite.TASKS_BY_DOMAIN, dict)


def test_load_takes_the_suites_arguments_with_the_same_names():
    ours = list(inspect.signature(suite.load).parameters)
    theirs = list(inspect.signature(dm_suite.load).parameters)
    assert ours == theirs


@pytest.mark.parametrize("domain, task", [("cartpole_x", "balance"), ("cart_pendulum", "swingup")])
def test_unknown_names_raise_what_the_suite_raises(domain, task):
    with pytest.raises(ValueError):
        dm_suite.load("cartpole_x", "balance")  # the suite's own behaviour, for reference
    with pytest.raises(ValueError, match="valid:"):
        suite.load(domain, task)


@pytest.mark.parametrize("domain, task", suite.ALL_TASKS)
def test_random_takes_a_seed_a_random_state_or_a_generator(domain, task):
    def first_observation(random):
        timestep = suite.load(domain, task, task_kwargs={"random": random}).reset()
        return np.concatenate([np.ravel(v) for v in timestep.observation.values()])

    same_seed = first_observation(7), first_observation(7)
    np.testing.assert_array_equal(*same_seed)
    same_state = first_observation(np.random.RandomState(7)), first_observation(np.random.RandomState(7))
    np.testing.assert_array_equal(*same_state)
    assert not np.array_equal(first_observation(np.random.RandomState(8)), same_state[0])
    generator = np.random.default_rng(7)
    env = suite.load(domain, task, task_kwargs={"random": generator})
    assert env.task.random is generator  # used as given: the caller owns the stream
    np.testing.assert_array_equal(first_observation(np.random.default_rng(7)), same_seed[0])
    for wrong in (1.5, "7", True):
        with pytest.raises(TypeError, match="random must be"):
            suite.load(domain, task, task_kwargs={"random": wrong})
    with pytest.raises(ValueError, match="non-negative"):
        suite.load(domain, task, task_kwargs={"random": -1})


@pytest.mark.parametrize("domain, task", suite.ALL_TASKS)
def test_time_limit_sets_the_number_of_steps(domain, task):
    env = suite.load(domain, task, task_kwargs={"random": 3, "time_limit": 2 * SHORT[domain, task]})
    timestep, steps = env.reset(), 0
    action = np.zeros(env.action_spec().shape)
    while not timestep.last():
        timestep, steps = env.step(action), steps + 1
    assert steps == 2 * STEPS[domain, task]
    interval = env.control_timestep()
    for bad in (0.5 * interval, 2.5 * interval, 0.0, -interval, math.inf, math.nan):
        with pytest.raises(ValueError, match="whole number"):
            suite.load(domain, task, task_kwargs={"time_limit": bad})
    with pytest.raises(ValueError, match="task_kwargs"):
        suite.load(domain, task, environment_kwargs={"time_limit": 1.0})
    with pytest.raises(ValueError, match="control_timestep"):
        suite.load(domain, task, environment_kwargs={"control_timestep": 2 * interval})


@pytest.mark.parametrize("domain, task", suite.ALL_TASKS)
def test_a_flat_observation_is_the_observation_concatenated(domain, task):
    nested = suite.load(domain, task, task_kwargs={"random": 4})
    flat = suite.load(domain, task, task_kwargs={"random": 4}, environment_kwargs={"flat_observation": True})
    expected = np.concatenate([np.ravel(v) for v in nested.reset().observation.values()])
    (observation,) = flat.reset().observation.values()
    np.testing.assert_array_equal(observation, expected)
    size = sum(int(np.prod(spec.shape)) for spec in nested.observation_spec().values())
    assert flat.observation_spec()["observations"].shape == (size,)
    flat.observation_spec()["observations"].validate(observation)


def test_visualize_reward_colours_the_pole_by_how_upright_it_is():
    plain = suite.load("cart_pendulum", "balance", task_kwargs={"random": 0})
    own = plain.physics.named.model.mat_rgba["pole"].copy()
    plain.reset()
    plain.step([0.0])
    np.testing.assert_array_equal(plain.physics.named.model.mat_rgba["pole"], own)

    env = suite.load("cart_pendulum", "balance", task_kwargs={"random": 0}, visualize_reward=True)
    assert env.task.visualize_reward is True
    env.reset()
    env.physics.set_state_vector(np.array([0.0, 0.0, 0.0, 0.0]))
    env.physics.set_disturbance(0.0)
    env.task.after_step(env.physics)  # upright: the pole's own colour
    np.testing.assert_allclose(env.physics.named.model.mat_rgba["pole"], own)
    env.physics.set_state_vector(np.array([0.0, 0.0, 3.0, 0.0]))  # fallen: red, by exp(-beta^2)
    env.task.after_step(env.physics)
    rgb = env.physics.named.model.mat_rgba["pole"][:3]
    weight = math.exp(-9.0)
    np.testing.assert_allclose(rgb, weight * own[:3] + (1 - weight) * np.array([0.85, 0.1, 0.1]))
    with pytest.raises(ValueError, match="bool"):
        env.task.visualize_reward = 1  # the suite's setter refuses non-bools too


def _cart_after(force: float) -> np.ndarray:
    env = suite.load("cart_pendulum", "balance", task_kwargs={"random": 5})
    env.reset()
    for _ in range(3):
        env.step([force])
    return env.physics.state()


def test_a_cart_force_beyond_its_range_acts_as_the_range_and_a_bad_force_is_refused():
    np.testing.assert_array_equal(_cart_after(1e6), _cart_after(25.0))  # MuJoCo clamps to ctrlrange
    np.testing.assert_array_equal(_cart_after(-1e6), _cart_after(-25.0))
    env = suite.load("cart_pendulum", "balance", task_kwargs={"random": 5})
    env.reset()
    before = env.physics.state()
    for bad, message in (([math.nan], "finite"), ([math.inf], "finite"), ([1.0, 2.0], "one force")):
        with pytest.raises(ValueError, match=message):
            env.step(bad)
    np.testing.assert_array_equal(env.physics.state(), before)


def _battery_after(action) -> tuple[float, float]:
    env = suite.load("battery", "trading", task_kwargs={"random": 6})
    env.reset()
    reward = sum(env.step(action).reward for _ in range(3))
    return env.physics.state_of_charge(), reward


def test_a_battery_action_beyond_its_spec_acts_as_the_bound_and_a_bad_action_is_refused():
    assert _battery_after([0.0, -1e5]) == _battery_after([0.0, 0.0])  # no free charge
    assert _battery_after([0.0, 2.0]) == _battery_after([0.0, 1.0])  # no double draw
    assert _battery_after([1e6, 0.0]) == _battery_after([360.0, 0.0])
    assert _battery_after([0.0, 1.0])[0] < _battery_after([0.0, 0.0])[0]  # computing does cost charge
    env = suite.load("battery", "trading", task_kwargs={"random": 6})
    env.reset()
    before = env.physics.state_of_charge()
    for bad, message in (([math.nan, 0.0], "finite"), ([0.0, math.inf], "finite"), ([1.0], "shape"), ([[1.0, 0.0]], "shape")):
        with pytest.raises(ValueError, match=message):
            env.step(bad)
    assert env.physics.state_of_charge() == before


def test_the_battery_says_it_has_nothing_to_render():
    env = battery_env.make_environment(random=0)
    with pytest.raises(NotImplementedError, match="Rerun"):
        env.physics.render()


def test_the_pole_angle_is_unwrapped_and_its_reward_keeps_falling_past_a_half_turn():
    env = suite.load("cart_pendulum", "balance", task_kwargs={"random": 0})
    env.reset()
    env.physics.set_state_vector(np.array([0.0, 0.0, math.pi - 0.2, 6.0]))  # swinging over the top
    env.physics.set_disturbance(0.0)
    angles, rewards = [], []
    for _ in range(3):
        timestep = env.step([0.0])
        angles.append(timestep.observation["pole_angle"])
        rewards.append(timestep.reward)
    assert angles[-1] > math.pi  # not wrapped into (-pi, pi]
    assert np.all(np.diff(angles) > 0) and np.all(np.diff(rewards) < 0)
    np.testing.assert_allclose(rewards, -np.square(angles))
    assert "unwrapped" in cp_env.__doc__
