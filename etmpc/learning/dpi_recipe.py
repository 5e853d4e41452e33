"""DPI's recipe as data: one YAML file per task, ``policies/<task>/dpi.yml``, beside PPO's ``ppo.yml``.

The file holds one mapping under the task's gymnasium id, as ``ppo.yml`` does::

    etmpc/cart_pendulum-kicks-v0:
      seeds: [0, 1, 2]            # training seeds; the shipped one is chosen on validation episodes
      episodes: 60                # training episodes per seed
      eval_every: 20              # episodes per DPI iteration (each ends with a policy scored on validation)
      normalisation_episodes: 20  # episodes that fix the features' normalisation
      features: error             # the policy's feature set (etmpc.policies.features)
      futures: 4                  # K: sampled futures per labelled decision
      horizon: 10                 # H: steps simulated ahead of each decision
      states_per_episode: 25      # decisions labelled per training episode
      ridge: 0.01                 # L2 weight on theta
      bases: [always, every:2, every:3, every:4, every:5]  # candidates for the first policy
      selection_episodes: 30      # training episodes that choose among the bases
      failure_cost: 0.0           # each failure's extra cost in the labels (etmpc study failure-cost)
      validation_episodes: 50     # training-distribution episodes that choose the shipped seed

It is the one recipe of the task's DPI: ``etmpc study learners`` trains and ships ``learned.json`` from it, and
``etmpc reproduce`` trains its own DPI from it, so that a reproduction at its full size makes the shipped run
again. Only these keys are accepted (a misspelt one is an error, never silently a default), every value is
checked where DPI checks it, and an error names the file and the key (``dpi.yml: ridge must be >= 0, got -1``).
"""

from __future__ import annotations

from dataclasses import fields, replace
from pathlib import Path
from typing import Any

from etmpc.common.errors import EtmpcError
from etmpc.common.resources import data_root
from etmpc.envs.registration import env_id
from etmpc.learning import dpi, hyperparams
from etmpc.learning.config import TrainConfig
from etmpc.learning.hyperparams import HyperparameterError
from etmpc.systems import canonical, folder_name, make_system, system_class

RUN_KEYS = ("seeds", "episodes", "eval_every", "normalisation_episodes", "features", "validation_episodes")
DPI_KEYS = tuple(f.name for f in fields(dpi.Settings))
LISTS = ("seeds", "bases")  # YAML sequences, kept as tuples


def shipped_path(task: str) -> Path:
    """Where the project keeps ``task``'s recipe, ``policies/<task>/dpi.yml`` (installed with the package)."""
    return data_root() / "policies" / folder_name(task) / "dpi.yml"


#: A task that ships no recipe (a task of your own) trains with DPI's defaults: 3 seeds x 60 episodes, one
#: iteration every 20, on the error features, its horizon at most the task's lookahead.
DEFAULT_SEEDS = (0, 1, 2)
DEFAULT_EPISODES = 60
DEFAULT_EVAL_EVERY = 20


def recipe(task: str) -> TrainConfig:
    """``task``'s DPI run: its shipped recipe; for a variant that ships none yet (a new noisy variant), that of the
    task whose world it plays (``variant_of``), for this task; else DPI's defaults (:data:`DEFAULT_SEEDS` ...)."""
    task = canonical(task)
    path = shipped_path(task)
    if path.is_file():
        return load(path, task)
    variant_of = getattr(system_class(task), "variant_of", None)
    if variant_of is not None and shipped_path(variant_of).is_file():
        return replace(load(shipped_path(variant_of), variant_of), domain=task)
    horizon = make_system(task).benchmark.capped(dpi.Settings.horizon)
    return TrainConfig(
        task,
        DEFAULT_SEEDS,
        DEFAULT_EPISODES,
        DEFAULT_EVAL_EVERY,
        features="error",
        algorithm="dpi",
        dpi=dpi.Settings(horizon=horizon),
    )


def load(path: str | Path, task: str) -> TrainConfig:
    """``task``'s DPI run as the file at ``path`` says it (``eval_episodes`` left to the caller)."""
    return parse(hyperparams.read(path), task, str(path))


def parse(document: Any, task: str, where: str) -> TrainConfig:
    """The run a loaded document gives ``task`` (see :func:`load`)."""
    key = env_id(task)
    if not isinstance(document, dict) or not isinstance(document.get(key), dict):
        found = sorted(document) if isinstance(document, dict) else type(document).__name__
        raise HyperparameterError(f"{where}: no mapping for {key} (found {found})")
    entry = document[key]
    unknown = sorted(str(name) for name in entry if name not in RUN_KEYS + DPI_KEYS)
    if unknown:
        raise HyperparameterError(f"{where}: unknown key {unknown[0]!r}; known: {', '.join(sorted(RUN_KEYS + DPI_KEYS))}")
    missing = [name for name in RUN_KEYS + DPI_KEYS if name not in entry]
    if missing:
        raise HyperparameterError(f"{where}: {missing[0]} is missing (a recipe says every key: {', '.join(missing)})")
    values: dict[str, Any] = {
        name: tuple(value) if name in LISTS and isinstance(value, list) else value for name, value in entry.items()
    }
    try:
        settings = dpi.Settings(**{name: values[name] for name in DPI_KEYS})
        return TrainConfig(task, **{name: values[name] for name in RUN_KEYS}, algorithm="dpi", dpi=settings)
    except (ValueError, TypeError, EtmpcError) as exc:
        raise HyperparameterError(f"{where}: {' '.join(str(exc).split())}") from None


def to_document(config: TrainConfig) -> dict:
    """The file's content for ``config`` (what :func:`parse` reads back to the same run)."""
    entry: dict[str, Any] = {name: getattr(config, name) for name in RUN_KEYS}
    entry |= {name: getattr(config.dpi, name) for name in DPI_KEYS}
    return {env_id(config.domain): {name: list(v) if isinstance(v, tuple) else v for name, v in entry.items()}}


def dump(config: TrainConfig, comment: str = "") -> str:
    """The file's text for ``config`` (``comment``: lines to put on top, each made a YAML comment)."""
    return hyperparams.text(to_document(config), comment)
