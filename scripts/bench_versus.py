"""``etmpc bench`` of this tree against an earlier commit, side by side in one run.

    python scripts/bench_versus.py REV [TASK ...] [--episodes 5] [--rounds 3]

Checks ``REV`` out into a temporary git worktree, then alternates ``etmpc bench --no-reference``
of the old tree and of this one (each in its own process, ``--rounds`` times each), and prints,
per task, the best round of each side and their ratio: the MPC solve median, the rest of a step,
the rollout step (where the old tree has one) and episodes per second under each policy both
trees bench. Best of the rounds, because on a shared machine noise only ever adds time.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def _bench(tree: Path, tasks: list[str], episodes: int, out: Path) -> dict:
    env = dict(os.environ, PYTHONPATH=str(tree), MUJOCO_GL=os.environ.get("MUJOCO_GL", "egl"))
    subprocess.run(
        [sys.executable, "-m", "etmpc.cli", "bench", *tasks, "--episodes", str(episodes), "--no-reference", "--json", str(out)],
        cwd=tree,
        env=env,
        check=True,
        stdout=subprocess.DEVNULL,
    )
    return json.loads(out.read_text())


def _metrics(figures: dict) -> dict[str, tuple[float, bool]]:
    """name -> (value, higher is better)."""
    m = {
        "MPC solve median (ms)": (figures["mpc_solve"]["median_ms"], False),
        "rest of a step, dm_env path (us)": (figures["rest_of_step"]["median_us"], False),
    }
    if "rollout_step" in figures:
        m["rollout step, no solve (us)"] = (figures["rollout_step"]["median_us"], False)
    for spec, rate in figures["episodes_per_second"].items():
        m[f"episodes/s {spec}"] = (rate, True)
    return m


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("rev", help="the earlier commit (anything git rev-parse takes)")
    parser.add_argument("tasks", nargs="*", default=["cart_pendulum", "battery"])
    parser.add_argument("--episodes", type=int, default=5)
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args(argv)

    with tempfile.TemporaryDirectory(prefix="etmpc-versus-") as tmp:
        old = Path(tmp) / "old"
        subprocess.run(
            ["git", "-C", str(REPO), "worktree", "add", "--detach", str(old), args.rev],
            check=True,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        try:
            rounds = {"old": [], "new": []}
            for r in range(args.rounds):
                for side, tree in (("old", old), ("new", REPO)):
                    rounds[side].append(_bench(tree, args.tasks, args.episodes, Path(tmp) / f"{side}{r}.json"))
                    print(f"round {r + 1}/{args.rounds}: {side} done", file=sys.stderr, flush=True)
        finally:
            subprocess.run(["git", "-C", str(REPO), "worktree", "remove", "--force", str(old)], check=False)

    rev = subprocess.run(
        ["git", "-C", str(REPO), "rev-parse", "--short", args.rev], capture_output=True, text=True
    ).stdout.strip()
    print(f"best of {args.rounds} rounds each, {args.episodes} test-set episodes; old = {rev}, new = this tree")
    for task in args.tasks:
        print(f"\n{task}\n{'':38}{'old':>10}{'new':>10}{'new better by':>15}")
        old_m = [_metrics(f[task]) for f in rounds["old"]]
        new_m = [_metrics(f[task]) for f in rounds["new"]]
        for name, (_, higher) in new_m[0].items():
            pick = max if higher else min
            new_v = pick(m[name][0] for m in new_m)
            if name not in old_m[0]:
                print(f"{name:38}{'-':>10}{new_v:>10.3f}")
                continue
            old_v = pick(m[name][0] for m in old_m)
            print(f"{name:38}{old_v:>10.3f}{new_v:>10.3f}{(new_v / old_v if higher else old_v / new_v):>14.2f}x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
