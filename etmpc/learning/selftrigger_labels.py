"""The self-trigger's labels and its fit (steps 2 and 3 of :mod:`etmpc.learning.selftrigger`): on a training
episode played by the base, at a few picked steps, a plan solved and each candidate keep length scored by its mean
return over sampled futures (:func:`label_episode`, DPI's labeller with this label); then the softmax model fitted to
each labelled solve's best candidate (:func:`fit`)."""

from __future__ import annotations

from typing import Protocol

import numpy as np
from scipy.optimize import minimize

from etmpc.evaluation.workers import context
from etmpc.learning import dpi
from etmpc.loop import Snapshot, play_on, run_episode
from etmpc.policies import parse_policy
from etmpc.policies.selftrigger import plan_features

SELF_ENTROPY = 0x73656C66  # "self"


class LabelSettings(Protocol):
    """What labelling reads of a run's settings (:class:`etmpc.learning.selftrigger.SelfSettings`)."""

    @property
    def solves_per_episode(self) -> int: ...

    @property
    def futures(self) -> int: ...

    @property
    def horizon(self) -> int: ...


class _KeepFor:
    """Keep the plan made at the snapshot ``n`` steps, then follow ``base`` (for :func:`play_on`)."""

    def __init__(self, first_plan, n: int, base):
        self.first_plan, self.n, self.base = first_plan, n, base
        self.spec, self.stochastic = f"keep:{n}+{base.spec}", base.stochastic
        self.observes = getattr(base, "observes", True)

    def decide(self, s, rng) -> bool:
        if s.plan is self.first_plan:
            return s.age >= self.n
        return self.base.decide(s, rng)


def _candidate_returns(base, candidates: tuple[int, ...], futures: int, horizon: int, rng: np.random.Generator):
    """The label of a picked step (for :class:`etmpc.learning.dpi.Labeller`): a plan solved there, its
    features, and every candidate ``n``'s mean return over ``futures`` futures sampled from what the
    controller knows (the same for all, no draws of ``base``) of keeping that plan ``n`` steps and then
    following ``base``, played ``horizon`` steps on."""

    def label(s, twin) -> tuple[list[float], list[float]]:
        ctx = s.context
        system = ctx.system
        snapshot = Snapshot.take(ctx)
        sampled = [system.sample_future(snapshot.episode, ctx.step, rng) for _ in range(futures)]
        solved = system.plan(snapshot.seen, snapshot.u_prev, snapshot.plan, snapshot.age, ctx.timestep)
        stop = ctx.step + horizon
        returns = [
            np.mean(
                [
                    play_on(system, twin, snapshot, _KeepFor(solved, n, base), None, True, future, solved, stop)
                    for future in sampled
                ]
            )
            for n in candidates
        ]
        return plan_features(solved).tolist(), [float(q) for q in returns]

    return label


def label_episode(key: str, base: str, candidates: tuple[int, ...], settings: LabelSettings, index: int) -> list:
    """Training episode ``index`` played by ``base``: ``[(features, returns per candidate), ...]``
    at its picked steps (those where the loop asks the policy: a plan is in force)."""
    system, env, _ = context(key)
    rngs = [np.random.default_rng(np.random.SeedSequence(SELF_ENTROPY, spawn_key=(index, k))) for k in range(3)]
    steps = set(
        rngs[1]
        .choice(
            np.arange(1, system.episode_steps), size=min(settings.solves_per_episode, system.episode_steps - 1), replace=False
        )
        .tolist()
    )
    policy = parse_policy(base, system)
    label = _candidate_returns(policy, candidates, settings.futures, max(candidates) + settings.horizon, rngs[2])
    labeller = dpi.Labeller(policy, steps, label, "label-self")
    run_episode(system, env, labeller, None, system.draw_episode(rngs[0]))
    return labeller.rows


def fit(features: np.ndarray, returns: np.ndarray, ridge: float) -> np.ndarray:
    """``theta (C, 1 + p)`` of the softmax model, fitted to each row's best candidate with weights
    ``best - mean return`` (normalised to mean 1) and ``ridge / 2 |theta[:, 1:]|^2``."""
    n, p = features.shape
    c = returns.shape[1]
    design = np.hstack([np.ones((n, 1)), features])
    best = np.argmax(returns, axis=1)
    weight = returns.max(axis=1) - returns.mean(axis=1)
    weight = weight / weight.mean() if weight.mean() > 0 else np.ones(n)
    target = np.zeros((n, c))
    target[np.arange(n), best] = 1.0
    penalty = np.ones((c, 1 + p))
    penalty[:, 0] = 0.0

    def loss(flat):
        theta = flat.reshape(c, 1 + p)
        logits = design @ theta.T
        logits -= logits.max(axis=1, keepdims=True)
        log_p = logits - np.log(np.exp(logits).sum(axis=1, keepdims=True))
        value = -np.sum(weight * np.sum(target * log_p, axis=1)) / n + 0.5 * ridge * np.sum(penalty * theta**2)
        grad = ((np.exp(log_p) - target) * weight[:, None]).T @ design / n + ridge * penalty * theta
        return value, grad.ravel()

    result = minimize(loss, np.zeros(c * (1 + p)), jac=True, method="L-BFGS-B", options={"maxiter": 1000})
    return result.x.reshape(c, 1 + p)
