"""PPO's hyperparameters as data: rl-zoo3-style YAML files, one per task, shipped beside its policy."""

import dataclasses

import pytest
import yaml

from etmpc.envs.registration import env_id
from etmpc.learning import hyperparams
from etmpc.learning.hyperparams import HyperparameterError
from etmpc.learning.ppo import PpoSettings
from etmpc.systems import make_system, names


@pytest.mark.parametrize("task", names())
def test_every_task_ships_a_file_that_reads_back_to_what_it_says(task):
    path = hyperparams.shipped_path(task)
    text = path.read_text()
    settings = hyperparams.load(path, task)
    entry = yaml.safe_load(text)[env_id(task)]
    # Each value in the file is the setting PPO gets, under rl-zoo3's name.
    assert settings.timesteps == entry["n_timesteps"] and settings.n_envs == entry["n_envs"]
    assert settings.hidden == tuple(entry["policy_kwargs"]["net_arch"])
    assert settings.reward_baseline == entry["env_kwargs"]["reward_baseline"]
    for name in ("n_steps", "batch_size", "n_epochs", "learning_rate", "gamma", "gae_lambda", "clip_range", "ent_coef", "seed"):
        assert getattr(settings, name) == entry[name], name
    # And writing the settings gives a document that reads back to the same settings.
    assert hyperparams.parse(yaml.safe_load(hyperparams.dump(settings, task, "a comment")), task, "dump") == settings
    # The baseline is one of the task's fixed schedules (what the environment takes).
    assert settings.reward_baseline in make_system(task).benchmark.baselines()


def test_settings_not_in_the_file_keep_the_given_defaults(tmp_path):
    path = tmp_path / "h.yml"
    path.write_text("etmpc/cart_pendulum-balance-v0:\n  n_timesteps: 4096\n  gamma: 0.95\n")
    base = PpoSettings(validation_episodes=7)
    assert hyperparams.load(path, "cart_pendulum", base) == dataclasses.replace(base, timesteps=4096, gamma=0.95)


@pytest.mark.parametrize("text, message", [
    ("etmpc/cart_pendulum-balance-v0:\n  n_timestep: 10\n", "unknown hyperparameter 'n_timestep'"),
    ("etmpc/battery-trading-v0:\n  gamma: 0.9\n", "no entry for etmpc/cart_pendulum-balance-v0"),
    ("etmpc/cart_pendulum-balance-v0:\n  policy: CnnPolicy\n", "not supported"),
    ("etmpc/cart_pendulum-balance-v0:\n  policy_kwargs: 'dict(net_arch=[64])'\n", "net_arch only"),
    ("etmpc/cart_pendulum-balance-v0:\n  policy_kwargs: {net_arch: [64, 0]}\n", "positive layer sizes"),
    ("etmpc/cart_pendulum-balance-v0:\n  env_kwargs: {price: 3}\n", "env_kwargs takes reward_baseline"),
    ("etmpc/cart_pendulum-balance-v0:\n  gamma: '0.9'\n", "gamma must be a number"),
    ("etmpc/cart_pendulum-balance-v0:\n  n_steps: 0\n", "n_steps >= 1"),
    ("etmpc/cart_pendulum-balance-v0: [1, 2]\n", "must map hyperparameter names"),
    ("etmpc/cart_pendulum-balance-v0: {gamma: [\n", "cannot read it"),
])
def test_a_bad_file_is_one_line_naming_it(tmp_path, text, message):
    path = tmp_path / "bad.yml"
    path.write_text(text)
    with pytest.raises(HyperparameterError, match=message) as caught:
        hyperparams.load(path, "cart_pendulum")
    assert str(path) in str(caught.value) and "\n" not in str(caught.value)
