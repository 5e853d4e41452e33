"""What recording costs: the same evaluation with and without ``--record``, side by side in one run.

    python scripts/bench_recording.py [TASK ...] [--policy SPEC ...] [--rounds 2] [--workers 2]

For each task and policy, alternates plain and recorded evaluations of the whole test set
(``--rounds`` times each, best of the rounds reported) and prints the wall times, their ratio and
the recording's size.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

from etmpc import evaluate


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("tasks", nargs="*", default=["cart_pendulum", "battery"])
    parser.add_argument("--policy", action="append", default=None, metavar="SPEC", help="default: always and every:3")
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args(argv)
    policies = args.policy or ["always", "every:3"]

    print(f"{'task':<15}{'policy':<12}{'plain s':>9}{'recorded s':>12}{'ratio':>8}{'size MB':>10}{'kB/episode':>12}")
    with tempfile.TemporaryDirectory() as tmp:
        for task in args.tasks:
            for spec in policies:
                plain, recorded = [], []
                path = Path(tmp) / f"{task}.rrd"
                for _ in range(args.rounds):
                    started = time.perf_counter()
                    result = evaluate(task, [spec], workers=args.workers, progress=False)
                    plain.append(time.perf_counter() - started)
                    started = time.perf_counter()
                    evaluate(task, [spec], workers=args.workers, progress=False, record=path)
                    recorded.append(time.perf_counter() - started)
                episodes = len(result.runs)
                size = path.stat().st_size
                print(
                    f"{task:<15}{spec:<12}{min(plain):>9.2f}{min(recorded):>12.2f}{min(recorded) / min(plain):>8.2f}"
                    f"{size / 1e6:>10.1f}{size / 1e3 / episodes:>12.0f}"
                )
    return 0


if __name__ == "__main__":
    sys.exit(main())
