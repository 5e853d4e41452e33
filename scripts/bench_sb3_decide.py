"""Microseconds per ``sb3:`` decision: Stable-Baselines3's ``predict`` (what ``sb3:`` called before) against
the numpy network (what it calls now), side by side in one run.

    python scripts/bench_sb3_decide.py [--task cart_pendulum] [--model policies/cart_pendulum/balance/ppo.zip]
                                       [--episodes 20] [--rounds 5]

The augmented states come from real test-set episodes played by the model. Each decision is timed on
its own (``perf_counter_ns``), old and new alternating in rounds, and the median is reported: with the
observation's computation and normalisation (what the loop pays per step), and for the network alone on
the normalised observation. PyTorch runs on one thread, as the workers ran it. Both answers are
compared at every call: the script fails if they ever differ.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from etmpc.evaluation.workers import play_test_episode
from etmpc.loop import AugmentedState
from etmpc.policies.sb3 import load_sb3


class _Recorder:
    """The model deciding, with a copy of every augmented state it was shown."""

    stochastic = False
    spec = "sb3-recorded"

    def __init__(self, policy):
        self.policy, self.states = policy, []

    def decide(self, s, rng) -> bool:
        self.states.append(
            AugmentedState(np.array(s.x), np.array(s.x_plan), s.age, np.array(s.x_predicted), s.plan, s.observation)
        )
        return self.policy.decide(s, rng)


def _timed(decide, inputs) -> tuple[list[float], list[int]]:
    """Microseconds of each call of ``decide`` on each input, and its answers."""
    clock, times, answers = time.perf_counter_ns, [], []
    for value in inputs:
        start = clock()
        answer = decide(value)
        times.append((clock() - start) / 1000)
        answers.append(int(answer))
    return times, answers


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--task", default="cart_pendulum")
    parser.add_argument("--model", default="policies/cart_pendulum/balance/ppo.zip")
    parser.add_argument("--episodes", type=int, default=20)
    parser.add_argument("--rounds", type=int, default=5)
    args = parser.parse_args()

    import torch
    from stable_baselines3 import PPO

    torch.set_num_threads(1)
    policy = load_sb3(args.model, args.task)
    model = PPO.load(args.model, device="cpu")  # the old path: trusted files only
    recorder = _Recorder(policy)
    for episode in range(args.episodes):
        play_test_episode(args.task, recorder, 0, 0, episode)
    states = recorder.states
    observations = [policy.normalised(s) for s in states]

    cases = {
        "observation + network": (
            states,
            lambda s: int(model.predict(policy.normalised(s), deterministic=True)[0]),
            lambda s: policy.decide(s, None),
        ),
        "network alone": (observations, lambda x: int(model.predict(x, deterministic=True)[0]), policy.network.action),
    }
    medians = {}
    for name, (inputs, old, new) in cases.items():
        old_times, new_times = [], []
        for _ in range(args.rounds):  # alternating: both meet the same state of the machine
            times, old_answers = _timed(old, inputs)
            old_times += times
            times, new_answers = _timed(new, inputs)
            new_times += times
            if old_answers != new_answers:
                raise SystemExit(f"{name}: the numpy network and SB3's predict disagree")
        medians[name] = statistics.median(old_times), statistics.median(new_times)

    calls = len(states) * args.rounds
    print(
        f"{args.task}: {len(states)} decisions of {args.episodes} test-set episodes, each timed {args.rounds} times "
        f"({calls} calls per cell); median microseconds per decision, torch on 1 thread"
    )
    print(f"{'':<24}{'old: SB3 predict':>18}{'new: numpy':>14}{'old / new':>12}")
    for name, (old, new) in medians.items():
        print(f"{name:<24}{old:>18.1f}{new:>14.1f}{old / new:>12.1f}")


if __name__ == "__main__":
    main()
