"""Replay a sample of every kept leaderboard row with this checkout and compare each episode's score with ``==``.

    python scripts/replay_rows.py            # 3 episodes of every kept row (a few minutes on 2 cores)
    python scripts/replay_rows.py 10         # 10 episodes of each

A change that must leave every number as it was (a default option, a refactoring) is checked here against the
rows the leaderboard keeps (``results/leaderboard/``): each sampled episode's normalised score, a function of
its objective and the stored references, must equal the kept row's bit for bit. Rows whose policy files changed
since they were kept, and the oracle's and the rollout meter's (the references' own, which the test suite
replays), are skipped.
"""

from __future__ import annotations

import hashlib
import json
import sys
from pathlib import Path

from etmpc.evaluation import metrics
from etmpc.evaluation.evaluate import evaluate
from etmpc.evaluation.references import stored
from etmpc.systems import names


def main() -> None:
    episodes = int(sys.argv[1]) if len(sys.argv) > 1 else 3
    checked = differ = 0
    for folder in sorted(Path("results/leaderboard").iterdir()):
        if not folder.is_dir() or folder.name in ("oracle", "rollout-meter"):
            continue
        for task in names():
            path = folder / f"{task}.json"
            if not path.is_file():
                continue
            kept = json.loads(path.read_text())
            files = kept["key"].get("files_sha256") or {}
            if any(hashlib.sha256(Path(f).read_bytes()).hexdigest() != digest for f, digest in files.items()):
                continue  # its policy changed: the leaderboard plays the row again
            refs = stored(task)
            played = evaluate(task, [kept["key"]["spec"]], episodes, workers=2, progress=False)
            for run in played.runs:
                best, cost = refs.costs(refs.periodic[refs.best][run.episode]), refs.costs(run.objective)
                score = float(metrics.normalized_scores(cost, best, refs.gap))
                checked += 1
                want = kept["row"]["episode_scores"][run.episode]
                if score != want:
                    differ += 1
                    print(f"{task} {kept['key']['spec']} episode {run.episode}: {score!r}, kept {want!r}")
    print(f"{checked} episodes of kept rows replayed, {differ} differ")
    sys.exit(1 if differ else 0)


if __name__ == "__main__":
    main()
