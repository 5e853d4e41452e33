"""PPO's settings (:class:`PpoSettings`, range-checked) and what its run needs from Stable-Baselines3:
the environments (:func:`_make_env`) and a save without what differs between runs (:func:`save_model`).
The run itself is :mod:`etmpc.learning.ppo`."""

from __future__ import annotations

import math
import numbers
import platform
import re
import typing
import zipfile
from dataclasses import asdict, dataclass, fields
from pathlib import Path


from etmpc.common import checks
from etmpc.common.checks import MAX_COUNT, short
from etmpc.common.errors import EtmpcError
from etmpc.learning.kernels import KERNELS
from etmpc.learning.resume import corrupt
from etmpc.systems import SystemKey


class SettingError(EtmpcError):
    """A PPO setting out of its range. ``rule`` names the settings as ``{field}``: ``str`` spells them as
    :class:`PpoSettings` does, :meth:`naming` as another reader does (a hyperparameter file, rl-zoo3's keys)."""

    def __init__(self, rule: str, got: str, why: str = ""):
        self.rule, self.got, self.why = rule, got, why
        super().__init__(self.naming({}))

    def naming(self, names: dict[str, str]) -> str:
        rule = self.rule.format_map({f.name: names.get(f.name, f.name) for f in fields(PpoSettings)})
        return f"{rule}, got {self.got}" + (f" ({self.why})" if self.why else "")


def _integer(least: int, most: float = math.inf):
    return lambda v: isinstance(v, numbers.Integral) and not isinstance(v, bool) and least <= int(v) <= most  # 8.0 is not


def _real(holds):
    return lambda v: isinstance(v, numbers.Real) and not isinstance(v, bool) and holds(v)  # NaN holds nothing


_COUNT = f"an integer in [1, {short(MAX_COUNT)}]"
# field -> (what it must be, the test); the first out of range is the one reported
RANGES = {
    "timesteps": (_COUNT, _integer(1, MAX_COUNT)),
    "seed": (f"an integer in [0, {2**32 - 1}]", _integer(0, 2**32 - 1)),  # NumPy's seeds (SB3 seeds it with this)
    **{name: (_COUNT, _integer(1, MAX_COUNT)) for name in ("n_envs", "checkpoints", "validation_episodes", "n_steps")},
    "batch_size": (f"an integer in [2, {short(MAX_COUNT)}] (Stable-Baselines3 asserts > 1)", _integer(2, MAX_COUNT)),
    "n_epochs": (_COUNT, _integer(1, MAX_COUNT)),
    "learning_rate": ("a finite number > 0", _real(lambda x: 0 < x < math.inf)),
    "gamma": ("in (0, 1]", _real(lambda x: 0 < x <= 1)),
    "gae_lambda": ("in [0, 1]", _real(lambda x: 0 <= x <= 1)),
    "clip_range": ("a finite number > 0", _real(lambda x: 0 < x < math.inf)),
    "ent_coef": ("a finite number >= 0", _real(lambda x: 0 <= x < math.inf)),
    "hidden": (
        "a non-empty tuple of positive layer sizes",
        lambda v: isinstance(v, tuple) and bool(v) and all(type(n) is int and 0 < n <= MAX_COUNT for n in v),
    ),
    "failure_cost": ("a finite number >= 0", _real(lambda x: 0 <= x < math.inf)),
    "reward_baseline": (
        "None or a fixed schedule's spec (always, never, every:T, or iterate:T on a task with compute levels)",
        lambda v: v is None or isinstance(v, str),
    ),
    "kernels": (f"one of {', '.join(KERNELS)}", lambda v: v in KERNELS),
}


@dataclass(frozen=True)
class PpoSettings:
    """PPO's settings (Stable-Baselines3's names); the defaults are its own but for the sizes. Each is
    checked when made (:class:`SettingError`), so that a file, an option or ``replace`` that sets one
    out of its range is one line, never a traceback from deep inside Stable-Baselines3 or a silent run."""

    timesteps: int = 200_000  # environment steps in all (the agent's: a reward baseline simulates as many again)
    seed: int = 0
    n_envs: int = 2  # environments stepped together (a hyperparameter: the processes are train_ppo's workers)
    checkpoints: int = 4  # slices of the budget; each ends with a save and a validation score
    validation_episodes: int = 30  # training-distribution episodes that choose selected.zip
    n_steps: int = 512  # steps per environment between updates
    batch_size: int = 256
    n_epochs: int = 10
    learning_rate: float = 3e-4
    gamma: float = 0.99
    gae_lambda: float = 0.95
    clip_range: float = 0.2
    ent_coef: float = 0.0
    hidden: tuple[int, ...] = (64, 64)
    reward_baseline: str | None = None  # the environment's reward relative to this fixed schedule (TriggerEnvironment)
    # what each of the task's failures costs on top of its reward, in the training environments' reward only
    # (TriggerEnvironment's failure_cost; the validation that chooses among checkpoints scores the task's own)
    failure_cost: float = 0.0
    # PyTorch's numerical kernels in the training process (etmpc.learning.kernels): "native", the CPU's own, or
    # "portable", the same networks on every x86-64 host
    kernels: str = "native"

    def __post_init__(self):
        for name, (allowed, holds) in RANGES.items():
            value = getattr(self, name)
            if not holds(value):
                raise SettingError(f"{{{name}}} must be {allowed}", repr(value))
            if isinstance(value, numbers.Integral):  # a NumPy integer too: JSON writes it as a number
                object.__setattr__(self, name, int(value))
        # What train_ppo makes of them: a rollout (n_steps per environment, fewer for a small budget) must
        # hold 2 steps (Stable-Baselines3 asserts it), and each checkpoint's slice of the budget at least one
        # rollout of every environment, or the slices together would run more steps than the budget.
        if self.n_steps * self.n_envs < 2:
            raise SettingError(
                "{n_steps} * {n_envs} must be >= 2 (Stable-Baselines3 asserts > 1)", f"{self.n_steps} * {self.n_envs}"
            )
        most = self.timesteps // max(2, self.n_envs)
        if self.checkpoints > most:
            raise SettingError(
                f"{{checkpoints}} must be at most {{timesteps}} // max(2, {{n_envs}}) = {most}",
                repr(self.checkpoints),
                "each slice of the budget holds a rollout of every environment, of 2 steps at least",
            )


