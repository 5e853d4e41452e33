"""Where a task's solve time goes: converged and failed solves, and the SQP iterations they take.

    python scripts/solve_profile.py [TASK] [--policy every:7] [--episodes 12] [--caps 30 50 100]

Plays ``--episodes`` training-distribution episodes (``make_env(random=5000 + i)``, never the stored
test set) of ``TASK`` (default quadrotor) under ``--policy``. Every solve is timed, and made again
from the same guess by the same ``sqpmethod`` with the same options in CasADi's virtual machine,
whose statistics give its SQP iterations (and the cold retry's, when the warm start failed). Prints the
share of the solve time spent in failed solves (a failed warm solve runs to the iteration limit, then
again from a cold start), the share held by the slowest 5 % of solves, the iteration quantiles of the
converged solves, and for each cap how many converged solves needed more iterations than it.
"""

from __future__ import annotations

import argparse
import sys
import time

import casadi as ca
import numpy as np


def main(argv=None) -> int:
    from etmpc.loop import run_episode
    from etmpc.policies import parse_policy
    from etmpc.systems import make_system

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("task", nargs="?", default="quadrotor")
    parser.add_argument("--policy", default="every:7")
    parser.add_argument("--episodes", type=int, default=12)
    parser.add_argument("--caps", type=int, nargs="+", default=[30, 50, 100])
    args = parser.parse_args(argv)

    system = make_system(args.task)
    mpc = system.mpc
    sqp = ca.nlpsol("profiled", "sqpmethod", mpc.nlp, mpc._sqp_options)  # the solve's own SQP, interpreted
    lower, upper = mpc.bounds()
    solves = []  # (seconds, success, SQP iterations)

    def counted(guess, p) -> tuple[int, bool]:
        sqp(x0=guess, p=p, lbx=lower, ubx=upper, lbg=0, ubg=0)
        stats = sqp.stats()
        return stats["iter_count"], stats["success"]

    def profiled(x, u_prev, warm=None, age=0, parameters=None):
        start = time.perf_counter()
        plan = type(mpc).solve(mpc, x, u_prev, warm, age, parameters)
        seconds = time.perf_counter() - start
        p = mpc.parameter_vector(x, u_prev, parameters)
        count, converged = counted(mpc.initial_guess(x, warm, age), p)
        if not converged and warm is not None:  # the solve's cold retry
            count += counted(mpc.initial_guess(x, None, 0), p)[0]
        solves.append((seconds, plan.success, count))
        return plan

    mpc.solve = profiled
    policy = parse_policy(args.policy, system)
    for i in range(args.episodes):
        run_episode(system, system.make_env(random=5000 + i), policy, np.random.default_rng(i))
    del mpc.solve

    seconds = np.array([s[0] for s in solves])
    ok = np.array([s[1] for s in solves])
    iterations = np.array([s[2] for s in solves])[ok]
    slowest = np.sort(seconds)[::-1][: max(1, len(seconds) // 20)]
    print(f"{args.task} under {args.policy}, {args.episodes} training-distribution episodes: {len(seconds)} solves")
    print(f"  {seconds.sum():.1f} s of solves; failed {int((~ok).sum())}, holding {seconds[~ok].sum() / seconds.sum():.0%} of it")
    print(f"  the slowest 5 % of solves hold {slowest.sum() / seconds.sum():.0%}; median solve {1e3 * np.median(seconds):.1f} ms")
    if len(iterations):
        q = np.quantile(iterations, [0.5, 0.9, 0.99])
        print(f"  SQP iterations of the converged: median {q[0]:.0f}, 90 % {q[1]:.0f}, 99 % {q[2]:.0f}, max {iterations.max()}")
    print(f"  iteration limit {mpc.settings.max_iterations} (a failed warm start is retried cold: up to twice that)")
    print("  (the SQP's own count; a solve's success is etmpc's KKT test, which may differ from sqpmethod's)")
    for cap in args.caps:
        print(f"  converged solves that needed more than {cap} iterations: {int((iterations > cap).sum())}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
