"""What a policy sees, as numbers: the feature sets of the learned policy, and the observation of the
trigger environment (``etmpc.envs``) and of the policies trained on it (``sb3:PATH``).

A feature set defines a raw vector ``r`` of the augmented state ``s``:

* ``error`` (the default): ``r = [x_i - x_hat_i, i - k, exogenous]``: the prediction error per state,
  the plan's age and, for a task whose system has them, its exogenous features (the battery's
  prices and production, now and as the kept plan assumed them);
* ``paper``: ``r = s = [x_i, x_k, i - k]``, the augmented state as the paper's text defines it;
* ``levels``: the ``error`` set and ``unconverged``, 1 when the kept plan is a real-time iterate its
  solver left short of convergence (:attr:`etmpc.control.plan.Plan.converged`), else 0: on a task with
  compute levels, how far the last iteration left the plan from its optimum, which the prediction error
  of a plan made this step cannot say.

The learned policy normalises ``[r, r^2]`` and adds a bias (``etmpc.policies.learned``); the
environment's observation is ``[r, r^2]`` of the ``error`` set, as float32 (:func:`observation`).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from etmpc.common.errors import EtmpcError
from etmpc.loop import AugmentedState
from etmpc.systems.base import system_type

FEATURE_SETS = ("error", "paper", "levels")
DEFAULT_FEATURES = "error"


def raw_state(s: AugmentedState) -> np.ndarray:
    """``s = [x_i, x_k, i - k]``."""
    return np.concatenate([s.x, s.x_plan, [float(s.age)]])


@lru_cache(maxsize=None)
def _exogenous(domain: str):
    """The task's exogenous features ``f(s) -> array`` and their names (its system's optional
    ``exogenous_features``, see :mod:`etmpc.systems.base`), or None."""
    system = system_type(domain)
    names = system.exogenous_feature_names
    return (system.exogenous_features, names) if system.exogenous_features is not None and names else None


def raw_features(features: str, domain: str, s: AugmentedState) -> np.ndarray:
    """The raw vector ``r`` of feature set ``features`` (see the module docstring)."""
    if features == "paper":
        return raw_state(s)
    exogenous = _exogenous(domain)
    error = np.concatenate([s.x - s.x_predicted, [float(s.age)]])
    error = error if exogenous is None else np.concatenate([error, exogenous[0](s)])
    return np.append(error, float(not s.plan.converged)) if features == "levels" else error


def raw_size(features: str, domain: str, nx: int) -> int:
    if features == "paper":
        return 2 * nx + 1
    exogenous = _exogenous(domain)
    return nx + 1 + (0 if exogenous is None else len(exogenous[1])) + (features == "levels")  # and unconverged


def feature_size(nx: int, features: str = "paper", domain: str = "") -> int:
    return 2 * raw_size(features, domain, nx) + 1


def check_features(name: str) -> str:
    if name not in FEATURE_SETS:
        raise EtmpcError(f"unknown feature set {name!r}; valid: {', '.join(FEATURE_SETS)}")
    return name


def raw_names(features: str, domain: str, state_names) -> tuple[str, ...]:
    """The name of each component of ``r``, in order."""
    if features == "paper":
        return (*(f"{n}_now" for n in state_names), *(f"{n}_at_plan" for n in state_names), "plan_age")
    exogenous = _exogenous(domain)
    names = (*(f"error_{n}" for n in state_names), "plan_age", *(() if exogenous is None else exogenous[1]))
    return (*names, "unconverged") if features == "levels" else names


def observation_names(domain: str, state_names) -> tuple[str, ...]:
    """The components of :func:`observation`: ``r`` of the ``error`` set, then each one squared."""
    names = raw_names("error", domain, state_names)
    return (*names, *(f"{n}^2" for n in names))


def observation(domain: str, s: AugmentedState | None, size: int) -> np.ndarray:
    """``[r, r^2]`` of the ``error`` features as float32; zeros where there is no plan yet (``s`` is
    None: at an episode's first step, where the loop must solve whatever it is told)."""
    if s is None:
        return np.zeros(size, dtype=np.float32)
    r = raw_features("error", domain, s)
    return np.concatenate([r, r * r]).astype(np.float32)
