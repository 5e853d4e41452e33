"""A second standard algorithm on the trigger environment: Stable-Baselines3's DQN, trained on the same
environment as the shipped PPO (the task's ``policies/<task>/ppo.yml``: its reward baseline, its budget of
environment steps, VecNormalize on observations and rewards) and scored as PPO's checkpoints are, on
training-distribution validation episodes (never the test set).

    python scripts/dqn_trial.py cart_pendulum/kicks --out results/dqn/kicks [--timesteps N]

Writes ``DIR/trial.json``: DQN's validation objective after each quarter of the budget, and the best
fixed schedule's and the shipped PPO run's settings beside it. ``DIR/step_<n>.zip`` is usable as
``sb3:PATH``. DQN's settings are SB3's defaults but for the sizes a 100-step episode needs (a replay
buffer of the whole budget, learning from 1000 steps, the target network every 1000 steps).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from etmpc.common.outputs import write_json
from etmpc.evaluation.workers import make_backend
from etmpc.learning import hyperparams
from etmpc.learning.config import VALIDATION_ENTROPY
from etmpc.learning.jobs import mean_scores
from etmpc.policies.sb3 import FORMAT, metadata_path
from etmpc.systems import system_key


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("task")
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--timesteps", type=int, default=None, help="default: the task's PPO budget")
    parser.add_argument("--validation-episodes", type=int, default=50)
    args = parser.parse_args()

    import torch
    from stable_baselines3 import DQN
    from stable_baselines3.common.monitor import Monitor
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    from etmpc.envs.gym import TriggerEnv

    key = system_key(args.task, None)
    ppo = hyperparams.shipped(key)
    timesteps = args.timesteps or ppo.timesteps
    torch.set_num_threads(1)

    def make():
        env = Monitor(TriggerEnv(key, reward_baseline=ppo.reward_baseline))
        env.reset(seed=ppo.seed * 1000)
        return env

    vec = VecNormalize(DummyVecEnv([make]), norm_obs=True, norm_reward=True, gamma=ppo.gamma)
    model = DQN("MlpPolicy", vec, seed=ppo.seed, device="cpu", gamma=ppo.gamma, buffer_size=timesteps,
                learning_starts=1000, target_update_interval=1000, policy_kwargs={"net_arch": list(ppo.hidden)}, verbose=0)
    names = list(vec.get_attr("observation_names")[0])
    args.out.mkdir(parents=True, exist_ok=True)
    rows, started = [], time.perf_counter()
    with make_backend("local", 2) as pool:
        for _ in range(4):
            model.learn(total_timesteps=timesteps // 4, reset_num_timesteps=False)
            path = args.out / f"step_{model.num_timesteps:08d}.zip"
            model.save(str(path))
            write_json(metadata_path(path), {
                "format": FORMAT, "version": 1, "task": key.task, "algorithm": "dqn", "observation_names": names,
                "observation_mean": vec.obs_rms.mean.tolist(), "observation_var": vec.obs_rms.var.tolist(),
                "recompute_price": key.make().recompute_price, "timesteps": int(model.num_timesteps)})
            score = mean_scores(pool, key, [f"sb3:{path}"], VALIDATION_ENTROPY, args.validation_episodes)[0]
            rows.append({"timesteps": int(model.num_timesteps), "validation_objective": score,
                         "wall_seconds": time.perf_counter() - started})
            print(f"{key.task}: DQN {model.num_timesteps} steps, validation objective {score:.5f}", flush=True)
    write_json(args.out / "trial.json", {"task": key.task, "algorithm": "dqn", "reward_baseline": ppo.reward_baseline,
                                         "checkpoints": rows, "validation_episodes": args.validation_episodes})


if __name__ == "__main__":
    main()
