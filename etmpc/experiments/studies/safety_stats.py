"""The safety audit's arithmetic (``etmpc study safety``): one policy's failures on the audit episodes, and a
learner paired with the best fixed schedule episode by episode. Pure functions of outcome arrays, rows of
``(objective, failures, recomputes)`` per episode as :func:`etmpc.learning.jobs.episode_outcomes` gives them.

The issue's safety target: the upper bound of the 95 % CI of the paired difference (learner failures minus the
schedule's, per episode) at most :data:`TARGET`. The CI is the normal one, ``mean ± 1.96 sd / sqrt(n)``
(:func:`etmpc.evaluation.metrics.mean_ci95`), and beside it a paired percentile bootstrap (the episodes' differences
resampled, seeded: :func:`etmpc.evaluation.metrics.stratified_interval` on one sample), which does not lean on
normality where failures are rare and a few episodes carry them all.
"""

from __future__ import annotations

import numpy as np

from etmpc.common.sense import sign
from etmpc.evaluation.metrics import BOOTSTRAP_SEED, mean_ci95, stratified_interval
from etmpc.learning.shields import SAFETY_BOUND

# the largest upper bound of the paired failures CI accepted, failures per episode: the bound a shield rule is
# certified by on validation episodes (etmpc.learning.shields), held here on fresh ones
TARGET = SAFETY_BOUND
OBJECTIVE, FAILURES, RECOMPUTES = 0, 1, 2  # the columns of an outcome array


def outcome(rows: np.ndarray) -> dict:
    """One policy on the audit episodes: its mean objective and recomputes, its failures per episode (± a 95 %
    CI), how many episodes had any, and the most in one episode (where a failure is a step outside the safe set,
    how long the worst episode stayed out)."""
    rows = np.asarray(rows, dtype=float)
    failures = rows[:, FAILURES]
    return {
        "objective": float(np.mean(rows[:, OBJECTIVE])),
        "recomputes": float(np.mean(rows[:, RECOMPUTES])),
        "failures": float(np.mean(failures)),
        "failures_ci95": mean_ci95(failures),
        "failed_episodes": int(np.count_nonzero(failures > 0)),
        "worst_episode_failures": float(np.max(failures)),
    }


def _mean(sample, axis=-1):
    return np.mean(sample, axis=axis)


def paired(rows: np.ndarray, fixed: np.ndarray, sense: str, seed: int = BOOTSTRAP_SEED) -> dict:
    """``rows`` (a learner's outcomes) against ``fixed`` (the schedule's, on the same episodes in the same order):
    the paired failures difference per episode (mean, normal 95 % CI half-width, its upper bound, the bootstrap's
    interval, whether the upper bound meets :data:`TARGET`); the same for the share of episodes with any failure
    (how often, whatever how long: where a failure is a step outside, the failures count severity too); and the
    paired objective difference as a percentage of
    the schedule's mean objective, oriented so that above 0 is better (± its 95 % CI)."""
    rows, fixed = np.asarray(rows, dtype=float), np.asarray(fixed, dtype=float)
    if rows.shape != fixed.shape or len(rows) < 2:
        raise ValueError(f"paired outcomes need the same episodes, at least two: {rows.shape} and {fixed.shape}")
    difference = rows[:, FAILURES] - fixed[:, FAILURES]
    mean, half = float(np.mean(difference)), mean_ci95(difference)
    if np.all(difference == difference[0]):  # no spread: every resample is the same (scipy's bootstrap would warn)
        bootstrap = (float(difference[0]), float(difference[0]))
    else:
        bootstrap = stratified_interval([difference], _mean, seed=seed)
    incidents = (rows[:, FAILURES] > 0).astype(float) - (fixed[:, FAILURES] > 0)  # an episode with any failure: 1
    scale = 100.0 / abs(float(np.mean(fixed[:, OBJECTIVE])))
    objective = sign(sense) * (rows[:, OBJECTIVE] - fixed[:, OBJECTIVE])
    return {
        "failures_difference": mean,
        "failures_difference_ci95": half,
        "failures_difference_upper": mean + half,
        "failures_difference_bootstrap": list(bootstrap),
        "meets_target": bool(mean + half <= TARGET),
        "failed_episodes_difference": float(np.mean(incidents)),
        "failed_episodes_difference_ci95": mean_ci95(incidents),
        "objective_gain_percent": scale * float(np.mean(objective)),
        "objective_gain_percent_ci95": scale * mean_ci95(objective),
        "recomputes_difference": float(np.mean(rows[:, RECOMPUTES] - fixed[:, RECOMPUTES])),
    }
