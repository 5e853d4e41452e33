"""The learned recomputation policy: logistic regression on normalised features of the augmented state.

``pi(0 | s) = sigma(theta^T phi(s))`` is the probability of *keeping* the plan (paper eq. logreg),
``pi(1 | s) = 1 - pi(0 | s)`` that of recomputing. The features are

    phi(s) = [ (r - mean) / std,  (r^2 - mean_sq) / std_sq,  1 ]

of a raw vector ``r`` chosen by the policy's *feature set*:

* ``error`` (the default for training): ``r = [x_i - x_hat_i, i - k, exogenous]``, the prediction
  error per state (its square comes with ``r^2``) and the plan's age, as the authors' own
  environment feeds its policy; for the battery also the exogenous information a good policy needs
  (its system's ``exogenous_features``; the battery's: the price and net production now, what the plan
  assumed for them, their differences, and the value at today's price of the trade the plan makes now);
* ``paper``: ``r = s = [x_i, x_k, i - k]``, the augmented state as the paper's text defines it;
* ``levels``: the ``error`` set and whether the kept plan is an unconverged real-time iterate
  (:mod:`etmpc.policies.features`).

The normalisation is measured once per training run (see :func:`etmpc.learning.train`) and saved with the
parameters, the feature set, the task and the hyperparameters in one JSON file, so ``--policy
rl:PATH`` evaluates it anywhere. The decision rule is saved too: ``sample`` draws the decision from
``pi`` (the paper's policy, and what GPOMDP's gradient needs), ``greedy`` takes the likelier answer
(what a classifier trained by DPI is). JSON keeps every float exactly (Python writes the shortest repr
that reads back to the same double). Files of format version 1 (before feature sets) are ``paper``.

**Compute levels.** On a task whose decisions are keep, one SQP iteration or a full solve
(``system.compute_levels``), the policy has a second stage on the same features:
``pi(solve | compute, s) = sigma(theta_level . phi(s))``, else one SQP iteration. It decides in two
steps: keep or compute as above, then, if computing, a full solve or an iteration (greedy: a full
solve exactly when ``theta_level . phi > 0``, so a tie takes the cheaper iteration; sampled: the
second draw is made only when the first says compute), and answers a level (``KEEP``, ``ITERATE``,
``SOLVE``). Such a file has ``theta_level`` and format version 3 (so an etmpc that does not know levels
refuses it rather than playing its first stage alone); a file without is a keep-or-solve policy, read
and played exactly as before. Neither kind is loaded for a task of the other kind (:func:`load_policy`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from etmpc.common import checks
from etmpc.common.documents import loads
from etmpc.common.errors import EtmpcError
from etmpc.common.numerics import dot
from etmpc.common.outputs import dumps, write_text
from etmpc.control.timing import ITERATE, KEEP, SOLVE
from etmpc.loop import AugmentedState, Decision, drawing
from etmpc.policies.features import FEATURE_SETS, feature_size, raw_features
from etmpc.systems import has_levels, same_task

FORMAT = "etmpc-logistic-policy"
VERSION = 2
LEVELS_VERSION = 3  # a policy with compute levels (theta_level)
INITIAL_KEEP_LOGIT = -3.0  # sigma(-3) = 0.047: at first the policy recomputes 95 % of the time
INITIAL_SOLVE_LOGIT = 3.0  # with levels, a recompute is at first a full solve 95 % of the time
# What a policy file's numbers may be (see LogisticPolicy.from_json for why), checked when it is read: the
# size of a weight (theta, theta_level), of a normalisation's mean or scale, and the smallest scale
# (Normalisation.fit writes a smaller standard deviation as 1). The self-trigger's files share them.
MAX_WEIGHT, MAX_SCALE, MIN_SCALE = checks.MAX_WEIGHT, checks.MAX_SCALE, checks.MIN_SCALE


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
    def from_json(cls, data: dict, where: str = "policy") -> Normalisation:
        """From a policy file's ``normalisation``, each number checked (:func:`file_numbers`)."""
        if not isinstance(data, dict):
            raise PolicyFileError(f"{where}: normalisation is not an object of mean, std, mean_sq and std_sq")
        return cls(
            *(
                file_numbers(data[name], f"normalisation.{name}", where, MAX_SCALE, MIN_SCALE if name.startswith("std") else None)
                for name in ("mean", "std", "mean_sq", "std_sq")
            )
        )


