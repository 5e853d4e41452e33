"""A policy trained by a standard RL library: Stable-Baselines3's PPO on the trigger environment.

``etmpc train --task TASK --algorithm ppo --out DIR`` trains PPO (an MLP policy) on ``etmpc.envs.gym.TriggerEnv``
with the task's hyperparameters (``policies/<task>/ppo.yml``, rl-zoo3's layout, see
:mod:`etmpc.learning.hyperparams`; ``--settings FILE`` for others, ``--set timesteps=N`` to change the
budget): ``n_envs`` environments, stepped in ``--workers`` processes (the numbers do not depend on
how many), observations and rewards normalised by ``VecNormalize``, and the reward taken against a
fixed schedule when ``env_kwargs`` names one (``reward_baseline``: see :mod:`etmpc.envs.trigger`), with each of
the task's failures costing ``failure_cost`` more there when it names one (safety in the reward; the validation
scores the task's own objective).
After each of ``checkpoints`` equal slices of the budget the network is saved
(``checkpoints/step_<n>.zip``, byte for byte the same for the same training: :func:`save_model`, and
beside it the ``.json`` that ``sb3:PATH`` reads: the task and the frozen normalisation, written by
:func:`etmpc.envs.save_normalization`; ``gymnasium.make(ID, normalize=JSON)`` applies it) and scored
on ``validation_episodes`` training-distribution episodes, drawn as ``etmpc train`` draws its own
(never the test set). The best becomes ``selected.zip`` / ``selected.json``; ``training.json`` keeps
the settings, the validation scores, the environment and simulated steps and the wall time.

Evaluate it like any policy: ``etmpc evaluate --task TASK --policy sb3:DIR/selected.zip``. PyTorch runs on
one thread per process, on the CPU, with the kernels ``kernels`` names (:mod:`etmpc.learning.kernels`:
``portable`` gives the same networks on every x86-64 host). Stable-Baselines3 and PyTorch are the optional
extra ``rl``.

On a task with compute levels (``cart_pendulum/kicks_levels``) the environment's actions are
``Discrete(3)`` (keep, one SQP iteration, a full solve): the network has three outputs, its ``sb3:``
policy answers the level, and the reward baseline may be ``iterate:T`` (real-time iterations, a fixed
schedule too). On a task with latency alone (``kicks_late``) the actions stay keep or recompute.

The budget is environment steps, in ``checkpoints`` slices; after each the network is saved, scored on
validation episodes and the run's state kept (``checkpoints/resume.json`` and the normalisation's
running statistics, ``checkpoints/resume_normalize.json``; both removed when the run ends, so a run's
files are what they were). A stopped run resumed continues from its last checkpoint's network and
statistics, with its environments reset, and reads them as data (:mod:`etmpc.learning.ppo_state`: each
field checked; a run, under way or finished, of another task, price, options or settings refused): the
statistics as JSON, the network and the optimiser into a model built from the run's settings with torch's
weights-only reader (nothing in the run's folder is unpickled, so a folder someone hands you runs no code). It is not bit
for bit the uninterrupted run (the episodes in progress, the rollout and the random generators' states
are not in Stable-Baselines3's save).
"""

from __future__ import annotations

import shutil
import time
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from etmpc.common.sense import best as best_of
from etmpc.common.errors import EtmpcError
from etmpc.common.outputs import refuse_foreign, write_json
from etmpc.learning.base import Learner
from etmpc.learning.kernels import in_effect, pin
from etmpc.learning.ppo_model import environments, load_weights, make_model, rollouts, save_checkpoint
from etmpc.learning.ppo_state import (
    FINISHED_FORMAT,
    NORMALIZE,
    RESUME,
    RESUME_FORMAT,
    check_progress,
    description,
    read_state,
    restore_running,
    running_statistics,
    state_file,
)
from etmpc.learning.ppo_settings import (  # noqa: F401 (SettingError and the rest re-exported, as before the split)
    PpoSettings,
    checked_checkpoints,
    SettingError,
    settings_json,
    _libraries,
    _make_env,
    _ours,
    save_model,
)
from etmpc.policies.features import observation_names
from etmpc.policies.learned import write_json_atomically
from etmpc.policies.sb3 import metadata_path
from etmpc.systems import SystemKey, system_key

if TYPE_CHECKING:
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecNormalize


class PpoLearner(Learner):
    """PPO (an MLP policy) on ``etmpc.envs.gym.TriggerEnv``, one seed (``settings.seed``)."""

    name = "ppo"
    Settings = PpoSettings
    policy_kind = "sb3"
    seeding = "one"
    unit = "environment steps"
    shipped = (
        "PPO (shipped)",
        "ppo.zip",
        "Stable-Baselines3 PPO on the trigger environment with the task's policies/<task>/ppo.yml (its reward against "
        "a fixed schedule), chosen on validation episodes",
    )

    def __init__(self, settings: PpoSettings | None = None, workers: int = 1):
        super().__init__(settings)
        self.workers = workers  # processes stepping the environments (the numbers do not depend on it)
        self.checkpoints: list[dict] = []
        self.result: dict | None = None
        self.vec: VecNormalize | None = None  # the environments, normalised (setup's; None once closed)
        self.model: PPO | None = None
        self.kernels: dict = {}  # the paths PyTorch takes in this process (etmpc.learning.kernels), read by check
        self._timesteps = 0
        self._simulated_before = 0  # a resumed run's steps before it resumed

    @classmethod
    def read_settings(cls, path, task) -> PpoSettings:
        """An rl-zoo3-style file (:mod:`etmpc.learning.hyperparams`); none: the task's shipped one."""
        from etmpc.learning import hyperparams

        return hyperparams.load(path, task) if path is not None else hyperparams.shipped(task)

    def default_seeds(self) -> tuple[int, ...]:
        return (self.settings.seed,)

    def owns(self, name: str) -> bool:
        return _ours(name)

    def check(self) -> None:
        refuse_foreign(self.out, self.owns, "PPO training run")
        if self.seeds[0] != self.settings.seed:
            self.settings = replace(self.settings, seed=self.seeds[0])
        pin(self.settings.kernels)  # before PyTorch is loaded
        self.sb3, self.torch = _libraries()
        self.kernels = in_effect()
        self.system = self.key.make()
        s = self.settings
        from etmpc.envs.trigger import checked_failure_cost, fixed_schedule

        if s.reward_baseline is not None:  # the environments' own checks, before the run's folder is made
            fixed_schedule(s.reward_baseline, self.system)
        checked_failure_cost(s.failure_cost, self.system)
        self.n_steps, self.slices = rollouts(s)  # the budget in whole rollouts

    def milestones(self) -> list[int]:
        return [int(x) for x in np.cumsum(self.slices)]

    @property
    def done(self) -> int:
        return self._timesteps

    def has_saved(self) -> bool:
        return (self.out / "training.json").exists() or (self.out / "checkpoints" / RESUME).exists()

    def saved_state(self) -> dict | None:
        """The run's state in :attr:`out`, each field checked (:func:`etmpc.learning.ppo_state.read_state`)."""
        return read_state(self.out)

    def identity(self) -> dict:
        return {"task": str(self.key), "settings": settings_json(self.settings)}

    def saved_identity(self, state: dict) -> tuple[str, dict]:
        saved = state.get("finished", state)
        return str(state_file(self.out, state)), {"task": saved["task"], "settings": saved["settings"]}

    def state(self) -> dict:
        return {
            "format": RESUME_FORMAT,
            "version": 1,
            "task": str(self.key),
            "settings": settings_json(self.settings),
            "checkpoints": self.checkpoints,
        }

    def setup(self) -> None:
        from stable_baselines3.common.vec_env import VecNormalize

        s, system = self.settings, self.system
        self.torch.set_num_threads(1)
        vec = VecNormalize(environments(self.key, s, self.workers), norm_obs=True, norm_reward=True, gamma=s.gamma)
        self.vec = vec
        self.model = make_model(self.sb3, vec, s, self.n_steps)
        if list(vec.get_attr("observation_names")[0]) != list(observation_names(system.name, system.state_names)):
            raise EtmpcError(f"{self.key.task}: the environment's observation is not the one sb3: computes")
        self.started = time.perf_counter()
        (self.out / "checkpoints").mkdir(parents=True, exist_ok=True)

    def load_state(self, state: dict) -> None:
        """Resume from :meth:`saved_state` (the run's task and settings checked by the runner, its checkpoints here)."""
        check_progress(self.out, state, self.milestones())
        if "finished" in state:
            self.result = state["finished"]
            self._timesteps = int(self.result["environment_steps"])
            return
        self.checkpoints = list(state["checkpoints"])
        last = self.checkpoints[-1]
        self.setup()  # the model and the normalisation the settings make, then the run's numbers into them
        model, vec = self._made()
        restore_running(vec, self.out / "checkpoints" / NORMALIZE)
        load_weights(model, self.out / last["file"])
        self._timesteps = int(last["timesteps"])
        model.num_timesteps = self._timesteps
        self.started = time.perf_counter() - last["wall_seconds"]
        self._simulated_before = int(last["simulated_steps"])
        self.say(f"{self.key.task}: PPO resumed at {self._timesteps} steps (its environments reset)")

    def _made(self) -> tuple[PPO, VecNormalize]:
        """The model and its environments, which :meth:`setup` makes (a resumed run's :meth:`load_state` too)."""
        if self.model is None or self.vec is None:
            raise EtmpcError("PPO: no model: the runner calls setup() or load_state() before it trains")
        return self.model, self.vec

    def learn(self, budget: int, callback) -> None:
        from etmpc.learning.runner import validate

        model, vec = self._made()
        out = self.out
        s = self.settings
        before = model.num_timesteps
        model.learn(total_timesteps=int(budget - model.num_timesteps), reset_num_timesteps=False)
        callback(int(model.num_timesteps - before))
        self._timesteps = int(model.num_timesteps)
        path = out / "checkpoints" / f"step_{model.num_timesteps:08d}.zip"
        save_checkpoint(model, vec, self.key, path, self.system.recompute_price, settings_json(s))
        score = validate(self.pool, self.key, [f"sb3:{path}"], s.validation_episodes)[0]
        simulated = self._simulated_before + int(sum(vec.get_attr("simulated_steps")))  # the baseline's steps too
        self.checkpoints.append(
            {
                "timesteps": int(model.num_timesteps),
                "simulated_steps": simulated,
                "file": str(path.relative_to(out)),
                "validation_objective": score,
                "wall_seconds": time.perf_counter() - self.started,
            }
        )
        self.say(
            f"{self.key.task}: PPO {model.num_timesteps} steps, validation objective {score:.5f} "
            f"({time.perf_counter() - self.started:.0f} s)"
        )

    def save(self) -> None:
        if self.result is None and self.checkpoints:  # under way: what resume needs
            write_json_atomically(self.out / "checkpoints" / NORMALIZE, running_statistics(self._made()[1]))
            write_json_atomically(self.out / "checkpoints" / RESUME, self.state())

    @property
    def chosen(self) -> bool:
        return self.result is not None

    def candidates(self) -> dict:
        return {c["file"]: f"sb3:{self.out / c['file']}" for c in self.checkpoints}

    def scores(self, validate) -> list[float]:
        return [c["validation_objective"] for c in self.checkpoints]  # scored as each was saved

    def choose(self, scores: list[float]) -> None:
        out, s, system = self.out, self.settings, self.system
        pick = best_of(self.checkpoints, system.objective_sense, key=lambda c: c["validation_objective"])
        shutil.copyfile(out / pick["file"], out / "selected.zip")
        meta = description(metadata_path(out / pick["file"]), self.key, pick["timesteps"], settings_json(s))
        write_json(
            out / "selected.json",
            dict(meta, validation_objective=pick["validation_objective"], validation_episodes=s.validation_episodes),
        )
        result = {
            "format": FINISHED_FORMAT,
            "version": 1,
            "task": str(self.key),
            "settings": settings_json(s),
            "workers": self.workers,
            "environment_steps": int(self._made()[0].num_timesteps),
            "simulated_steps": self.checkpoints[-1]["simulated_steps"],
            "wall_seconds": time.perf_counter() - self.started,
            "checkpoints": self.checkpoints,
            "selected": pick["file"],
            "objective_sense": system.objective_sense,
            "stable_baselines3": self.sb3.__version__,
            "torch": self.torch.__version__,
            "kernels": dict(setting=s.kernels, **self.kernels),
        }
        write_json(out / "training.json", result)
        for name in (RESUME, NORMALIZE):
            (out / "checkpoints" / name).unlink(missing_ok=True)
        self.result = result

    def close(self) -> None:
        if self.vec is not None:
            self.vec.close()
            self.vec = None

    def policy(self) -> str:
        return f"sb3:{self.out / 'selected.zip'}"

    def simulated_steps(self) -> int | None:
        return self.checkpoints[-1]["simulated_steps"] if self.checkpoints else None


def train_ppo(
    task: str | SystemKey,
    out: Path,
    settings: PpoSettings = PpoSettings(),
    workers: int = 1,
    recompute_price: float | None = None,
    say=lambda line: None,
    resume: bool = False,
    progress: bool = False,
) -> dict:
    """Train on ``task`` (a name, at ``recompute_price`` if given, or a :class:`SystemKey`), checkpoint,
    choose on validation episodes; returns ``training.json``'s content. A stopped run in ``out`` starts
    again, or with ``resume`` continues from its last checkpoint (not bit for bit: see
    the module docstring). :class:`PpoLearner` driven by
    :func:`etmpc.learning.runner.run`."""
    from etmpc.learning.runner import run

    out = Path(out)
    key = system_key(task, recompute_price)
    if (out / "training.json").exists():
        raise EtmpcError(f"{out} already holds a PPO run; choose another --out")
    if not resume:
        (out / "checkpoints" / RESUME).unlink(missing_ok=True)  # a stopped run starts again
    learner = PpoLearner(settings, workers)
    run(learner, key, out, (settings.seed,), workers, resume, progress=progress, say=say)
    assert learner.result is not None  # the runner ends by choosing, or finds the run had chosen
    return learner.result
