"""The Stable-Baselines3 side of a PPO run (:class:`etmpc.learning.ppo.PpoLearner`): the budget in whole
rollouts (:func:`rollouts`), the vectorised trigger environments (:func:`environments`), the PPO model the
settings make (:func:`make_model`), a checkpoint saved (:func:`save_checkpoint`) and its weights read back into
it (:func:`load_weights`).
Stable-Baselines3 is imported when first used: it is the optional extra ``rl``."""

from __future__ import annotations

import pickle
import warnings
import zipfile
from pathlib import Path

import numpy as np

from etmpc.common.errors import EtmpcError
from etmpc.envs.normalization import save_normalization
from etmpc.learning.ppo_settings import PpoSettings, _make_env, save_model
from etmpc.learning.resume import AGAIN
from etmpc.policies.sb3 import metadata_path
from etmpc.systems import SystemKey


def rollouts(s: PpoSettings) -> tuple[int, list[int]]:
    """``(n_steps, slices)``: the steps per environment between updates, and the environment steps of each of
    the ``checkpoints`` slices of the budget. PPO collects ``n_steps`` per environment between updates: a budget
    too small for that shrinks ``n_steps``, and each slice is a whole number of rollouts (so the steps reported
    are the steps run)."""
    n_steps = min(s.n_steps, max(1, s.timesteps // (s.checkpoints * s.n_envs)))
    rollout = n_steps * s.n_envs
    slices = [max(1, round(s.timesteps / s.checkpoints / rollout)) * rollout] * s.checkpoints
    return n_steps, slices


def environments(key: SystemKey, s: PpoSettings, workers: int):
    """The ``n_envs`` trigger environments of ``key``'s task, seeded from ``s.seed``, in ``workers`` processes or
    in this one (the same numbers either way), their rewards as float32."""
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecEnvWrapper

    class Float32Rewards(VecEnvWrapper):
        """Rewards as float32, as DummyVecEnv keeps them (SubprocVecEnv hands float64): so that one
        process or several give the same numbers."""

        def reset(self):
            return self.venv.reset()

        def step_wait(self):
            obs, rewards, dones, infos = self.venv.step_wait()
            return obs, rewards.astype(np.float32), dones, infos

    envs = [_make_env(key, s.seed * 1000 + i, s.reward_baseline, s.failure_cost) for i in range(s.n_envs)]
    # The environments in worker processes or in this one: the same numbers either way.
    return Float32Rewards(SubprocVecEnv(envs) if min(workers, s.n_envs) > 1 else DummyVecEnv(envs))


def make_model(sb3, vec, s: PpoSettings, n_steps: int):
    """Stable-Baselines3's PPO (an MLP policy of ``s.hidden``) on ``vec``, on the CPU, seeded from ``s.seed``, with
    :func:`rollouts`' ``n_steps``, and a logger that writes nowhere."""
    from stable_baselines3.common.logger import Logger

    rollout = n_steps * s.n_envs
    model = sb3.PPO(
        "MlpPolicy",
        vec,
        seed=s.seed,
        device="cpu",
        n_steps=n_steps,
        batch_size=min(s.batch_size, rollout),
        n_epochs=s.n_epochs,
        learning_rate=s.learning_rate,
        gamma=s.gamma,
        gae_lambda=s.gae_lambda,
        clip_range=s.clip_range,
        ent_coef=s.ent_coef,
        policy_kwargs={"net_arch": list(s.hidden)},
        verbose=0,
    )
    # A logger that writes nowhere: left to itself, every learn() makes an empty tempdir/SB3-<date> folder
    model.set_logger(Logger(folder=None, output_formats=[]))
    return model


def save_checkpoint(model, vec, key: SystemKey, path: Path, recompute_price: float, settings: dict) -> None:
    """The network at ``path`` (:func:`~etmpc.learning.ppo_settings.save_model`: the same bytes for the same
    training) and beside it the description ``sb3:PATH`` reads (:func:`etmpc.envs.save_normalization`: ``key``'s
    task at ``recompute_price``, the normalisation frozen, the steps so far and the run's ``settings``)."""
    save_model(model, path)
    save_normalization(
        vec,
        key,
        metadata_path(path),
        recompute_price=recompute_price,
        timesteps=int(model.num_timesteps),
        settings=settings,
        **({"options": dict(key.options)} if key.options else {}),  # trained with some of the task's options
    )


def load_weights(model, path: Path) -> None:
    """A checkpoint's network and optimiser (``path``, a ``checkpoints/step_N.zip``) into ``model``, read with
    PyTorch's weights-only reader: nothing is unpickled; a file that is not this run's weights is one line."""
    try:  # the weights only: PyTorch's weights-only reader refuses a pickle (and would warn of its protocol)
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", message="Detected pickle protocol")
            model.set_parameters(str(path), exact_match=True, device="cpu")
    except (pickle.UnpicklingError, RuntimeError, ValueError, KeyError, OSError, EOFError, zipfile.BadZipFile) as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise EtmpcError(f"{path}: not this run's weights ({first[:160]}); {AGAIN}") from None
