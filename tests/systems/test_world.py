"""A system reads the world's laws through one reference, its task: episodes are drawn and redrawn
past a step by the task, and what a controller has already seen is never redrawn."""

from __future__ import annotations

import numpy as np
import pytest

from etmpc.systems import make_system

TASKS = ["cart_pendulum", "cart_pendulum/kicks", "battery", "reacher", "quadrotor"]


@pytest.mark.parametrize("task", TASKS)
def test_a_system_draws_its_episodes_through_its_task(task):
    system = make_system(task)
    assert system.world is system.world  # one environment, made once
    mine, worlds = system.draw_episode(np.random.default_rng(3)), system.world.draw_episode(np.random.default_rng(3))
    for name, values in mine.arrays().items():
        np.testing.assert_array_equal(values, worlds.arrays()[name])
    assert system.episode_parameters() == system.world.episode_parameters()
    assert system.signals(mine).keys() == system.world.signals(worlds).keys()


@pytest.mark.parametrize("task", TASKS)
@pytest.mark.parametrize("step", [0, 7, 40])
def test_a_resampled_future_keeps_the_past_and_redraws_the_rest_reproducibly(task, step):
    system = make_system(task)
    episode = system.draw_episode(np.random.default_rng(5))
    first = system.sample_future(episode, step, np.random.default_rng(11))
    again = system.world.resample_episode(episode, step, np.random.default_rng(11))
    other = system.sample_future(episode, step, np.random.default_rng(12))
    old, new, same, differs = episode.arrays(), first.arrays(), again.arrays(), False
    for name, values in old.items():
        np.testing.assert_array_equal(new[name], same[name])  # the same generator, the same future
        if np.ndim(values) == 0 or np.shape(values)[0] < step:  # a scalar, or not per step (an initial state)
            np.testing.assert_array_equal(new[name], values)
            continue
        np.testing.assert_array_equal(new[name][:step], values[:step])  # what has happened stays
        differs |= not np.array_equal(other.arrays()[name], new[name])
    assert differs  # another generator, another future
