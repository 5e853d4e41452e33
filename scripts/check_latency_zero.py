"""Latency 0 is the paper's loop bit for bit: the stored references (every:1, every:3, every:5 on all 100
episodes, the oracle on the first 5) and the leaderboard's shipped DPI and PPO rows, played again now,
against their stored numbers, compared exactly (``==`` on the floats), on the four tasks without time in
the loop.

    python scripts/check_latency_zero.py
"""

import json
from pathlib import Path
from etmpc.evaluation.evaluate import evaluate
from etmpc.evaluation.references import stored


def main():
    REPO = Path(__file__).resolve().parents[1]
    board = json.loads((REPO / "docs/leaderboard.json").read_text())
    rows = {(e["name"], r["task"]): r for e in board["entries"] for r in e["rows"]}
    checked = mismatched = 0
    for task, folder in [
        ("cart_pendulum", "cart_pendulum"),
        ("cart_pendulum/kicks", "cart_pendulum-kicks"),
        ("reacher", "reacher"),
        ("battery", "battery"),
    ]:
        refs = stored(task)
        specs = ["every:1", "every:3", "every:5", f"oracle:{refs.best}"]
        oracle_eps = 5
        result = evaluate(task, specs[:3], workers=2, progress=False)
        oracle = evaluate(task, specs[3:], episodes=oracle_eps, workers=2, progress=False)
        for spec in specs:
            src = oracle if spec.startswith("oracle") else result
            got = [r.objective for r in sorted((r for r in src.runs if r.policy == spec), key=lambda r: r.episode)]
            want = refs.oracle[:oracle_eps] if spec.startswith("oracle") else refs.periodic[spec]
            same = got == list(want)
            checked += len(got)
            mismatched += 0 if same else 1
            print(f"{task:22s} {spec:18s} {len(got):3d} episodes: {'identical' if same else 'DIFFERENT'}", flush=True)
        learned = evaluate(
            task,
            [f"rl:{REPO}/policies/{folder}/learned.json", f"sb3:{REPO}/policies/{folder}/ppo.zip"],
            workers=2,
            progress=False,
        )
        for name, summary in zip(["DPI (shipped)", "PPO (shipped)"], learned.summaries):
            want = rows[(name, task)]["objective_mean"]
            same = summary.objective_mean == want
            mismatched += 0 if same else 1
            print(
                f"{task:22s} {name:18s} 100 episodes: mean {summary.objective_mean!r} vs leaderboard {want!r}: "
                + ("identical" if same else "DIFFERENT"),
                flush=True,
            )
    print(f"{checked} reference episodes and 8 leaderboard rows checked; {mismatched} differ")


if __name__ == "__main__":
    main()
