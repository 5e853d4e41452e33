"""PPO from Stable-Baselines3 on the trigger environment (the 'rl' extra), and its network as a policy."""

import json
import platform
import zipfile

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

import gymnasium as gym  # noqa: E402

from etmpc.cli import main  # noqa: E402
from etmpc.evaluation.evaluate import evaluate  # noqa: E402
from etmpc.learning.ppo import PpoSettings, train_ppo  # noqa: E402
from etmpc.policies import parse_policy  # noqa: E402
from etmpc.policies.sb3 import load_sb3  # noqa: E402


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("ppo")
    settings = PpoSettings(timesteps=1024, checkpoints=2, validation_episodes=2, n_steps=256, batch_size=128, n_epochs=2)
    return out, train_ppo("battery", out, settings, workers=1)


def test_a_run_keeps_the_checkpoint_best_on_validation_episodes(run):
    out, result = run
    assert result["environment_steps"] == 1024 and len(result["checkpoints"]) == 2
    best = max(result["checkpoints"], key=lambda c: c["validation_objective"])  # the battery's objective is a profit
    assert result["selected"] == best["file"]
    assert (out / "selected.zip").read_bytes() == (out / best["file"]).read_bytes()
    meta = json.loads((out / "selected.json").read_text())
    assert meta["task"] == "battery/trading" and meta["validation_objective"] == best["validation_objective"]


def test_the_policy_decides_as_the_network_does_on_the_environments_normalised_observation(run):
    from stable_baselines3 import PPO

    out, _ = run
    policy = parse_policy(f"sb3:{out / 'selected.zip'}", "battery")
    model = PPO.load(str(out / "selected.zip"), device="cpu")
    meta = json.loads((out / "selected.json").read_text())
    mean, scale = np.array(meta["observation_mean"]), np.sqrt(np.array(meta["observation_var"]) + 1e-8)
    env = gym.make("etmpc/battery-trading-v1").unwrapped
    obs, _ = env.reset(seed=11)
    decisions = 0
    while True:
        s = env.core.loop.augmented_state()
        if s is not None:  # an unforced decision: the policy answers what the network answers
            expected = int(model.predict(np.clip((obs - mean) / scale, -10, 10).astype(np.float32), deterministic=True)[0])
            assert policy.decide(s, None) == (expected == 1)
            decisions += 1
        obs, _, terminated, truncated, _ = env.step(1)
        if terminated or truncated:
            break
    assert decisions > 50


def test_it_evaluates_like_any_policy(run):
    out, _ = run
    result = evaluate("battery", [f"sb3:{out / 'selected.zip'}", "every:3"], episodes=2, workers=2, progress=False)
    assert [s.episodes for s in result.summaries] == [2, 2]


def test_a_model_for_another_task_or_without_its_description_is_one_line(run, tmp_path, capsys):
    out, _ = run
    assert main(["evaluate", "--task", "cart_pendulum", "--policy", f"sb3:{out / 'selected.zip'}", "--episodes", "1"]) == 2
    assert "trained on 'battery/trading', not 'cart_pendulum/balance'" in capsys.readouterr().err
    lone = tmp_path / "lone.zip"
    lone.write_bytes((out / "selected.zip").read_bytes())
    assert main(["evaluate", "--task", "battery", "--policy", f"sb3:{lone}", "--episodes", "1"]) == 2
    assert "has no lone.json beside it" in capsys.readouterr().err
    with pytest.raises(Exception, match="not found"):
        load_sb3(str(tmp_path / "missing.zip"), "battery")


def _beside_a_valid_description(run, directory, name: str, data: bytes, meta_edit=None):
    out, _ = run
    model = directory / f"{name}.zip"
    model.write_bytes(data)
    meta = json.loads((out / "selected.json").read_text())
    if meta_edit is not None:
        meta_edit(meta)
    model.with_suffix(".json").write_text(json.dumps(meta))
    return model


def _foreign_zip() -> bytes:
    import io
    import zipfile

    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w") as archive:
        archive.writestr("notes.txt", "not a model")
    return buffer.getvalue()


