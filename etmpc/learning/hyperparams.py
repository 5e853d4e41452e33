"""A PPO run's hyperparameters as data: one YAML file per task, in rl-zoo3's layout.

The file holds one mapping under the task's gymnasium id, with rl-zoo3's key names::

    etmpc/cart_pendulum-balance-v0:
      n_timesteps: 61440        # environment steps in all
      policy: MlpPolicy
      n_envs: 2                 # environments stepped together (not processes: see --workers)
      normalize: true           # VecNormalize on observations and rewards
      env_kwargs:
        reward_baseline: every:4  # TriggerEnv's keywords (see etmpc.envs.trigger)
      n_steps: 512
      batch_size: 256
      n_epochs: 10
      learning_rate: 3.0e-4
      gamma: 0.99
      gae_lambda: 0.95
      clip_range: 0.2
      ent_coef: 0.0
      policy_kwargs:
        net_arch: [64, 64]
      seed: 0
      checkpoints: 4            # etmpc's own: slices of the budget, each saved and scored on validation episodes
      kernels: portable         # etmpc's own: PyTorch's kernels, the same on every x86-64 host (default: native)

Two differences from rl-zoo3: ``policy_kwargs`` is a mapping, not Python text (nothing from a file is
ever evaluated), and only keys this project reads are accepted (a misspelt one is an error, never
silently a default). Every value is checked against its range (:class:`PpoSettings`), and an error
names the file and the key as written in it (``ppo.yml: gamma must be in (0, 1], got 1.5``). The project
ships one per task beside its PPO policy, ``policies/<task>/ppo.yml`` (:func:`shipped`), chosen on
training-distribution episodes only.
"""

from __future__ import annotations

import math
from dataclasses import fields, replace
from pathlib import Path
from typing import Any

from etmpc.common.documents import yaml_loads
from etmpc.common.errors import EtmpcError
from etmpc.common.resources import data_root
from etmpc.envs.registration import env_id
from etmpc.learning.ppo_settings import PpoSettings, SettingError
from etmpc.systems import SystemKey, folder_name

# rl-zoo3's key -> PpoSettings' field (the same name where not listed)
RENAMED = {"n_timesteps": "timesteps"}
KEYS = {field: key for key, field in RENAMED.items()} | {"hidden": "net_arch"}  # how messages name the fields
IGNORED = {"policy": "MlpPolicy", "normalize": True}  # keys that must say what this project does
ENV_KWARGS = ("reward_baseline", "failure_cost")


class HyperparameterError(EtmpcError):
    """A hyperparameter file that cannot be read, or says something this project does not do."""


def shipped_path(task: str | SystemKey) -> Path:
    """Where the project keeps ``task``'s file, ``policies/<task>/ppo.yml`` (installed with the package)."""
    return data_root() / "policies" / folder_name(task.task if isinstance(task, SystemKey) else task) / "ppo.yml"


def shipped(task: str | SystemKey, base: PpoSettings = PpoSettings()) -> PpoSettings:
    """``task``'s shipped hyperparameters over ``base``; ``base`` itself for a task that ships none."""
    path = shipped_path(task)
    return load(path, task.task if isinstance(task, SystemKey) else task, base) if path.is_file() else base


def load(path: str | Path, task: str, base: PpoSettings = PpoSettings()) -> PpoSettings:
    """``base`` with what the file at ``path`` sets for ``task`` (``DOMAIN`` or ``DOMAIN/TASK``)."""
    return parse(read(path), task, str(path), base)


def read(path: str | Path) -> Any:
    """The YAML document in a learner's recipe file (``ppo.yml``, ``dpi.yml``), or one line saying why not."""
    path = Path(path)
    try:
        return yaml_loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise HyperparameterError(f"{path}: cannot read it ({' '.join(str(exc).split())})") from None


