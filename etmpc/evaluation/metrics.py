"""The benchmark's statistics: pure functions of score and objective arrays, as rliable's ``metrics.py``.

No playing, no files, no formatting: every function here takes numbers and gives numbers, and the same
numbers give the same bits (the bootstrap is seeded). :mod:`etmpc.evaluation.scorecard` holds the
results and plays the policies; :mod:`etmpc.evaluation.compare` pairs evaluations episode by episode.

**The sense.** An objective is a cost (``"min"``: lower is better) or a profit (``"max"``). Which way is
better is decided in one place, :mod:`etmpc.common.sense` (re-exported here, and usable by the views):
:func:`oriented` turns objectives into values where higher is better, :func:`best` picks the best of
candidates, :func:`higher_or_lower` says it in words.

**The normalized score** of a policy with per-episode costs ``c_e`` (lower is better) between a
baseline ``B_e`` (0) and a reference with the mean gap ``D = mean_e (B_e - O_e)`` (100):
``s_e = 100 (B_e - c_e) / D`` per episode, and the task's score ``100 mean_e (B_e - c_e) / D`` (the
mean summed exactly, :func:`exact_mean`).

**The aggregates** over tasks, each a sample of episode scores (rliable's, Agarwal et al. 2021): the
interquartile mean of every episode score together, the probability of improvement (per task the share
of episodes with a score above 0, ties counting half; averaged over tasks), the performance profile, and
95 % stratified bootstrap intervals (episodes resampled within each task).
"""

from __future__ import annotations

import math

import numpy as np

from etmpc.common.numerics import fsum
from etmpc.common.sense import SENSES, best, higher_or_lower, oriented, sign  # noqa: F401 (re-exported)

BOOTSTRAP_RESAMPLES = 2000
BOOTSTRAP_SEED = 0
# The fewest episodes per task for which a card's 95 % CIs (a task's 1.96 sd / sqrt(n), the suite's percentile
# bootstrap) cover about what they say. On normal scores the 1.96 interval covers 91.8 % at 10 episodes, 93.5 % at
# 20, 94.0 % at 30 (the t quantile it stands for); episode scores are skewed, and do worse: the percentile
# bootstrap interval of the mean of the stored oracles' episode scores, subsamples of n episodes, 300 draws,
# covered the whole test set's mean in 83/90/92 % of draws (reacher, n = 10/20/30) and 79/87/91 % (quadrotor),
# 93 % for both at 50 (the IQM's interval did better: 92-96 % from 10 on). Below this the command says so
# (:func:`etmpc.evaluation.scoretable.format_scorecard`); the card itself is the same.
CI_EPISODES = 30  # measured by scripts/ci_coverage.py


# -- per task ---------------------------------------------------------------------------------------
def exact_mean(values) -> float:
    """The mean, summed exactly (``fsum``): the same on every machine, and ``mean(x) / mean(x)`` is 1."""
    values = list(np.asarray(values, dtype=float))
    return fsum(values) / len(values)


def normalized_scores(costs, baseline, gap: float) -> np.ndarray:
    """Per episode, ``100 (B_e - c_e) / D``: 0 is the baseline's cost ``B_e``, 100 is ``D`` better."""
    return 100.0 * (baseline - costs) / gap


def normalized_score(costs, baseline, gap: float) -> float:
    """The task's score, ``100 mean_e (B_e - c_e) / D`` (the mean of :func:`normalized_scores`, summed exactly)."""
    return 100.0 * exact_mean(baseline - costs) / gap


def mean_ci95(values) -> float:
    """The half-width of the 95 % normal interval of the mean, ``1.96 sd / sqrt(n)``; NaN below two values."""
    values = np.asarray(values, dtype=float)
    return float(1.96 * np.std(values, ddof=1) / math.sqrt(values.size)) if values.size > 1 else math.nan


def episode_improvement(scores) -> np.ndarray:
    """Per episode: 1 where the score is above 0 (better than the baseline), 0.5 on a tie, else 0."""
    scores = np.asarray(scores, dtype=float)
    return (scores > 0) + 0.5 * (scores == 0)


def improvement_share(scores) -> float:
    """The share of episodes better than the baseline (ties counting half): a task's P(improve)."""
    return float(np.mean(episode_improvement(scores)))


def paired_differences(values, reference, sense: str) -> dict:
    """``values - reference``, paired per episode: the episodes, the mean difference, its 95 % CI
    (:func:`mean_ci95`) and the episodes where ``values`` is the better (NaN means for none)."""
    diff = np.asarray(values, dtype=float) - np.asarray(reference, dtype=float)
    return {
        "episodes": len(diff),
        "mean_difference": float(diff.mean()) if len(diff) else math.nan,
        "ci95": mean_ci95(diff),
        "better_episodes": int((oriented(diff, sense) > 0).sum()),
    }


# -- over tasks -------------------------------------------------------------------------------------
def _iqm(*samples, axis=-1):
    """The 25 %-trimmed mean of every sample together (vectorised, for the bootstrap)."""
    from scipy import stats  # here, not at the top: scipy.stats takes 0.4 s to import, and most commands never use it

    return stats.trim_mean(np.concatenate(samples, axis=axis), 0.25, axis=axis)


def _mean_of_means(*samples, axis=-1):
    return np.mean(np.stack([np.mean(s, axis=axis) for s in samples], axis=-1), axis=-1)


def stratified_interval(
    samples: list[np.ndarray], statistic, resamples: int = BOOTSTRAP_RESAMPLES, seed: int = BOOTSTRAP_SEED
) -> tuple[float, float]:
    """The 95 % percentile interval of ``statistic(*samples)``, each sample resampled on its own
    (``scipy.stats.bootstrap``, seeded); NaNs when a sample has fewer than two values."""
    if any(len(s) < 2 for s in samples):
        return (math.nan, math.nan)
    from scipy import stats

    result = stats.bootstrap(
        tuple(samples),
        statistic,
        n_resamples=resamples,
        method="percentile",
        vectorized=True,
        paired=False,
        rng=np.random.default_rng(seed),
    )
    return float(result.confidence_interval.low), float(result.confidence_interval.high)


def _samples(task_scores) -> list[np.ndarray]:
    return [np.asarray(s, dtype=float) for s in task_scores]


def iqm(task_scores) -> float:
    """The interquartile mean of every task's episode scores together (rliable's ``aggregate_iqm``)."""
    return float(_iqm(*_samples(task_scores)))


def iqm_ci95(task_scores) -> tuple[float, float]:
    """:func:`iqm`'s 95 % stratified bootstrap interval."""
    return stratified_interval(_samples(task_scores), _iqm)


def probability_of_improvement(task_scores) -> float:
    """The mean over tasks of :func:`improvement_share`: each task weighs the same."""
    return float(np.mean([improvement_share(s) for s in task_scores]))


def probability_of_improvement_ci95(task_scores) -> tuple[float, float]:
    """:func:`probability_of_improvement`'s 95 % stratified bootstrap interval."""
    return stratified_interval([episode_improvement(s) for s in task_scores], _mean_of_means)


def performance_profile(task_scores, thresholds) -> np.ndarray:
    """rliable's performance profile: at each threshold ``tau``, the share of episodes whose score
    exceeds ``tau``, averaged over the tasks (each weighs the same); NaNs without a task."""
    samples = _samples(task_scores)
    if not samples:
        return np.full(len(thresholds), math.nan)
    return np.mean([(s[None, :] > np.asarray(thresholds)[:, None]).mean(axis=1) for s in samples], axis=0)
