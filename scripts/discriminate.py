"""Can triggers be told apart on a task? The oracle bound and the rollout policy against the periodic front.

    python scripts/discriminate.py TASK [--price P] [--episodes 30] [--json PATH]

On the first EPISODES stored test-set episodes it plays every periodic schedule ``every:1`` …
``every:N`` and the task's event triggers (``threshold:X`` at its Benchmark's sweep levels), picks
the best periodic schedule at price P (default: the task's own), then plays ``oracle:BEST`` (an upper
bound, not a policy) and ``rollout:BEST:4:H`` at that price (``H``: 20, or the task's shorter
``Benchmark.lookahead``). Each state-dependent policy is
compared with the periodic front interpolated to its own mean rate of computations, per episode
(``etmpc.experiments.pareto.versus_front``, as ``etmpc sweep`` does): the gain in control objective,
its 95 % CI and the episodes it wins. A task discriminates when the oracle gains clearly, with a CI
that excludes 0 (docs/adding-a-task.md, step 9).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import etmpc
from etmpc.experiments.pareto import best_periodic, episode_table, versus_front
from etmpc.systems import make_system


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("task")
    parser.add_argument("--price", type=float, default=None, help="price of a computation (default: the task's)")
    parser.add_argument("--episodes", type=int, default=30)
    parser.add_argument("--workers", type=int, default=None)
    parser.add_argument("--json", type=Path, default=None, help="write every evaluation and row here")
    args = parser.parse_args()
    system = make_system(args.task)
    price = system.recompute_price if args.price is None else args.price
    periodic = [f"every:{t}" for t in range(1, system.horizon + 1)]
    events = [f"threshold:{x:g}" for x in system.benchmark.sweep_thresholds]
    common = dict(episodes=args.episodes, progress=False, **({} if args.workers is None else {"workers": args.workers}))
    started = time.perf_counter()
    fixed = etmpc.evaluate(args.task, periodic + events, **common).to_json()
    best = best_periodic(fixed, periodic, price, system.objective_sense)
    specs = [f"oracle:{best}", f"rollout:{best}:4:{system.benchmark.capped(20)}"]
    priced = etmpc.evaluate(args.task, specs, recompute_price=price, **common).to_json()
    table = {**episode_table(fixed), **episode_table(priced)}
    print(f"{args.task}: best periodic schedule at price {price:g}: {best}; {args.episodes} episodes, "
          f"{time.perf_counter() - started:.0f} s")
    print(f"{'policy':28s} {'computations':>12s}  {'gain over the front at its rate':>31s}  better in")
    rows = {}
    for spec in events + specs:
        rows[spec] = row = versus_front(table, periodic, spec, system.objective_sense)
        if row is None:
            print(f"{spec:28s} outside the periodic schedules' range of rates")
            continue
        ci = row["gain_percent_ci95"]
        ci = f"{ci:.2f} %" if ci is not None else "(one episode)"
        print(f"{spec:28s} {row['computations']:12.1f}  {row['gain_percent']:+18.2f} % ± {ci:>8s}  "
              f"{row['better_episodes']}/{row['episodes']}")
    if args.json is not None:
        args.json.write_text(json.dumps({"price": price, "best_periodic": best, "fixed": fixed, "priced": priced, "rows": rows}))


if __name__ == "__main__":
    main()
