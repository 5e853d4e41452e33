"""A shipped policy plays the same everywhere: loaded the standard way (``PPO.load``) and stepped by
Stable-Baselines3's own loop on the documented environment with its ``normalize=`` keyword, it makes
exactly the decisions ``etmpc evaluate --task TASK --policy sb3:…`` makes, step by step; without the keyword
(what a user measured) it is another policy. And ``sb3:`` scores a model saved by a plain
``model.save()``, on the raw observation, or refuses in one line when its normalisation is unknown.

``evaluate`` runs here with one worker, in this process: each episode it plays is caught on its way
through ``play_test_episode`` (the function its ``_run`` calls), so the per-step recompute flags are
the command's own, not a replay.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("stable_baselines3")

import gymnasium as gym  # noqa: E402

import etmpc  # noqa: E402,F401  (registers the environments)
from etmpc.cli import main  # noqa: E402
from etmpc.common.errors import EtmpcError  # noqa: E402
from etmpc.envs.registration import env_id  # noqa: E402
from etmpc.evaluation import evaluate as evaluate_module  # noqa: E402
from etmpc.policies.sb3 import load_sb3  # noqa: E402
from etmpc.systems import folder_name, names  # noqa: E402

from tests.conftest import REPO

# policies/<directory>: its task, for every shipped PPO network
SHIPPED = {folder_name(task): task for task in names() if (REPO / "policies" / folder_name(task) / "ppo.zip").exists()}
BATTERY = env_id("battery")  # its gymnasium id (a version that grows with its observation)
EPISODES = int(os.environ.get("ETMPC_SB3_EPISODES", "5"))  # test-set episodes 0 .. EPISODES - 1


def sb3_plays(model, env, episode: int) -> dict:
    """Stable-Baselines3's own way: ``predict`` on what the environment hands out, ``step``, until done."""
    obs, info = env.reset(options={"test_episode": episode})
    recompute, forced, done = [], [], False
    while not done:
        action, _ = model.predict(obs, deterministic=True)
        obs, reward, terminated, truncated, info = env.step(action)
        recompute.append(info["recompute"])
        forced.append(info["forced"])
        done = terminated or truncated
    core = env.unwrapped.core
    ret = core.episode_return
    return {
        "recompute": np.array(recompute),
        "forced": np.array(forced),
        "objective": ret if core.system.objective_sense == "max" else -ret,
    }


def evaluate_plays(task: str, spec: str, episodes: int, tmp_path: Path, monkeypatch) -> dict[int, dict]:
    """``etmpc evaluate --task TASK --policy SPEC``: per episode its per-step recompute and forced flags (caught as
    it plays them) and the objective and recomputations it reports."""
    caught, original = {}, evaluate_module.play_test_episode

    def catching(domain, policy, seed, repeat, episode, *rest):
        played = original(domain, policy, seed, repeat, episode, *rest)
        n = played.trajectory.steps
        caught[episode] = {"recompute": played.trajectory.recompute[:n].copy(), "forced": played.trajectory.forced[:n].copy()}
        return played

    monkeypatch.setattr(evaluate_module, "play_test_episode", catching)
    out = tmp_path / f"{task.replace('/', '-')}.json"
    assert (
        main(["evaluate", "--task", task, "--policy", spec, "--episodes", str(episodes), "--workers", "1", "--json", str(out)])
        == 0
    )
    monkeypatch.undo()
    for run in json.loads(out.read_text())["runs"]:
        caught[run["episode"]] |= {"objective": run["objective"], "recomputes": run["recomputes"]}
    assert sorted(caught) == list(range(episodes))
    return caught


def test_every_shipped_network_is_compared():
    """No ``policies/*/*/ppo.zip`` escapes the comparison below (a folder no task of the suite names would)."""
    shipped = (REPO / "policies").glob("*/*/ppo.zip")
    assert sorted(SHIPPED) == sorted(p.parent.relative_to(REPO / "policies").as_posix() for p in shipped)
    assert {"cart_pendulum/balance", "battery/trading", "reacher/jumps", "quadrotor/waypoints"} <= set(SHIPPED)


