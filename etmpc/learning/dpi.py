"""Direct policy iteration: rollout-labelled, cost-sensitive classification of the logistic policy.

The stronger learner of ``etmpc train --algorithm dpi`` (Lagoudakis & Parr 2003; Lazaric,
Ghavamzadeh & Munos 2010, "Analysis of a classification-based policy iteration algorithm"). The
code below reads in the algorithm's order:

0. **The first policy** (:func:`choose_base`). ``pi_0`` is the best fixed schedule among
   :attr:`Settings.bases`, chosen on training episodes (never the test set): iteration 0 labels
   decisions by rollouts over it, so ``pi_1`` already imitates the rollout policy over the best
   schedule, which improves on it.

Then each iteration, for the current policy ``pi_t``:

1. **States** (:func:`label_episode`). Play training episodes under ``pi_t`` and pick
   ``states_per_episode`` of its decisions in each at random.
2. **Rollouts** (:class:`Labeller`). At each picked decision, estimate the return of keeping and of
   recomputing with :func:`etmpc.policies.rollout.q_values`: ``futures`` futures sampled from what the
   controller knows, the same for both answers (common random numbers), each simulated ``horizon``
   steps ahead under ``pi_t`` and valued at ``system.truncation_value`` there. Where the sensor is
   not exact, each play starts from the plant's true state, which the controller only estimates: the
   labels are privileged (a teacher that knows more than the student), the policy learnt is not (its
   features are the filter's). The weighted classifier's best decision given those features is the sign
   of the labels' mean given them; for a calibrated filter (the true state is then a draw from its
   belief) that is the mean plays from states drawn from the belief would give.
3. **Classification** (:func:`fit`). Label the decision *keep* when keeping returns at least as
   much, weight it by how much the better answer gains (``|Q(keep) - Q(recompute)|``: a mistake
   costs that much), and fit ``theta`` by weighted, ridge-regularised logistic regression on every
   decision labelled so far (L-BFGS).
4. **The next policy** (:func:`iteration`). ``pi_{t+1}(keep | s) = sigma(theta . phi(s))``, for
   every seed of the run.

**Which policy is shipped.** Policy iteration with an approximate classifier need not improve at every
iteration (on ``kicks_late`` one run's policies computed 127, 55, then 24 times an episode). Every
iteration's policy of every seed is kept (the learner's ``history``), and the run's ``selected.json`` is
the best of them all on the validation episodes (training distribution, never the test set), not the last
iteration of the best seed.

**Compute levels.** On a task whose decisions are keep, one SQP iteration or a full solve, the policy
has a second stage, ``pi(solve | compute, s) = sigma(theta_level . phi(s))`` (see
:mod:`etmpc.policies.learned`), and DPI labels the three answers: ``q_values`` gives each one's
returns, and a labelled decision's row holds their means, ``(phi, q_keep, q_solve, step, q_iterate)``
(a keep-or-solve task's rows are ``(phi, q_keep, q_solve, step)``, as before). Stage 1 is fitted as
above with the advantage of keeping ``q_keep - max(q_iterate, q_solve)``; stage 2 by :func:`fit_level`:
label *iterate* where ``q_iterate >= q_solve``, weight ``|q_iterate - q_solve|``, on the labelled decisions
where the just-fitted stage 1 computes (:func:`fit_level_labels` says why). ``pi_0``'s candidates then
include the real-time iterations ``iterate:1..5`` (:func:`level_bases`; ``iterate:1``, one iteration at
every step, is the best schedule of ``kicks_levels``).

:func:`label_episode` is a worker's job (a pure function of its arguments, as those of
:mod:`etmpc.learning.jobs`); the rest runs in the driver, :func:`etmpc.learning.train.train`.
:class:`Labeller` also labels the self-trigger's training (:mod:`etmpc.learning.selftrigger`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.optimize import minimize

from etmpc.common import checks
from etmpc.common.numerics import dot
from etmpc.common.sense import oriented
from etmpc.evaluation.workers import context
from etmpc.loop import run_episode
from etmpc.policies import parse_policy
from etmpc.policies.learned import LogisticPolicy
from etmpc.policies.rollout import q_values

DPI_ENTROPY = 0x6470_6921  # "dpi!"
BASES = ("always", "every:2", "every:3", "every:4", "every:5")  # pi_0's candidates by default
LEVEL_BASES = ("iterate:1", "iterate:2", "iterate:3", "iterate:4", "iterate:5")  # and on a task with compute levels


@dataclass(frozen=True)
class Settings:
    """DPI's hyperparameters."""

    futures: int = 4  # K: sampled futures per labelled decision
    horizon: int = 20  # H: steps simulated ahead of each decision (the MPC's own horizon)
    states_per_episode: int = 25  # decisions labelled per training episode
    ridge: float = 1e-2  # L2 weight on theta (not on the bias), per labelled decision
    bases: tuple[str, ...] = BASES  # candidates for pi_0 (with levels, by default also LEVEL_BASES: level_bases)
    selection_episodes: int = 30  # training episodes that choose pi_0 among the bases
    # what each of the task's failures (falls, steps outside the geofence) in a labelling rollout costs on top of
    # its reward: safety in the labels, its weight chosen on validation episodes (etmpc study failure-cost); 0: none
    failure_cost: float = 0.0

    def __post_init__(self):
        checks.typed(self, finite=True, most=checks.MAX_COUNT)
        for name in ("futures", "horizon", "states_per_episode", "selection_episodes"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be >= 1, got {getattr(self, name)}")
        for name in ("ridge", "failure_cost"):
            if getattr(self, name) < 0:
                raise ValueError(f"{name.replace('_', ' ')} must be >= 0, got {getattr(self, name)}")


# 0. The first policy.


def level_bases(settings: Settings, levels: bool) -> Settings:
    """``settings`` for a task with compute levels (``levels``): the default candidates for ``pi_0``
    grow the real-time iterations ``iterate:1..5``; candidates someone chose are kept as they are, and a
    keep-or-solve task's settings are returned unchanged."""
    return replace(settings, bases=BASES + LEVEL_BASES) if levels and settings.bases == BASES else settings


def choose_base(settings: Settings, sense: str, mean_scores) -> str:
    """``pi_0``: the best of ``settings.bases``. ``mean_scores(policies, episodes)`` gives each
    policy's mean objective on the first ``episodes`` of a stream of training-distribution episodes
    (never the test set); ``sense`` (``"max"`` or ``"min"``) says which is best."""
    means = mean_scores(list(settings.bases), settings.selection_episodes)
    pick = int(np.argmax(oriented(np.asarray(means, dtype=float), sense)))
    return settings.bases[pick]


# 1-2. Labels by rollouts.


def episode_rngs(seed: int, episode: int) -> list[np.random.Generator]:
    """The draws of DPI's training ``episode`` of ``seed``: the episode, the picked steps, the
    sampled futures and the policy's own decisions."""
    return [np.random.default_rng(np.random.SeedSequence(DPI_ENTROPY, spawn_key=(seed, episode, k))) for k in range(4)]


class Labeller:
    """Plays ``base`` and, at the chosen ``steps``, appends ``label(s, twin)`` to :attr:`rows`:
    whatever the learner estimates there by simulating in ``twin`` (an environment of the same task,
    made at the first chosen step; the running episode is left untouched). DPI's label is both
    answers' returns (:func:`label_episode`), the self-trigger's every keep length's
    (:func:`etmpc.learning.selftrigger.label_episode`); ``name`` prefixes the spec."""

    simulates = True

    def __init__(self, base, steps: set[int], label, name: str = "label"):
        self.base, self.steps, self.label = base, steps, label
        self.spec, self.stochastic = f"{name}:{base.spec}", base.stochastic
        self.rows: list = []
        self._twin = None

    def decide(self, s, rng) -> bool:
        ctx = s.context
        if ctx.step in self.steps:
            if self._twin is None:
                self._twin = ctx.system.make_env()
            self.rows.append(self.label(s, self._twin))
        return self.base.decide(s, rng)


def label_episode(domain: str, base, settings: Settings, policy_json: dict, seed: int, e: int) -> list:
    """DPI's training episode ``e`` of ``seed`` under ``base`` (``pi_t``: a fixed spec or a policy's
    JSON): ``[(phi, q_keep, q_recompute, step), ...]`` at its picked decisions; on a task with compute
    levels ``[(phi, q_keep, q_solve, step, q_iterate), ...]``."""
    system, env, _ = context(domain)
    base = parse_policy(base, system) if isinstance(base, str) else LogisticPolicy.from_json(base)
    featurise = LogisticPolicy.from_json(policy_json).phi
    episode_rng, pick_rng, future_rng, policy_rng = episode_rngs(seed, e)
    picked = set(
        pick_rng.choice(system.episode_steps, size=min(settings.states_per_episode, system.episode_steps), replace=False).tolist()
    )

    # Where the sensor is not exact, the labels' plays start from the plant's true state (privileged
    # information, as in learning with a privileged critic): the policy learnt reads only the filter's.
    def answers(s, twin):  # every answer's returns over the same sampled futures
        return q_values(
            s.context,
            base,
            settings.futures,
            future_rng,
            twin,
            settings.horizon,
            failure_cost=settings.failure_cost,
            from_belief=False,
        )

    def label(s, twin):  # every answer over the same sampled futures, then phi(s)
        if system.compute_levels:
            keep, iterate, solve = answers(s, twin)
            return featurise(s), float(np.mean(keep)), float(np.mean(solve)), s.context.step, float(np.mean(iterate))
        keep, recompute = answers(s, twin)
        return featurise(s), float(np.mean(keep)), float(np.mean(recompute)), s.context.step

    labeller = Labeller(base, picked, label)
    run_episode(system, env, labeller, policy_rng, system.draw_episode(episode_rng))
    return [(phi.tolist(), *rest) for phi, *rest in labeller.rows]


def _label_job(job) -> list:
    """A pool's job ``("label", args)``: :func:`label_episode` (the name is how progress counts it)."""
    return label_episode(*job[1])


# 3. Classification.


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


def fit_labels(rows: list, ridge: float, theta0: np.ndarray | None = None) -> np.ndarray:
    """:func:`fit` on :func:`label_episode`'s rows ``(phi, q_keep, q_recompute, ...)``: the advantage of
    keeping is ``q_keep - q_recompute``; with compute levels (rows ``(phi, q_keep, q_solve, step,
    q_iterate)``) ``q_keep - max(q_iterate, q_solve)``, keeping against the better of the two."""
    return fit(np.array([row[0] for row in rows]), np.array([keep_advantage(row) for row in rows]), ridge, theta0)


def keep_advantage(row) -> float:
    return row[1] - row[2] if len(row) < 5 else row[1] - max(row[4], row[2])


def fit_level(features: np.ndarray, iterate_advantage: np.ndarray, ridge: float) -> np.ndarray:
    """Stage 2 of a policy with compute levels: ``theta_level``, with ``sigma(theta_level . phi)`` the
    probability of a full solve when computing, fitted as :func:`fit` fits stage 1: label *iterate*
    where ``iterate_advantage = q_iterate - q_solve >= 0`` (a tie takes the cheaper answer), weight its
    size. :func:`fit` gives the logit of its label, iterate; the logit of a solve is its negative."""
    return -fit(features, iterate_advantage, ridge)


def fit_level_labels(rows: list, ridge: float, theta) -> np.ndarray:
    """:func:`fit_level` on the rows of a task with compute levels where stage 1 (``theta``, the one just
    fitted) computes: at a state the policy keeps, it never asks stage 2, and a wrong level costs
    nothing. The greedy policy's loss at a labelled state splits exactly so, ``q_best - q_chosen =``
    (stage 1's loss: ``q_keep - max(q_iterate, q_solve)`` if it computes where keeping is best, ``q_best
    - q_keep`` if it keeps where computing is) ``+ 1[stage 1 computes] |q_iterate - q_solve| 1[wrong
    level]``; so stage 2 is fitted where its mistakes cost, and its linear boundary is not spent on
    states where it is never asked. (Where stage 1 computes is decided as the policy decides it, on the
    exact logit.) If stage 1 computes at none of the rows, on all of them."""
    features = np.array([row[0] for row in rows], dtype=float)
    theta = np.asarray(theta, dtype=float)
    computes = np.array([dot(theta, phi) < 0.0 for phi in features], dtype=bool)
    if not computes.any():
        computes[:] = True
    advantage = np.array([row[4] - row[2] for row in rows], dtype=float)
    return fit_level(features[computes], advantage[computes], ridge)


# 4. The next policy.


def iteration(state, pool, tick, start: int, stop: int) -> None:
    """One DPI iteration per seed of ``state`` (the run's :class:`etmpc.learning.checkpoint.RunState`,
    updated in place): label episodes ``start..stop-1`` by rollouts over the current policy (over the
    chosen schedule at iteration 0) on ``pool``, then refit ``theta`` (and, with compute levels,
    ``theta_level``) on every label so far. ``tick`` is told of each finished job."""
    config = state.config

    def base(seed):  # pi_t: the schedule, then the policy at the learner's parameters (checkpoint.policy_of)
        learner = state.learners[str(seed)]
        if learner["iterations"] == 0:
            return state.base
        return dict(state.policy, **{name: list(learner[name]) for name in ("theta", "theta_level") if name in learner})

    jobs = [("label", (config.system, base(s), config.dpi, state.policy, s, e)) for s in config.seeds for e in range(start, stop)]
    results = pool.map(_label_job, jobs, tick)
    per_seed = stop - start
    for k, seed in enumerate(config.seeds):
        learner = state.learners[str(seed)]
        for rows in results[k * per_seed : (k + 1) * per_seed]:
            learner["data"] += [list(row) for row in rows]
        learner["theta"] = fit_labels(learner["data"], config.dpi.ridge).tolist()
        if "theta_level" in learner:  # compute levels: stage 2 too
            learner["theta_level"] = fit_level_labels(learner["data"], config.dpi.ridge, learner["theta"]).tolist()
        learner["iterations"] += 1
        learner["episodes"] = stop
        # every iteration's policy, for the validation that chooses among them (checkpoint.candidates)
        kept = {name: learner[name] for name in ("theta", "theta_level") if name in learner}
        learner.setdefault("history", []).append({"episodes": stop, **kept})
        state.training += [
            {"episode": e, "seed": seed, "labels": len(rows)}
            for e, rows in zip(range(start, stop), results[k * per_seed : (k + 1) * per_seed])
        ]
