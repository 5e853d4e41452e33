"""``sb3:PATH``: a policy trained with Stable-Baselines3 on the trigger environment (``etmpc.envs``).

``PATH`` is the model's ``.zip`` (``stable_baselines3.PPO.save``); beside it, ``PATH`` with the suffix
``.json`` says what it was trained on: the task, the observation's names, and the running mean and
variance of the observations it was normalised with while training (``VecNormalize``'s, frozen). The
policy computes the environment's observation (:func:`etmpc.policies.features.observation`, made
finite as the environment makes it: :func:`finite_observation`), normalises it the same way
(:func:`normalise`, what ``gymnasium.make(ID, normalize=JSON)`` applies too) and takes the network's
likeliest action (deterministic: it draws nothing).

A model has as many actions as the trigger environment it was trained on: two (keep, recompute: the
policy answers ``True``/``False``) or, on a task with compute levels (``cart_pendulum/kicks_levels``),
three (the policy answers the level: 0 keep, 1 one SQP iteration, 2 a full solve). A model plays on
the task it was trained on, or on a task that plays that task's world with time in the loop (the
system's ``variant_of``: a model of ``cart_pendulum/kicks`` on ``kicks_late`` and ``kicks_levels``, where
its recompute is a full solve); a model whose actions are not its task's is refused when loaded.

Without the ``.json`` (a model saved by a plain ``model.save(PATH)``), the policy is evaluated on the
task it is given and sees the raw observation, as a model trained on the plain environment saw it; its
observation size is checked against the task's. A model trained behind ``VecNormalize`` (its zip keeps
the last un-normalised observation, ``_last_original_obs``) is refused then: its statistics are not in
the zip (``etmpc.envs.save_normalization`` writes the ``.json``). A normalising ``gymnasium`` wrapper
leaves no such trace: such a model needs its ``.json`` too.

A policy file is data, never code. ``PPO.load`` unpickles every ``:serialized:`` entry of the zip's
``data``, so a file could run anything in every process that loads it; here nothing of it is
unpickled. ``data`` is read as JSON; the one pickle consulted, the policy's class, is only *parsed*
(:mod:`pickletools`: the globals it names, nothing run) and must be a plain reference to
``ActorCriticPolicy`` (PPO's ``MlpPolicy``); the spaces and ``policy_kwargs`` (at most ``net_arch``)
are read from their plain JSON fields. The weights come from ``policy.pth`` through torch's
weights-only reader, are checked against that architecture, and become numpy arrays once, in the
process that parses the spec; workers receive them with the policy, without torch.

The network (tanh layers, SB3's default, then the action logits) is evaluated in numpy
(:class:`Network`). PyTorch is needed to read the weights only: the optional extra ``rl``
(``pip install 'etmpc[rl]'``).
"""

from __future__ import annotations

from pathlib import Path
from typing import ClassVar

import numpy as np

from etmpc.common import checks
from etmpc.common.documents import read_document
from etmpc.common.errors import EtmpcError
from etmpc.loop import AugmentedState, Decision
from etmpc.policies.features import observation, observation_names
from etmpc.policies.sb3_network import (  # noqa: F401 (re-exported: what reads a zip as data, and the network)
    ALGORITHMS,
    DEFAULT_NET_ARCH,
    MAX_ENTRY,
    POLICY_CLASS,
    TOLERANCE,
    Network,
    _entries,
    _fields,
    metadata_path,
    open_network,
    pickled_globals,
)
from etmpc.systems import canonical, has_levels
from etmpc.systems.base import system_type

FORMAT = "etmpc-sb3-policy"
CLIP = 10.0  # VecNormalize's clip_obs
EPSILON = 1e-8  # VecNormalize's epsilon


def finite_observation(obs: np.ndarray) -> np.ndarray:
    """The trigger environment's observation as it hands it out: a diverged plant's features clipped to
    the float32 range, NaN as 0 (unchanged, the same array, when all are finite)."""
    if np.isfinite(obs.sum()):
        return obs
    # float32's range as Python floats (exactly: every float32 is a double), as numpy's stubs type the bounds
    largest = float(np.finfo(np.float32).max)
    return np.nan_to_num(obs, nan=0.0, posinf=largest, neginf=-largest)


def normalise(obs: np.ndarray, mean: np.ndarray | None, scale: np.ndarray | None) -> np.ndarray:
    """What the network sees of the environment's observation ``obs``: ``VecNormalize``'s frozen
    ``clip((obs - mean) / scale, -10, 10)`` as float32, ``scale = sqrt(var + 1e-8)`` (float64 ``mean`` and
    ``scale``); ``obs`` itself as float32 without a normalisation (``mean`` None)."""
    if mean is None:
        return np.asarray(obs, dtype=np.float32)
    return np.clip((obs - mean) / scale, -CLIP, CLIP).astype(np.float32)


def task_actions(task: str) -> int:
    """The trigger environment's actions on ``task``: 3 on a task with compute levels, else 2 (read from
    its system's ``Config``, without building the system)."""
    return 3 if has_levels(task) else 2


def plays_on(trained_on: str, task: str) -> bool:
    """Whether a model trained on ``trained_on`` plays on ``task`` (both canonical): the same task, or one
    that plays its world with time in the loop (``task``'s system names it as its ``variant_of``)."""
    cls = system_type(task)
    variant = cls.variant_of
    return trained_on == task or (variant is not None and canonical(variant) == trained_on)