@pytest.mark.parametrize("directory", list(SHIPPED))
def test_ppo_load_on_the_documented_environment_decides_as_etmpc_evaluate(directory, tmp_path, monkeypatch):
    from stable_baselines3 import PPO

    torch.set_num_threads(1)
    path, task = REPO / "policies" / directory / "ppo.zip", SHIPPED[directory]
    model = PPO.load(str(path), device="cpu")  # shipped files: trusted (sb3: itself never unpickles)
    theirs = evaluate_plays(task, f"sb3:{path}", EPISODES, tmp_path, monkeypatch)
    normalised = gym.make(env_id(task), normalize=str(path.with_suffix(".json")))
    plain = gym.make(env_id(task))
    lines, steps, asked, control = [], 0, 0, []
    for e in range(EPISODES):
        ours = sb3_plays(model, normalised, e)
        # Step for step: every computation, forced or asked for; the forced steps (the first, and where the
        # plan ran out) are forced in both, whatever the network says there.
        np.testing.assert_array_equal(ours["forced"], theirs[e]["forced"], err_msg=f"episode {e}")
        np.testing.assert_array_equal(ours["recompute"], theirs[e]["recompute"], err_msg=f"episode {e}")
        assert ours["recompute"].sum() == theirs[e]["recomputes"] and ours["objective"] == theirs[e]["objective"]
        steps += len(ours["recompute"])
        asked += int((~ours["forced"]).sum())
        # The control: the same model, stepped the same way on the environment without the keyword.
        raw = sb3_plays(model, plain, e)
        n = min(len(raw["recompute"]), len(ours["recompute"]))
        control.append(
            (
                int(raw["recompute"].sum()),
                int(ours["recompute"].sum()),
                int((raw["recompute"][:n] != ours["recompute"][:n]).sum()),
                len(raw["recompute"]),
            )
        )
    lines.append(
        f"{task}: {EPISODES} episodes, {steps} steps compared ({asked} decided by the network), 0 mismatches; "
        "without normalize= (recomputes, with it, steps that differ, steps): " + ", ".join(map(str, control))
    )
    print("\n" + "\n".join(lines))  # shown with -s
    assert any(c[2] > 0 for c in control), "without its normalisation the policy should decide otherwise"


def test_the_keyword_refuses_another_tasks_normalisation_in_one_line(tmp_path):
    kicks = REPO / "policies" / "cart_pendulum" / "kicks" / "ppo.json"
    huge = json.loads((REPO / "policies" / "cart_pendulum" / "balance" / "ppo.json").read_text())
    huge["observation_mean"][0] = 10**400  # was an OverflowError traceback
    (tmp_path / "huge.json").write_text(json.dumps(huge))
    for given, says in [
        (tmp_path / "huge.json", "huge.json: observation_mean[0] is 10000000000000000000..., not a finite number"),
        (kicks, "its policy was trained on 'cart_pendulum/kicks', not 'cart_pendulum/balance'"),
        (kicks.with_suffix(".zip"), "is a model; give its description, normalize="),
        (kicks.with_name("nosuch.json"), "no such file"),
        (REPO / "policies" / "cart_pendulum" / "balance" / "learned.json", "is not an etmpc Stable-Baselines3 policy"),
        (3, "the path of a policy's .json is needed"),
    ]:
        with pytest.raises(EtmpcError) as refused:
            gym.make("etmpc/cart_pendulum-balance-v0", normalize=given)
        assert says in str(refused.value) and len(str(refused.value).splitlines()) == 1, str(refused.value)
        if given == 3 or str(given).endswith(".zip"):  # a wrong type, a wrong value: Python's own errors too
            assert isinstance(refused.value, TypeError if given == 3 else ValueError)


def test_the_keyword_composes_with_make_vec_env_and_keeps_the_spaces():
    from stable_baselines3.common.env_util import make_vec_env

    sidecar = str(REPO / "policies" / "battery" / "trading" / "ppo.json")
    vec = make_vec_env(BATTERY, n_envs=1, env_kwargs={"normalize": sidecar})
    plain = gym.make(BATTERY)
    normalised = gym.make(BATTERY, normalize=sidecar)
    assert vec.observation_space == plain.observation_space == normalised.observation_space
    obs, info = normalised.reset(options={"test_episode": 0})
    obs, *_, info = normalised.step(1)
    spec = normalised.unwrapped.normalization
    expected = np.clip((info["observation"] - spec.mean) / np.sqrt(spec.var + 1e-8), -10, 10).astype(np.float32)
    assert obs.dtype == np.float32 and obs.tobytes() == expected.tobytes()
    vec.close()


