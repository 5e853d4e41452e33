"""The control loop of the paper's Algorithm 1, generic over the system.

Each step: measure ``x_i``; if there is no plan, or the plan has run out (age = N), or the task put
the plant back in the last step (``task.restarted``: a fallen pole re-erected), or the policy draws
``a_i = 1``, solve a new plan from ``x_i``. Apply the planned input plus the feedback correction
(``-K (x_i - x_hat_i)``, with a fixed LQR gain or one along the plan), clipped to the input bounds.
If a solve fails, the previous plan is kept while it has steps left (the feedback keeps correcting
around it) and the failure is counted; a forced solve that fails is used as it is (the solver's last
iterate). Every recompute attempt counts as a computation (``a_i = 1``).

A system plugs in by providing what :class:`etmpc.systems.base.System` lists; a policy by providing
what :class:`Policy` lists, deciding from an :class:`AugmentedState`. Nothing here knows about MuJoCo,
batteries or any particular policy.

This module may import ``etmpc.common``, ``etmpc.control`` and ``etmpc.systems``.

Two ways to play the same loop, bit for bit the same numbers:

* :func:`run_episode` steps the ``dm_env`` interface and keeps everything (a :class:`Trajectory`),
  one :class:`ClosedLoop` step per control interval (``etmpc.envs`` plays the same steps for an agent);
* :func:`play_on` continues from a :class:`Snapshot` of a running episode, stepping the task and
  the physics directly (no ``TimeStep`` per step) and keeping only the return: the fast path the
  rollout policies simulate their futures with.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol

import dm_env
import numpy as np
from dm_control.rl.control import PhysicsError

from etmpc.common.frozen import frozen, readonly
from etmpc.control.plan import Plan
from etmpc.systems.base import System


# -- what the loop asks of a policy ------------------------------------------------------------------
@dataclass(frozen=True)
class AugmentedState:
    """What a policy sees at a decision (paper, section 2.2): ``s = [x_i, x_k, i - k]`` (the current
    state, the state the plan was made from, the plan's age), the plan's prediction ``x_hat_i`` (a
    function of ``s``, handed along for the event trigger), the kept plan, the task's observation and,
    for policies that simulate, the loop's whole state.

    Everything in it is read-only (:mod:`etmpc.common.frozen`): the arrays are read-only views, the
    plan a frozen value, the observation a frozen mapping. A policy that writes into what it is shown
    gets an error, never a changed run; to compute with a value, copy it (``np.array(s.x)``)."""

    x: np.ndarray  # x_i, measured now
    x_plan: np.ndarray  # x_k, measured when the plan was made
    age: int  # i - k
    x_predicted: np.ndarray  # x_hat_i, the plan's prediction for now
    plan: Any = None  # the kept Plan (its inputs and the forecasts it was made with)
    observation: Mapping | None = None  # what the task shows now (for the exogenous features)
    context: Any = None  # a DecisionContext: the loop's whole state, for policies that simulate (simulates = True)


class Policy(Protocol):
    spec: str
    stochastic: bool
    # Optional ``observes = False``: decide never reads ``s.observation`` (the fast path of
    # etmpc.loop.play_on then skips making it). Without the attribute, a policy is assumed to read it.

    def decide(self, s: AugmentedState, rng: np.random.Generator) -> bool: ...



# -- what one episode did --------------------------------------------------------------------------
@dataclass
class Trajectory:
    """Everything one episode did, step by step (arrays preallocated for the full episode)."""

    states: np.ndarray  # (T + 1, nx) measured; rows past `steps` stay NaN
    applied: np.ndarray  # (T, nu) input sent to the plant
    planned: np.ndarray  # (T, nu) the plan's input for that step
    correction: np.ndarray  # (T, nu) LQR correction before clipping
    predicted: np.ndarray  # (T, nx) the plan's prediction x_hat_i
    plan_age: np.ndarray  # (T,) i - k at the decision
    recompute: np.ndarray  # (T,) a_i: a computation was spent (includes forced ones)
    forced: np.ndarray  # (T,) the plan had run out (or there was none)
    rewards: np.ndarray  # (T,) the environment's reward for the step
    solve_time_s: np.ndarray  # (T,) wall time of the MPC computation (NaN where none happened)
    step_time_s: np.ndarray  # (T,) wall time of the whole step, solve included
    feedback_time_s: np.ndarray  # (T,) wall time of the input: the plan's, plus the LQR correction, clipped
    decide_time_s: np.ndarray  # (T,) wall time of the policy's decision (0 where the loop did not ask it)
    plans: list[tuple[int, Plan]] = field(default_factory=list)  # (step made, plan), successful or used
    steps: int = 0
    solver_failures: int = 0
    nonfinite: bool = False  # the episode ended early on a non-finite state

    @classmethod
    def empty(cls, steps: int, nx: int, nu: int) -> Trajectory:
        nan = lambda *shape: np.full(shape, np.nan)  # noqa: E731
        return cls(
            states=nan(steps + 1, nx), applied=nan(steps, nu), planned=nan(steps, nu), correction=nan(steps, nu),
            predicted=nan(steps, nx), plan_age=np.zeros(steps, int), recompute=np.zeros(steps, bool),
            forced=np.zeros(steps, bool), rewards=np.zeros(steps), solve_time_s=nan(steps), step_time_s=nan(steps),
            feedback_time_s=np.zeros(steps), decide_time_s=np.zeros(steps),
        )

    def cpu_seconds(self) -> dict[str, float]:
        """The controller's time spent in this episode, summed over its steps (wall clock per call, so a
        machine-dependent figure): the MPC's ``solve``s, the ``feedback`` (the LQR), the trigger's
        ``decide``s (a rollout's simulations included)."""
        n = self.steps
        return {"solve": float(np.nansum(self.solve_time_s[:n])), "feedback": float(self.feedback_time_s[:n].sum()),
                "decide": float(self.decide_time_s[:n].sum())}

    @property
    def recomputes(self) -> int:
        return int(self.recompute[: self.steps].sum())

    def policy_rewards(self, recompute_price: float) -> np.ndarray:
        """Per-step rewards the policy maximises: the environment's, minus the price of a computation."""
        return self.rewards[: self.steps] - recompute_price * self.recompute[: self.steps]

    def policy_return(self, recompute_price: float) -> float:
        """The policy's return: rewards minus the price of every computation."""
        return float(self.rewards[: self.steps].sum() - recompute_price * self.recomputes)


@dataclass(frozen=True, eq=False)
class DecisionContext:
    """The loop's whole state at a decision, for policies that simulate futures (``rollout:``)."""

    system: Any
    env: dm_env.Environment
    step: int  # i: the decision is about the input of interval i
    plan: Plan
    age: int
    u_prev: np.ndarray
    timestep: dm_env.TimeStep


@dataclass(eq=False)
class Continuation:
    """What one :func:`play_on` did, step by step, for a caller that picks it up again later (the
    oracle's memo): what each step added to the return, whether it computed, and the controller's
    state after it (``x``, the plan, its age, ``u_prev``). Summed from 0.0 in order, ``added[k:]``
    gives exactly what a play on from the state after step ``k - 1`` returns."""

    start: int  # the step it started at
    added: list[float] = field(default_factory=list)
    recomputed: list[bool] = field(default_factory=list)
    after: list[tuple] = field(default_factory=list)

    def return_from(self, k: int) -> float:
        """The return from its ``k``-th step on, summed as :func:`play_on` sums it."""
        total = 0.0
        for added in self.added[k:]:
            total += added
        return total


@dataclass(frozen=True, eq=False)
class Snapshot:
    """A running episode, frozen at a decision: the plant, the task's position in its episode and the
    controller's memory. :func:`play_on` continues from it exactly."""

    physics: Any  # the physics' own snapshot (see each Physics.snapshot)
    step: int
    episode: Any  # the episode the task was playing
    plan: Plan
    age: int
    u_prev: np.ndarray
    x: np.ndarray
    observation: Mapping

    @classmethod
    def take(cls, context: DecisionContext) -> Snapshot:
        env = context.env
        x = context.system.state(context.timestep)
        return cls(env.physics.snapshot(), context.step, env.task.episode, context.plan, context.age,
                   np.array(context.u_prev), x, context.timestep.observation)


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
