"""The loop itself: :class:`ClosedLoop` (one control interval per step), :func:`run_episode` and
:func:`play_on` (see :mod:`etmpc.loop`)."""

from __future__ import annotations

import math
import time
from typing import Any

import dm_env
import numpy as np
from dm_control.rl.control import PhysicsError

from etmpc.common.frozen import frozen, readonly
from etmpc.control.plan import Plan
from etmpc.loop.records import Continuation, Trajectory
from etmpc.loop.state import AugmentedState, DecisionContext, Policy, Snapshot
from etmpc.systems.base import System


def _shown(timestep: dm_env.TimeStep) -> dm_env.TimeStep:
    """The step with its observation frozen: the loop shows it to policies, and they cannot write into it."""
    return dm_env.TimeStep(timestep.step_type, timestep.reward, timestep.discount, frozen(timestep.observation))


def _input(system: System, plan: Plan, age: int, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(u, u_planned, correction, x_predicted)``: the plan's input plus the LQR correction, clipped."""
    u_planned = plan.input_at(age)
    x_predicted = plan.state_at(age)
    correction = np.zeros(u_planned.shape) if age == 0 else system.feedback.correction(x, x_predicted, plan, age)
    # np.minimum(np.maximum(.)) is np.clip's arithmetic without its Python-level overhead.
    return np.minimum(np.maximum(u_planned + correction, system.u_min), system.u_max), u_planned, correction, x_predicted


class ClosedLoop:
    """Algorithm 1, one control interval at a time: an episode in play, and its step.

    :func:`run_episode` drives it with a policy; ``etmpc.envs`` hands each decision to an agent
    instead. Both play this class, so the numbers are the same, bit for bit.

    >>> loop = ClosedLoop(system, env).reset(episode)
    >>> while not loop.done:
    ...     s = loop.augmented_state()          # None when the decision is forced
    ...     loop.step(s is not None and my_rule(s))
    >>> loop.trajectory
    """

    def __init__(self, system: System, env: dm_env.Environment):
        self.system, self.env = system, env
        self.done = True

    def reset(self, episode: Any = None) -> ClosedLoop:
        """Start an episode: a stored one if given, else one drawn by the task."""
        system = self.system
        self.env.task.use_episode(episode)
        self.timestep = _shown(self.env.reset())
        self.x = readonly(system.state(self.timestep))
        nu = system.u_min.shape[0]
        self.trajectory = Trajectory.empty(system.episode_steps, self.x.shape[0], nu)
        self.plan: Plan | None = None
        self.age, self.u_prev, self.step_index, self.done = 0, readonly(np.zeros(nu)), 0, False
        self._arrive()
        return self

    @property
    def forced(self) -> bool:
        """The plan has run out (age = N), or there is none yet: the loop must solve, whatever is asked."""
        return self.plan is None or self.age >= self.plan.horizon

    def augmented_state(self, context: bool = False) -> AugmentedState | None:
        """What a policy sees at this step's decision; ``None`` when the decision is forced. With
        ``context``, the loop's whole state too (for policies that simulate)."""
        return None if self.forced else self.observed_state(context)

    def observed_state(self, context: bool = False) -> AugmentedState | None:
        """The augmented state now, also when the decision is forced; ``None`` before the first plan."""
        if self.plan is None:
            return None
        plan, age = self.plan, self.age
        ctx = DecisionContext(self.system, self.env, self.step_index, plan, age, self.u_prev, self.timestep) if context else None
        return AugmentedState(self.x, plan.states[0], age, plan.state_at(age), plan, self.timestep.observation, ctx)

    def step(self, recompute: bool, started: float | None = None) -> float:
        """Play this control interval: solve a new plan if ``recompute`` (or if forced), apply the
        plan's input plus the LQR correction, clipped, and step the plant. Returns the environment's
        reward (0 when the plant failed: the episode then ends, non-finite). ``started``: when the
        step's decision began (the step's wall time counts from there)."""
        if self.done:
            raise RuntimeError("the episode is over: reset the loop")
        start = time.perf_counter() if started is None else started
        system, traj, i, x, plan = self.system, self.trajectory, self.step_index, self.x, self.plan
        forced = self.forced
        recompute = forced or bool(recompute)
        if recompute:
            solve_start = time.perf_counter()
            new = system.plan(x, self.u_prev, plan, self.age, self.timestep)
            traj.solve_time_s[i] = time.perf_counter() - solve_start  # the whole computation
            if not new.success:
                traj.solver_failures += 1
            if new.success or forced:  # a failed solve keeps the old plan only while it has steps left
                plan, self.plan, self.age = new, new, 0
                traj.plans.append((i, plan))
        feedback_start = time.perf_counter()
        u, u_planned, correction, x_predicted = _input(system, plan, self.age, x)
        traj.feedback_time_s[i] = time.perf_counter() - feedback_start
        try:
            self.timestep = _shown(self.env.step(system.action(u, recompute)))
        except PhysicsError:
            traj.nonfinite, self.done = True, True
            return 0.0
        traj.applied[i], traj.planned[i], traj.correction[i] = u, u_planned, correction
        traj.predicted[i], traj.plan_age[i] = x_predicted, self.age
        traj.recompute[i], traj.forced[i] = recompute, forced
        traj.rewards[i] = reward = self.timestep.reward
        traj.steps = self.step_index = i + 1
        self.x = readonly(system.state(self.timestep))
        u.flags.writeable = False  # the loop's own new array (np.minimum's): shown as u_prev, never written again
        self.age, self.u_prev = self.age + 1, u
        if self.env.task.restarted:  # the task put the plant back: the plan no longer applies
            self.age = plan.horizon
        traj.step_time_s[i] = time.perf_counter() - start
        if self.timestep.last() or self.step_index >= system.episode_steps:
            self._finish()
        else:
            self._arrive()
        return reward

    def _arrive(self) -> None:
        """At the start of a step: the state is recorded; a non-finite one ends the episode."""
        self.trajectory.states[self.step_index] = self.x
        if not np.all(np.isfinite(self.x)):
            self.trajectory.nonfinite, self.done = True, True

    def _finish(self) -> None:
        traj = self.trajectory
        traj.states[traj.steps] = self.x
        traj.nonfinite = not bool(np.all(np.isfinite(self.x)))
        self.done = True


def run_episode(
    system: System,
    env: dm_env.Environment,
    policy: Policy,
    rng: np.random.Generator | None = None,
    episode: Any = None,
) -> Trajectory:
    """Play one episode (a stored one if given, else one drawn by the task) under ``policy``."""
    loop = ClosedLoop(system, env).reset(episode)
    simulates = getattr(policy, "simulates", False)
    while not loop.done:
        started = time.perf_counter()
        s = loop.augmented_state(simulates)
        recompute = s is not None and bool(policy.decide(s, rng))
        if s is not None:
            loop.trajectory.decide_time_s[loop.step_index] = time.perf_counter() - started
        loop.step(recompute, started)
    return loop.trajectory


def play_on(
    system: System,
    env: dm_env.Environment,
    snapshot: Snapshot,
    policy: Policy,
    rng: np.random.Generator | None,
    first: bool,
    episode: Any = None,
    first_plan: Plan | None = None,
    stop: int | None = None,
    trace: Continuation | None = None,
) -> float:
    """Continue ``snapshot`` in ``env`` (a twin of the one it was taken in) and return the policy's
    return from the snapshot's step on: rewards minus the price of each computation, plus
    ``system.truncation_value`` of the last state when the play stops before the episode's end.

    The first decision is ``first`` (recompute or keep), the later ones ``policy``'s. ``episode``
    replaces the episode being played from the snapshot's step on (a sampled future); ``first_plan``
    is the plan a recompute at the first step gives, when the caller has solved it already (it is
    the same for every future). ``stop`` is the step to stop before (default: the episode's end). A
    plant that fails (non-finite state) returns ``-inf``. ``trace``, if given (a new :class:`Continuation`),
    is filled step by step.

    Steps the task and the physics directly, as ``control.Environment.step`` does, without making
    a ``TimeStep``; reads the state off the physics (``system.measure``) and makes the task's
    observation only when a solve or a policy reads it (a policy that does not sets ``observes =
    False``): the same numbers as :func:`run_episode`, bit for bit (tests/test_rollout.py).
    """
    task, physics = env.task, env.physics
    physics.restore(snapshot.physics)
    task.resume(snapshot.episode if episode is None else episode, snapshot.step)
    n_sub_steps, price = env._n_sub_steps, system.recompute_price
    end = system.episode_steps if stop is None else min(stop, system.episode_steps)
    plan, age, u_prev, x, observation = snapshot.plan, snapshot.age, snapshot.u_prev, snapshot.x, snapshot.observation
    observes = getattr(policy, "observes", True)  # the observation is made only when someone reads it
    total = 0.0
    for i in range(snapshot.step, end):
        if i == snapshot.step:
            recompute = plan is None or age >= plan.horizon or first  # a plan that has run out forces a solve
        elif plan is None or age >= plan.horizon:
            recompute = True
        else:
            if observes and observation is None:
                observation = frozen(task.get_observation(physics))
            recompute = bool(policy.decide(AugmentedState(x, plan.states[0], age, plan.state_at(age), plan, observation), rng))
        if recompute:
            if i == snapshot.step and first_plan is not None:
                new = first_plan
            else:
                if observation is None:
                    observation = task.get_observation(physics)
                new = system.plan(x, u_prev, plan, age, dm_env.TimeStep(dm_env.StepType.MID, None, None, observation))
            if new.success or plan is None or age >= plan.horizon:
                plan, age = new, 0
        u = _input(system, plan, age, x)[0]
        try:
            task.before_step(system.action(u, recompute), physics)
            physics.step(n_sub_steps)
        except PhysicsError:
            return -math.inf
        task.after_step(physics)
        added = task.get_reward(physics) - price * recompute
        total += added
        observation, x = None, readonly(system.measure(physics))
        if not np.isfinite(x).all():
            return -math.inf
        age, u_prev = age + 1, u
        if task.restarted:  # as in ClosedLoop.step: the next decision is forced
            age = plan.horizon
        if trace is not None:
            trace.added.append(added)
            trace.recomputed.append(recompute)
            trace.after.append((x, plan, age, u_prev))
    if end < system.episode_steps:
        total += system.truncation_value(x)
    return total
