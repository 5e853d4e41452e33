"""PPO's hyperparameters as data: rl-zoo3-style YAML files, one per task, shipped beside its policy."""

import dataclasses
import json
import re

import numpy as np
import pytest
import yaml

from etmpc.envs.registration import env_id
from etmpc.learning import hyperparams
from etmpc.learning.hyperparams import HyperparameterError
from etmpc.learning.ppo import PpoSettings, SettingError
from etmpc.learning.ppo_settings import settings_json
from etmpc.systems import make_system, names


@pytest.mark.parametrize("task", names())
def test_every_tasks_file_is_the_recipe_of_the_network_it_ships_beside(task):
    # ppo.yml is what `etmpc train --algorithm ppo` (and `etmpc reproduce`) trains by default: the shipped network's
    # own settings, seed included, as its ppo.json records them
    path = hyperparams.shipped_path(task)
    made = json.loads(path.with_name("ppo.json").read_text())["settings"]
    settings = hyperparams.load(path, task, PpoSettings(validation_episodes=made["validation_episodes"]))
    assert settings_json(settings) == made


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
    system = make_system(task)
    assert settings.reward_baseline in system.benchmark.baselines(system.compute_levels)


def test_settings_not_in_the_file_keep_the_given_defaults(tmp_path):
    path = tmp_path / "h.yml"
    path.write_text("etmpc/cart_pendulum-balance-v0:\n  n_timesteps: 4096\n  gamma: 0.95\n")
    base = PpoSettings(validation_episodes=7)
    assert hyperparams.load(path, "cart_pendulum", base) == dataclasses.replace(base, timesteps=4096, gamma=0.95)


@pytest.mark.parametrize(
    "text, message",
    [
        ("etmpc/cart_pendulum-balance-v0:\n  n_timestep: 10\n", "unknown hyperparameter 'n_timestep'"),
        ("etmpc/battery-trading-v0:\n  gamma: 0.9\n", "no entry for etmpc/cart_pendulum-balance-v0"),
        ("etmpc/cart_pendulum-balance-v0:\n  policy: CnnPolicy\n", "not supported"),
        ("etmpc/cart_pendulum-balance-v0:\n  policy_kwargs: 'dict(net_arch=[64])'\n", "net_arch only"),
        ("etmpc/cart_pendulum-balance-v0:\n  policy_kwargs: {net_arch: [64, 0]}\n", "positive layer sizes"),
        ("etmpc/cart_pendulum-balance-v0:\n  env_kwargs: {price: 3}\n", "env_kwargs takes reward_baseline"),
        ("etmpc/cart_pendulum-balance-v0:\n  gamma: '0.9'\n", "gamma must be a number"),
        ("etmpc/cart_pendulum-balance-v0:\n  n_steps: 0\n", "n_steps must be an integer in [1, 1e9], got 0"),
        ("etmpc/cart_pendulum-balance-v0: [1, 2]\n", "must map hyperparameter names"),
        ("etmpc/cart_pendulum-balance-v0: {gamma: [\n", "cannot read it"),
    ],
)
def test_a_bad_file_is_one_line_naming_it(tmp_path, text, message):
    path = tmp_path / "bad.yml"
    path.write_text(text)
    with pytest.raises(HyperparameterError, match=re.escape(message)) as caught:
        hyperparams.load(path, "cart_pendulum")
    assert str(path) in str(caught.value) and "\n" not in str(caught.value)


HEAD = "etmpc/cart_pendulum-balance-v0:\n"


