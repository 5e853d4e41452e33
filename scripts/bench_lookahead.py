"""CPU time per episode of the leaderboard's two slowest rows: the oracle and the rollout meter.

Plays ``oracle:BEST`` and ``rollout:BEST:4:H`` (the leaderboard's specs) on the first episodes of
each task's stored test set, one process, and prints the CPU seconds per episode and a digest of
the objectives (so two trees that give the same numbers show the same digest). Run it once per
tree, side by side, to compare an old tree with a new one:

    git worktree add /tmp/old-tree OLD_COMMIT
    PYTHONPATH=/tmp/old-tree python scripts/bench_lookahead.py --json old.json
    PYTHONPATH=. python scripts/bench_lookahead.py --json new.json
    python scripts/bench_lookahead.py --compare old.json new.json
"""

from __future__ import annotations

import argparse
import hashlib
import json
import platform
import time

TASKS = ("cart_pendulum", "cart_pendulum/kicks", "battery", "reacher/jumps")
FUTURES = 4  # the leaderboard's rollout meter


def measure(episodes: int) -> dict:
    import etmpc
    from etmpc.evaluation.evaluate import evaluate
    from etmpc.evaluation.references import references_path
    from etmpc.systems import make_system

    out = {"etmpc": etmpc.__file__, "machine": platform.processor() or platform.machine(), "rows": {}}
    for task in TASKS:
        best = json.loads(references_path(task).read_text())["best"]
        lookahead = make_system(task).benchmark.lookahead
        for spec in (f"oracle:{best}", f"rollout:{best}:{FUTURES}:{lookahead}"):
            evaluate(task, [spec], episodes=1, workers=1, progress=False)  # warm: compiled code, caches
            started = time.process_time()
            result = evaluate(task, [spec], episodes=episodes, workers=1, progress=False)
            cpu = (time.process_time() - started) / episodes
            objectives = [r.objective for r in sorted(result.runs, key=lambda r: r.episode)]
            digest = hashlib.sha256(json.dumps(objectives).encode()).hexdigest()[:16]
            out["rows"][f"{task} {spec}"] = {"cpu_s_per_episode": cpu, "objectives_sha256": digest}
            print(f"{task:22s} {spec:32s} {cpu:7.3f} s/episode  objectives {digest}", flush=True)
    return out


def compare(old_path: str, new_path: str) -> None:
    old, new = (json.load(open(p)) for p in (old_path, new_path))
    print(f"{'row':56s} {'old s/ep':>9s} {'new s/ep':>9s} {'speed-up':>9s}  same numbers")
    for row, a in old["rows"].items():
        b = new["rows"][row]
        print(
            f"{row:56s} {a['cpu_s_per_episode']:9.3f} {b['cpu_s_per_episode']:9.3f} "
            f"{a['cpu_s_per_episode'] / b['cpu_s_per_episode']:8.2f}x  {a['objectives_sha256'] == b['objectives_sha256']}"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--episodes", type=int, default=5)
    parser.add_argument("--json", help="write the measurements here")
    parser.add_argument("--compare", nargs=2, metavar=("OLD", "NEW"), help="compare two --json files")
    args = parser.parse_args()
    if args.compare:
        compare(*args.compare)
        return
    result = measure(args.episodes)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(result, f, indent=1)


if __name__ == "__main__":
    main()
