"""The trigger problem as a ``dm_env.Environment``: one control interval of the loop per step, and the
action says whether to keep the plan (0) or to recompute it now (1).

It is the loop of ``etmpc evaluate``, not a copy: each step is one :meth:`etmpc.loop.ClosedLoop.step`.
An agent that answers as ``always`` or ``every:3`` gets exactly the rewards, computations and
trajectory that ``evaluate`` reports for them (``tests/test_envs.py``).

* **Observation**: a float32 vector, :data:`TriggerEnvironment.observation_names`: the ``error``
  features ``r`` of :mod:`etmpc.policies.features` (the prediction error ``x_i - x_hat_i`` per state,
  the plan's age and, for the battery, its prices and production now and as the kept plan assumed
  them), then each squared. Unbounded, but finite: a diverged plant's are clipped to the float32
  range. Zeros at the first step, before there is a plan.
* **Action**: ``0`` keep, ``1`` recompute. When there is no plan (the first step) or the plan has run
  out (age N), the loop recomputes whatever the action says: :attr:`info` says it was ``forced``.
* **Reward**: the task's reward for the interval minus the price of a computation when one was made,
  forced ones included (:attr:`info` has both parts). Higher is better on every task: the cart
  pendulum's reward is ``-beta^2``.
* **Episodes**: ``reset()`` draws a training-distribution episode from the environment's own
  generator (``seed``); ``reset(test_episode=i)`` plays episode ``i`` of the stored test set. An
  episode ends at the task's time limit (``LAST`` with discount 1: a truncation), or early, with
  discount 0, when the plant fails.
"""

from __future__ import annotations

import math
from typing import Any

import dm_env
import numpy as np
from dm_env import specs

from etmpc.evaluation import testsets
from etmpc.loop import ClosedLoop
from etmpc.policies.features import observation, observation_names
from etmpc.systems import make_system, system_key

KEEP, RECOMPUTE = 0, 1


def check_action(action: Any) -> int:
    """``0`` or ``1`` (a Python or numpy integer or bool, or a 0-d or 1-element array of one); anything
    else raises ``ValueError``."""
    if isinstance(action, (int, np.integer)) and not isinstance(action, (bool, np.bool_)):
        value = int(action)  # the common case, checked without building an array
    else:
        array = np.asarray(action)
        if array.size != 1 or array.dtype.kind not in "biu":
            raise ValueError(f"an action is 0 (keep the plan) or 1 (recompute), got {action!r}")
        value = int(array.reshape(()))
    if value not in (KEEP, RECOMPUTE):
        raise ValueError(f"an action is 0 (keep the plan) or 1 (recompute), got {value}")
    return value


class TriggerEnvironment(dm_env.Environment):
    """The trigger problem of task ``task`` (``DOMAIN`` or ``DOMAIN/TASK``), at ``price`` per
    computation (default: the task's own). See the module's docstring."""

    def __init__(self, task: str = "cart_pendulum", seed: int | None = None, price: float | None = None,
                 test_set: str | None = None):
        self.key = system_key(task, price)
        self.system = make_system(self.key)
        self.loop = ClosedLoop(self.system, self.system.make_env())
        self.observation_names = observation_names(self.system.name, self.system.state_names)
        self._size = len(self.observation_names)
        self._rng = np.random.default_rng(seed)
        self._test_set_path = test_set
        self._test_set = None
        self.info: dict = {}

    # -- dm_env ---------------------------------------------------------------------------------------
    def reset(self, test_episode: int | None = None) -> dm_env.TimeStep:
        """A new episode: drawn from the environment's generator, or test-set episode ``test_episode``."""
        episode = self.system.draw_episode(self._rng) if test_episode is None else self.test_episode(test_episode)
        self.loop.reset(episode)
        self.info = {"step": 0}
        return dm_env.restart(self._observation())

    def step(self, action) -> dm_env.TimeStep:
        if self.loop.done:
            return self.reset()
        asked = check_action(action)
        loop, system = self.loop, self.system
        forced = loop.forced
        recompute = forced or asked == RECOMPUTE
        control = loop.step(recompute)
        price = system.recompute_price * recompute
        reward = control - price
        self.info = {"step": loop.step_index, "recompute": recompute, "forced": forced, "control_reward": control,
                     "computation_cost": price, "nonfinite": loop.trajectory.nonfinite}
        if not loop.done:
            return dm_env.transition(reward, self._observation())
        if loop.trajectory.nonfinite:  # the plant failed: a termination
            return dm_env.termination(reward, self._observation())
        return dm_env.truncation(reward, self._observation())

    def observation_spec(self) -> specs.Array:
        return specs.Array((self._size,), np.float32, name="trigger_features")

    def action_spec(self) -> specs.BoundedArray:
        return specs.BoundedArray((), np.int64, KEEP, RECOMPUTE, name="recompute")

    def reward_spec(self) -> specs.Array:
        return specs.Array((), np.float64, name="reward")

    # -- the rest -------------------------------------------------------------------------------------
    def seed(self, seed: int | None) -> None:
        """Restart the generator that draws training episodes."""
        self._rng = np.random.default_rng(seed)

    @property
    def generator(self) -> np.random.Generator:
        return self._rng

    @generator.setter
    def generator(self, rng: np.random.Generator) -> None:
        self._rng = rng

    def test_episode(self, index: int):
        """Episode ``index`` of the stored test set (or of ``test_set``)."""
        if self._test_set is None:
            path = self._test_set_path or testsets.default_path(self.system.domain, self.system.task)
            self._test_set = testsets.load(path, self.system.domain, self.system.task)
        return self.system.episode_from_arrays(self._test_set.episode_arrays(int(index)))

    def _observation(self) -> np.ndarray:
        obs = observation(self.system.name, self.loop.observed_state(), self._size)
        if not np.isfinite(obs.sum()):  # a diverged plant: clipped to the float32 range, NaN as 0
            obs = np.nan_to_num(obs, nan=0.0, posinf=np.finfo(np.float32).max, neginf=np.finfo(np.float32).min)
        return obs

    @property
    def episode_return(self) -> float:
        """The return of the episode so far, as ``evaluate`` computes an objective's sum."""
        traj = self.loop.trajectory
        return traj.policy_return(self.system.recompute_price) if traj.steps else math.nan
