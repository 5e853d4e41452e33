"""One API shape: ``etmpc.evaluate``, ``etmpc.score`` and the environments (``gymnasium.make(ID, ...)`` and the
``dm_env`` one) take the task's options as ``options=`` and a test set as ``test_set=``. The old names
(``evaluate``'s ``testset_path=``, the environments' ``task_options=``) work for this release with a
``DeprecationWarning`` and give the same numbers; the old and the new name at once are refused in one line."""

from __future__ import annotations

import inspect
import warnings

import gymnasium as gym
import numpy as np
import pytest

import etmpc
from etmpc.common.errors import EtmpcError
from etmpc.envs.gym import TriggerEnv
from etmpc.envs.trigger import TriggerEnvironment
from etmpc.evaluation import testsets
from etmpc.systems import system_key

TASK = "cart_pendulum/kicks"
OPTIONS = {"disturbances.kick_scale": "2"}  # acts on the stored test set: the kicks are scaled as they are played
GYM_ID = "etmpc/cart_pendulum-kicks-v0"


def stored_test_set() -> str:
    return str(testsets.default_path("cart_pendulum", "kicks"))


@pytest.mark.parametrize("entry", [etmpc.evaluate, etmpc.score, TriggerEnv, TriggerEnvironment])
def test_every_entry_point_takes_options_and_test_set_by_those_names(entry):
    """The names as Python itself binds them: a keyword each entry point does not have is its TypeError."""
    parameters = inspect.signature(entry).parameters
    assert {"options", "test_set"} <= set(parameters)
    with pytest.raises(TypeError, match="unexpected keyword argument 'task_optionz'"):
        entry(task_optionz=OPTIONS)


def objectives(evaluation) -> list[float]:
    return [run["objective"] for run in evaluation.to_json()["runs"]]


def test_evaluate_takes_options_and_test_set_and_plays_what_the_old_names_play():
    new = etmpc.evaluate(TASK, ["every:3"], 2, workers=1, progress=False, options=OPTIONS, test_set=stored_test_set())
    with pytest.warns(DeprecationWarning, match="testset_path= is deprecated: call it test_set=") as caught:
        old = etmpc.evaluate(
            system_key(TASK, None, OPTIONS), ["every:3"], 2, workers=1, progress=False, testset_path=stored_test_set()
        )
    assert caught[0].filename == __file__  # the warning names the caller's line
    plain = etmpc.evaluate(TASK, ["every:3"], 2, workers=1, progress=False)
    assert objectives(new) == objectives(old) != objectives(plain)  # the options acted, the same under both names
    assert new.options == old.options == dict(system_key(TASK, None, OPTIONS).options)


def test_evaluate_refuses_both_names_at_once_and_options_beside_a_key_that_carries_its_own():
    with pytest.raises(EtmpcError, match=r"^test_set: give it once \(testset_path= is its old name\)$"):
        etmpc.evaluate(TASK, ["every:3"], 1, test_set=stored_test_set(), testset_path=stored_test_set())
    with pytest.raises(TypeError, match="a SystemKey alone"):
        etmpc.evaluate(system_key(TASK), ["every:3"], 1, options=OPTIONS)
    with pytest.raises(EtmpcError, match="unknown option 'disturbances.kick'"):
        etmpc.evaluate(TASK, ["every:3"], 1, options={"disturbances.kick": "2"})


def play(env) -> list[float]:
    """The rewards of the stored test set's episode 0 (its kicks come late: played to the end), recomputing every
    third step."""
    env.reset(options={"test_episode": 0})
    rewards, done = [], False
    while not done:
        _, reward, terminated, truncated, _ = env.step(int(len(rewards) % 3 == 0))
        rewards, done = rewards + [float(reward)], terminated or truncated
    return rewards


def test_gymnasium_make_takes_options_and_the_old_name_warns_at_the_callers_line_with_the_same_rewards():
    new = gym.make(GYM_ID, options=OPTIONS, test_set=stored_test_set())
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        old = gym.make(GYM_ID, task_options=OPTIONS)
    deprecations = [w for w in caught if issubclass(w.category, DeprecationWarning)]
    assert [str(w.message) for w in deprecations] == ["the keyword task_options= is deprecated: call it options="]
    assert deprecations[0].filename == __file__  # past gymnasium.make's frames: shown where Python shows them
    plain = gym.make(GYM_ID)
    assert play(new) == play(old) != play(plain)
    with pytest.raises(EtmpcError, match=r"^options: give it once \(task_options= is its old name\)$"):
        gym.make(GYM_ID, options=OPTIONS, task_options=OPTIONS)


def test_the_dm_env_environment_takes_options_and_the_old_name_warns_with_the_same_rewards():
    def rewards(env) -> list[float]:
        env.reset(test_episode=0)
        return [float(env.step(np.int64(k % 3 == 0)).reward) for k in range(20)]

    new = TriggerEnvironment(TASK, options=OPTIONS, test_set=stored_test_set())
    with pytest.warns(DeprecationWarning, match="task_options= is deprecated: call it options=") as caught:
        old = TriggerEnvironment(TASK, task_options=OPTIONS)
    assert caught[0].filename == __file__
    assert new.key == old.key and rewards(new) == rewards(old)
    with pytest.raises(EtmpcError, match=r"^options: give it once"):
        TriggerEnvironment(TASK, options=OPTIONS, task_options=OPTIONS)
