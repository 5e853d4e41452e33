"""Steps per second of the trigger environment (gymnasium) against the loop's own, side by side.

    python scripts/bench_env.py [TASK ...] [--episodes 20] [--rounds 3]

The same training-distribution episodes are played under ``every:3``, once by ``run_episode`` (the
loop ``evaluate`` plays) and once through ``gymnasium.make("etmpc/...")`` by an agent answering as
``every:3`` does; alternating rounds, the best of each. Prints steps/s of both and their ratio.
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import numpy as np

import etmpc  # noqa: F401  (registers the environments)
from etmpc.envs.registration import env_id
from etmpc.loop import run_episode
from etmpc.policies import parse_policy
from etmpc.systems import make_system, names


def _episodes(system, count: int) -> list:
    rng = np.random.default_rng(0)
    return [system.draw_episode(rng) for _ in range(count)]


def loop_rate(system, env, episodes) -> float:
    policy, steps = parse_policy("every:3", system), 0
    start = time.perf_counter()
    for episode in episodes:
        steps += run_episode(system, env, policy, None, episode).steps
    return steps / (time.perf_counter() - start)


def env_rate(gym_env, episodes) -> float:
    core, steps = gym_env.unwrapped.core, 0
    start = time.perf_counter()
    for episode in episodes:
        core.loop.reset(episode)  # the same episodes as the loop's (reset draws its own)
        done = False
        while not done:
            _, _, terminated, truncated, _ = gym_env.step(int(core.loop.age >= 3))
            steps += 1
            done = terminated or truncated
    return steps / (time.perf_counter() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("tasks", nargs="*", default=list(names()))
    parser.add_argument("--episodes", type=int, default=20)
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args()
    for task in args.tasks:
        system = make_system(task)
        env, gym_env = system.make_env(), gym.make(env_id(task))
        gym_env.reset(seed=0)
        episodes = _episodes(system, args.episodes)
        loop_best, env_best = 0.0, 0.0
        for _ in range(args.rounds):
            loop_best = max(loop_best, loop_rate(system, env, episodes))
            env_best = max(env_best, env_rate(gym_env, episodes))
        print(
            f"{task}: loop {loop_best:,.0f} steps/s, environment {env_best:,.0f} steps/s, "
            f"loop / environment {loop_best / env_best:.2f} (best of {args.rounds} alternating rounds, "
            f"{args.episodes} episodes each, every:3)"
        )


if __name__ == "__main__":
    main()
