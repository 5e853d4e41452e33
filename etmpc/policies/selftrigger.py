"""Self-triggering: at each solve, say how long the new plan will be kept (``self:PATH``).

The paper names it as future work: instead of asking at every step whether to recompute (event
triggering), the controller announces, when it makes a plan, the number of steps ``n`` in
``CANDIDATES`` it will keep it, so the next solve is known in advance. The loop then keeps the plan
exactly ``n`` steps (or until it runs out: ``n = N`` is ``never``).

**The policy** is a multinomial logistic model over the candidates, greedy: ``n = argmax_c
theta_c . [1, z]``, with ``z`` the normalised features of the plan as it is made
(:func:`plan_features`: the state it starts from, the spread of its predicted states, the mean
size of its inputs, and the spread of each forecast it was made with). Nothing measured after the
solve enters, so the announcement is made at the solve.

**Training** (:func:`train_self`) is one step of rollout policy improvement over a base schedule,
as :mod:`etmpc.learning.dpi` does for event triggering:

1. the base ``every:T`` is the best of ``bases`` on training-distribution episodes (as DPI chooses
   its first schedule);
2. on training-distribution episodes played by the base, at a few picked steps, a plan is solved and
   every candidate ``n`` scored: the mean return, over ``K`` futures sampled from what the
   controller knows (common random numbers), of keeping that plan ``n`` steps and then following
   the base, ``H`` steps past the longest candidate plus the truncation value;
3. the model is fitted to each labelled solve's best candidate by ridge-regularised cross-entropy,
   each solve weighted by how much the choice matters (best minus mean return), for each ridge of
   ``ridges``;
4. the policy kept is the best, on validation episodes of the training distribution, of these fits
   and of the base itself written as a self-trigger (a constant announcement ``T``), so what
   training returns is never worse than its base on those episodes. The test set is never seen.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
from scipy.optimize import minimize

from etmpc.common.errors import EtmpcError
from etmpc.loop import Snapshot, play_on, run_episode
from etmpc.common.numerics import matvec
from etmpc.common.outputs import write_json
from etmpc.policies import Always, AugmentedState, Every, parse_policy

FORMAT = "etmpc-self-trigger"
CANDIDATES = (1, 2, 3, 4, 5, 6, 8, 10, 12, 15, 20)
SELF_ENTROPY = 0x73656C66  # "self"


def plan_features(plan) -> np.ndarray:
    """What a plan says about itself when it is made: ``x_k``, ``x_k^2``, the range of each predicted
    state over the horizon, its first input and mean |input| per input, and the mean and standard
    deviation of each forecast it was made with."""
    x = np.asarray(plan.states[0], float)
    spread = np.ptp(np.asarray(plan.states, float), axis=0)
    inputs = np.asarray(plan.inputs, float)
    forecasts = [f(plan.forecasts[name]) for name in sorted(plan.forecasts) for f in (np.mean, np.std)]
    return np.concatenate([x, x * x, spread, inputs[0], np.mean(np.abs(inputs), axis=0), np.asarray(forecasts, float)])


@dataclass(eq=False)
class SelfTrigger:
    """``self:PATH``: keep each plan for the number of steps announced when it was made."""

    path: str
    domain: str
    candidates: tuple[int, ...]
    theta: np.ndarray  # (len(candidates), 1 + p)
    mean: np.ndarray  # (p,) feature normalisation
    scale: np.ndarray
    stochastic: bool = False
    observes: ClassVar[bool] = False
    _plan: Any = None
    _keep: int = 0

    @property
    def spec(self) -> str:
        return f"self:{self.path}"

    def announce(self, plan) -> int:
        """The number of steps ``plan`` will be kept, decided as it is made."""
        z = (plan_features(plan) - self.mean) / self.scale
        logits = matvec(self.theta, np.concatenate([[1.0], z]))  # not @: the choice must not depend on the BLAS kernel
        if not np.all(np.isfinite(logits)):
            raise EtmpcError(f"self-trigger policy {self.path} gives a non-finite score for a plan")
        return int(self.candidates[int(np.argmax(logits))])

    def decide(self, s: AugmentedState, rng: np.random.Generator) -> bool:
        if s.plan is not self._plan:  # a plan seen for the first time: its announcement
            self._plan, self._keep = s.plan, self.announce(s.plan)
        return s.age >= self._keep

    def __getstate__(self):
        return {k: v for k, v in self.__dict__.items() if k not in ("_plan", "_keep")} | {"_plan": None, "_keep": 0}

    def to_json(self, hyperparameters: dict | None = None) -> dict:
        return {"format": FORMAT, "version": 1, "domain": self.domain, "candidates": list(self.candidates),
                "theta": self.theta.tolist(), "mean": self.mean.tolist(), "scale": self.scale.tolist(),
                "hyperparameters": hyperparameters or {}}

    @classmethod
    def constant(cls, path: str, domain: str, candidates: tuple[int, ...], n: int, p: int) -> SelfTrigger:
        """The self-trigger that always announces ``n`` (``every:n``), over ``p`` features."""
        theta = np.zeros((len(candidates), 1 + p))
        theta[candidates.index(n), 0] = 1.0
        return cls(path, domain, tuple(candidates), theta, np.zeros(p), np.ones(p))


def load_self(path: str, domain: str | None) -> SelfTrigger:
    """A self-triggering policy from its file; any problem is one :class:`EtmpcError`."""
    try:
        data = json.loads(Path(path).read_text())
    except FileNotFoundError:
        raise EtmpcError(f"self-trigger policy {path} not found") from None
    except (OSError, ValueError) as exc:
        raise EtmpcError(f"self-trigger policy {path} is unreadable: {exc}") from None
    return from_json(data, str(path), domain)


def from_json(data: Any, path: str, domain: str | None) -> SelfTrigger:
    """A self-triggering policy from its JSON (``path``: its name in messages and its spec)."""
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise EtmpcError(f"{path} is not a self-trigger policy (format {FORMAT!r})")
    if domain is not None and data.get("domain") != domain:
        raise EtmpcError(f"self-trigger policy {path} is for {data.get('domain')!r}, not {domain!r}")
    try:
        candidates = tuple(int(c) for c in data["candidates"])
        theta, mean, scale = (np.asarray(data[k], dtype=float) for k in ("theta", "mean", "scale"))
    except (KeyError, TypeError, ValueError) as exc:
        raise EtmpcError(f"self-trigger policy {path} is incomplete or malformed ({exc})") from None
    if (not candidates or min(candidates) < 1 or len(set(candidates)) != len(candidates) or theta.shape != (len(candidates), mean.size + 1)
            or scale.shape != mean.shape or not (np.all(np.isfinite(theta)) and np.all(scale > 0))):
        raise EtmpcError(f"self-trigger policy {path} has inconsistent or non-finite parameters")
    return SelfTrigger(str(path), data["domain"], candidates, theta, mean, scale)


# -- training ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class SelfSettings:
    bases: tuple[str, ...] = ("always", "every:2", "every:3", "every:5", "every:8", "every:12", "every:20")
    selection_episodes: int = 20  # training-distribution episodes that choose the base
    episodes: int = 40  # labelled training episodes
    solves_per_episode: int = 8  # labelled solves per episode
    futures: int = 2  # K
    horizon: int = 10  # H: steps simulated past the longest candidate
    ridges: tuple[float, ...] = (1e-2, 1e-1, 1.0)
    validation_episodes: int = 20  # training-distribution episodes that choose among the fits and the base
    candidates: tuple[int, ...] = CANDIDATES

    def __post_init__(self):
        for name in ("selection_episodes", "episodes", "solves_per_episode", "futures", "validation_episodes"):
            if getattr(self, name) < 1:
                raise EtmpcError(f"self-trigger training needs {name} >= 1, got {getattr(self, name)}")
        if self.horizon < 0 or not self.ridges or min(self.ridges) <= 0 or not self.bases:
            raise EtmpcError("self-trigger training needs horizon >= 0, ridges > 0 and at least one base")

    def to_json(self) -> dict:
        return {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(self).items()}


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


class _Labeller:
    """Plays ``base``; at the picked steps, scores every candidate ``n`` for a plan solved there."""

    simulates = True

    def __init__(self, base, steps: set[int], settings: SelfSettings, rng: np.random.Generator):
        self.base, self.steps, self.settings, self.rng = base, steps, settings, rng
        self.spec, self.stochastic = f"label-self:{base.spec}", base.stochastic
        self.rows: list[tuple[list[float], list[float]]] = []
        self._twin = None

    def decide(self, s, rng) -> bool:
        ctx = s.context
        if ctx.step in self.steps:
            system = ctx.system
            if self._twin is None:
                self._twin = system.make_env()
            snapshot = Snapshot.take(ctx)
            futures = [system.sample_future(snapshot.episode, ctx.step, self.rng) for _ in range(self.settings.futures)]
            solved = system.plan(snapshot.x, snapshot.u_prev, snapshot.plan, snapshot.age, ctx.timestep)
            stop = ctx.step + self.settings.horizon
            returns = [np.mean([play_on(system, self._twin, snapshot, _KeepFor(solved, n, self.base), None, True, future,
                                        solved, stop) for future in futures]) for n in self.settings.candidates]
            self.rows.append((plan_features(solved).tolist(), [float(q) for q in returns]))
        return self.base.decide(s, rng)


def label_episode(key: str, base: str, candidates: tuple[int, ...], settings: SelfSettings, index: int) -> list:
    """Training episode ``index`` played by ``base``: ``[(features, returns per candidate), ...]``
    at its picked steps (those where the loop asks the policy: a plan is in force)."""
    from etmpc.evaluation.workers import context

    system, env, _ = context(key)
    rngs = [np.random.default_rng(np.random.SeedSequence(SELF_ENTROPY, spawn_key=(index, k))) for k in range(3)]
    steps = set(rngs[1].choice(np.arange(1, system.episode_steps), size=min(settings.solves_per_episode,
                                                                            system.episode_steps - 1), replace=False).tolist())
    labeller = _Labeller(parse_policy(base, system.error_weights, system.domain), steps,
                         replace(settings, candidates=candidates, horizon=max(candidates) + settings.horizon), rngs[2])
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


def train_self(key: str, out: Path, settings: SelfSettings = SelfSettings(), workers: int = 1, backend: str = "local",
               address: str | None = None, say=lambda line: None) -> SelfTrigger:
    """Choose the base, label, fit, validate and write ``out`` (the policy file); returns the
    policy. ``key``: a system key (``DOMAIN`` or ``DOMAIN@PRICE``, see :mod:`etmpc.systems`)."""
    from etmpc.experiments.sweep import system_horizon
    from etmpc.systems import make_system
    from etmpc.learning.train import SELECTION_ENTROPY, VALIDATION_ENTROPY, _mean_scores
    from etmpc.evaluation.workers import make_backend

    system = make_system(key)
    better = np.argmax if system.objective_sense == "max" else np.argmin
    candidates = tuple(c for c in settings.candidates if c <= system_horizon(system))
    if not candidates:
        raise EtmpcError(f"no candidate keep length fits the MPC horizon ({system_horizon(system)} steps)")
    with make_backend(backend, workers, address) as pool:
        scores = _mean_scores(pool, key, list(settings.bases), SELECTION_ENTROPY, settings.selection_episodes)
        base = settings.bases[int(better(scores))]
        say(f"self-trigger: base {base} (best of {len(settings.bases)} on {settings.selection_episodes} training episodes)")
        labelled = pool.map(_label_job, [(key, base, candidates, settings, i) for i in range(settings.episodes)])
        rows = [row for episode in labelled for row in episode]
        if not rows:
            raise EtmpcError("no solves were labelled; give more episodes")
        features = np.array([f for f, _ in rows])
        returns = np.array([q for _, q in rows])
        mean, scale = features.mean(axis=0), features.std(axis=0)
        scale = np.where(scale > 1e-12, scale, 1.0)
        fits = {}
        period = _period(base, system)
        if period in candidates:  # the base itself, as a self-trigger: what training must beat (first: it wins ties)
            fits[f"constant {period} (the base)"] = SelfTrigger.constant(str(out), system.domain, candidates, period, mean.size)
        for r in settings.ridges:
            fits[f"ridge {r:g}"] = SelfTrigger(str(out), system.domain, candidates, fit((features - mean) / scale, returns, r),
                                               mean, scale)
        jsons = [policy.to_json() for policy in fits.values()]
        validation = _mean_scores(pool, key, jsons, VALIDATION_ENTROPY, settings.validation_episodes)
    chosen = list(fits)[int(better(validation))]
    say(f"self-trigger: kept {chosen} ({', '.join(f'{n}: {v:.6g}' for n, v in zip(fits, validation))} on "
        f"{settings.validation_episodes} validation episodes)")
    policy = fits[chosen]
    best = np.array(candidates)[np.argmax(returns, axis=1)]
    hyper = dict(settings.to_json(), system=key, recompute_price=system.recompute_price, base=base,
                 base_selection=dict(zip(settings.bases, scores)), labelled_solves=len(rows),
                 best_keep_counts={str(c): int(np.sum(best == c)) for c in candidates},
                 validation=dict(zip(fits, validation)), chosen=chosen)
    write_json(Path(out), policy.to_json(hyper))
    return policy


def _period(spec: str, system) -> int:
    """``T`` of a periodic base (``always``: 1, ``every:T``: T); 0 for anything else."""
    policy = parse_policy(spec, system.error_weights, system.domain)
    if isinstance(policy, Always):
        return 1
    return policy.period if isinstance(policy, Every) else 0


def _label_job(job) -> list:
    return label_episode(*job)
