"""``sb3:PATH``: a trigger trained with Stable-Baselines3 on the trigger environment (``etmpc.envs``).

``PATH`` is the model's ``.zip`` (``stable_baselines3.PPO.save``); beside it, ``PATH`` with the suffix
``.json`` says what it was trained on: the task, the observation's names, and the running mean and
variance of the observations it was normalised with while training (``VecNormalize``'s, frozen). The
policy computes the environment's observation (:func:`etmpc.policies.features.observation`),
normalises it the same way and takes the network's likelier action (deterministic: it draws nothing).

Stable-Baselines3 and PyTorch are the optional extra ``rl`` (``pip install 'etmpc[rl]'``); the model is
loaded in each worker process when first asked, on one thread.
"""

from __future__ import annotations

import warnings
import zipfile
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from etmpc.common.documents import read_document
from etmpc.common.errors import EtmpcError
from etmpc.common.interrupts import described, genuine
from etmpc.loop import AugmentedState
from etmpc.policies.features import observation, observation_names
from etmpc.systems import canonical, system_class

FORMAT = "etmpc-sb3-policy"
CLIP = 10.0  # VecNormalize's clip_obs
EPSILON = 1e-8  # VecNormalize's epsilon


def metadata_path(model: Path) -> Path:
    return Path(model).with_suffix(".json")


class SB3Policy:
    """A Stable-Baselines3 model as a recomputation policy (see the module's docstring)."""

    stochastic: ClassVar[bool] = False
    observes: ClassVar[bool] = True

    def __init__(self, path: str | Path, task: str, mean: np.ndarray, var: np.ndarray, algorithm: str = "ppo"):
        self.path, self.task, self.algorithm = Path(path), task, algorithm
        self.mean, self.scale = np.asarray(mean, float), np.sqrt(np.asarray(var, float) + EPSILON)
        cls = system_class(task)
        self.domain = cls.name
        self._size = self.mean.size
        self._model: Any = None

    @property
    def spec(self) -> str:
        return f"sb3:{self.path}"

    def __getstate__(self):  # the network stays in its process: each worker loads its own
        return {k: v for k, v in self.__dict__.items() if k != "_model"} | {"_model": None}

    def _load(self):
        self._model = open_model(self.path, self.algorithm, self._size)
        return self._model

    def normalised(self, s: AugmentedState) -> np.ndarray:
        obs = (observation(self.domain, s, self._size) - self.mean) / self.scale
        return np.clip(obs, -CLIP, CLIP).astype(np.float32)

    def decide(self, s: AugmentedState, rng: np.random.Generator) -> bool:
        model = self._model or self._load()
        action, _ = model.predict(self.normalised(s), deterministic=True)
        return bool(int(action) == 1)


def open_model(path: Path, algorithm: str, size: int):
    """The Stable-Baselines3 model in ``path``, on the CPU and one thread; :class:`EtmpcError` (one line)
    unless it is a model of ``algorithm`` with ``size`` observations and two actions."""
    try:
        import stable_baselines3
        import torch
    except ImportError:
        raise EtmpcError(f"sb3:{path} needs Stable-Baselines3: pip install 'etmpc[rl]'") from None
    torch.set_num_threads(1)
    cls = getattr(stable_baselines3, algorithm.upper(), None)
    if not (isinstance(cls, type) and hasattr(cls, "load")):
        raise EtmpcError(f"sb3:{path}: {metadata_path(path).name} names the algorithm {algorithm!r}, which "
                         "Stable-Baselines3 does not have (e.g. ppo, dqn, a2c)")
    not_a_model = f"sb3:{path} is not a Stable-Baselines3 model"
    try:
        with zipfile.ZipFile(path) as archive:
            members = set(archive.namelist())
    except (zipfile.BadZipFile, OSError) as exc:
        raise EtmpcError(f"{not_a_model} (not a readable zip file: {described(exc)})") from None
    if not {"data", "policy.pth"} <= members:
        raise EtmpcError(f"{not_a_model} (its zip has no 'data' and 'policy.pth'; save one with model.save(PATH))")
    try:
        with warnings.catch_warnings():  # a model saved by another version warns; the checks below decide
            warnings.simplefilter("ignore")
            model = cls.load(str(path), device="cpu")
    except BaseException as exc:  # a truncated or foreign file fails deep inside torch or zipfile
        if genuine(exc):
            raise
        raise EtmpcError(f"{not_a_model} of {algorithm} ({described(exc)})") from None
    shape, actions = getattr(model.observation_space, "shape", None), getattr(model.action_space, "n", None)
    if shape != (size,) or actions != 2:
        raise EtmpcError(f"sb3:{path} takes observations of shape {shape} and {actions} actions; the trigger "
                         f"environment has ({size},) and 2 (keep, recompute)")
    return model


def load_sb3(path: str, task: str | None) -> SB3Policy:
    """``sb3:PATH``, checked against ``task`` (the one it is evaluated on), and loaded once here so that
    a file that is not a model fails before any work starts."""
    model = Path(path)
    if model.suffix == ".json":
        raise EtmpcError(f"sb3:{model} is the model's description; give the model itself, sb3:{model.with_suffix('.zip')}")
    if not model.is_file():
        raise EtmpcError(f"policy file {model} not found")
    meta_file = metadata_path(model)
    meta = read_document(meta_file, FORMAT, missing=f"{model} has no {meta_file.name} beside it (what it was trained on)",
                         unreadable=f"{meta_file} cannot be read ({{error}})",
                         foreign=f"{meta_file} is not an etmpc Stable-Baselines3 policy (format {FORMAT!r})")
    try:
        trained_on = canonical(str(meta["task"]))
        cls = system_class(trained_on)
        mean, var = np.asarray(meta["observation_mean"], float), np.asarray(meta["observation_var"], float)
        names = tuple(meta["observation_names"])
    except (KeyError, TypeError, ValueError) as exc:
        raise EtmpcError(f"{meta_file} is corrupt ({exc!r})") from None
    if task is not None and canonical(task) != trained_on:
        raise EtmpcError(f"policy {model} was trained on {trained_on!r}, not {canonical(task)!r}")
    if names != observation_names(cls.name, cls.state_names) or mean.shape != var.shape or mean.shape != (len(names),):
        raise EtmpcError(f"{meta_file}: its observation does not match the task's")
    if not (np.all(np.isfinite(mean)) and np.all(np.isfinite(var)) and np.all(var >= 0)):
        raise EtmpcError(f"{meta_file} has non-finite or negative normalisation")
    algorithm = meta.get("algorithm", "ppo")
    if not isinstance(algorithm, str):
        raise EtmpcError(f"{meta_file} is corrupt (algorithm {algorithm!r} is not a name)")
    policy = SB3Policy(model, trained_on, mean, var, algorithm)
    policy._load()
    return policy
