"""The ``gpomdp`` study's measurements of the learner itself (:mod:`etmpc.learning.gpomdp`): its training, logged
block by block, and the spread of its gradient estimate at the initial policy under each baseline.

* :func:`train_logged` trains one seed on its episodes ``start..stop-1`` exactly as ``etmpc train`` does
  (:func:`etmpc.learning.jobs.train_block`: the same streams, the same updates, the same parameters; a test holds
  them equal) and says what the block did: the length of each update ``|theta' - theta|``, the net move over the
  block, the keep probability at the policy's decisions, the recomputes and the returns.
* :func:`diagnosis_episode` plays one episode at a fixed policy (the run's initial one) from the study's own
  stream, and :func:`gradient_spread` turns such episodes into one GPOMDP estimate each, per baseline, with the
  baselines cross-fitted (each episode's from the others, as a run's from earlier episodes), so their spread is
  the estimator's own.

Every function a worker runs is a pure function of its arguments.
"""

from __future__ import annotations

import math

import numpy as np

from etmpc.evaluation.workers import context
from etmpc.learning.config import TRAIN_ENTROPY
from etmpc.learning.gpomdp import VALUE_RIDGE, gradient, rewards_to_go
from etmpc.learning.jobs import _learner_from_json, _learner_to_json, play
from etmpc.policies.features import raw_names
from etmpc.policies.learned import LogisticPolicy

DIAGNOSIS_ENTROPY = 0x6469_6167_6E6F_7365  # "diagnose": episodes of the training distribution that train nothing


def _draws(entropy: int, key: tuple[int, ...]) -> tuple[np.random.Generator, np.random.Generator]:
    """The episode's generator and the policy's, as ``etmpc train`` spawns them."""
    return (
        np.random.default_rng(np.random.SeedSequence(entropy, spawn_key=(*key, 0))),
        np.random.default_rng(np.random.SeedSequence(entropy, spawn_key=(*key, 1))),
    )


def train_logged(task: str, policy_json: dict, learner_json: dict, seed: int, start: int, stop: int) -> tuple[dict, dict]:
    """Train ``seed`` on its episodes ``start..stop-1`` (as :func:`etmpc.learning.jobs.train_block`); returns the learner
    and the block's log: ``step`` (the root mean square of ``|theta' - theta|`` per update), ``path`` (their sum),
    ``drift`` (``|theta_stop - theta_start|``), ``keep`` (the mean keep probability at the decisions),
    ``recomputes`` and ``return`` (per episode)."""
    system, env, _ = context(task)
    policy = LogisticPolicy.from_json(policy_json)
    learner = _learner_from_json(learner_json)
    first = learner.theta.copy()
    steps, keeps, recomputes, returns = [], [], [], []
    for e in range(start, stop):
        draw_episode, draw_policy = _draws(TRAIN_ENTROPY, (seed, e))
        sample = play(system, env, policy.with_theta(learner.theta, record=True), draw_policy, system.draw_episode(draw_episode))
        before = learner.theta
        learner.update(sample.features, sample.recompute, sample.keep_probability, sample.steps, sample.rewards)
        steps.append(float(np.linalg.norm(learner.theta - before)))
        keeps.append(float(np.mean(sample.keep_probability)) if len(sample.steps) else float("nan"))
        recomputes.append(sample.recomputes)
        returns.append(float(sample.rewards.sum()))
    log = {
        "episodes": stop,
        "step": math.sqrt(float(np.mean(np.square(steps)))),
        "path": float(np.sum(steps)),
        "drift": float(np.linalg.norm(learner.theta - first)),
        "keep": float(np.nanmean(keeps)),
        "recomputes": float(np.mean(recomputes)),
        "return": float(np.mean(returns)),
    }
    return _learner_to_json(learner), log


def diagnosis_episode(task: str, policy_json: dict, index: int) -> dict:
    """Episode ``index`` of the diagnosis stream at ``policy_json``: what GPOMDP's estimate needs, as lists."""
    system, env, _ = context(task)
    draw_episode, draw_policy = _draws(DIAGNOSIS_ENTROPY, (index,))
    policy = LogisticPolicy.from_json(policy_json).with_theta(LogisticPolicy.from_json(policy_json).theta, record=True)
    sample = play(system, env, policy, draw_policy, system.draw_episode(draw_episode))
    return {
        "features": sample.features.tolist(),
        "recompute": sample.recompute.tolist(),
        "keep_probability": sample.keep_probability.tolist(),
        "steps": sample.steps.tolist(),
        "rewards": sample.rewards.tolist(),
    }