def parse(document: Any, task: str, where: str, base: PpoSettings = PpoSettings()) -> PpoSettings:
    """The settings a loaded document gives ``task`` (see :func:`load`)."""
    key = env_id(task)
    if not isinstance(document, dict) or key not in document:
        found = sorted(document) if isinstance(document, dict) else type(document).__name__
        raise HyperparameterError(f"{where}: no entry for {key} (found {found})")
    entry = document[key]
    if not isinstance(entry, dict):
        raise HyperparameterError(f"{where}: {key} must map hyperparameter names to values, got {entry!r}")
    known = {f.name for f in fields(PpoSettings)} - {"hidden", *ENV_KWARGS, "validation_episodes"}
    values: dict[str, Any] = {}
    for name, value in entry.items():
        if name in IGNORED:
            if value != IGNORED[name]:
                raise HyperparameterError(f"{where}: {name}: {value!r} is not supported (only {IGNORED[name]!r})")
        elif name == "policy_kwargs":
            values["hidden"] = _net_arch(value, where)
        elif name == "env_kwargs":
            values.update(_env_kwargs(value, where))
        elif isinstance(name, str) and RENAMED.get(name, name) in known:
            if isinstance(value, str) and _numeral(value):  # PyYAML's YAML 1.1 reads 3e-4 and 1e6 as text
                raise HyperparameterError(
                    f"{where}: {name} must be a number, got {value!r} (YAML reads it as text: "
                    "write it out, 0.0003, or with a dot and a signed exponent, 3.0e-4)"
                )
            values[RENAMED.get(name, name)] = value  # checked by PpoSettings, below
        else:
            raise HyperparameterError(
                f"{where}: unknown hyperparameter {name!r}; known: "
                f"{', '.join(sorted({*known - set(RENAMED.values()), *RENAMED, *IGNORED, 'policy_kwargs', 'env_kwargs'}))}"
            )
    try:
        return replace(base, **values)
    except SettingError as exc:  # named as the file names it
        raise HyperparameterError(f"{where}: {exc.naming(KEYS)}") from None
    except EtmpcError as exc:
        raise HyperparameterError(f"{where}: {exc}") from None


def to_document(settings: PpoSettings, task: str) -> dict:
    """The file's content for ``settings`` (what :func:`load` reads back to the same settings)."""
    entry = {"n_timesteps": settings.timesteps, "policy": "MlpPolicy", "n_envs": settings.n_envs, "normalize": True}
    env_kwargs = {"reward_baseline": settings.reward_baseline, "failure_cost": settings.failure_cost}
    if env_kwargs := {name: value for name, value in env_kwargs.items() if value}:  # what differs from the defaults
        entry["env_kwargs"] = env_kwargs
    for f in fields(PpoSettings):
        if f.name not in ("timesteps", "n_envs", "hidden", *ENV_KWARGS, "validation_episodes"):
            entry[f.name] = getattr(settings, f.name)
    entry["policy_kwargs"] = {"net_arch": list(settings.hidden)}
    return {env_id(task): entry}


def dump(settings: PpoSettings, task: str, comment: str = "") -> str:
    """The file's text for ``settings`` (``comment``: lines to put on top, each made a YAML comment)."""
    return text(to_document(settings, task), comment)


def text(document: dict, comment: str = "") -> str:
    """A recipe file's text: ``document`` as YAML in its keys' order, under ``comment``'s lines made comments."""
    import yaml

    head = "".join(f"# {line}\n".replace("# \n", "#\n") for line in comment.splitlines())
    return head + yaml.safe_dump(document, sort_keys=False, default_flow_style=None)


def _numeral(text: str) -> bool:
    try:
        return math.isfinite(float(text))
    except ValueError:
        return False


def _net_arch(value: Any, where: str) -> tuple[int, ...]:
    if not isinstance(value, dict) or set(value) != {"net_arch"}:
        raise HyperparameterError(f"{where}: policy_kwargs takes net_arch only (a list of layer sizes), got {value!r}")
    arch = value["net_arch"]
    if not isinstance(arch, list) or not arch or not all(isinstance(n, int) and not isinstance(n, bool) and n > 0 for n in arch):
        raise HyperparameterError(f"{where}: net_arch must be a list of positive layer sizes, got {arch!r}")
    return tuple(arch)


def _env_kwargs(value: Any, where: str) -> dict:
    if not isinstance(value, dict) or not set(value) <= set(ENV_KWARGS):
        raise HyperparameterError(f"{where}: env_kwargs takes {', '.join(ENV_KWARGS)}, got {value!r}")
    return dict(value)