# -- a model saved by plain model.save() ----------------------------------------------------------
def _decisions_match(model_path: Path, env: gym.Env, episodes: int, tmp_path: Path, monkeypatch) -> int:
    from stable_baselines3 import PPO

    model = PPO.load(str(model_path), device="cpu")  # made by this test: trusted
    theirs = evaluate_plays("battery", f"sb3:{model_path}", episodes, tmp_path, monkeypatch)
    compared, chosen = 0, set()
    for e in range(episodes):
        ours = sb3_plays(model, env, e)
        np.testing.assert_array_equal(ours["recompute"], theirs[e]["recompute"], err_msg=f"episode {e}")
        assert ours["objective"] == theirs[e]["objective"]
        compared += len(ours["recompute"])
        chosen |= set(ours["recompute"][~ours["forced"]].tolist())
    assert chosen == {False, True}, "the network should both keep and recompute, or the comparison shows little"
    return compared


def test_a_model_saved_by_plain_model_save_is_scored_on_the_raw_observation(tmp_path, monkeypatch):
    from stable_baselines3 import PPO

    torch.set_num_threads(1)
    env = gym.make(BATTERY)
    model = PPO("MlpPolicy", env, seed=0, n_steps=128, batch_size=64, n_epochs=1, learning_rate=1e-3, device="cpu").learn(
        total_timesteps=256
    )
    model.save(tmp_path / "m.zip")
    assert not (tmp_path / "m.json").exists()
    policy = load_sb3(str(tmp_path / "m.zip"), "battery")
    assert not policy.normalises and policy.task == "battery/trading"
    compared = _decisions_match(tmp_path / "m.zip", env, 2, tmp_path, monkeypatch)
    assert compared > 100
    # Its observation size is the battery's: on the cart pendulum it is refused in one line.
    with pytest.raises(EtmpcError, match=r"takes observations of shape \(\d+,\) and '2' actions; the trigger environment has"):
        load_sb3(str(tmp_path / "m.zip"), "cart_pendulum")
    # Without a task to evaluate on, a description is still needed.
    with pytest.raises(EtmpcError, match="has no m.json beside it"):
        load_sb3(str(tmp_path / "m.zip"), None)


def test_a_model_trained_behind_vecnormalize_needs_its_statistics_which_save_normalization_writes(tmp_path, monkeypatch, capsys):
    from stable_baselines3 import PPO
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import VecNormalize

    from etmpc.envs import save_normalization

    torch.set_num_threads(1)
    vec = VecNormalize(make_vec_env(BATTERY, n_envs=1, seed=0))
    model = PPO("MlpPolicy", vec, seed=0, n_steps=128, batch_size=64, n_epochs=1, device="cpu").learn(total_timesteps=256)
    model.save(tmp_path / "n.zip")
    # Nothing in its zip says how it normalised, but that it did: refused, saying what writes the statistics.
    assert (
        main(["evaluate", "--task", "battery", "--policy", f"sb3:{tmp_path / 'n.zip'}", "--episodes", "1", "--workers", "1"]) == 2
    )
    err = capsys.readouterr().err
    assert "has no n.json beside it" in err and "trained behind VecNormalize" in err and "save_normalization(" in err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    save_normalization(vec, "battery", tmp_path / "n.json")
    assert load_sb3(str(tmp_path / "n.zip"), "battery").normalises
    normalised = gym.make(BATTERY, normalize=str(tmp_path / "n.json"))
    assert _decisions_match(tmp_path / "n.zip", normalised, 2, tmp_path, monkeypatch) > 100
    with pytest.raises(EtmpcError, match="clip_obs=10 and epsilon=1e-08; this one has clip_obs=5.0"):
        save_normalization(VecNormalize(make_vec_env(BATTERY, n_envs=1), clip_obs=5.0), "battery", tmp_path / "other.json")
    vec.close()
