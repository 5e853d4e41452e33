"""What a task's noisy variant adds to its base (``cart_pendulum/kicks_noisy``, ``quadrotor/waypoints_noisy``):
a sensor that reads part of the state with noise, the extended Kalman filter between it and the controller
(:mod:`etmpc.control.sensing`), and two features of the filter for learned triggers, beside the base task's:

* ``innovation_nis``: the last reading's normalised innovation squared (``nu' S^-1 nu``): about the number of
  entries read while the filter's model holds, large right after something it did not predict (a kick, a gust);
* ``estimate_std``: the estimate's standard deviation, ``sqrt(trace P)``: how far to trust the state error a
  threshold trigger reads. It sums the variances' sizes, ``sqrt(sum |P_ii|)``, the same number for any
  covariance: a filter driven far from its model (a quadrotor tumbling past its Euler angles' singularity)
  can round one to a negative variance, which then reads as a large spread, not as NaN.

A trigger on the state error reads the filter's estimate minus the plan's prediction: partly noise, which a
threshold fires on and a learner can learn to discount. The variants play their base task's episodes (the same
seed), so their scores pair with it episode by episode.
"""

from __future__ import annotations

import numpy as np

FILTER_FEATURES = ("innovation_nis", "estimate_std")


def filter_features(s) -> np.ndarray:
    """:data:`FILTER_FEATURES` at augmented state ``s`` (its ``belief``; zeros where the sensor is exact)."""
    belief = s.belief
    if belief is None:
        return np.zeros(2)
    return np.array([belief.nis, float(np.sqrt(np.abs(np.diag(belief.covariance)).sum()))])


class WithFilterFeatures:
    """A system's exogenous features followed by :data:`FILTER_FEATURES`: ``base(s)`` then the filter's."""

    def __init__(self, base):
        self.base = base

    def __call__(self, s) -> np.ndarray:
        return np.concatenate([self.base(s), filter_features(s)])
