"""The learned recomputation policy: logistic regression on normalised features of the augmented state.

``pi(0 | s) = sigma(theta^T phi(s))`` is the probability of *keeping* the plan (paper eq. logreg),
``pi(1 | s) = 1 - pi(0 | s)`` that of recomputing. The features are

    phi(s) = [ (r - mean) / std,  (r^2 - mean_sq) / std_sq,  1 ]

of a raw vector ``r`` chosen by the policy's *feature set*:

* ``error`` (the default for training): ``r = [x_i - x_hat_i, i - k, exogenous]``, the prediction
  error per state (its square comes with ``r^2``) and the plan's age, as the authors' own
  environment feeds its policy; for the battery also the exogenous information a good trigger needs
  (its system's ``exogenous_features``; the battery's: the price and net production now, what the plan
  assumed for them, their differences, and the value at today's price of the trade the plan makes now);
* ``paper``: ``r = s = [x_i, x_k, i - k]``, the augmented state as the paper's text defines it.

The normalisation is measured once per training run (see :func:`etmpc.learning.train`) and saved with the
parameters, the feature set, the task and the hyperparameters in one JSON file, so ``--policy
rl:PATH`` evaluates it anywhere. The decision rule is saved too: ``sample`` draws the decision from
``pi`` (the paper's policy, and what GPOMDP's gradient needs), ``greedy`` takes the likelier answer
(what a classifier trained by DPI is). JSON keeps every float exactly (Python writes the shortest repr
that reads back to the same double). Files of format version 1 (before feature sets) are ``paper``.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from etmpc.common.errors import EtmpcError
from etmpc.common.numerics import dot
from etmpc.common.outputs import dumps, write_text
from etmpc.loop import AugmentedState
from etmpc.policies.features import FEATURE_SETS, feature_size, raw_features

FORMAT = "etmpc-logistic-policy"
VERSION = 2
INITIAL_KEEP_LOGIT = -3.0  # sigma(-3) = 0.047: at first the policy recomputes 95 % of the time


class PolicyFileError(EtmpcError):
    """A policy or checkpoint file that is missing, corrupt, or made for another task."""


@dataclass(frozen=True, eq=False)
class Normalisation:
    """Mean and standard deviation of ``s`` and of ``s^2`` (constant components get std 1)."""

    mean: np.ndarray
    std: np.ndarray
    mean_sq: np.ndarray
    std_sq: np.ndarray

    @classmethod
    def fit(cls, states: np.ndarray) -> Normalisation:
        """From a sample of raw augmented states, one per row."""
        states = np.asarray(states, dtype=float)
        if states.ndim != 2 or states.shape[0] < 2:
            raise ValueError("need at least two augmented states to normalise")
        std = lambda v: np.where(np.std(v, axis=0) > 1e-12, np.std(v, axis=0), 1.0)  # noqa: E731
        return cls(states.mean(axis=0), std(states), (states**2).mean(axis=0), std(states**2))

    def features(self, s: np.ndarray) -> np.ndarray:
        return np.concatenate([(s - self.mean) / self.std, (s * s - self.mean_sq) / self.std_sq, [1.0]])

    def to_json(self) -> dict:
        return {name: getattr(self, name).tolist() for name in ("mean", "std", "mean_sq", "std_sq")}

    @classmethod
    def from_json(cls, data: dict) -> Normalisation:
        return cls(*(np.asarray(data[name], dtype=float) for name in ("mean", "std", "mean_sq", "std_sq")))


def sigmoid(z: float) -> float:
    return 1.0 / (1.0 + math.exp(-z)) if z >= 0 else math.exp(z) / (1.0 + math.exp(z))


@dataclass(eq=False)
class LogisticPolicy:
    """``pi(keep | s) = sigma(theta . phi(s))``; draws its decisions from the generator it is given.

    With ``record`` set, every decision appends ``(phi, recompute, p_keep)`` to :attr:`decisions`
    (what GPOMDP needs); the control loop only asks at steps where the plan has not run out.
    """

    theta: np.ndarray
    normalisation: Normalisation
    domain: str
    hyperparameters: dict = field(default_factory=dict)
    record: bool = False
    decisions: list = field(default_factory=list)
    features: str = "paper"  # the feature set (FEATURE_SETS)
    greedy: bool = False  # True: recompute exactly when pi(keep | s) < 1/2, drawing nothing

    @property
    def stochastic(self) -> bool:
        return not self.greedy

    @property
    def spec(self) -> str:
        return f"rl:{self.hyperparameters.get('name', self.domain)}"

    @classmethod
    def initial(
        cls,
        normalisation: Normalisation,
        domain: str,
        hyperparameters: dict | None = None,
        features: str = "paper",
        greedy: bool = False,
    ) -> LogisticPolicy:
        theta = np.zeros(normalisation.mean.size * 2 + 1)
        theta[-1] = INITIAL_KEEP_LOGIT
        return cls(theta, normalisation, domain, dict(hyperparameters or {}), features=features, greedy=greedy)

    def with_theta(self, theta: np.ndarray, record: bool = False) -> LogisticPolicy:
        return LogisticPolicy(
            np.array(theta, dtype=float),
            self.normalisation,
            self.domain,
            self.hyperparameters,
            record,
            features=self.features,
            greedy=self.greedy,
        )

    def phi(self, s: AugmentedState) -> np.ndarray:
        return self.normalisation.features(raw_features(self.features, self.domain, s))

    def keep_probability(self, s: AugmentedState) -> float:
        return sigmoid(self.decision_value(self.phi(s)))

    def decision_value(self, phi: np.ndarray) -> float:
        """The logit ``theta . phi`` of keeping, the same on every machine: the terms ``theta_j phi_j``
        are formed first (each rounded as IEEE multiplication rounds it) and judged before they are
        summed. Terms of ``+inf`` only give ``+inf`` (a sure keep), of ``-inf`` only ``-inf`` (a sure
        recompute), and finite terms are summed exactly and rounded once (``etmpc.common.numerics.dot``); an
        exact sum beyond the double range is ``+-inf`` by its sign. Terms of both infinities, or NaN,
        have no value: that is an error, on every machine (a BLAS ``theta @ phi`` gives NaN or
        ``-inf`` for them depending on the CPU's kernel)."""
        with np.errstate(over="ignore", invalid="ignore"):
            logit = dot(self.theta, phi)
        if math.isnan(logit):
            raise PolicyFileError(
                f"the {self.domain} policy's decision value is not a number at this state "
                "(its parameters overflow against the features): retrain it or check its file"
            )
        return logit

    def decide(self, s: AugmentedState, rng: np.random.Generator) -> bool:
        phi = self.phi(s)
        logit = self.decision_value(phi)
        p_keep = sigmoid(logit)
        # Greedy: recompute when pi(keep | s) < 1/2, i.e. when the logit is negative (decided on the
        # logit itself, so no exp rounding can move the boundary).
        recompute = logit < 0.0 if self.greedy else bool(rng.random() >= p_keep)
        if self.record:
            self.decisions.append((phi, recompute, p_keep))
        return recompute

    # -- file -------------------------------------------------------------------------------------
    def to_json(self) -> dict:
        return {
            "format": FORMAT,
            "version": VERSION,
            "domain": self.domain,
            "features": self.features,
            "decision": "greedy" if self.greedy else "sample",
            "theta": self.theta.tolist(),
            "normalisation": self.normalisation.to_json(),
            "hyperparameters": self.hyperparameters,
        }

    def save(self, path: str | Path) -> None:
        """Write atomically: a crash leaves the old file or the new one, never half of one."""
        write_json_atomically(Path(path), self.to_json())

    @classmethod
    def from_json(cls, data: dict, where: str = "policy") -> LogisticPolicy:
        if not isinstance(data, dict) or data.get("format") != FORMAT:
            raise PolicyFileError(
                f"{where} is not an etmpc logistic policy (format {data.get('format') if isinstance(data, dict) else None!r})"
            )
        if data.get("version") not in (1, VERSION):
            raise PolicyFileError(f"{where} has format version {data.get('version')!r}; this etmpc reads 1 and {VERSION}")
        features = data.get("features", "paper") if data.get("version") == VERSION else "paper"
        if features not in FEATURE_SETS:
            raise PolicyFileError(f"{where} has unknown feature set {features!r}; this etmpc knows {', '.join(FEATURE_SETS)}")
        decision = data.get("decision", "sample") if data.get("version") == VERSION else "sample"
        if decision not in ("sample", "greedy"):
            raise PolicyFileError(f"{where} has unknown decision rule {decision!r}; this etmpc knows sample, greedy")
        try:
            normalisation = Normalisation.from_json(data["normalisation"])
            theta = np.asarray(data["theta"], dtype=float)
            policy = cls(
                theta,
                normalisation,
                str(data["domain"]),
                dict(data.get("hyperparameters", {})),
                features=features,
                greedy=decision == "greedy",
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise PolicyFileError(f"{where} is corrupt ({exc!r})") from None
        n = normalisation.mean.size
        if theta.shape != (2 * n + 1,) or any(getattr(normalisation, a).shape != (n,) for a in ("std", "mean_sq", "std_sq")):
            raise PolicyFileError(f"{where} is corrupt: {theta.size} parameters for {n} state components")
        if not (np.all(np.isfinite(theta)) and np.all(normalisation.std > 0) and np.all(normalisation.std_sq > 0)):
            raise PolicyFileError(f"{where} is corrupt: non-finite parameters or non-positive scales")
        return policy


def load_policy(path: str | Path, domain: str | None = None, nx: int | None = None) -> LogisticPolicy:
    """Read a saved policy; check it was made for ``domain`` and its feature size fits ``nx`` states."""
    path = Path(path)
    try:
        data = json.loads(path.read_text())
    except FileNotFoundError:
        raise PolicyFileError(f"policy file {path} not found") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise PolicyFileError(f"policy file {path} cannot be read ({exc})") from None
    policy = LogisticPolicy.from_json(data, where=f"policy file {path}")
    if domain is not None and policy.domain != domain:
        raise PolicyFileError(f"policy file {path} was trained on {policy.domain!r}, not {domain!r}")
    if nx is not None and policy.theta.size != feature_size(nx, policy.features, policy.domain):
        raise PolicyFileError(
            f"policy file {path} has {policy.theta.size} features; {domain or 'this task'} needs "
            f"{feature_size(nx, policy.features, policy.domain)} ({policy.features} features)"
        )
    return policy


def write_json_atomically(path: Path, data: dict) -> None:
    """``data`` as compact JSON (the shipped policy files' format), written atomically."""
    write_text(path, dumps(data, indent=None))
