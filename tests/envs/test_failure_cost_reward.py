"""A failure cost in the trigger environment's reward (``failure_cost=C``, PPO's ``failure_cost``): the same
actions on the same episode lose exactly ``C`` per failure the environment counts, at the step it happens; with a
reward baseline the baseline's failures cost the same; bad costs are one line; PPO's files carry it."""

import numpy as np
import pytest

from etmpc.common.errors import EtmpcError
from etmpc.envs.gym import TriggerEnv
from etmpc.envs.trigger import TriggerEnvironment
from etmpc.learning import hyperparams
from etmpc.learning.ppo_settings import PpoSettings, SettingError, settings_json

TASK = "cart_pendulum/kicks"
SEED = 2  # an episode in which keeping every plan to its end lets the pole fall twice


def _play(action: int, **kwargs) -> tuple[list[float], list[int]]:
    """Rewards and the environment's failure count after each step of one episode, answering ``action`` always."""
    env = TriggerEnvironment(TASK, seed=SEED, **kwargs)
    ts, rewards, failures = env.reset(), [], []
    while not ts.last():
        ts = env.step(action)
        rewards.append(ts.reward)
        failures.append(env.info["failures"])
    return rewards, failures


def test_each_failure_costs_its_price_at_the_step_it_happens():
    plain, failures = _play(0)
    costly, same = _play(0, failure_cost=7.5)
    assert same == failures and failures[-1] >= 1  # the same episode and actions; it has falls to price
    new = np.diff([0, *failures])
    assert np.array_equal(np.array(plain) - np.array(costly), 7.5 * new)  # exactly, step by step


def test_with_a_reward_baseline_the_baselines_failures_cost_the_same():
    keep, keep_failures = _play(0)  # the baseline's own rewards and falls: never recomputes but when forced
    assert keep_failures[-1] >= 1
    plain, agent_failures = _play(1, reward_baseline="never")
    costly, _ = _play(1, reward_baseline="never", failure_cost=3.0)
    agent, baseline = np.diff([0, *agent_failures]), np.diff([0, *keep_failures])
    assert np.allclose(np.array(costly) - np.array(plain), 3.0 * (baseline - agent), rtol=0, atol=1e-12)


@pytest.mark.parametrize("bad", [-1.0, float("nan"), float("inf"), True, "3"])
def test_a_bad_failure_cost_is_one_line(bad):
    with pytest.raises(EtmpcError, match="failure_cost must be a finite number >= 0"):
        TriggerEnvironment(TASK, failure_cost=bad)
    with pytest.raises(EtmpcError, match="failure_cost must be a finite number >= 0"):
        TriggerEnv(TASK, failure_cost=bad)


def test_ppo_keeps_its_failure_cost_in_its_files_and_earlier_files_read_as_before(tmp_path):
    with pytest.raises(SettingError, match="failure_cost must be a finite number >= 0"):
        PpoSettings(failure_cost=-0.5)
    costly = PpoSettings(reward_baseline="every:3", failure_cost=10.0)
    path = tmp_path / "ppo.yml"
    path.write_text(hyperparams.dump(costly, TASK))
    assert "failure_cost: 10.0" in path.read_text() and hyperparams.load(path, TASK) == costly
    assert settings_json(costly)["failure_cost"] == 10.0
    assert "failure_cost" not in settings_json(PpoSettings())  # a run without one writes what runs before it wrote
    path.write_text(hyperparams.dump(PpoSettings(), TASK))
    assert "failure_cost" not in path.read_text() and hyperparams.load(path, TASK) == PpoSettings()
