"""Cross-check the scorecard's aggregate against rliable's own implementation, outside the project.

    python3 -m venv /tmp/rlv && /tmp/rlv/bin/pip install rliable==1.2.0 'pandas<3'
    etmpc score every:2 every:5 --json card.json
    /tmp/rlv/bin/python scripts/check_rliable.py card.json

rliable (Agarwal et al., 2021) is archived upstream: version 1.2.0 no longer imports with pandas 3
(its dependency ``arch`` fails), which is why etmpc computes the same statistics with
``scipy.stats.bootstrap`` instead. This script reads a scorecard's JSON, builds each trigger's
(episodes x tasks) matrix of normalized scores, and prints rliable's IQM and stratified-bootstrap CI
beside etmpc's: the point estimates agree to rounding, the intervals to the bootstrap's noise.
"""

import json
import sys

import numpy as np
from rliable import library, metrics


def main(path: str) -> None:
    card = json.load(open(path))
    print(f"{'trigger':<28}{'rliable IQM':>14}{'etmpc IQM':>12}{'rliable 95 % CI':>22}{'etmpc 95 % CI':>22}")
    for a in card["aggregates"]:
        rows = [r for r in card["rows"] if r["policy"] == a["policy"] and r["episode_scores"]]
        matrix = np.array([r["episode_scores"] for r in rows]).T  # runs (episodes) x tasks
        point, ci = library.get_interval_estimates({"x": matrix}, lambda x: np.array([metrics.aggregate_iqm(x)]),
                                                   reps=2000)
        low, high = ci["x"][:, 0]
        ours = "[{:.2f}, {:.2f}]".format(*a["iqm_ci95"])
        print(f"{a['policy']:<28}{point['x'][0]:>14.4f}{a['iqm']:>12.4f}{f'[{low:.2f}, {high:.2f}]':>22}{ours:>22}")


if __name__ == "__main__":
    main(sys.argv[1])