class SB3Policy:
    """A Stable-Baselines3 model as a recomputation policy (see the module's docstring). It pickles
    with its network's numpy weights: a worker process decides without reading the file again.
    ``mean`` and ``var`` None: the raw observation (a model trained on the plain environment).
    A two-action network answers ``True``/``False``, a three-action one the compute level."""

    stochastic: ClassVar[bool] = False
    observes: ClassVar[bool] = True

    def __init__(self, path: str | Path, task: str, mean: np.ndarray | None, var: np.ndarray | None, network: Network):
        self.path, self.task, self.network = Path(path), task, network
        self.mean = None if mean is None else np.asarray(mean, float)
        self.scale = None if var is None else np.sqrt(np.asarray(var, float) + EPSILON)
        cls = system_type(task)
        self.domain = cls.name
        self._size = (network.hidden[0][0] if network.hidden else network.head[0]).shape[1]
        self._levels = network.actions == 3  # keep, one SQP iteration, a full solve: the level is the answer

    @property
    def normalises(self) -> bool:
        """Whether the observation is normalised (a ``.json`` beside the model), or seen raw."""
        return self.mean is not None

    @property
    def spec(self) -> str:
        return f"sb3:{self.path}"

    def normalised(self, s: AugmentedState) -> np.ndarray:
        """What the network sees at ``s``: the environment's observation, normalised (:func:`normalise`)."""
        return normalise(finite_observation(observation(self.domain, s, self._size)), self.mean, self.scale)

    def decide(self, s: AugmentedState, rng: np.random.Generator | None) -> Decision:
        action = self.network.action(self.normalised(s))
        return action if self._levels else action == 1


def read_description(meta_file: Path, task: str | None, trained: str, missing: str) -> tuple[str, np.ndarray, np.ndarray, dict]:
    """The task, the observation's mean and variance and the whole of an etmpc description (``sb3:``'s
    ``.json`` beside a model, what ``normalize=`` reads), checked against ``task`` if given (``trained``
    names what was trained in that message, ``missing`` is the message of a missing file)."""
    meta = read_document(
        meta_file,
        FORMAT,
        missing=missing,
        unreadable=f"{meta_file} cannot be read ({{error}})",
        foreign=f"{meta_file} is not an etmpc Stable-Baselines3 policy (format {FORMAT!r})",
    )
    try:
        trained_on = canonical(str(meta["task"]))
        cls = system_type(trained_on)
        # finite numbers, a variance >= 0 (checks.json_numbers: an integer beyond a double is refused, not an OverflowError)
        mean = checks.json_numbers(meta["observation_mean"], "observation_mean")
        var = checks.json_numbers(meta["observation_var"], "observation_var", smallest=0.0)
        names = tuple(meta["observation_names"])
    except checks.BadValue as exc:
        raise EtmpcError(f"{meta_file}: {exc}") from None
    except (KeyError, TypeError, ValueError) as exc:
        raise EtmpcError(f"{meta_file} is corrupt ({exc!r})") from None
    if task is not None and canonical(task) != trained_on:
        raise EtmpcError(f"{trained} was trained on {trained_on!r}, not {canonical(task)!r}")
    if names != observation_names(cls.name, cls.state_names) or mean.shape != var.shape or mean.shape != (len(names),):
        raise EtmpcError(f"{meta_file}: its observation does not match the task's")
    return trained_on, mean, var, meta


def load_sb3(path: str, task: str | None) -> SB3Policy:
    """``sb3:PATH``, checked against ``task`` (the one it is evaluated on: the one it was trained on, or
    one that plays that one's world with time in the loop, see :func:`plays_on`) and its actions against
    those of the task it was trained on, and loaded once here so that a file that is not a model fails
    before any work starts. Without ``PATH.json``: on ``task``, on the raw observation, unless the zip
    shows it was trained behind ``VecNormalize`` (see the module's docstring)."""
    model = Path(path)
    if model.suffix == ".json":
        raise EtmpcError(f"sb3:{model} is the model's description; give the model itself, sb3:{model.with_suffix('.zip')}")
    if not model.is_file():
        raise EtmpcError(f"policy file {model} not found")
    meta_file = metadata_path(model)
    missing = f"{model} has no {meta_file.name} beside it (what it was trained on)"
    if task is not None and not meta_file.exists():
        return _raw(model, canonical(task), missing)
    trained_on, mean, var, meta = read_description(meta_file, None, f"policy {model}", missing)
    if task is not None and not plays_on(trained_on, canonical(task)):
        raise EtmpcError(f"policy {model} was trained on {trained_on!r}, not {canonical(task)!r}")
    algorithm = meta.get("algorithm", "ppo")
    if not isinstance(algorithm, str):
        raise EtmpcError(f"{meta_file} is corrupt (algorithm {algorithm!r} is not a name)")
    network = open_network(model, algorithm, mean.size, task_actions(trained_on), trained_on)
    if task is not None and network.actions > task_actions(canonical(task)):  # not in etmpc's tasks: a guard
        raise EtmpcError(f"policy {model} answers compute levels, which {canonical(task)} has not (keep or solve)")
    return SB3Policy(model, trained_on, mean, var, network)


def _raw(model: Path, task: str, missing: str) -> SB3Policy:
    """A model with no description, on ``task``'s raw observation; refused if it was trained behind ``VecNormalize``."""
    if _fields(model, _entries(model)[0]).get("_last_original_obs") is not None:
        raise EtmpcError(
            f"{missing}, and it was trained behind VecNormalize, whose statistics its zip does not keep: "
            f"write them with etmpc.envs.save_normalization(vec_normalize, {task!r}, "
            f"{str(metadata_path(model))!r})"
        )
    cls = system_type(task)
    size = len(observation_names(cls.name, cls.state_names))
    return SB3Policy(model, task, None, None, open_network(model, "ppo", size, task_actions(task), task))
