"""How often a card's 95 % CIs cover on few episodes: the measurement behind ``etmpc.evaluation.metrics.CI_EPISODES``.

    python scripts/ci_coverage.py   # about a minute

On normal scores: the coverage of ``mean ± 1.96 sd / sqrt(n)`` (a task's CI) and of the same with the
uncorrected sd (what the percentile bootstrap of the mean approaches), from the t distribution. On real,
skewed scores: each task's stored oracle episode scores (its whole test set) taken as the population,
subsamples of ``n`` episodes drawn with replacement, and how often the stratified percentile bootstrap
interval (``metrics.stratified_interval``, 1000 resamples) of the mean and of the IQM holds the population's.
300 draws per cell: a share is good to about ±2.5 %.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import stats

from etmpc.evaluation import metrics
from etmpc.evaluation.references import stored

SIZES = (10, 20, 30, 50)
DRAWS = 300


def main() -> None:
    print("normal scores: n, coverage of 1.96 sd/sqrt(n), of 1.96 sd_ml/sqrt(n)")
    for n in (5, 10, 15, 20, 25, 30, 50, 100):
        t = 2 * stats.t.cdf(1.96, n - 1) - 1
        ml = 2 * stats.t.cdf(1.96 * math.sqrt((n - 1) / n), n - 1) - 1
        print(f"  {n:3d}  {t:.3f}  {ml:.3f}")
    rng = np.random.default_rng(1)
    print("the stored oracles' episode scores: share of draws whose bootstrap interval holds the whole test set's")
    for task in ("cart_pendulum", "battery", "reacher", "quadrotor"):
        refs = stored(task)
        best = refs.costs(np.array(refs.periodic[refs.best]))
        population = metrics.normalized_scores(refs.costs(np.array(refs.oracle)), best, refs.gap)
        mean, iqm = population.mean(), stats.trim_mean(population, 0.25)
        cells = []
        for n in SIZES:
            mean_hits = iqm_hits = 0
            for _ in range(DRAWS):
                sample = rng.choice(population, n)
                low, high = metrics.stratified_interval(
                    [sample], lambda x, axis=-1: np.mean(x, axis=axis), resamples=1000, seed=int(rng.integers(1e9))
                )
                mean_hits += low <= mean <= high
                low, high = metrics.stratified_interval([sample], metrics._iqm, resamples=1000, seed=int(rng.integers(1e9)))
                iqm_hits += low <= iqm <= high
            cells.append(f"n={n}: mean {mean_hits / DRAWS:.2f} iqm {iqm_hits / DRAWS:.2f}")
        print(f"  {task} (skew {stats.skew(population):.1f}): " + "; ".join(cells), flush=True)


if __name__ == "__main__":
    main()
