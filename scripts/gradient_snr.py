"""How much signal is in GPOMDP's gradient estimate: can a given number of training episodes tell
which way to move the policy?

    python scripts/gradient_snr.py cart_pendulum [--policy PATH] [--episodes 800] [--workers 2]

Plays ``--episodes`` training episodes under one fixed policy (the initial policy of ``etmpc train``
by default) and computes every episode's GPOMDP estimate (the paper's gamma by default), once without a
baseline and once with the ``state`` baseline, cross-fitted (fitted on the other half of the
episodes). For each coordinate of theta it prints the mean estimate, its z-score (mean over its
standard error) and the number of episodes at which that coordinate's z would reach 2. A z-score
well below 2 on every coordinate means the estimates at this sample size are noise, whatever
the learning rate.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

from etmpc.learning.gpomdp import VALUE_RIDGE, Settings, gradient, rewards_to_go
from etmpc.policies.learned import LogisticPolicy, Normalisation, load_policy
from etmpc.learning.jobs import normalisation_states, play
from etmpc.evaluation.workers import context, make_backend

ENTROPY = 0x5A12  # this script's own episodes, apart from training's and the test set's


def _episodes(job: tuple) -> list:
    domain, policy_json, lo, hi = job
    system, env, _ = context(domain)
    policy = LogisticPolicy.from_json(policy_json)
    samples = []
    for e in range(lo, hi):
        episode = system.draw_episode(np.random.default_rng(np.random.SeedSequence(ENTROPY, spawn_key=(e, 0))))
        rng = np.random.default_rng(np.random.SeedSequence(ENTROPY, spawn_key=(e, 1)))
        samples.append(play(system, env, policy.with_theta(policy.theta, record=True), rng, episode))
    return samples


def _value_weights(samples, returns) -> np.ndarray:
    x = np.concatenate([s.features for s in samples])
    y = np.concatenate([g[s.steps] for s, g in zip(samples, returns)])
    return np.linalg.solve(x.T @ x + VALUE_RIDGE * np.eye(x.shape[1]), x.T @ y)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("task", nargs="?", default="cart_pendulum")
    parser.add_argument("--policy", default=None, metavar="PATH", help="policy file (default: train's initial policy)")
    parser.add_argument("--episodes", type=int, default=800)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--discount", type=float, default=Settings().discount, help="gamma (default: the paper's)")
    args = parser.parse_args(argv)

    system = context(args.task)[0]
    if args.policy is None:
        states = np.concatenate([normalisation_states(args.task, i) for i in range(20)])
        policy = LogisticPolicy.initial(Normalisation.fit(states), args.task, {})
    else:
        policy = load_policy(args.policy, args.task, len(system.error_weights))
    gamma = args.discount
    chunk = 25
    jobs = [(args.task, policy.to_json(), lo, min(lo + chunk, args.episodes)) for lo in range(0, args.episodes, chunk)]
    with make_backend("local", args.workers) as backend:
        samples = [s for part in backend.map(_episodes, jobs) for s in part]
    returns = [rewards_to_go(s.rewards, gamma) for s in samples]

    half = len(samples) // 2
    weights = (_value_weights(samples[half:], returns[half:]), _value_weights(samples[:half], returns[:half]))
    print(f"{args.task}: {len(samples)} episodes, {np.mean([s.recomputes for s in samples]):.1f} recomputes per episode, "
          f"gamma {gamma}")
    for name, baseline in (("none", lambda i, s: None), ("state, cross-fitted", lambda i, s: s.features @ weights[i >= half])):
        g = np.array([gradient(s.features, s.recompute, s.keep_probability, s.steps, returns[i], baseline(i, s))
                      for i, s in enumerate(samples)])
        mean, std = g.mean(0), g.std(0, ddof=1)
        z = mean / (std / np.sqrt(len(g)))
        needed = (2 * std / np.maximum(np.abs(mean), 1e-300)) ** 2
        print(f"baseline {name}: max |z| {np.abs(z).max():.2f}; fewest episodes for z = 2 on any coordinate: "
              f"{needed.min():,.0f}")
        print("  coordinate  " + " ".join(f"{i:>7d}" for i in range(len(mean))))
        print("  mean        " + " ".join(f"{v:>7.4f}" for v in mean))
        print("  z           " + " ".join(f"{v:>7.2f}" for v in z))
    return 0


if __name__ == "__main__":
    sys.exit(main())