@pytest.mark.parametrize(
    "entry, message",
    [
        ("gamma: 1.5", "gamma must be in (0, 1], got 1.5"),
        ("gamma: 0", "gamma must be in (0, 1], got 0"),
        ("gamma: [0.9]", "gamma must be in (0, 1], got [0.9]"),
        ("gae_lambda: 1.01", "gae_lambda must be in [0, 1], got 1.01"),
        ("gae_lambda: -0.1", "gae_lambda must be in [0, 1], got -0.1"),
        ("learning_rate: -3.0e-4", "learning_rate must be a finite number > 0, got -0.0003"),
        ("learning_rate: 0", "learning_rate must be a finite number > 0, got 0"),
        ("learning_rate: .nan", "learning_rate must be a finite number > 0, got nan"),
        ("learning_rate: .inf", "learning_rate must be a finite number > 0, got inf"),
        ("learning_rate: 3e-4", "learning_rate must be a number, got '3e-4' (YAML reads it as text"),
        ("clip_range: 0.0", "clip_range must be a finite number > 0, got 0.0"),
        ("clip_range: .inf", "clip_range must be a finite number > 0, got inf"),
        ("ent_coef: -0.01", "ent_coef must be a finite number >= 0, got -0.01"),
        ("ent_coef: .nan", "ent_coef must be a finite number >= 0, got nan"),
        ("n_timesteps: 0", "n_timesteps must be an integer in [1, 1e9], got 0"),
        ("n_timesteps: 8.5", "n_timesteps must be an integer in [1, 1e9], got 8.5"),
        ("n_timesteps: 1e6", "n_timesteps must be a number, got '1e6'"),
        ("n_steps: 8.5", "n_steps must be an integer in [1, 1e9], got 8.5"),
        ("n_steps: 8.0", "n_steps must be an integer in [1, 1e9], got 8.0"),
        ("n_steps: true", "n_steps must be an integer in [1, 1e9], got True"),
        ("n_epochs: 0", "n_epochs must be an integer in [1, 1e9], got 0"),
        ("n_envs: 0", "n_envs must be an integer in [1, 1e9], got 0"),
        ("n_envs: 2.0", "n_envs must be an integer in [1, 1e9], got 2.0"),
        ("checkpoints: 0", "checkpoints must be an integer in [1, 1e9], got 0"),
        ("checkpoints: yes", "checkpoints must be an integer in [1, 1e9], got True"),
        ("batch_size: 1", "batch_size must be an integer in [2, 1e9] (Stable-Baselines3 asserts > 1), got 1"),
        ("batch_size: 64.0", "batch_size must be an integer in [2, 1e9]"),
        ("seed: -1", "seed must be an integer in [0, 4294967295], got -1"),
        ("seed: 4294967296", "seed must be an integer in [0, 4294967295], got 4294967296"),
        ("seed: 0.5", "seed must be an integer in [0, 4294967295], got 0.5"),
        ("policy_kwargs: {net_arch: [64, 0]}", "net_arch must be a list of positive layer sizes"),
        ("n_steps: 1\n  n_envs: 1", "n_steps * n_envs must be >= 2 (Stable-Baselines3 asserts > 1), got 1 * 1"),
        ("n_timesteps: 10\n  n_envs: 1\n  checkpoints: 6", "checkpoints must be at most n_timesteps // max(2, n_envs) = 5"),
        ("n_timesteps: 10\n  n_envs: 4\n  checkpoints: 3", "checkpoints must be at most n_timesteps // max(2, n_envs) = 2"),
    ],
)
def test_a_value_out_of_its_range_is_one_line_naming_the_file_the_key_and_the_range(tmp_path, capsys, entry, message):
    from etmpc.cli import main

    path = tmp_path / "ppo.yml"
    path.write_text(HEAD + f"  {entry}\n")
    code = main(
        ["train", "--task", "cart_pendulum", "--algorithm", "ppo", "--hyperparams", str(path), "--out", str(tmp_path / "run")]
    )
    captured = capsys.readouterr()
    assert code == 2 and captured.out == ""
    assert captured.err.startswith(f"etmpc: error: {path}: {message}") and captured.err.count("\n") == 1, captured.err
    assert "Traceback" not in captured.err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ppo.yml"]  # nothing written


def test_a_file_at_the_edges_of_every_range_is_accepted(tmp_path):
    path = tmp_path / "ppo.yml"
    path.write_text(
        HEAD
        + "".join(
            f"  {line}\n"
            for line in (
                "n_timesteps: 8",
                "n_envs: 1",
                "n_steps: 2",
                "batch_size: 2",
                "n_epochs: 1",
                "checkpoints: 4",
                "learning_rate: 1.0e-6",
                "gamma: 1",
                "gae_lambda: 0",
                "clip_range: 10",
                "ent_coef: 0",
                "seed: 4294967295",
                "policy_kwargs: {net_arch: [1]}",
            )
        )
    )
    settings = hyperparams.load(path, "cart_pendulum")
    assert (settings.timesteps, settings.checkpoints, settings.seed, settings.gamma, settings.hidden) == (
        8,
        4,
        2**32 - 1,
        1,
        (1,),
    )


def test_the_checks_hold_for_the_python_api_and_the_command_lines_overrides_too(tmp_path, capsys):
    with pytest.raises(SettingError, match=re.escape("gamma must be in (0, 1], got 1.5")):
        dataclasses.replace(PpoSettings(), gamma=1.5)
    with pytest.raises(SettingError, match=re.escape("checkpoints must be at most timesteps // max(2, n_envs) = 1")):
        PpoSettings(timesteps=3, checkpoints=2)
    assert PpoSettings(seed=np.int64(7)).seed.__class__ is int  # written to JSON as a number
    from etmpc.cli import main

    for option, message in (
        (["--timesteps", "6"], "checkpoints must be at most timesteps // max(2, n_envs) = 3, got 4"),
        (["--seeds", "4294967296"], "seed must be an integer in [0, 4294967295], got 4294967296"),
    ):
        assert main(["train", "--task", "cart_pendulum", "--algorithm", "ppo", *option, "--out", str(tmp_path / "run")]) == 2
        err = capsys.readouterr().err
        assert err.startswith(f"etmpc: error: {message}") and err.count("\n") == 1, err
    assert list(tmp_path.iterdir()) == []
