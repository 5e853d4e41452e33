"""The recompute decision as a ``dm_env.Environment``: one control interval of the loop per step, and the
action says whether to keep the plan (0) or to recompute it now (1).

It is the loop of ``etmpc evaluate``, not a copy: each step is one :meth:`etmpc.loop.ClosedLoop.step`.
An agent that answers as ``always`` or ``every:3`` gets exactly the rewards, recomputes and
trajectory that ``evaluate`` reports for them (``tests/envs/test_trigger_env.py``).

* **Observation**: a float32 vector, :data:`TriggerEnvironment.observation_names`: the ``error``
  features ``r`` of :mod:`etmpc.policies.features` (the prediction error ``x_i - x_hat_i`` per state,
  the plan's age and, for the battery, its prices and production now and as the kept plan assumed
  them), then each squared. Unbounded, but finite: a diverged plant's are clipped to the float32
  range. Zeros at the first step, before there is a plan.
* **Action**: ``0`` keep, ``1`` recompute. When there is no plan (the first step) or the plan has run
  out (age N), the loop recomputes whatever the action says: :attr:`info` says it was ``forced``. On a
  task with compute levels (``kicks_levels``) ``0`` keep, ``1`` one SQP iteration, ``2`` a full solve
  (``Discrete(3)``). On a task with a latency, an action while a solve is in flight is ignored:
  :attr:`info` says ``in_flight`` (and ``pending``: one is still under way after the step), ``level``
  and ``work`` (what was computed and its priced work).
* **Reward**: the task's reward for the interval minus the price of a recompute when one was made,
  forced ones included (:attr:`info` has both parts). Higher is better on every task: the cart
  pendulum's reward is ``-beta^2``.
* **Failures**: :attr:`info` ``["failures"]`` is the episode's failures so far (an int: the task's
  ``failures``, e.g. falls or steps off balance, counted over the steps played; 0 at the reset), on every
  task that counts them (every built-in one); at the episode's end it is what ``evaluate`` reports for it.
* **Reward against a baseline** (``reward_baseline="every:3"``, off by default): the same episode is
  also played, in lockstep, under a fixed schedule (``always``, ``never`` or ``every:T``), and the
  reward is the agent's minus the baseline's for the same interval. The baseline never depends on the
  agent's actions, so every policy's ranking (and the optimal policy) is unchanged; what goes is most of
  the variance the episode's own draw (its disturbances, prices, targets) puts into a return, which
  otherwise drowns the effect of one decision. It costs a second simulation (and the baseline's
  solves): :attr:`simulated_steps` counts both. :attr:`episode_return` stays the task's own return.
* **A failure cost** (``failure_cost=C``, 0 by default): each of the task's failures costs ``C`` more, in
  the reward of the step it happens in (:attr:`info` ``["failure_penalty"]``), on top of what the task's
  reward already charges: safety as a weight in the reward, for a learner trained on it. With a reward
  baseline, the baseline's failures cost the same (it is the same reward, played by the schedule). Only
  on a task that counts failures.
* **Episodes**: ``reset()`` draws a training-distribution episode from the environment's own
  generator (``seed``); ``reset(test_episode=i)`` plays episode ``i`` of the stored test set. An
  episode ends at the task's time limit (``LAST`` with discount 1: a truncation), or early, with
  discount 0, when the plant fails.
"""

from __future__ import annotations

import math
import numbers
import os
from pathlib import Path
from typing import Any

import dm_env
import numpy as np
from dm_env import specs

from etmpc.common import checks
from etmpc.common.errors import EtmpcError
from etmpc.envs.registration import env_id
from etmpc.evaluation import testsets
from etmpc.loop import ClosedLoop
from etmpc.policies import parse_policy
from etmpc.policies.features import observation, observation_names
from etmpc.policies.sb3 import finite_observation
from etmpc.policies.specs import find
from etmpc.systems import SystemKey, system_key

KEEP, RECOMPUTE = 0, 1  # a task's actions; on a task with compute levels 0 keep, 1 one SQP iteration, 2 a full solve
MEANINGS = {2: "0 (keep the plan) or 1 (recompute)", 3: "0 (keep the plan), 1 (one SQP iteration) or 2 (a full solve)"}


def check_action(action: Any, actions: int = 2) -> int:
    """The action as an int, if it is exactly what the action space holds: ``0`` or ``1`` as a Python
    int (``True``/``False`` are ints in Python), a numpy integer scalar (``np.int64(1)``, what a
    vectorised environment hands each copy) or a 0-d integer array (``np.array(1)``, what
    Stable-Baselines3's ``predict`` returns for one observation): the forms ``gymnasium.spaces.
    Discrete(2).contains`` accepts. Anything else (a float, a list, an array of another shape, a
    numpy bool, a string) raises :class:`InvalidAction`. ``actions``: 2, or 3 on a task with compute levels."""
    if isinstance(action, int) or (
        isinstance(action, (np.integer, np.ndarray)) and action.shape == () and np.issubdtype(action.dtype, np.integer)
    ):
        value = int(action)
        if 0 <= value < actions:
            return value
        raise InvalidAction(f"an action is {MEANINGS[actions]}, got {value}")
    shape = f" of shape {action.shape}" if isinstance(action, np.ndarray) else ""
    raise InvalidAction(
        f"an action is {MEANINGS[actions]}: an int, a numpy integer or a 0-d integer "
        f"array, got {type(action).__name__}{shape} {action!r}"
    )


