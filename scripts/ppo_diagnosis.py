"""Why PPO stalled on the trigger environment, measured: how much of a return's spread is the episode's
own draw, which no decision changes, and how much a reward against a fixed schedule removes.

For each task, on training-distribution episodes (never the test set), an agent that answers at random
(PPO's first policy: keep or recompute with probability 1/2) plays each episode twice, once with the
task's own reward and once against the task's reward baseline (its ``policies/<task>/ppo.yml``). The
script prints and writes (``--out FILE.json``) per task:

* the spread (std over episodes) of the return, with the task's reward and against the baseline;
* the same spread for ``always`` (the agent a learner must tell apart from the baseline);
* how far the return's effect of the discount reaches: ``gamma^T`` at the episode's length ``T``.

    python scripts/ppo_diagnosis.py --episodes 20 --out results/ppo_diagnosis.json
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from etmpc.envs.trigger import TriggerEnvironment
from etmpc.learning import hyperparams
from etmpc.systems import names


def returns(task: str, rule, episodes: int, baseline: str | None, seed: int = 0) -> np.ndarray:
    """The undiscounted sum of the environment's rewards over ``episodes`` training-distribution episodes."""
    env = TriggerEnvironment(task, seed=seed, reward_baseline=baseline)
    rng = np.random.default_rng(seed + 1)
    out = []
    for _ in range(episodes):
        env.reset()
        total = 0.0
        while True:
            step = env.step(rule(rng))
            total += step.reward
            if step.last():
                break
        out.append(total)
    return np.array(out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--episodes", type=int, default=20)
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()
    coin = lambda rng: int(rng.random() < 0.5)  # noqa: E731
    always = lambda rng: 1  # noqa: E731
    found = {}
    for task in names():
        settings = hyperparams.shipped(task)
        steps = TriggerEnvironment(task).system.episode_steps
        row = {"reward_baseline": settings.reward_baseline, "episodes": args.episodes, "episode_steps": steps,
               "gamma": settings.gamma, "gamma_to_the_episode_length": settings.gamma ** steps}
        for name, rule in (("coin", coin), ("always", always)):
            own = returns(task, rule, args.episodes, None)
            relative = returns(task, rule, args.episodes, settings.reward_baseline)
            row[name] = {"return_std": float(own.std(ddof=1)), "relative_return_std": float(relative.std(ddof=1)),
                         "relative_return_mean": float(relative.mean()), "spread_removed": float(1 - relative.std(ddof=1) / own.std(ddof=1))}
        found[task] = row
        print(f"{task}: return std {row['coin']['return_std']:.4g} with its own reward, {row['coin']['relative_return_std']:.4g} "
              f"against {settings.reward_baseline} (a coin-flip agent); always: {row['always']['return_std']:.4g} -> "
              f"{row['always']['relative_return_std']:.4g}, its mean gain {row['always']['relative_return_mean']:+.4g}", flush=True)
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(found, indent=2) + "\n")


if __name__ == "__main__":
    main()
