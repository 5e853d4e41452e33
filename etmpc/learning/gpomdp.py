"""GPOMDP (Baxter & Bartlett 2001) for the logistic recomputation policy, one episode per update.

For an episode with per-step rewards ``r_t`` (the environment's reward minus the price of a
recompute, so higher is better on both tasks) and the policy's decisions at steps ``t`` in
``D`` (steps where the plan had not run out; forced recomputes are not the policy's doing)::

    G_t = sum_{tau >= t} gamma^(tau - t) r_tau                       (discounted reward to go)
    g   = sum_{t in D} grad log pi(a_t | s_t) (G_t - b_t)
    theta <- theta + alpha g

which is Baxter & Bartlett's eligibility-trace estimate ``sum_t r_t z_t``, ``z_t = gamma z_{t-1} +
grad log pi_t``, reordered (see the tests). For ``pi(keep | s) = sigma(theta . phi)`` and
``a = 1`` meaning recompute, ``grad log pi(a | s) = (1 - a - p_keep) phi``.

``b_t`` is an optional baseline (variance reduction, off by default as in the paper). It is built
from earlier episodes only and depends on nothing the action at ``t`` changes, so the estimate stays
unbiased (``E[grad log pi(a_t | s_t) | s_t] = 0``):

- ``mean``: the running mean of ``G_t`` at each step index, ``b <- b + (G - b) / n``;
- ``state``: a linear value function ``b_t = w . phi(s_t)`` on the policy's own features, fitted by
  ridge least squares to every earlier decision's ``G_t``. The features hold the squares of the
  state, so it can follow a quadratic cost to go; on the cart pendulum most of ``G_t``'s variance is
  the episode's initial state, which this removes and a per-step mean cannot.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from etmpc.common import checks

BASELINES = ("none", "mean", "state")
SCALES = ("none", "advantage")
VALUE_RIDGE = 1.0  # ridge of the state baseline's least squares (features are normalised to O(1))


@dataclass(frozen=True)
class Settings:
    """GPOMDP's hyperparameters (the paper's values by default)."""

    discount: float = 0.975  # gamma
    learning_rate: float = 0.05  # alpha
    baseline: str = "none"  # "none" (the paper), "mean" (per step index) or "state" (linear in phi)
    scale: str = "none"  # "none" (the paper: alpha g) or "advantage" (advantages over their running RMS)

    def __post_init__(self):
        checks.typed(self, finite=True, most=checks.MAX_COUNT)
        if not 0.0 < self.discount <= 1.0:
            raise ValueError(f"discount must be in (0, 1], got {self.discount}")
        if not 0.0 < self.learning_rate < math.inf:
            raise ValueError(f"learning rate must be a finite number > 0, got {self.learning_rate}")
        if self.baseline not in BASELINES:
            raise ValueError(f"baseline must be one of {', '.join(BASELINES)}, got {self.baseline!r}")
        if self.scale not in SCALES:
            raise ValueError(f"scale must be one of {', '.join(SCALES)}, got {self.scale!r}")


def rewards_to_go(rewards: np.ndarray, discount: float) -> np.ndarray:
    """``G_t = r_t + gamma G_{t+1}``."""
    returns = np.empty(len(rewards))
    running = 0.0
    for t in range(len(rewards) - 1, -1, -1):
        running = rewards[t] + discount * running
        returns[t] = running
    return returns


def gradient(
    features: np.ndarray,
    recompute: np.ndarray,
    keep_probability: np.ndarray,
    steps: np.ndarray,
    returns: np.ndarray,
    baseline: np.ndarray | None = None,
) -> np.ndarray:
    """GPOMDP's estimate from one episode.

    ``features (d, p)``, ``recompute (d,)``, ``keep_probability (d,)``: the policy's ``d`` decisions,
    made at step indices ``steps (d,)``; ``returns (T,)`` the rewards to go; ``baseline (d,)``, its
    value at each decision, or None.
    """
    if len(steps) == 0:
        return np.zeros(features.shape[1] if features.ndim == 2 else 0)
    advantage = returns[steps] - (baseline if baseline is not None else 0.0)
    score = (1.0 - np.asarray(recompute, dtype=float)) - keep_probability  # d log pi / d (theta . phi)
    return (score * advantage) @ features


@dataclass
class Learner:
    """The parameters and the baselines' state: everything a checkpoint has to keep."""

    theta: np.ndarray
    settings: Settings
    baseline_mean: np.ndarray  # (T,) running mean of G_t
    episodes: int = 0
    value_gram: np.ndarray | None = None  # (p, p) sum of phi phi^T over earlier decisions ("state")
    value_target: np.ndarray | None = None  # (p,) sum of phi G over earlier decisions ("state")
    advantage_count: int = 0  # decisions seen so far ("advantage" scale)
    advantage_square_sum: float = 0.0  # the sum of their advantages' squares

    def __post_init__(self):
        p = len(self.theta)
        self.value_gram = np.zeros((p, p)) if self.value_gram is None else np.asarray(self.value_gram, float)
        self.value_target = np.zeros(p) if self.value_target is None else np.asarray(self.value_target, float)

    @classmethod
    def start(cls, theta: np.ndarray, settings: Settings, steps: int) -> Learner:
        return cls(np.array(theta, dtype=float), settings, np.zeros(steps), 0)

    def value_weights(self) -> np.ndarray:
        """The state baseline's ``w`` from the decisions seen so far (0 before any)."""
        assert self.value_gram is not None and self.value_target is not None  # made by __post_init__
        return np.linalg.solve(self.value_gram + VALUE_RIDGE * np.eye(len(self.value_target)), self.value_target)

    def _advantage_rms(self, advantage: np.ndarray) -> float:
        """The root mean square of the earlier episodes' advantages (for the first episode, of its own), then this
        episode's added to the running sums."""
        square = float(advantage @ advantage)
        count, total = (self.advantage_count, self.advantage_square_sum) if self.advantage_count else (len(advantage), square)
        self.advantage_count += len(advantage)
        self.advantage_square_sum += square
        rms = math.sqrt(total / count)
        return rms if rms > 0.0 else 1.0  # all advantages 0 so far: g is 0 too

    def update(self, features, recompute, keep_probability, steps, rewards) -> np.ndarray:
        """One GPOMDP step from one episode; returns the gradient used."""
        features, steps = np.asarray(features, float), np.asarray(steps, int)
        returns = rewards_to_go(np.asarray(rewards, dtype=float), self.settings.discount)
        baseline = None
        if self.episodes and self.settings.baseline == "mean":
            baseline = self.baseline_mean[steps]
        elif self.episodes and self.settings.baseline == "state" and len(steps):
            baseline = features @ self.value_weights()
        g = gradient(features, recompute, np.asarray(keep_probability), steps, returns, baseline)
        if self.settings.scale == "advantage" and len(steps):
            g = g / self._advantage_rms(returns[steps] - (baseline if baseline is not None else 0.0))
        self.theta = self.theta + self.settings.learning_rate * g
        self.episodes += 1
        n = len(returns)
        self.baseline_mean[:n] += (returns - self.baseline_mean[:n]) / self.episodes
        if len(steps):
            self.value_gram += features.T @ features
            self.value_target += features.T @ returns[steps]
        return g