def check_index(index: Any, what: str = "test_episode") -> int:
    """A test-set episode's index: a whole number (an int or numpy integer, never a float or a bool)."""
    if isinstance(index, bool) or not isinstance(index, (int, np.integer)):
        raise checks.BadValue(f"{what} must be an integer index of the test set, got {type(index).__name__} {index!r}")
    return int(index)


def fixed_schedule(spec: str, system):
    """The baseline of a relative reward: a fixed schedule (it must not depend on what the agent does). A bad
    one is an argument's bad value (:class:`~etmpc.common.checks.BadValue`, a ``ValueError`` too), or of the
    wrong type (:class:`~etmpc.common.checks.BadType`, a ``TypeError``), as Python's own are."""
    needed = "reward_baseline: a fixed schedule (always, never, every:T or iterate:T) is needed"
    if not isinstance(spec, str):
        raise checks.BadType(f"{needed}, got {type(spec).__name__} {spec!r}")
    kind = find(spec)
    if kind is None or kind.family != "periodic":
        raise checks.BadValue(f"{needed}, got {spec!r}")
    try:
        return parse_policy(spec, system)
    except EtmpcError as exc:
        raise checks.BadValue(f"{needed}: {exc}") from None


class InvalidAction(EtmpcError, ValueError):
    """An action the environment does not take (a ``ValueError``, as gymnasium's are)."""


def not_picklable(env) -> TypeError:
    """What pickling a trigger environment raises: it holds a compiled MPC and a simulation."""
    return NotPicklable(
        f"{type(env).__name__} of {env.key} cannot be pickled (it holds a compiled MPC and a MuJoCo "
        "or battery simulation): make one in each process instead, e.g. with "
        f"gymnasium.make({env.gym_id!r}), or a function that makes it (SubprocVecEnv takes those)"
    )


