"""Training throughput and memory: how fast GPOMDP training runs at its start and its end, how much
memory a worker needs, and what that means for the paper's protocol.

    python scripts/bench_training.py cart_pendulum --policy RUN/seed0/last.json [--workers 2] [--backend ray]

Measured side by side in one run, on the worker processes that training itself uses:

- training episodes/s of one worker at the start (the initial policy recomputes ~95 % of the time)
  and at the end (each ``--policy``, e.g. a run's ``last.json``; without one, a policy that keeps
  its plan ~95 % of the time stands in as the cheap extreme);
- test-set evaluation episodes/s for the same policies;
- the peak resident memory of every worker process (``VmHWM``: ``ru_maxrss`` would also count the
  peak of whatever process started this one, since Linux keeps it across ``exec``);
- the paper protocol's wall time projected from these rates (5 seeds x 1500 episodes, evaluated
  every 150 on the 100-episode test set), to set beside a real ``etmpc train`` run.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import sys
import time
from pathlib import Path

import numpy as np

from etmpc.learning.gpomdp import Learner, Settings
from etmpc.policies.learned import INITIAL_KEEP_LOGIT, LogisticPolicy, Normalisation, load_policy
from etmpc.learning.jobs import evaluate_theta, normalisation_states, train_block, _learner_to_json
from etmpc.evaluation.backends import make_backend
from etmpc.evaluation.workers import context


def peak_rss_mib() -> float:
    """This process's peak resident memory in MiB: ``VmHWM`` of its own address space where Linux
    gives it (``ru_maxrss`` survives ``exec``, so a script started by a 1 GiB test runner would
    report 1 GiB), else ``ru_maxrss``."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def _job(job: tuple) -> dict:
    """One measurement on a worker: ``episodes`` training or evaluation episodes of one policy."""
    kind, domain, policy_json, seed, episodes = job
    system, _, testset = context(domain)
    started = time.perf_counter()
    if kind == "train":
        learner = _learner_to_json(Learner.start(np.array(policy_json["theta"]), Settings(), system.episode_steps))
        _, stats = train_block(domain, policy_json, learner, seed, 0, episodes)
        recomputes = float(np.mean([s["recomputes"] for s in stats]))
    else:
        results = [evaluate_theta(domain, testset.sha256, policy_json, 0, e % testset.episodes) for e in range(episodes)]
        recomputes = float(np.mean([r[2] for r in results]))
    elapsed = time.perf_counter() - started
    return {
        "kind": kind,
        "seed": seed,
        "episodes": episodes,
        "seconds": elapsed,
        "recomputes": recomputes,
        "pid": os.getpid(),
        "maxrss_mib": peak_rss_mib(),
    }


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("task", nargs="?", default="cart_pendulum")
    parser.add_argument("--policy", action="append", default=[], metavar="PATH", help="trained policy file(s) for 'end'")
    parser.add_argument("--episodes", type=int, default=20, help="episodes per measurement (default 20)")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--backend", choices=("local", "ray"), default="local")
    parser.add_argument("--json", default=None, metavar="PATH")
    args = parser.parse_args(argv)

    system = context(args.task)[0]
    states = np.concatenate([normalisation_states(args.task, i) for i in range(10)])
    initial = LogisticPolicy.initial(Normalisation.fit(states), args.task, {})
    policies = {"start (initial policy)": initial.to_json()}
    if args.policy:
        for path in args.policy:
            policies[f"end ({path})"] = load_policy(path, args.task, len(system.error_weights)).to_json()
    else:
        keeper = initial.with_theta(np.concatenate([np.zeros(initial.theta.size - 1), [-INITIAL_KEEP_LOGIT]]))
        policies["mostly keeps (bias +3)"] = keeper.to_json()

    # Two measurements per policy and kind, so each worker does both kinds of work.
    jobs = [
        (kind, args.task, policy, seed, args.episodes)
        for policy in policies.values()
        for kind in ("train", "evaluate")
        for seed in range(args.workers)
    ]
    started = time.perf_counter()
    with make_backend(args.backend, args.workers) as backend:
        results = backend.map(_job, jobs)
    wall = time.perf_counter() - started

    rates = {}
    print(
        f"{args.task}: {args.episodes} episodes per measurement, {args.workers} workers ({args.backend}), "
        f"measured together in {wall:.1f} s"
    )
    print(f"{'policy':<44}{'train ep/s':>12}{'eval ep/s':>12}{'recomputes':>12}   (per worker)")
    for i, name in enumerate(policies):
        mine = results[i * 2 * args.workers : (i + 1) * 2 * args.workers]
        rate = {
            kind: sum(r["episodes"] for r in mine if r["kind"] == kind) / sum(r["seconds"] for r in mine if r["kind"] == kind)
            for kind in ("train", "evaluate")
        }
        recomputes = np.mean([r["recomputes"] for r in mine if r["kind"] == "train"])
        rates[name] = dict(rate, recomputes=float(recomputes))
        print(f"{name:<44}{rate['train']:>12.2f}{rate['evaluate']:>12.2f}{recomputes:>12.1f}")

    peak = {}
    for r in results:
        peak[r["pid"]] = max(peak.get(r["pid"], 0.0), r["maxrss_mib"])
    print(f"peak resident memory per worker: {', '.join(f'{v:.0f} MiB' for v in peak.values())} (target <= 1024 MiB)")

    seeds, episodes, every, test_episodes = 5, 1500, 150, 100
    train_episodes = seeds * episodes
    eval_episodes = seeds * (episodes // every + 1) * test_episodes
    projections = {}
    for name, rate in rates.items():
        projections[name] = (train_episodes / rate["train"] + eval_episodes / rate["evaluate"]) / args.workers
    start_name = next(iter(rates))
    print(
        f"paper protocol ({seeds} seeds x {episodes} episodes, {eval_episodes} evaluation episodes), "
        f"projected on {args.workers} workers:"
    )
    for name, seconds in projections.items():
        print(f"  at the rates of {name}: {seconds / 60:.1f} min (target <= 15 min)")
    print(f"  the real run lies between these: it starts at the rates of '{start_name}'")

    if args.json:
        with open(args.json, "w") as f:
            json.dump(
                {
                    "task": args.task,
                    "episodes": args.episodes,
                    "workers": args.workers,
                    "backend": args.backend,
                    "wall_seconds": wall,
                    "rates": rates,
                    "peak_rss_mib": list(peak.values()),
                    "protocol_projection_seconds": projections,
                    "results": results,
                },
                f,
                indent=2,
            )
        print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
