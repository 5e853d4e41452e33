"""GPOMDP (Baxter & Bartlett 2001) for the logistic recomputation policy, one episode per update.

For an episode with per-step rewards ``r_t`` (the environment's reward minus the price of a
computation, so higher is better for both systems) and the policy's decisions at steps ``t`` in
``D`` (steps where the plan had not run out; forced recomputes are not the policy's doing)::

    G_t = sum_{tau >= t} gamma^(tau - t) r_tau                       (discounted reward to go)
    g   = sum_{t in D} grad log pi(a_t | s_t) (G_t - b_t)
    theta <- theta + alpha g

which is Baxter & Bartlett's eligibility-trace estimate ``sum_t r_t z_t``, ``z_t = gamma z_{t-1} +
grad log pi_t``, reordered (see the tests). For ``pi(keep | s) = sigma(theta . phi)`` and
``a = 1`` meaning recompute, ``grad log pi(a | s) = (1 - a - p_keep) phi``.

``b_t`` is an optional baseline (variance reduction, off by default as in the paper): the running
mean of ``G_t`` at each step index over the episodes seen so far, ``b <- b + (G - b) / n``. It uses
only earlier episodes, so the estimate stays unbiased.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

BASELINES = ("none", "mean")


@dataclass(frozen=True)
class Settings:
    """GPOMDP's hyperparameters (the paper's values by default)."""

    discount: float = 0.975  # gamma
    learning_rate: float = 0.05  # alpha
    baseline: str = "none"  # "none" (the paper) or "mean": running mean of G_t per step index

    def __post_init__(self):
        if not 0.0 < self.discount <= 1.0:
            raise ValueError(f"discount must be in (0, 1], got {self.discount}")
        if not self.learning_rate > 0.0:
            raise ValueError(f"learning rate must be > 0, got {self.learning_rate}")
        if self.baseline not in BASELINES:
            raise ValueError(f"baseline must be one of {', '.join(BASELINES)}, got {self.baseline!r}")


def rewards_to_go(rewards: np.ndarray, discount: float) -> np.ndarray:
    """``G_t = r_t + gamma G_{t+1}``."""
    returns = np.empty(len(rewards))
    running = 0.0
    for t in range(len(rewards) - 1, -1, -1):
        running = rewards[t] + discount * running
        returns[t] = running
    return returns


def gradient(features: np.ndarray, recompute: np.ndarray, keep_probability: np.ndarray, steps: np.ndarray,
             returns: np.ndarray, baseline: np.ndarray | None = None) -> np.ndarray:
    """GPOMDP's estimate from one episode.

    ``features (d, p)``, ``recompute (d,)``, ``keep_probability (d,)``: the policy's ``d`` decisions,
    made at step indices ``steps (d,)``; ``returns (T,)`` the rewards to go; ``baseline (T,)`` or None.
    """
    if len(steps) == 0:
        return np.zeros(features.shape[1] if features.ndim == 2 else 0)
    advantage = returns[steps] - (baseline[steps] if baseline is not None else 0.0)
    score = (1.0 - np.asarray(recompute, dtype=float)) - keep_probability  # d log pi / d (theta . phi)
    return (score * advantage) @ features


@dataclass
class Learner:
    """The parameters and the baseline's state: everything a checkpoint has to keep."""

    theta: np.ndarray
    settings: Settings
    baseline_mean: np.ndarray  # (T,) running mean of G_t
    episodes: int = 0

    @classmethod
    def start(cls, theta: np.ndarray, settings: Settings, steps: int) -> Learner:
        return cls(np.array(theta, dtype=float), settings, np.zeros(steps), 0)

    def update(self, features, recompute, keep_probability, steps, rewards) -> np.ndarray:
        """One GPOMDP step from one episode; returns the gradient used."""
        returns = rewards_to_go(np.asarray(rewards, dtype=float), self.settings.discount)
        baseline = self.baseline_mean[: len(returns)] if self.settings.baseline == "mean" and self.episodes else None
        g = gradient(np.asarray(features), recompute, np.asarray(keep_probability), np.asarray(steps, int), returns, baseline)
        self.theta = self.theta + self.settings.learning_rate * g
        self.episodes += 1
        n = len(returns)
        self.baseline_mean[:n] += (returns - self.baseline_mean[:n]) / self.episodes
        return g