def checked_failure_cost(value, system) -> float:
    """``failure_cost`` as a float: a finite number >= 0; above 0 only on a task that counts failures."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not (math.isfinite(value) and not value < 0):
        raise EtmpcError(f"failure_cost must be a finite number >= 0, got {value!r}")
    if value and system.failures is None:
        raise EtmpcError(f"failure_cost: task {system.name} counts no failures, so none can cost")
    return float(value)


class NotPicklable(EtmpcError, TypeError):
    """Pickling something that must be made in each process (a ``TypeError``, as pickle's own are)."""


class TriggerEnvironment(dm_env.Environment):
    """The recompute decision of task ``task`` (``DOMAIN`` or ``DOMAIN/TASK``, or a
    :class:`~etmpc.systems.SystemKey`), at ``recompute_price`` per recompute (default: the task's own), with
    ``options`` (the task's options, a mapping NAME -> value or ``(name, value)`` pairs: :mod:`etmpc.systems.options`;
    the keyword of :func:`etmpc.evaluate` and :func:`etmpc.score`), on ``test_set`` (a test set file, default the
    stored one). ``task_options=``, the old name of ``options=``, works for this release with a
    ``DeprecationWarning``. See the module's docstring."""

    def __init__(
        self,
        task: str | SystemKey = "cart_pendulum",
        seed: int | None = None,
        recompute_price: float | None = None,
        test_set: str | None = None,
        reward_baseline: str | None = None,
        options=None,
        failure_cost: float = 0.0,
        *,
        task_options=None,
    ):
        if not isinstance(task, (str, SystemKey)):
            raise checks.BadType(f"task: a task name (str) is needed, got {type(task).__name__} {task!r}")
        if seed is not None:
            checks.argument("seed", checks.seed, seed)
        if test_set is not None and not isinstance(test_set, (str, os.PathLike)):
            raise checks.BadType(f"test_set: a file path is needed, got {type(test_set).__name__} {test_set!r}")
        from etmpc.systems.options import pairs

        named = "task_options" if task_options is not None else "options"  # a wrong shape is said in the keyword given
        options = checks.renamed("options", options, "task_options", task_options, required=False)
        options = pairs(() if options is None else options, named)
        self.key = system_key(task, recompute_price, options)  # the task, its price and options, checked here
        self.system = self.key.make()
        self.failure_cost = checked_failure_cost(failure_cost, self.system)
        self.actions = 3 if self.system.compute_levels else 2  # Discrete(3) on a task with compute levels
        self.loop = ClosedLoop(self.system, self.system.make_env())
        self.observation_names = observation_names(self.system.name, self.system.state_names)
        self._size = len(self.observation_names)
        self._rng = np.random.default_rng(seed)
        self._test_set_path = test_set
        self._test_set: testsets.TestSet | None = None
        self.info: dict = {}
        self._episode = None  # the episode being played
        self.reward_baseline = None if reward_baseline is None else fixed_schedule(reward_baseline, self.system)
        self._shadow = None if reward_baseline is None else ClosedLoop(self.system, self.key.make().make_env())
        self.simulated_steps = 0  # the agent's steps, and the baseline's
        self._failed = [0, 0]  # the episode's failures so far: the agent's, the baseline's (for the failure cost)

    @property
    def gym_id(self) -> str:
        """This task's id in gymnasium's registry."""
        return env_id(f"{self.system.domain}/{self.system.task}")

    def __reduce__(self):
        raise not_picklable(self)

    # -- dm_env ---------------------------------------------------------------------------------------
    def reset(self, test_episode: int | None = None) -> dm_env.TimeStep:
        """A new episode: drawn from the environment's generator, or test-set episode ``test_episode``."""
        if test_episode is not None:
            test_episode = check_index(test_episode)
        episode = self.system.draw_episode(self._rng) if test_episode is None else self.test_episode(test_episode)
        self.loop.reset(episode)
        self._episode = episode
        if self._shadow is not None:
            self._shadow.reset(episode)
        self.info = {"step": 0} | self._failures()
        self._failed = [0, 0]
        return dm_env.restart(self._observation())

    def step(self, action) -> dm_env.TimeStep:
        if self.loop.done:
            return self.reset()
        asked = check_action(action, self.actions)
        loop = self.loop
        forced, in_flight = loop.forced, loop.in_flight
        reward = loop.step(asked if self.actions == 3 else asked == RECOMPUTE)  # the task's reward, net of the recompute's price
        self.info = {
            "step": loop.step_index,
            "recompute": loop.recomputed,
            "forced": forced,
            "control_reward": loop.reward,
            "computation_cost": loop.cost,
            "nonfinite": loop.trajectory.nonfinite,
        } | self._failures()
        if not (self.system.latency.instant and self.actions == 2):  # time in the loop: what was computed, and when
            self.info |= {"in_flight": in_flight, "level": int(loop.level), "work": loop.work, "pending": loop.in_flight}
        self.simulated_steps += 1
        if self.failure_cost:
            self.info["failure_penalty"] = penalty = self._penalty(0, self.info["failures"])
            reward -= penalty
        if self._shadow is not None:
            baseline = self._baseline_step()
            reward -= baseline
            self.info["baseline_reward"] = baseline
        if not loop.done:
            return dm_env.transition(reward, self._observation())
        if loop.trajectory.nonfinite:  # the plant failed: a termination
            return dm_env.termination(reward, self._observation())
        return dm_env.truncation(reward, self._observation())

    def _failures(self) -> dict:
        """``{"failures": n}``, the episode's failures so far, on a task that counts them (else nothing)."""
        if self.system.failures is None:
            return {}
        return {"failures": int(self.system.failures(self.loop.trajectory, self._episode))}

    def _baseline_step(self) -> float:
        """One interval of the baseline's loop (its reward net of its recomputes; 0 once it is over)."""
        shadow = self._shadow
        baseline = self.reward_baseline
        assert shadow is not None and baseline is not None  # step plays it only where a baseline was given
        if shadow.done:
            return 0.0
        s = None if shadow.forced else shadow.observed_state()  # not forced: a plan is in force, so s is shown
        recompute = s is None or baseline.decide(s, None)
        self.simulated_steps += 1
        reward = shadow.step(recompute)
        if self.failure_cost:
            reward -= self._penalty(1, int(self.system.failures(shadow.trajectory, self._episode)))
        return reward

    def _penalty(self, who: int, failures: int) -> float:
        """The failure cost of this step's new failures (``who``: 0 the agent, 1 the baseline), ``failures``
        being the episode's so far."""
        new, self._failed[who] = failures - self._failed[who], failures
        return self.failure_cost * new

    def observation_spec(self) -> specs.Array:
        return specs.Array((self._size,), np.float32, name="trigger_features")

    def action_spec(self) -> specs.BoundedArray:
        return specs.BoundedArray((), np.int64, KEEP, self.actions - 1, name="recompute" if self.actions == 2 else "compute")

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
            testsets.check_options_act(self.key, self._test_set_path)  # its training episodes are drawn: they feel them
            path = self._test_set_path or testsets.default_path(self.system.domain, self.system.task)
            test_set = testsets.load(Path(path), self.system.domain, self.system.task)
            test_set.check_playable(self.system, self.loop.env.task)  # a bad episode is refused here, named
            self._test_set = test_set
        return self.system.episode_from_arrays(self._test_set.episode_arrays(check_index(index, "the index")))

    def _observation(self) -> np.ndarray:
        # a diverged plant's: clipped to the float32 range, NaN as 0, as sb3: sees it too (the same function)
        return finite_observation(observation(self.system.name, self.loop.observed_state(), self._size))

    @property
    def episode(self):
        """The episode being played (None before the first reset)."""
        return self._episode

    @property
    def episode_return(self) -> float:
        """The return of the episode so far, as ``evaluate`` computes an objective's sum."""
        traj = self.loop.trajectory
        return traj.policy_return(self.system.recompute_price) if traj.steps else math.nan
