"""What one pool of workers for every stage saves: a sweep run twice, side by side in one process.

    python scripts/bench_shared_pools.py TASK [--out DIR] [--workers 2] [--quick]

Runs ``etmpc sweep TASK`` into ``DIR/own`` with a new pool of workers per stage (as before
``etmpc.evaluation.workers.shared_pools``), then into ``DIR/shared`` with one pool for the whole
sweep, and prints both wall times, their ratio, and whether the two sweeps' numbers agree.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import time
from pathlib import Path

from etmpc.experiments import sweep as sweeps


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("task")
    parser.add_argument("--out", type=Path, default=Path("results/bench_shared_pools"))
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--quick", action="store_true")
    args = parser.parse_args()
    settings = sweeps.plan([args.task], quick=args.quick)[args.task]
    seconds, paretos = {}, {}
    shared = sweeps.shared_pools
    for name in ("own", "shared"):
        sweeps.shared_pools = shared if name == "shared" else contextlib.nullcontext
        started = time.perf_counter()
        paretos[name] = sweeps.sweep(args.task, args.out / name, settings, args.workers, progress=False)
        seconds[name] = time.perf_counter() - started
    sweeps.shared_pools = shared
    def strip(name: str) -> str:  # the numbers, without the timings and the run's own directory in policy paths
        kept = {k: v for k, v in paretos[name].items() if k not in ("wall_seconds_this_invocation", "cpu_seconds_of_evaluations")}
        return json.dumps(kept, sort_keys=True, default=str).replace(str(args.out / name), "DIR")

    print(f"{args.task}: a pool per stage {seconds['own']:.1f} s, one pool {seconds['shared']:.1f} s, "
          f"ratio {seconds['own'] / seconds['shared']:.3f}; the same numbers: {strip('own') == strip('shared')}")


if __name__ == "__main__":
    main()