def estimates(episodes: list[dict], discount: float, baseline: str, scale: bool = False) -> np.ndarray:
    """One GPOMDP estimate per episode ``(M, p)``, with ``baseline`` cross-fitted: ``mean``, each step index's mean
    of the other episodes' ``G_t``; ``state``, the ridge fit (the learner's) of ``G_t`` on ``phi`` over the other
    episodes' decisions. ``scale``: each estimate divided by the root mean square of the advantages of all
    episodes (the ``advantage`` scale's divisor, as it settles)."""
    data = [(np.asarray(e["features"], float).reshape(len(e["steps"]), -1), np.asarray(e["steps"], int), e) for e in episodes]
    returns = [rewards_to_go(np.asarray(e["rewards"], float), discount) for _, _, e in data]
    p = data[0][0].shape[1]
    length = max(len(r) for r in returns)
    sums, counts = np.zeros(length), np.zeros(length)
    gram, target = VALUE_RIDGE * np.eye(p), np.zeros(p)
    for (phi, steps, _), g in zip(data, returns):
        sums[: len(g)] += g
        counts[: len(g)] += 1
        gram += phi.T @ phi
        target += phi.T @ g[steps]
    rows, advantages = [], []
    for (phi, steps, e), g in zip(data, returns):
        b = None
        if baseline == "mean":
            others = np.maximum(counts[steps] - 1, 1)
            b = (sums[steps] - g[steps]) / others
        elif baseline == "state":
            b = phi @ np.linalg.solve(gram - phi.T @ phi, target - phi.T @ g[steps])
        rows.append(gradient(phi, np.asarray(e["recompute"], bool), np.asarray(e["keep_probability"]), steps, g, b))
        advantages.append(g[steps] - (0.0 if b is None else b))
    estimates = np.array(rows)
    if scale:
        everything = np.concatenate(advantages)
        estimates = estimates / math.sqrt(float(np.mean(everything**2)))
    return estimates


def spread(g: np.ndarray, names: tuple[str, ...], learning_rate: float, episodes: int) -> dict:
    """What a set of per-episode estimates ``g (M, p)`` says about training at ``learning_rate`` for ``episodes``:
    the step per update (``learning_rate`` times the root mean square of ``|g|``), the estimates' total variance,
    each coordinate's z-score (mean over its standard error), and for the bias (the last coordinate: the keep
    logit everywhere) the move the mean gradient makes over the run against the noise's random walk."""
    m, sd = g.mean(axis=0), g.std(axis=0, ddof=1)
    z = m / np.where(sd > 0, sd / math.sqrt(len(g)), np.inf)
    order = np.argsort(-np.abs(z))
    return {
        "step": learning_rate * math.sqrt(float(np.mean(np.sum(g**2, axis=1)))),
        "variance": float(np.sum(sd**2)),
        "walk": float(learning_rate * math.sqrt(float(np.sum(sd**2))) * math.sqrt(episodes)),
        "mean_norm": float(np.linalg.norm(m)),
        "bias_mean": float(m[-1]),
        "bias_sd": float(sd[-1]),
        "bias_drift": float(learning_rate * m[-1] * episodes),
        "bias_noise": float(learning_rate * sd[-1] * math.sqrt(episodes)),
        "significant": [{"name": names[i], "z": float(z[i])} for i in order if abs(z[i]) > 3.0],
    }


def feature_names(task: str, features: str) -> tuple[str, ...]:
    """The policy's parameters by name: each raw feature, its square, and the bias."""
    system = context(task)[0]
    raw = raw_names(features, system.name, system.state_names)
    return (*raw, *(f"{n}^2" for n in raw), "bias")


#: The estimators the diagnosis compares: (discount, baseline, advantages over their RMS).
ESTIMATORS = (
    (0.975, "none", False),
    (0.975, "mean", False),
    (0.975, "state", False),
    (0.7, "none", False),
    (0.7, "state", False),
    (0.975, "none", True),
    (0.975, "state", True),
)


def estimator_name(discount: float, baseline: str, scaled: bool) -> str:
    return f"gamma {discount:g}, {baseline}{', scaled' if scaled else ''}"


def gradient_spread(task: str, features: str, episodes: list[dict], learning_rate: float, run_episodes: int) -> dict:
    """:func:`spread` of the estimates of each of :data:`ESTIMATORS` (``learning_rate`` in the reward's unit; 1 for the
    scaled ones: their step and walk per unit of alpha), and the reward's scale: the returns' mean and standard
    deviation over the episodes, the mean reward per step, the recompute's price and the mean keep probability."""
    names = feature_names(task, features)
    result: dict = {"estimators": []}  # a list of named rows (a page's number markers find one by its name)
    for discount, baseline, scaled in ESTIMATORS:
        g = estimates(episodes, discount, baseline, scale=scaled)
        rate = 1.0 if scaled else learning_rate
        result["estimators"].append(dict(name=estimator_name(discount, baseline, scaled), **spread(g, names, rate, run_episodes)))
    returns = np.array([sum(e["rewards"]) for e in episodes])
    system = context(task)[0]
    result["reward"] = {
        "return_mean": float(returns.mean()),
        "return_sd": float(returns.std(ddof=1)),
        "per_step": float(np.mean([np.mean(e["rewards"]) for e in episodes])),
        "recompute_price": float(system.recompute_price),
        "keep": float(np.mean([np.mean(e["keep_probability"]) for e in episodes])),
    }
    return result
