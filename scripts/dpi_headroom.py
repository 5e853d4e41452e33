"""How much a causal trigger could still gain over a learned policy, measured on training-distribution
episodes (never the test set): a rollout over the policy, and DPI continued from it.

* ``score``: each policy's objective on ``--episodes`` episodes of a development stream of the training
  distribution (its own seed entropy: neither DPI's training nor its validation episodes), paired
  against the first policy given, with a 95 % CI (``--out`` keeps every episode's objective, for other
  pairs). A rollout over the learned policy with many futures
  (``rollout:rl:PATH:32:20``) is a one-step lookahead over it with an almost exact Q: what a trigger that
  can see what that lookahead sees would gain over the policy.
* ``refine``: DPI continued from a learned policy: ``--iterations`` more iterations, each labelling
  ``--label-episodes`` episodes played by the current policy with ``--futures`` futures and fitting the
  logistic classifier on that iteration's labels alone (on-policy), each iterate scored as ``score`` does,
  paired against the policy it started from.

    python scripts/dpi_headroom.py score battery always rl:policies/battery/learned.json \\
        rollout:rl:policies/battery/learned.json:32:20 --episodes 60
    python scripts/dpi_headroom.py refine battery rl:policies/battery/learned.json --futures 32 \\
        --label-episodes 60 --iterations 3 --episodes 200 --out results/dpi_refine.json
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from etmpc.evaluation.compare import paired
from etmpc.evaluation.workers import default_workers, make_backend
from etmpc.learning import dpi
from etmpc.learning.jobs import episode_scores
from etmpc.policies.learned import load_policy
from etmpc.systems import make_system

DEVELOPMENT_ENTROPY = 0x646576  # "dev": a stream of its own, apart from training, selection and validation
REFINE_SEED = 1000  # DPI's episode streams for the refining iterations, apart from any training run's seeds


def objectives(pool, task: str, policies: list, episodes: int) -> list[dict[int, float]]:
    """Each policy's objective (a spec or a logistic policy's JSON) on each development episode."""
    return [dict(enumerate(values.tolist())) for values in episode_scores(pool, task, policies, DEVELOPMENT_ENTROPY, episodes)]


def score(pool, args, sense: str) -> dict:
    found = dict(zip(args.policies, objectives(pool, args.task, args.policies, args.episodes)))
    reference = found[args.policies[0]]
    rows = {name: dict(paired(values, reference, sense), objectives=list(values.values())) for name, values in found.items()}
    for name, row in rows.items():
        print(f"{name:55s} {row['objective_mean']:.5f}  {row['gain_percent']:+.2f} % ± {row['gain_percent_ci95']:.2f} "
              f"against {args.policies[0]}", flush=True)
    return {"reference": args.policies[0], "rows": rows}


def refine(pool, args, sense: str) -> dict:
    start = load_policy(args.policies[0].removeprefix("rl:"), make_system(args.task).name)
    settings = dpi.Settings(futures=args.futures, horizon=args.horizon, states_per_episode=args.labels, ridge=args.ridge)
    template = start.to_json()
    [reference] = objectives(pool, args.task, [template], args.episodes)
    current, rows = template, []
    for iteration in range(args.iterations):
        began = time.perf_counter()
        episodes = range(iteration * args.label_episodes, (iteration + 1) * args.label_episodes)
        labelled = pool.map(dpi._label_job, [("label", (args.task, current, settings, template, REFINE_SEED, e)) for e in episodes])
        labels = [row for rows_ in labelled for row in rows_]
        current = dict(template, theta=dpi.fit_labels(labels, settings.ridge, np.asarray(current["theta"])).tolist())
        [values] = objectives(pool, args.task, [current], args.episodes)
        row = dict(paired(values, reference, sense), iteration=iteration + 1, labels=len(labels),
                   seconds=round(time.perf_counter() - began, 1))
        rows.append(row)
        print(f"iteration {iteration + 1}: {row['labels']} labels, {row['objective_mean']:.5f}, {row['gain_percent']:+.2f} % "
              f"± {row['gain_percent_ci95']:.2f} against {args.policies[0]} ({row['seconds']} s)", flush=True)
    return {"start": args.policies[0], "settings": vars(args) | {"out": str(args.out)}, "iterations": rows, "policy": current}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("what", choices=("score", "refine"))
    parser.add_argument("task")
    parser.add_argument("policies", nargs="+", help="score: the reference first, then the others; refine: the rl:PATH to start from")
    parser.add_argument("--episodes", type=int, default=100, help="development episodes scored (default 100)")
    parser.add_argument("--futures", type=int, default=32, help="refine: K per label (default 32)")
    parser.add_argument("--horizon", type=int, default=20, help="refine: H (default 20)")
    parser.add_argument("--labels", type=int, default=25, help="refine: decisions labelled per episode (default 25)")
    parser.add_argument("--label-episodes", type=int, default=60, help="refine: episodes labelled per iteration (default 60)")
    parser.add_argument("--iterations", type=int, default=3)
    parser.add_argument("--ridge", type=float, default=dpi.Settings().ridge)
    parser.add_argument("--workers", type=int, default=default_workers())
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()
    sense = make_system(args.task).objective_sense
    with make_backend("local", args.workers) as pool:
        found = (score if args.what == "score" else refine)(pool, args, sense)
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(found, indent=2) + "\n")


if __name__ == "__main__":
    main()
