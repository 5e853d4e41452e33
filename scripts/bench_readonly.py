"""What showing a trigger read-only values costs: the loop with its guard and without it, side by side.

    python scripts/bench_readonly.py [TASK ...] [--episodes 20] [--rounds 5] [--policy never]

The loop hands every policy read-only views of the state, the plan and the observation
(:mod:`etmpc.common.frozen`). This plays the same training-distribution episodes under ``--policy``
(``never`` by default: the fewest solves, so the guard's share of a step is at its largest) with the
guard, and with the guard replaced by the identity in the same process; alternating rounds, the best
of each. Prints steps/s of both, their ratio, and checks the two played the same trajectories.
"""

from __future__ import annotations

import argparse
import contextlib
import time

import numpy as np

import etmpc.control.plan as plan_module
import etmpc.loop as loop_module
from etmpc.loop import run_episode
from etmpc.policies import parse_policy
from etmpc.systems import make_system, names


@contextlib.contextmanager
def unguarded():
    """The loop and the plan as they were before the guard: nothing made read-only."""
    saved = (loop_module.readonly, loop_module.frozen, plan_module.readonly, plan_module.FrozenMapping)
    loop_module.readonly = loop_module.frozen = plan_module.readonly = lambda value: value
    plan_module.FrozenMapping = dict
    try:
        yield
    finally:
        loop_module.readonly, loop_module.frozen, plan_module.readonly, plan_module.FrozenMapping = saved


def play(system, env, policy, episodes) -> tuple[float, list]:
    steps, trajectories = 0, []
    start = time.perf_counter()
    for episode in episodes:
        trajectories.append(run_episode(system, env, policy, None, episode))
        steps += trajectories[-1].steps
    return steps / (time.perf_counter() - start), trajectories


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("tasks", nargs="*", default=list(names()))
    parser.add_argument("--episodes", type=int, default=20)
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--policy", default="never")
    args = parser.parse_args()
    print(f"{'task':<22}{'guarded steps/s':>17}{'unguarded':>12}{'ratio':>8}  same trajectories")
    for task in args.tasks:
        system = make_system(task)
        env, policy = system.make_env(), parse_policy(args.policy, system.error_weights, system.name)
        rng = np.random.default_rng(0)
        episodes = [system.draw_episode(rng) for _ in range(args.episodes)]
        best = {"guarded": 0.0, "unguarded": 0.0}
        runs = {}
        for _ in range(args.rounds):
            rate, runs["guarded"] = play(system, env, policy, episodes)
            best["guarded"] = max(best["guarded"], rate)
            with unguarded():
                rate, runs["unguarded"] = play(system, env, policy, episodes)
            best["unguarded"] = max(best["unguarded"], rate)
        same = all(np.array_equal(a.states, b.states, equal_nan=True) and np.array_equal(a.recompute, b.recompute)
                   for a, b in zip(runs["guarded"], runs["unguarded"]))
        print(f"{task:<22}{best['guarded']:>17,.0f}{best['unguarded']:>12,.0f}"
              f"{best['unguarded'] / best['guarded']:>8.3f}  {same}")


if __name__ == "__main__":
    main()
