"""The learned recomputation policy: logistic regression on normalised features of the augmented state.

``pi(0 | s) = sigma(theta^T phi(s))`` is the probability of *keeping* the plan (paper eq. logreg),
``pi(1 | s) = 1 - pi(0 | s)`` that of recomputing. The features are

    phi(s) = [ (s - mean) / std,  (s^2 - mean_sq) / std_sq,  1 ],   s = [x_i, x_k, i - k]

so ``len(phi) = 2 (2 nx + 1) + 1``. The normalisation is measured once per training run (see
:func:`etmpc.train`) and saved with the parameters, the task and the hyperparameters in one JSON
file, so ``--policy rl:PATH`` evaluates it anywhere. JSON keeps every float exactly (Python writes
the shortest repr that reads back to the same double).
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from etmpc.errors import EtmpcError
from etmpc.policies import AugmentedState

FORMAT = "etmpc-logistic-policy"
VERSION = 1
INITIAL_KEEP_LOGIT = -3.0  # sigma(-3) = 0.047: at first the policy recomputes 95 % of the time


class PolicyFileError(EtmpcError):
    """A policy or checkpoint file that is missing, corrupt, or made for another task."""


def raw_state(s: AugmentedState) -> np.ndarray:
    """``s = [x_i, x_k, i - k]``."""
    return np.concatenate([s.x, s.x_plan, [float(s.age)]])


def feature_size(nx: int) -> int:
    return 2 * (2 * nx + 1) + 1


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
    stochastic: bool = True

    @property
    def spec(self) -> str:
        return f"rl:{self.hyperparameters.get('name', self.domain)}"

    @classmethod
    def initial(cls, normalisation: Normalisation, domain: str, hyperparameters: dict | None = None) -> LogisticPolicy:
        theta = np.zeros(normalisation.mean.size * 2 + 1)
        theta[-1] = INITIAL_KEEP_LOGIT
        return cls(theta, normalisation, domain, dict(hyperparameters or {}))

    def with_theta(self, theta: np.ndarray, record: bool = False) -> LogisticPolicy:
        return LogisticPolicy(np.array(theta, dtype=float), self.normalisation, self.domain, self.hyperparameters, record)

    def keep_probability(self, s: AugmentedState) -> float:
        return self._keep_probability(self.normalisation.features(raw_state(s)))

    def _keep_probability(self, phi: np.ndarray) -> float:
        return sigmoid(float(self.theta @ phi))

    def decide(self, s: AugmentedState, rng: np.random.Generator) -> bool:
        phi = self.normalisation.features(raw_state(s))
        p_keep = self._keep_probability(phi)
        recompute = bool(rng.random() >= p_keep)
        if self.record:
            self.decisions.append((phi, recompute, p_keep))
        return recompute

    # -- file -------------------------------------------------------------------------------------
    def to_json(self) -> dict:
        return {
            "format": FORMAT,
            "version": VERSION,
            "domain": self.domain,
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
            raise PolicyFileError(f"{where} is not an etmpc logistic policy (format {data.get('format') if isinstance(data, dict) else None!r})")
        if data.get("version") != VERSION:
            raise PolicyFileError(f"{where} has format version {data.get('version')!r}; this etmpc reads {VERSION}")
        try:
            normalisation = Normalisation.from_json(data["normalisation"])
            theta = np.asarray(data["theta"], dtype=float)
            policy = cls(theta, normalisation, str(data["domain"]), dict(data.get("hyperparameters", {})))
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
    if nx is not None and policy.theta.size != feature_size(nx):
        raise PolicyFileError(f"policy file {path} has {policy.theta.size} features; {domain or 'this task'} needs {feature_size(nx)}")
    return policy


def write_json_atomically(path: Path, data: dict) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    with open(tmp, "w") as f:
        json.dump(data, f)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)