@pytest.mark.parametrize(
    "case, says",
    [
        ("foreign-zip", "is not a Stable-Baselines3 model (its zip has no 'data' and 'policy.pth'"),
        ("empty-file", "is not a Stable-Baselines3 model (not a readable zip file"),
        ("truncated-model", "is not a Stable-Baselines3 model"),
        ("the-description-itself", "is the model's description; give the model itself"),
        ("unknown-algorithm", "names the algorithm 'nosuch', which Stable-Baselines3 does not have"),
        ("algorithm-not-a-name", "algorithm 3 is not a name"),
    ],
)
def test_a_file_that_is_not_a_model_is_one_line_before_any_work(run, case, says, tmp_path, capsys):
    out, _ = run
    model_bytes = (out / "selected.zip").read_bytes()
    data = {"foreign-zip": _foreign_zip(), "empty-file": b"", "truncated-model": model_bytes[: len(model_bytes) // 2]}
    edit = {
        "unknown-algorithm": lambda m: m.update(algorithm="nosuch"),
        "algorithm-not-a-name": lambda m: m.update(algorithm=3),
    }.get(case)
    model = _beside_a_valid_description(run, tmp_path, case, data.get(case, model_bytes), edit)
    spec = f"sb3:{model.with_suffix('.json') if case == 'the-description-itself' else model}"
    assert (
        main(
            [
                "evaluate",
                "--task",
                "battery",
                "--policy",
                spec,
                "--episodes",
                "2",
                "--workers",
                "2",
                "--json",
                str(tmp_path / "ev.json"),
            ]
        )
        == 2
    )
    err = capsys.readouterr().err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1 and says in err, err
    assert not (tmp_path / "ev.json").exists()


@pytest.mark.slow
def test_the_numbers_do_not_depend_on_the_worker_processes_and_the_baselines_steps_are_counted(tmp_path):
    from stable_baselines3 import PPO

    settings = PpoSettings(
        timesteps=512,
        checkpoints=1,
        validation_episodes=1,
        n_steps=128,
        batch_size=128,
        n_epochs=1,
        n_envs=2,
        reward_baseline="every:2",
    )
    runs = [train_ppo("battery", tmp_path / f"w{w}", settings, workers=w) for w in (1, 2)]
    weights = [PPO.load(str(tmp_path / f"w{w}" / "selected.zip"), device="cpu").policy.state_dict() for w in (1, 2)]
    assert weights[0].keys() == weights[1].keys()
    for name in weights[0]:  # the same network, trained in one process or in two
        np.testing.assert_array_equal(weights[0][name].numpy(), weights[1][name].numpy(), err_msg=name)
    assert runs[0]["checkpoints"][0]["validation_objective"] == runs[1]["checkpoints"][0]["validation_objective"]
    # Byte for byte, the model file too (no clock in it): a policy trained again can be compared so.
    assert (tmp_path / "w1" / "selected.zip").read_bytes() == (tmp_path / "w2" / "selected.zip").read_bytes()
    # The agent's 512 steps and the baseline's as many (a battery episode never ends early).
    assert runs[0]["environment_steps"] == 512 and runs[0]["simulated_steps"] == 1024


@pytest.mark.slow
def test_two_processes_save_the_same_training_byte_for_byte(tmp_path):
    """What a process or a machine puts into Stable-Baselines3's zip (memory addresses in its descriptions,
    the kernel's build) is left out: a training played again on the same machine saves the same zip, byte for byte."""
    import subprocess
    import sys
    from stable_baselines3 import PPO

    def trained(name: str) -> bytes:
        out = tmp_path / name
        done = subprocess.run(
            [
                sys.executable,
                "-m",
                "etmpc.cli",
                "train",
                "--task",
                "cart_pendulum",
                "--algorithm",
                "ppo",
                "--timesteps",
                "256",
                "--validation-episodes",
                "1",
                "--workers",
                "1",
                "--out",
                str(out),
            ],
            capture_output=True,
            text=True,
            timeout=600,
        )
        assert done.returncode == 0, done.stderr
        return (out / "selected.zip").read_bytes()

    first, second = trained("a"), trained("b")
    assert first == second
    with zipfile.ZipFile(tmp_path / "a" / "selected.zip") as saved:
        assert b" at 0x" not in saved.read("data")
        assert saved.read("system_info.txt").splitlines()[0] == f"- OS: {platform.system()} {platform.machine()}".encode()
    PPO.load(str(tmp_path / "a" / "selected.zip"), device="cpu")  # the descriptions were never what loading reads


def test_training_leaves_no_logger_folder_in_the_temporary_directory(tmp_path, monkeypatch):
    """Stable-Baselines3 left to itself makes an empty tempdir/SB3-<date> folder at every learn()."""
    import tempfile

    scratch = tmp_path / "tmp"
    scratch.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(scratch))
    monkeypatch.delenv("SB3_LOGDIR", raising=False)
    settings = PpoSettings(timesteps=512, checkpoints=2, validation_episodes=1, n_steps=128, batch_size=128, n_epochs=1)
    train_ppo("battery", tmp_path / "run", settings, workers=1)
    assert list(scratch.iterdir()) == []
