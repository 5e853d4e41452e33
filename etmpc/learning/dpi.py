"""Direct policy iteration: rollout-labelled, cost-sensitive classification of the logistic policy.

The stronger learner of ``etmpc train --algorithm dpi`` (Lagoudakis & Parr 2003; Lazaric,
Ghavamzadeh & Munos 2010, "Analysis of a classification-based policy iteration algorithm"). Each
iteration, for the current policy ``pi_t``:

1. **States.** Play training episodes under ``pi_t`` and pick ``states_per_episode`` of its
   decisions in each at random.
2. **Rollouts.** At each picked decision, estimate the return of keeping and of recomputing with
   :func:`etmpc.policies.rollout.q_values`: ``futures`` futures sampled from what the controller knows,
   the same for both answers (common random numbers), each simulated ``horizon`` steps ahead
   under ``pi_t`` and valued at ``system.truncation_value`` there.
3. **Classification.** Label the decision *keep* when keeping returns at least as much, weight it
   by how much the better answer gains (``|Q(keep) - Q(recompute)|``: a mistake costs that much),
   and fit ``theta`` by weighted, ridge-regularised logistic regression on every decision labelled
   so far (L-BFGS). ``pi_{t+1}(keep | s) = sigma(theta . phi(s))``.

``pi_0`` is the best fixed schedule among :attr:`Settings.bases`, chosen on training episodes
(never the test set): iteration 0 labels decisions by rollouts over it, so ``pi_1`` already
imitates the rollout policy over the best schedule, which improves on it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize

from etmpc.policies.rollout import q_values

DPI_ENTROPY = 0x6470_6921  # "dpi!"


@dataclass(frozen=True)
class Settings:
    """DPI's hyperparameters."""

    futures: int = 4  # K: sampled futures per labelled decision
    horizon: int = 20  # H: steps simulated ahead of each decision (the MPC's own horizon)
    states_per_episode: int = 25  # decisions labelled per training episode
    ridge: float = 1e-2  # L2 weight on theta (not on the bias), per labelled decision
    bases: tuple[str, ...] = ("always", "every:2", "every:3", "every:4", "every:5")  # candidates for pi_0
    selection_episodes: int = 30  # training episodes that choose pi_0 among the bases

    def __post_init__(self):
        for name in ("futures", "horizon", "states_per_episode", "selection_episodes"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be >= 1, got {getattr(self, name)}")
        if self.ridge < 0:
            raise ValueError(f"ridge must be >= 0, got {self.ridge}")


class Labeller:
    """Plays ``base`` and, at the chosen steps, estimates both answers' returns by rollouts."""

    simulates = True

    def __init__(self, base, featurise, steps: set[int], settings: Settings, rng: np.random.Generator):
        self.base, self.featurise, self.steps, self.settings, self.rng = base, featurise, steps, settings, rng
        self.spec, self.stochastic = f"label:{base.spec}", base.stochastic
        self.rows: list[tuple[np.ndarray, float, float, int]] = []
        self._twin = None

    def decide(self, s, rng) -> bool:
        ctx = s.context
        if ctx.step in self.steps:
            if self._twin is None:
                self._twin = ctx.system.make_env()
            keep, recompute = q_values(ctx, self.base, self.settings.futures, self.rng, self._twin, self.settings.horizon)
            self.rows.append((self.featurise(s), float(np.mean(keep)), float(np.mean(recompute)), ctx.step))
        return self.base.decide(s, rng)


def fit(features: np.ndarray, keep_advantage: np.ndarray, ridge: float, theta0: np.ndarray | None = None) -> np.ndarray:
    """``theta`` minimising the weighted logistic loss of labels ``keep = advantage >= 0`` with
    weights ``|advantage|`` (normalised to mean 1), plus ``ridge / 2 |theta[:-1]|^2`` (the last
    feature is the bias)."""
    features, advantage = np.asarray(features, float), np.asarray(keep_advantage, float)
    n, p = features.shape
    keep = (advantage >= 0).astype(float)
    weight = np.abs(advantage)
    weight = weight / weight.mean() if weight.mean() > 0 else np.ones(n)
    penalty = np.ones(p)
    penalty[-1] = 0.0

    def loss(theta):
        z = features @ theta
        # log(1 + e^z) - keep z, and its gradient (sigma(z) - keep), computed stably.
        value = np.sum(weight * (np.logaddexp(0.0, z) - keep * z)) / n + 0.5 * ridge * np.sum(penalty * theta * theta)
        sig = np.where(z >= 0, 1.0 / (1.0 + np.exp(-np.abs(z))), np.exp(-np.abs(z)) / (1.0 + np.exp(-np.abs(z))))
        grad = features.T @ (weight * (sig - keep)) / n + ridge * penalty * theta
        return value, grad

    start = np.zeros(p) if theta0 is None else np.asarray(theta0, float)
    result = minimize(loss, start, jac=True, method="L-BFGS-B", options={"maxiter": 500, "gtol": 1e-10})
    return result.x


def episode_rngs(seed: int, episode: int) -> list[np.random.Generator]:
    """The draws of DPI's training ``episode`` of ``seed``: the episode, the picked steps, the
    sampled futures and the policy's own decisions."""
    return [np.random.default_rng(np.random.SeedSequence(DPI_ENTROPY, spawn_key=(seed, episode, k))) for k in range(4)]
