"""A trigger trained by a standard RL library: Stable-Baselines3's PPO on the trigger environment.

``etmpc train TASK --algorithm ppo --out DIR`` trains PPO (an MLP policy) on ``etmpc.envs.gym.TriggerEnv``
with the task's hyperparameters (``policies/<task>/ppo.yml``, rl-zoo3's layout, see
:mod:`etmpc.learning.hyperparams`; ``--hyperparams FILE`` for others, ``--timesteps N`` to change the
budget): ``n_envs`` environments, stepped in ``--workers`` processes (the numbers do not depend on
how many), observations and rewards normalised by ``VecNormalize``, and the reward taken against a
fixed schedule when ``env_kwargs`` names one (``reward_baseline``: see :mod:`etmpc.envs.trigger`).
After each of ``checkpoints`` equal slices of the budget the network is saved
(``checkpoints/step_<n>.zip``, byte for byte the same for the same training: :func:`save_model`, and
beside it the ``.json`` that ``sb3:PATH`` reads: the task and the frozen normalisation, written by
:func:`etmpc.envs.save_normalization`; ``gymnasium.make(ID, normalize=JSON)`` applies it) and scored
on ``validation_episodes`` training-distribution episodes, drawn as ``etmpc train`` draws its own
(never the test set). The best becomes ``selected.zip`` / ``selected.json``; ``training.json`` keeps
the settings, the validation scores, the environment and simulated steps and the wall time.

Evaluate it like any policy: ``etmpc evaluate TASK --policy sb3:DIR/selected.zip``. PyTorch runs on
one thread per process, on the CPU. Stable-Baselines3 and PyTorch are the optional extra ``rl``.
"""

from __future__ import annotations

import json
import math
import numbers
import platform
import re
import shutil
import time
import zipfile
from dataclasses import asdict, dataclass, fields
from pathlib import Path

import numpy as np

from etmpc.common.errors import EtmpcError
from etmpc.common.outputs import refuse_foreign, write_json
from etmpc.evaluation.workers import make_backend
from etmpc.learning.config import VALIDATION_ENTROPY
from etmpc.learning.jobs import mean_scores
from etmpc.envs.normalization import save_normalization
from etmpc.policies.features import observation_names
from etmpc.policies.sb3 import metadata_path
from etmpc.systems import SystemKey, system_key


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
    return lambda v: isinstance(v, numbers.Integral) and not isinstance(v, bool) and least <= v <= most  # 8.0 is not


def _real(holds):
    return lambda v: isinstance(v, numbers.Real) and not isinstance(v, bool) and holds(v)  # NaN holds nothing