def file_numbers(values, field: str, where: str, largest: float, smallest: float | None = None) -> np.ndarray:
    """The numbers of field ``field`` of a policy file (``where``), as :func:`etmpc.common.checks.json_numbers`
    checks them; else :class:`PolicyFileError` in one line naming the file, the field and the first bad number."""
    try:
        return checks.json_numbers(values, field, largest, smallest)
    except checks.BadValue as exc:
        raise PolicyFileError(f"{where}: {exc}") from None


def sigmoid(z: float) -> float:
    return 1.0 / (1.0 + math.exp(-z)) if z >= 0 else math.exp(z) / (1.0 + math.exp(z))


@dataclass(eq=False)
class LogisticPolicy:
    """``pi(keep | s) = sigma(theta . phi(s))``; draws its decisions from the generator it is given.

    With ``record`` set, every decision appends ``(phi, answer, p_keep)`` to :attr:`decisions`
    (what GPOMDP needs); the control loop only asks at steps where the plan has not run out. With
    ``theta_level`` it is a policy with compute levels (see the module docstring).
    """

    theta: np.ndarray
    normalisation: Normalisation
    domain: str
    hyperparameters: dict = field(default_factory=dict)
    record: bool = False
    decisions: list = field(default_factory=list)
    features: str = "paper"  # the feature set (FEATURE_SETS)
    greedy: bool = False  # True: recompute exactly when pi(keep | s) < 1/2, drawing nothing
    theta_level: np.ndarray | None = None  # compute levels: pi(solve | compute, s) = sigma(theta_level . phi(s))

    @property
    def levels(self) -> bool:
        """Whether it answers compute levels (keep, one SQP iteration, a full solve) rather than keep or solve."""
        return self.theta_level is not None

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
        levels: bool = False,
    ) -> LogisticPolicy:
        theta = np.zeros(normalisation.mean.size * 2 + 1)
        theta[-1] = INITIAL_KEEP_LOGIT
        theta_level = None
        if levels:
            theta_level = np.zeros(theta.size)
            theta_level[-1] = INITIAL_SOLVE_LOGIT
        hyper = dict(hyperparameters or {})
        return cls(theta, normalisation, domain, hyper, features=features, greedy=greedy, theta_level=theta_level)

    def with_theta(self, theta: np.ndarray, record: bool = False, theta_level: np.ndarray | None = None) -> LogisticPolicy:
        """The same policy with parameters ``theta`` (and ``theta_level``, if given; else its own)."""
        level = self.theta_level if theta_level is None else np.array(theta_level, dtype=float)
        return LogisticPolicy(
            np.array(theta, dtype=float),
            self.normalisation,
            self.domain,
            self.hyperparameters,
            record,
            features=self.features,
            greedy=self.greedy,
            theta_level=level,
        )

    def phi(self, s: AugmentedState) -> np.ndarray:
        return self.normalisation.features(raw_features(self.features, self.domain, s))

    def keep_probability(self, s: AugmentedState) -> float:
        return sigmoid(self.decision_value(self.phi(s)))

    def solve_probability(self, s: AugmentedState) -> float:
        """``pi(solve | compute, s)`` of a policy with compute levels."""
        return sigmoid(self.level_value(self.phi(s)))

    def decision_value(self, phi: np.ndarray) -> float:
        """The logit ``theta . phi`` of keeping, the same on every machine: the terms ``theta_j phi_j``
        are formed first (each rounded as IEEE multiplication rounds it) and judged before they are
        summed. Terms of ``+inf`` only give ``+inf`` (a sure keep), of ``-inf`` only ``-inf`` (a sure
        recompute), and finite terms are summed exactly and rounded once (``etmpc.common.numerics.dot``); an
        exact sum beyond the double range is ``+-inf`` by its sign. Terms of both infinities, or NaN,
        have no value: that is an error, on every machine (a BLAS ``theta @ phi`` gives NaN or
        ``-inf`` for them depending on the CPU's kernel)."""
        return self._logit(self.theta, phi, "decision value")

    def level_value(self, phi: np.ndarray) -> float:
        """The logit ``theta_level . phi`` of a full solve over one SQP iteration, as :meth:`decision_value`."""
        assert self.theta_level is not None  # a policy with compute levels: it has level parameters
        return self._logit(self.theta_level, phi, "level value")

    def _logit(self, theta: np.ndarray, phi: np.ndarray, what: str) -> float:
        with np.errstate(over="ignore", invalid="ignore"):
            logit = dot(theta, phi)
        if math.isnan(logit):
            raise PolicyFileError(
                f"the {self.domain} policy's {what} is not a number at this state "
                "(its parameters overflow against the features): retrain it or check its file"
            )
        return logit

    def decide(self, s: AugmentedState, rng: np.random.Generator | None) -> Decision:
        phi = self.phi(s)
        logit = self.decision_value(phi)
        p_keep = sigmoid(logit)
        # Greedy: recompute when pi(keep | s) < 1/2, i.e. when the logit is negative (decided on the
        # logit itself, so no exp rounding can move the boundary).
        recompute = logit < 0.0 if self.greedy else bool(drawing(rng).random() >= p_keep)
        answer: Decision = recompute
        if self.theta_level is not None:  # compute levels: then a full solve or one SQP iteration
            answer = KEEP
            if recompute:
                level = self.level_value(phi)
                solve = level > 0.0 if self.greedy else bool(drawing(rng).random() < sigmoid(level))
                answer = SOLVE if solve else ITERATE
        if self.record:
            self.decisions.append((phi, answer, p_keep))
        return answer

    # -- file -------------------------------------------------------------------------------------
    def to_json(self) -> dict:
        data = {
            "format": FORMAT,
            "version": VERSION if self.theta_level is None else LEVELS_VERSION,
            "domain": self.domain,
            "features": self.features,
            "decision": "greedy" if self.greedy else "sample",
            "theta": self.theta.tolist(),
        }
        if self.theta_level is not None:
            data["theta_level"] = self.theta_level.tolist()
        return dict(data, normalisation=self.normalisation.to_json(), hyperparameters=self.hyperparameters)

    def save(self, path: str | Path) -> None:
        """Write atomically: a crash leaves the old file or the new one, never half of one."""
        write_json_atomically(Path(path), self.to_json())

    @classmethod
    def from_json(cls, data: dict, where: str = "policy") -> LogisticPolicy:
        """A policy from its file's content (``where`` names the file in errors), checked: its format, and
        each number (:func:`file_numbers`) finite, a weight at most :data:`MAX_WEIGHT` (1e6) in size, the
        normalisation's means and scales at most :data:`MAX_SCALE` (1e100), its scales at least
        :data:`MIN_SCALE` (1e-12, what :meth:`Normalisation.fit` writes). A bad one is refused here, in one
        line naming the file and the field, rather than clipped or played.

        Why refused, and why these bounds: a fitted policy's weights are of order 1 (every shipped file's are
        below 4) on features scaled to unit variance. A weight of 1e6 puts the logit beyond +-37, where the
        probability is exactly 0 or 1 in double precision, at 1e-4 standard deviations of its feature: a
        larger one decides nothing a smaller one does not, and only makes the dot product overflow. Weights
        of +-1e308 gave terms of +inf and -inf, a logit with no value, and an error in the middle of a run,
        after its work was spent; an integer too large for a double was an ``OverflowError`` traceback.
        Within the bounds, the logit at any state whose raw features are within +-1e100 is a finite number
        (no term exceeds 1e6 x 1e212), so a file that loads decides wherever a plant goes that far. Beyond,
        a logit of +-inf is still a probability (:func:`sigmoid` gives 1 or 0); only terms of both
        infinities have no value, and are an error naming the policy (:meth:`decision_value`)."""
        if not isinstance(data, dict) or data.get("format") != FORMAT:
            raise PolicyFileError(
                f"{where} is not an etmpc logistic policy (format {data.get('format') if isinstance(data, dict) else None!r})"
            )
        version = data.get("version")
        if version not in (1, VERSION, LEVELS_VERSION):
            raise PolicyFileError(f"{where} has format version {version!r}; this etmpc reads 1, {VERSION} and {LEVELS_VERSION}")
        if (version == LEVELS_VERSION) != ("theta_level" in data):
            raise PolicyFileError(
                f"{where} is corrupt: theta_level (compute levels) comes with format version {LEVELS_VERSION}, "
                f"and only with it (this file: version {version}, {'with' if 'theta_level' in data else 'without'} theta_level)"
            )
        features = data.get("features", "paper") if version != 1 else "paper"
        if features not in FEATURE_SETS:
            raise PolicyFileError(f"{where} has unknown feature set {features!r}; this etmpc knows {', '.join(FEATURE_SETS)}")
        decision = data.get("decision", "sample") if version != 1 else "sample"
        if decision not in ("sample", "greedy"):
            raise PolicyFileError(f"{where} has unknown decision rule {decision!r}; this etmpc knows sample, greedy")
        try:
            normalisation = Normalisation.from_json(data["normalisation"], where)
            theta = file_numbers(data["theta"], "theta", where, MAX_WEIGHT)
            theta_level = file_numbers(data["theta_level"], "theta_level", where, MAX_WEIGHT) if "theta_level" in data else None
            policy = cls(
                theta,
                normalisation,
                str(data["domain"]),
                dict(data.get("hyperparameters", {})),
                features=features,
                greedy=decision == "greedy",
                theta_level=theta_level,
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise PolicyFileError(f"{where} is corrupt ({exc!r})") from None
        n = normalisation.mean.size
        if theta.shape != (2 * n + 1,) or any(getattr(normalisation, a).shape != (n,) for a in ("std", "mean_sq", "std_sq")):
            raise PolicyFileError(f"{where} is corrupt: {theta.size} parameters for {n} state components")
        if theta_level is not None and theta_level.shape != theta.shape:
            raise PolicyFileError(f"{where} is corrupt: theta_level is not {theta.size} finite numbers")
        return policy


def load_policy(path: str | Path, domain: str | None = None, nx: int | None = None) -> LogisticPolicy:
    """Read a saved policy; check it was made for ``domain``, decides as that task's decisions are (keep or
    solve, or compute levels: :func:`etmpc.systems.has_levels`) and its feature size fits ``nx`` states."""
    path = Path(path)
    try:
        data = loads(path.read_text())
    except FileNotFoundError:
        raise PolicyFileError(f"policy file {path} not found") from None
    except (OSError, ValueError) as exc:  # UnicodeDecodeError and JSONDecodeError are ValueErrors
        raise PolicyFileError(f"policy file {path} cannot be read ({exc})") from None
    policy = LogisticPolicy.from_json(data, where=f"policy file {path}")
    if domain is not None and not same_task(policy.domain, domain):
        raise PolicyFileError(f"policy file {path} was trained on {policy.domain!r}, not {domain!r}")
    if domain is not None and policy.levels != has_levels(domain):
        raise PolicyFileError(
            f"policy file {path} decides {_DECISIONS[policy.levels]}, but task {domain}'s decisions are "
            f"{_DECISIONS[not policy.levels]}: train a policy for it"
        )
    if nx is not None and policy.theta.size != feature_size(nx, policy.features, policy.domain):
        raise PolicyFileError(
            f"policy file {path} has {policy.theta.size} features; {domain or 'this task'} needs "
            f"{feature_size(nx, policy.features, policy.domain)} ({policy.features} features)"
        )
    return policy


_DECISIONS = {False: "keep or solve", True: "keep, one SQP iteration or a full solve (compute levels)"}


def write_json_atomically(path: Path, data: dict) -> None:
    """``data`` as compact JSON (the shipped policy files' format), written atomically."""
    write_text(path, dumps(data, indent=None))
