"""A trained policy's frozen observation normalisation, carried by the environment as data (JSON), never
as a pickle.

``etmpc train --algorithm ppo`` trains behind Stable-Baselines3's ``VecNormalize`` and writes its
statistics, frozen, beside the model: ``ppo.json`` (``sb3:PATH`` reads it). ``gymnasium.make(ID,
normalize="…/ppo.json")`` hands out the observation that policy was trained on (:class:`Normalization`,
the same function as ``sb3:``, so the same bits): ``PPO.load`` and ``model.predict`` on it decide as
``etmpc evaluate --policy sb3:…`` does. :func:`save_normalization` writes that file for a
``VecNormalize`` of one's own (``vec_normalize.save`` pickles; this is JSON).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from etmpc.common.checks import BadType, BadValue
from etmpc.common.outputs import write_json
from etmpc.policies.features import observation_names
from etmpc.policies.sb3 import CLIP, EPSILON, FORMAT, normalise, read_description
from etmpc.systems import SystemKey, system_key
from etmpc.systems.base import system_type


@dataclass(frozen=True, eq=False)
class Normalization:
    """``VecNormalize``'s frozen normalisation of one task's observation, read from an etmpc description
    (:meth:`read`); calling it normalises an observation exactly as ``sb3:`` does (:func:`~etmpc.policies.sb3.normalise`)."""

    path: Path
    task: str
    mean: np.ndarray
    var: np.ndarray

    @classmethod
    def read(cls, path: str | os.PathLike, task: str | SystemKey) -> Normalization:
        """The normalisation in ``path`` (a policy's ``.json``), checked against ``task``: the same task,
        the same observation names; :class:`EtmpcError` in one line otherwise (``BadType``, a ``TypeError``,
        for a ``path`` that is not one; ``BadValue``, a ``ValueError``, for a model given instead of its description)."""
        if not isinstance(path, (str, os.PathLike)):
            raise BadType(f"normalize: the path of a policy's .json is needed, got {type(path).__name__} {path!r}")
        path = Path(path)
        if path.suffix == ".zip":
            raise BadValue(f"normalize={path} is a model; give its description, normalize={path.with_suffix('.json')}")
        key = system_key(task)
        trained_on, mean, var, _ = read_description(
            path, key.task, f"normalize={path}: its policy", f"normalize={path}: no such file"
        )
        return cls(path, trained_on, mean, var)

    @property
    def scale(self) -> np.ndarray:
        return np.sqrt(self.var + EPSILON)

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        return normalise(obs, self.mean, self.scale)


def save_normalization(vec_normalize, task: str | SystemKey, path: str | os.PathLike, **extra) -> Path:
    """Write the observation statistics of ``vec_normalize`` (Stable-Baselines3's ``VecNormalize``, as
    trained on ``task``'s environment) to ``path``, as the ``.json`` that ``sb3:MODEL`` reads beside
    ``MODEL`` and ``normalize=`` reads: ``save_normalization(vec, "cart_pendulum", "ppo_cart.json")``.
    ``extra`` fields are kept in it (``etmpc train`` writes its settings). Returns ``path``."""
    key = system_key(task)
    cls = system_type(key.task)
    names = list(observation_names(cls.name, cls.state_names))
    rms = getattr(vec_normalize, "obs_rms", None)
    mean = np.asarray(getattr(rms, "mean", np.nan), float)
    var = np.asarray(getattr(rms, "var", np.nan), float)
    if not getattr(vec_normalize, "norm_obs", False) or mean.shape != (len(names),) or var.shape != mean.shape:
        raise BadValue(
            f"save_normalization: a VecNormalize with norm_obs=True on {key.task}'s {len(names)} "
            f"observations is needed, got {type(vec_normalize).__name__}"
        )
    clip, epsilon = getattr(vec_normalize, "clip_obs", None), getattr(vec_normalize, "epsilon", None)
    if (clip, epsilon) != (CLIP, EPSILON):
        raise BadValue(
            f"save_normalization: sb3: normalises with VecNormalize's defaults, clip_obs={CLIP:g} and "
            f"epsilon={EPSILON:g}; this one has clip_obs={clip!r}, epsilon={epsilon!r}"
        )
    if not (np.all(np.isfinite(mean)) and np.all(np.isfinite(var)) and np.all(var >= 0)):
        raise BadValue("save_normalization: its statistics are non-finite or negative")
    path = Path(path)
    write_json(
        path,
        {
            "format": FORMAT,
            "version": 1,
            "task": key.task,
            "algorithm": "ppo",
            "observation_names": names,
            "observation_mean": mean.tolist(),
            "observation_var": var.tolist(),
            **extra,
        },
    )
    return path