# field -> (what it must be, the test); the first out of range is the one reported
RANGES = {
    "timesteps": ("an integer >= 1", _integer(1)),
    "seed": (f"an integer in [0, {2**32 - 1}]", _integer(0, 2**32 - 1)),  # NumPy's seeds (SB3 seeds it with this)
    **{name: ("an integer >= 1", _integer(1)) for name in ("n_envs", "checkpoints", "validation_episodes", "n_steps")},
    "batch_size": ("an integer >= 2 (Stable-Baselines3 asserts > 1)", _integer(2)),
    "n_epochs": ("an integer >= 1", _integer(1)),
    "learning_rate": ("a finite number > 0", _real(lambda x: 0 < x < math.inf)),
    "gamma": ("in (0, 1]", _real(lambda x: 0 < x <= 1)),
    "gae_lambda": ("in [0, 1]", _real(lambda x: 0 <= x <= 1)),
    "clip_range": ("a finite number > 0", _real(lambda x: 0 < x < math.inf)),
    "ent_coef": ("a finite number >= 0", _real(lambda x: 0 <= x < math.inf)),
    "hidden": ("a non-empty tuple of positive layer sizes",
               lambda v: isinstance(v, tuple) and bool(v) and all(type(n) is int and n > 0 for n in v)),
    "reward_baseline": ("None or a fixed schedule's spec (always, never or every:T)", lambda v: v is None or isinstance(v, str)),
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
            raise SettingError("{n_steps} * {n_envs} must be >= 2 (Stable-Baselines3 asserts > 1)",
                               f"{self.n_steps} * {self.n_envs}")
        most = self.timesteps // max(2, self.n_envs)
        if self.checkpoints > most:
            raise SettingError(f"{{checkpoints}} must be at most {{timesteps}} // max(2, {{n_envs}}) = {most}",
                               repr(self.checkpoints), "each slice of the budget holds a rollout of every environment, "
                               "of 2 steps at least")


def _libraries():
    try:
        import stable_baselines3
        import torch
    except ImportError:
        raise EtmpcError("--algorithm ppo needs Stable-Baselines3 and PyTorch: pip install 'etmpc[rl]'") from None
    return stable_baselines3, torch


def _make_env(key: SystemKey, seed: int, reward_baseline: str | None):
    def make():
        from stable_baselines3.common.monitor import Monitor

        from etmpc.envs.gym import TriggerEnv

        env = Monitor(TriggerEnv(key, reward_baseline=reward_baseline))
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
    1980-01-01. The same training gives the same bytes in any process on machines of a kind, so a
    regenerated shipped policy can be compared byte for byte."""
    from etmpc.envs.gym import trigger_spaces

    fresh = trigger_spaces(model.observation_space.shape[0])
    if fresh != (model.observation_space, model.action_space):
        raise EtmpcError(f"a trigger model's spaces are {fresh}, not {(model.observation_space, model.action_space)}")
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


def train_ppo(task: str | SystemKey, out: Path, settings: PpoSettings = PpoSettings(), workers: int = 1,
              recompute_price: float | None = None, say=lambda line: None) -> dict:
    """Train on ``task`` (a name, at ``recompute_price`` if given, or a :class:`SystemKey`), checkpoint,
    choose on validation episodes; returns ``training.json``'s content."""
    sb3, torch = _libraries()
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecEnvWrapper, VecNormalize

    class Float32Rewards(VecEnvWrapper):
        """Rewards as float32, as DummyVecEnv keeps them (SubprocVecEnv hands float64): so that one
        process or several give the same numbers."""

        def reset(self):
            return self.venv.reset()

        def step_wait(self):
            obs, rewards, dones, infos = self.venv.step_wait()
            return obs, rewards.astype(np.float32), dones, infos

    out = Path(out)
    key = system_key(task, recompute_price)
    system = key.make()
    refuse_foreign(out, _ours, "PPO training run")
    if (out / "training.json").exists():
        raise EtmpcError(f"{out} already holds a PPO run; choose another --out")
    torch.set_num_threads(1)
    # PPO collects n_steps per environment between updates: a budget too small for that shrinks n_steps,
    # and each checkpoint's slice is a whole number of rollouts (so the steps reported are the steps run).
    n_envs = settings.n_envs
    n_steps = min(settings.n_steps, max(1, settings.timesteps // (settings.checkpoints * n_envs)))
    rollout = n_steps * n_envs
    slices = [max(1, round(settings.timesteps / settings.checkpoints / rollout)) * rollout] * settings.checkpoints
    envs = [_make_env(key, settings.seed * 1000 + i, settings.reward_baseline) for i in range(n_envs)]
    # The environments in worker processes or in this one: the same numbers either way.
    vec = Float32Rewards(SubprocVecEnv(envs) if min(workers, n_envs) > 1 else DummyVecEnv(envs))
    vec = VecNormalize(vec, norm_obs=True, norm_reward=True, gamma=settings.gamma)
    model = sb3.PPO("MlpPolicy", vec, seed=settings.seed, device="cpu", n_steps=n_steps,
                    batch_size=min(settings.batch_size, rollout), n_epochs=settings.n_epochs, learning_rate=settings.learning_rate,
                    gamma=settings.gamma, gae_lambda=settings.gae_lambda, clip_range=settings.clip_range,
                    ent_coef=settings.ent_coef, policy_kwargs={"net_arch": list(settings.hidden)}, verbose=0)
    if list(vec.get_attr("observation_names")[0]) != list(observation_names(system.name, system.state_names)):
        raise EtmpcError(f"{key.task}: the environment's observation is not the one sb3: computes")
    checkpoints, started = [], time.perf_counter()
    (out / "checkpoints").mkdir(parents=True, exist_ok=True)
    try:
        with make_backend("local", workers) as pool:
            for steps in slices:
                model.learn(total_timesteps=int(steps), reset_num_timesteps=False)
                path = out / "checkpoints" / f"step_{model.num_timesteps:08d}.zip"
                save_model(model, path)
                save_normalization(vec, key, metadata_path(path), recompute_price=system.recompute_price,
                                   timesteps=int(model.num_timesteps), settings=_json(settings))
                score = mean_scores(pool, key, [f"sb3:{path}"], VALIDATION_ENTROPY, settings.validation_episodes)[0]
                simulated = int(sum(vec.get_attr("simulated_steps")))  # the baseline's steps too
                checkpoints.append({"timesteps": int(model.num_timesteps), "simulated_steps": simulated,
                                    "file": str(path.relative_to(out)),
                                    "validation_objective": score, "wall_seconds": time.perf_counter() - started})
                say(f"{key.task}: PPO {model.num_timesteps} steps, validation objective {score:.5f} "
                    f"({time.perf_counter() - started:.0f} s)")
    finally:
        vec.close()
    pick = (max if system.objective_sense == "max" else min)(checkpoints, key=lambda c: c["validation_objective"])
    shutil.copyfile(out / pick["file"], out / "selected.zip")
    meta = json.loads(metadata_path(out / pick["file"]).read_text())
    write_json(out / "selected.json", dict(meta, validation_objective=pick["validation_objective"],
                                           validation_episodes=settings.validation_episodes))
    result = {"format": "etmpc-ppo-run", "version": 1, "task": str(key), "settings": _json(settings), "workers": workers,
              "environment_steps": int(model.num_timesteps), "simulated_steps": checkpoints[-1]["simulated_steps"],
              "wall_seconds": time.perf_counter() - started,
              "checkpoints": checkpoints, "selected": pick["file"], "objective_sense": system.objective_sense,
              "stable_baselines3": sb3.__version__, "torch": torch.__version__}
    write_json(out / "training.json", result)
    return result


def _json(settings: PpoSettings) -> dict:
    data = asdict(settings)
    data["hidden"] = list(settings.hidden)
    return data