def _libraries():
    try:
        import stable_baselines3
        import torch
    except ImportError:
        raise EtmpcError("--algorithm ppo needs Stable-Baselines3 and PyTorch: pip install 'etmpc[rl]'") from None
    return stable_baselines3, torch


def _make_env(key: SystemKey, seed: int, reward_baseline: str | None, failure_cost: float = 0.0):
    def make():
        from stable_baselines3.common.monitor import Monitor

        from etmpc.envs.gym import TriggerEnv

        env = Monitor(TriggerEnv(key, reward_baseline=reward_baseline, failure_cost=failure_cost))
        env.reset(seed=seed)
        return env

    return make


def save_model(model, path: Path) -> None:
    """``model.save(path)`` without what differs between two runs of the same training: the wall-clock
    start, the episode times the Monitor kept, and the spaces' histories (a space pickles its generator
    and whether it came from another process; they are made afresh, equal, and PPO never samples from
    them); the memory addresses in the descriptions Stable-Baselines3 writes beside each pickled object
    (``<function f at 0x7f...>``: a description only, loading reads the pickle) and the kernel's build in
    ``system_info.txt`` (the OS line keeps the system and the machine). The zip's entries are dated
    1980-01-01. The same training gives the same bytes in any process on one machine, so a policy trained
    again there can be compared byte for byte; on a machine whose math library (PyTorch's MKL) takes another
    code path, the weights may differ in their last bits, and over a long training grow apart."""
    from etmpc.envs.gym import trigger_spaces

    fresh = trigger_spaces(model.observation_space.shape[0], int(model.action_space.n))
    if fresh != (model.observation_space, model.action_space):
        raise EtmpcError(f"a policy model's spaces are {fresh}, not {(model.observation_space, model.action_space)}")
    model.observation_space, model.action_space = fresh
    raw = path.with_name(path.stem + ".unpacked.zip")
    model.save(str(raw), exclude=["start_time", "ep_info_buffer", "ep_success_buffer"])
    with zipfile.ZipFile(raw) as source, zipfile.ZipFile(path, "w") as target:
        for info in source.infolist():
            entry = zipfile.ZipInfo(info.filename, date_time=(1980, 1, 1, 0, 0, 0))
            entry.compress_type, entry.external_attr = info.compress_type, info.external_attr
            target.writestr(entry, _without_run_details(info.filename, source.read(info.filename)))
    raw.unlink()


_ADDRESS = re.compile(rb" at 0x[0-9a-f]+>")


def _without_run_details(name: str, data: bytes) -> bytes:
    """An entry of a saved model without the addresses of this process and the kernel of this machine."""
    if name == "data":
        return _ADDRESS.sub(b">", data)
    if name == "system_info.txt":
        return re.sub(rb"^- OS: .*$", f"- OS: {platform.system()} {platform.machine()}".encode(), data, count=1, flags=re.M)
    return data


def _ours(name: str) -> bool:
    return name in ("checkpoints", "selected.zip", "selected.json", "training.json")


def settings_json(settings: PpoSettings) -> dict:
    """``settings`` as a run's files keep them; without a failure cost, or with the native kernels, as before
    there were such settings (so the files of earlier runs are read as the same settings)."""
    data = asdict(settings)
    data["hidden"] = list(settings.hidden)
    if not settings.failure_cost:
        del data["failure_cost"]
    if settings.kernels == "native":
        del data["kernels"]
    return data


# -- a run's saved state, read back on --resume from a folder a user may hand in ----------------------
_CHECKPOINT_FILE = re.compile(r"checkpoints/step_[0-9]{8}\.zip")


@dataclass(frozen=True)
class SavedCheckpoint:
    """One checkpoint as a run's ``checkpoints/resume.json`` and ``training.json`` list it."""

    timesteps: int
    simulated_steps: int
    file: str  # checkpoints/step_N.zip, inside the run's folder
    validation_objective: float
    wall_seconds: float


def checked_checkpoints(entries, where: str) -> list[dict]:
    """``entries`` if each is a :class:`SavedCheckpoint` (each field of its type, finite, none missing or other)
    of the run's own folder (its file one of the run's ``checkpoints/step_N.zip``, never a path elsewhere); else
    :class:`EtmpcError`, one line naming the file ``where`` and the field."""
    try:
        if not isinstance(entries, list) or not entries:
            raise ValueError(f"its checkpoints are {str(entries)[:40]!r}, not a list of them")
        for i, entry in enumerate(entries):
            name = f"checkpoints[{i}]"
            saved = SavedCheckpoint(**checks.typed_json(entry, typing.get_type_hints(SavedCheckpoint), name, most=2**62))
            if min(saved.timesteps - 1, saved.simulated_steps, saved.wall_seconds) < 0:
                raise ValueError(
                    f"{name}: its steps are {saved.timesteps} and {saved.simulated_steps}, its seconds {saved.wall_seconds}"
                )
            if not _CHECKPOINT_FILE.fullmatch(saved.file):
                raise ValueError(f"checkpoint file {saved.file[:80]!r} is not one of the run's checkpoints/step_N.zip")
    except ValueError as exc:
        raise corrupt(where, exc) from None
    return entries
