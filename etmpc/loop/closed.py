"""The loop itself: :class:`ClosedLoop`, one control interval per step (see :mod:`etmpc.loop`); what plays
it, episode by episode, is in :mod:`etmpc.loop.play`."""

from __future__ import annotations

import time
from collections.abc import Mapping
from typing import Any

import dm_env
import numpy as np
from dm_control.rl.control import PhysicsError

from etmpc.common.checks import BadValue
from etmpc.common.frozen import frozen, readonly
from etmpc.control.plan import Plan
from etmpc.control.timing import ANSWERS, KEEP, SOLVE, level_of
from etmpc.loop.flight import Flight
from etmpc.loop.records import Trajectory, computation_cost
from etmpc.loop.sensed import Sensed
from etmpc.loop.state import AugmentedState, DecisionContext, Snapshot
from etmpc.systems.base import System

# The clock of the trajectory's timings: the CPU time of the thread that runs the loop (the solve, MuJoCo,
# the feedback and the policy all run in it), so a step played while other processes share the cores
# does not count the time it waited for a core. Their competition for caches and memory still slows it
# (measured in docs/scorecard.md): compare CPU figures played on an idle machine.
cpu_clock = time.thread_time


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
    """Algorithm 1, one control interval at a time: an episode in play, and its step. The only place
    a control interval is played.

    :func:`run_episode` drives it with a policy; ``etmpc.envs`` hands each decision to an agent
    instead; :func:`play_on` (the rollouts, the oracle, the self-trigger's labels) continues a
    :class:`Snapshot` in its light mode. All of them play :meth:`step`, so the numbers are the same,
    bit for bit.

    >>> loop = ClosedLoop(system, env).reset(episode)
    >>> while not loop.done:
    ...     s = loop.augmented_state()          # None when the decision is forced
    ...     loop.step(s is not None and my_rule(s))
    >>> loop.trajectory

    ``records=False`` is the light mode: the task and the physics are stepped directly, as
    ``control.Environment.step`` steps them, without a ``TimeStep`` (the state is read off the
    physics, ``system.measure``, and the task's observation is made only when a solve or a policy
    reads it), and nothing is recorded or timed (no :attr:`trajectory`). It starts from a snapshot
    (:meth:`resume`); a plant that fails sets :attr:`failed`.

    Time in the loop (:mod:`etmpc.control.timing`): on a task with a latency, a solve started at step
    ``k`` is :attr:`pending` until ``k + d``; the policy is not asked meanwhile (:attr:`in_flight`)
    and the plan comes into force with age ``d``. On a task with compute levels a decision is
    ``KEEP``, ``ITERATE`` or ``SOLVE`` (``True``/``False`` are a full solve/keep), and a recompute
    costs its SQP iterations.

    Sensing (:mod:`etmpc.control.sensing`): :attr:`x` is always the plant's state (recorded, rewarded,
    judged for failures); :attr:`seen` is what the controller reads of it: :attr:`x` itself with an exact
    sensor, else the filter's estimate (:attr:`belief`'s mean) after this step's reading. The MPC plans from
    :attr:`seen`, the feedback corrects from it, and the policy is shown it.
    """

    def __init__(self, system: System, env: dm_env.Environment, records: bool = True):
        self.system, self.env, self.records = system, env, records
        self.done, self.failed = True, False
        # the last step's: the task's reward, whether it computed, what (a level), its work and its price
        self.reward, self.recomputed, self.level, self.work, self.cost = 0.0, False, KEEP, 0, 0.0
        self.levels = system.compute_levels
        self.sensed = Sensed(system, env)  # what the controller reads of the state (etmpc.control.sensing)
        self.flight = Flight(system)  # the solve in flight (etmpc.control.timing): latency and compute levels

    def reset(self, episode: Any = None) -> ClosedLoop:
        """Start an episode: a stored one if given, else one drawn by the task."""
        if not self.records:
            raise RuntimeError("a light loop continues a snapshot: use resume()")
        system = self.system
        self.env.task.use_episode(episode)
        self.timestep = _shown(self.env.reset())
        self.x = readonly(system.state(self.timestep))
        nu = system.u_min.shape[0]
        self.trajectory = Trajectory.empty(system.episode_steps, self.x.shape[0], nu, sensing=not self.sensed.exact)
        self.plan: Plan | None = None
        self.age, self.u_prev, self.step_index, self.done, self.failed = 0, readonly(np.zeros(nu)), 0, False, False
        self.flight.restart()
        self.sensed.new_episode()
        self._sense(None)
        self._arrive()
        return self

    def resume(self, snapshot: Snapshot, episode: Any = None, start: np.ndarray | None = None) -> ClosedLoop:
        """Continue ``snapshot`` (of a twin environment) in the light mode, from ``episode`` and ``start`` if given."""
        if self.records:
            raise RuntimeError("only a light loop (records=False) resumes a snapshot")
        self.env.physics.restore(snapshot.physics)
        x, shown = snapshot.x, snapshot.observation
        if start is not None:  # the plant moved: its observation is made again when read
            x, shown = readonly(np.array(start, dtype=float)), None
            self.env.physics.set_state_vector(x)
            self.env.physics.forward()
        self.env.task.resume(snapshot.episode if episode is None else episode, snapshot.step)
        self.plan, self.age, self.u_prev, self.x = snapshot.plan, snapshot.age, snapshot.u_prev, x
        self.sensed.resume(snapshot.belief, snapshot.seen)
        self._observation, self.step_index, self.done, self.failed = shown, snapshot.step, False, False
        self.flight.restart(snapshot.pending, snapshot.plan is None)
        self.timestep = None
        return self

    @property
    def forced(self) -> bool:
        """The plan has run out (age = N; with a latency of ``d`` intervals, it would run out before a
        solve started now arrives: age >= N - d), or there is none yet: the loop must solve, whatever
        is asked. Never while a solve is in flight."""
        return self.flight.forced(self.plan, self.age)

    @property
    def in_flight(self) -> bool:
        """A solve is under way: its plan is not in force yet, and no other starts (the policy is not asked)."""
        return self.flight.pending is not None

    @property
    def pending(self) -> tuple[int, int, Plan, int] | None:
        """The solve in flight, ``(arrives at, made for, plan, started)``, or None (:class:`~etmpc.loop.flight.Flight`)."""
        return self.flight.pending

    @property
    def seen(self) -> np.ndarray:
        """What the controller reads of the state now: :attr:`x`, or the filter's estimate (:mod:`etmpc.loop.sensed`)."""
        return self.sensed.seen

    @property
    def belief(self) -> Any:
        """The filter's :class:`~etmpc.control.sensing.Belief` after this step's reading; None with an exact sensor."""
        return self.sensed.belief

    @property
    def observation(self) -> Mapping:
        """What the task shows now (frozen); in the light mode made when first read."""
        if self.records:
            return self.timestep.observation
        if self._observation is None:
            self._observation = frozen(self.env.task.get_observation(self.env.physics))
        return self._observation

    def augmented_state(self, context: bool = False, observes: bool = True) -> AugmentedState | None:
        """What a policy sees at this step's decision; ``None`` when the decision is forced. With
        ``context``, the loop's whole state too (for policies that simulate); without ``observes``,
        no observation (a policy that never reads it: the light mode then does not make it). Also
        ``None`` while a solve is in flight: the policy is not asked then."""
        return None if (self.forced or self.flight.pending is not None) else self.observed_state(context, observes)

    def observed_state(self, context: bool = False, observes: bool = True) -> AugmentedState | None:
        """The augmented state now, also when the decision is forced; ``None`` before the first plan."""
        if self.plan is None:
            return None
        plan, age = self.plan, self.age
        loop = (self.system, self.env, self.step_index, plan, age, self.u_prev, self.timestep, self.belief)
        ctx, shown = DecisionContext(*loop) if context else None, self.observation if observes else None
        return AugmentedState(self.seen, plan.states[0], age, plan.state_at(age), plan, shown, ctx, self.belief)

    def step(self, recompute: bool | int, started: float | None = None, solved: Plan | None = None) -> float:
        """Play this control interval: compute a new plan if ``recompute`` (or if forced; on a task
        with compute levels ``recompute`` is the level), apply the plan in force's input plus the LQR
        correction, clipped, and step the plant. Returns the policy's reward for it: the task's
        (:attr:`reward`) minus the price of the recompute started, if one was (:attr:`cost`). A plant that
        fails (non-finite), or a non-finite input, ends the episode; the step's reward is then 0. ``started``:
        when the step's decision began, on :data:`cpu_clock` (the step's time counts from there). ``solved``:
        the plan this step's recompute gives, when the caller has it already. While a solve is in flight the
        answer is ignored (recorded as :attr:`in_flight` in the trajectory)."""
        if self.done:
            raise RuntimeError("the episode is over: reset the loop")
        records = self.records
        start = (cpu_clock() if started is None else started) if records else 0.0
        system, i, x = self.system, self.step_index, self.seen
        in_flight = self.flight.pending is not None
        forced = self.forced
        level = SOLVE if forced else KEEP if in_flight else self._level(recompute)
        work = 0
        if level != KEEP:
            new = solved if solved is not None else self._compute(level, i)
            work = new.iterations if self.levels else 1  # its SQP iterations on a task with levels, else 1 per solve
            if self.flight.start(new, i, self.plan):  # no delay: in force now; else in flight
                self._deliver(new, i, forced)
        plan = self.plan
        feedback_start = cpu_clock() if records else 0.0
        u, u_planned, correction, x_predicted = _input(system, plan, self.age, x)
        if records:
            self.trajectory.feedback_time_s[i] = cpu_clock() - feedback_start
        recompute = level != KEEP
        reward = self._advance(system.action(u, recompute)) if np.isfinite(u).all() else None  # as a diverged plant
        self.recomputed, self.level, self.work = recompute, level, work
        self.cost = computation_cost(work, system.recompute_price)
        if reward is None:  # the plant failed
            self.failed = self.done = True
            if records:
                self.trajectory.nonfinite = True
            self.reward = 0.0
            return self.reward - self.cost
        self.reward = reward
        if records:
            traj = self.trajectory
            traj.recompute[i], traj.forced[i], traj.level[i], traj.work[i] = recompute, forced, level, work
            traj.in_flight[i] = in_flight
            traj.applied[i], traj.planned[i], traj.correction[i] = u, u_planned, correction
            traj.predicted[i], traj.plan_age[i] = x_predicted, self.age
            traj.rewards[i] = reward
            traj.steps = i + 1
        self.step_index = i + 1
        u.flags.writeable = False  # the loop's own new array (np.minimum's): shown as u_prev, never written again
        self.age, self.u_prev = self.age + 1, u
        restarted = self.env.task.restarted
        self._sense(None if restarted else u)
        if restarted:  # the task put the plant back: the plan (and one in flight) no longer applies
            self.age = plan.horizon
            self.flight.restart()
        else:
            landed = self.flight.arrives(self.step_index)
            if landed is not None:
                _, made, arrived, started = landed
                self._deliver(arrived, made, self.age >= plan.horizon, self.step_index, started)
        if records:
            self.trajectory.step_time_s[i] = cpu_clock() - start
            if self.timestep.last() or self.step_index >= system.episode_steps:
                self._finish()
            else:
                self._arrive()
        elif not np.isfinite(self.x).all():
            self.failed = self.done = True
        elif self.step_index >= system.episode_steps:
            self.done = True
        return reward - self.cost

    def _level(self, answer) -> int:
        """A decision as a compute level (:func:`~etmpc.control.timing.level_of`): on a task with levels,
        ``KEEP``/``ITERATE``/``SOLVE`` (a bool is keep or a full solve); elsewhere a bool, 0 or 1. Any other
        answer is refused, naming the task: read by its truth, 2 was a full solve on a keep-or-solve task."""
        level = level_of(answer, self.levels)
        if level is None:
            got = f"{type(answer).__name__} {answer!r}"
            raise BadValue(f"a decision is {ANSWERS[self.levels]} on task {self.system.name}, got {got}")
        return level

    def _deliver(self, new: Plan, made: int, expired: bool, now: int | None = None, started: int | None = None) -> None:
        """Put ``new`` (made for step ``made``, its recompute started at ``started``) in force now, unless
        it failed and the plan in force still has steps left (``expired``: it has none, or there is no plan)."""
        if new.success or expired or self.plan is None:
            now = made if now is None else now
            self.plan, self.age = new, now - made
            if self.records:
                self.trajectory.plans.append((made, new))
                self.trajectory.arrivals.append(now)
                self.trajectory.starts.append(made if started is None else started)

    def _compute(self, level: int, i: int) -> Plan:
        """A new plan from the state now (or, delay-compensated, from the state the kept plan predicts
        for when it will arrive): a full solve or one SQP iteration; timed and a failure counted when
        recording."""
        system, warm = self.system, self.plan
        x, u_prev, age = self.flight.solve_from(self.seen, self.u_prev, warm, self.age)
        solver = system.plan if level == SOLVE else system.iterate
        if not self.records:
            observation = self._observation
            if observation is None:
                observation = self.env.task.get_observation(self.env.physics)
            return solver(x, u_prev, warm, age, dm_env.TimeStep(dm_env.StepType.MID, None, None, observation))
        solve_start = cpu_clock()
        new = solver(x, u_prev, warm, age, self.timestep)
        self.trajectory.solve_time_s[i] = cpu_clock() - solve_start
        if not new.success:
            self.trajectory.solver_failures += 1
        return new

    def _sense(self, u: np.ndarray | None) -> None:
        """What the controller sees of the state now (:attr:`seen`, after the interval under ``u``; ``None``:
        the filter starts again); a reading is recorded with the estimate."""
        sensed = self.sensed
        if sensed.sense(self.x, u, self.step_index) and self.records:
            self.trajectory.measurements[self.step_index] = sensed.reading
            self.trajectory.estimates[self.step_index] = sensed.seen
            self.trajectory.nis[self.step_index] = sensed.belief.nis

    def _advance(self, action) -> float | None:
        """Step the plant over one control interval; the task's reward, or None if the plant failed."""
        if self.records:
            try:
                self.timestep = _shown(self.env.step(action))
            except PhysicsError:
                return None
            self.x = readonly(self.system.state(self.timestep))
            return self.timestep.reward
        task, physics = self.env.task, self.env.physics  # as control.Environment.step, without a TimeStep
        try:
            task.before_step(action, physics)
            physics.step(self.env._n_sub_steps)
        except PhysicsError:
            return None
        task.after_step(physics)
        reward = task.get_reward(physics)
        self._observation, self.x = None, readonly(self.system.measure(physics))
        return reward

    def _arrive(self) -> None:
        """At the start of a step: the state is recorded; a non-finite one ends the episode."""
        self.trajectory.states[self.step_index] = self.x
        if not np.all(np.isfinite(self.x)):
            self.trajectory.nonfinite, self.done, self.failed = True, True, True

    def _finish(self) -> None:
        self.trajectory.states[self.trajectory.steps] = self.x
        self.trajectory.nonfinite = self.failed = not bool(np.all(np.isfinite(self.x)))
        self.done = True
