"""The two ways :class:`~etmpc.loop.closed.ClosedLoop` plays a step, as two strategies with one interface
(:class:`Mode`), chosen once when the loop is made:

* :data:`RECORDING` steps the ``dm_env`` interface (a ``TimeStep`` per step) and keeps everything: the
  episode's :class:`~etmpc.loop.records.Trajectory`, its plans, readings and CPU times (:data:`cpu_clock`).
  It starts an episode (:meth:`~etmpc.loop.closed.ClosedLoop.reset`).
* :data:`LIGHT` steps the task and the physics directly, as ``control.Environment.step`` steps them,
  makes the task's observation only when a solve or a policy reads it, and keeps and times nothing: the
  hot path of the rollouts and the oracle. It continues a :class:`~etmpc.loop.state.Snapshot`
  (:meth:`~etmpc.loop.closed.ClosedLoop.resume`).

Both play the same arithmetic, so their numbers are the same, bit for bit. A mode keeps no state of its
own: what it keeps (the trajectory, the ``TimeStep``, the observation made) is the loop's, handed in.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from typing import Any, Protocol

import dm_env
import numpy as np
from dm_control.rl.control import PhysicsError

from etmpc.common.frozen import frozen, readonly
from etmpc.control.plan import Plan
from etmpc.loop.records import Trajectory
from etmpc.loop.sensed import Sensed
from etmpc.loop.state import Snapshot

# The clock of the trajectory's timings: the CPU time of the thread that runs the loop (the solve, MuJoCo,
# the feedback and the policy all run in it), so a step played while other processes share the cores
# does not count the time it waited for a core. Their competition for caches and memory still slows it
# (measured in docs/scorecard.md): compare CPU figures played on an idle machine.
cpu_clock = time.thread_time


def _shown(timestep: dm_env.TimeStep) -> dm_env.TimeStep:
    """The step with its observation frozen: the loop shows it to policies, and they cannot write into it."""
    return dm_env.TimeStep(timestep.step_type, timestep.reward, timestep.discount, frozen(timestep.observation))


class Kept:
    """What a mode sets on the loop it plays (:class:`~etmpc.loop.closed.ClosedLoop` is one), at an episode's
    start, a snapshot's resume and every step: the loop keeps it, the mode writes it."""

    x: np.ndarray  # the plant's state now
    timestep: dm_env.TimeStep | None  # the recording mode's last TimeStep; None in the light mode
    trajectory: Trajectory  # the recording mode's record of the episode (a light loop keeps none)
    _observation: Mapping | None  # the light mode's observation now, made when first read (None: not yet)


class Mode(Protocol):
    """What the loop asks of a mode; ``loop`` is the :class:`~etmpc.loop.closed.ClosedLoop` in play."""

    def start(self, loop: Any, episode: Any) -> None:
        """The plant at an episode's start: ``loop.x``, what the task shows, and what is kept."""

    def resume(self, loop: Any, snapshot: Snapshot, episode: Any, start: np.ndarray | None) -> None:
        """The plant of ``snapshot`` (its state ``start`` if given), on ``episode`` if given."""

    def observation(self, loop: Any) -> Mapping:
        """What the task shows now, frozen."""

    def tick(self) -> float:
        """The clock now, where the mode times the step."""

    def solve(self, loop: Any, solver: Any, x: np.ndarray, u_prev: np.ndarray, warm: Plan | None, age: int, i: int) -> Plan:
        """``solver``'s plan from ``x`` (a full solve or one SQP iteration), shown what the task shows."""

    def fed(self, loop: Any, i: int, since: float) -> None:
        """Step ``i``'s input (the plan's plus the feedback) took from ``since`` until now."""

    def advance(self, loop: Any, action: Any) -> float | None:
        """Step the plant over one control interval: the task's reward, or None if the plant failed."""

    def delivered(self, loop: Any, made: int, plan: Plan, now: int, started: int) -> None:
        """``plan``, made for step ``made`` by a recompute started at ``started``, came into force at ``now``."""

    def sensed(self, loop: Any, sensed: Sensed) -> None:
        """The sensor read the state at this step and the filter estimated it."""

    def played(self, loop: Any, i: int, forced: bool, in_flight: bool, u, u_planned, correction, x_predicted) -> None:
        """Step ``i`` was played (before the loop moves on): what it applied, and why."""

    def failed(self, loop: Any) -> None:
        """The plant failed in this step (or its input was not finite): the episode ends."""

    def ended(self, loop: Any, i: int, start: float) -> None:
        """The step ``i``, begun at ``start``, is over: whether the episode ends (see :meth:`settle`)."""

    def settle(self, loop: Any) -> None:
        """At an episode's start (after :meth:`start` and the first reading): a non-finite state ends it."""


class Recording:
    """Steps the ``dm_env`` interface and keeps (:attr:`ClosedLoop.trajectory`) and times everything."""

    def start(self, loop, episode) -> None:
        system = loop.system
        loop.env.task.use_episode(episode)
        loop.timestep = _shown(loop.env.reset())
        loop.x = readonly(system.state(loop.timestep))
        nu = system.u_min.shape[0]
        loop.trajectory = Trajectory.empty(system.episode_steps, loop.x.shape[0], nu, sensing=not loop.sensed.exact)

    def resume(self, loop, snapshot, episode, start) -> None:
        raise RuntimeError("only a light loop (records=False) resumes a snapshot")

    def observation(self, loop) -> Mapping:
        return loop.timestep.observation

    def tick(self) -> float:
        return cpu_clock()

    def solve(self, loop, solver, x, u_prev, warm, age, i) -> Plan:
        """Timed, and a failure counted."""
        solve_start = cpu_clock()
        new = solver(x, u_prev, warm, age, loop.timestep)
        loop.trajectory.solve_time_s[i] = cpu_clock() - solve_start
        if not new.success:
            loop.trajectory.solver_failures += 1
        return new

    def fed(self, loop, i, since) -> None:
        loop.trajectory.feedback_time_s[i] = cpu_clock() - since

    def advance(self, loop, action) -> float | None:
        try:
            loop.timestep = _shown(loop.env.step(action))
        except PhysicsError:
            return None
        loop.x = readonly(loop.system.state(loop.timestep))
        return loop.timestep.reward

    def delivered(self, loop, made, plan, now, started) -> None:
        loop.trajectory.plans.append((made, plan))
        loop.trajectory.arrivals.append(now)
        loop.trajectory.starts.append(started)

    def sensed(self, loop, sensed) -> None:
        traj = loop.trajectory
        i = loop.step_index
        traj.measurements[i] = sensed.reading
        traj.estimates[i] = sensed.seen
        traj.nis[i] = sensed.belief.nis

    def played(self, loop, i, forced, in_flight, u, u_planned, correction, x_predicted) -> None:
        traj = loop.trajectory
        traj.recompute[i] = loop.recomputed
        traj.forced[i] = forced
        traj.level[i] = loop.level
        traj.work[i] = loop.work
        traj.in_flight[i] = in_flight
        traj.applied[i] = u
        traj.planned[i] = u_planned
        traj.correction[i] = correction
        traj.predicted[i] = x_predicted
        traj.plan_age[i] = loop.age
        traj.rewards[i] = loop.reward
        traj.steps = i + 1

    def failed(self, loop) -> None:
        loop.trajectory.nonfinite = True

    def ended(self, loop, i, start) -> None:
        loop.trajectory.step_time_s[i] = cpu_clock() - start
        self.settle(loop)

    def settle(self, loop) -> None:
        """The state is recorded; a non-finite one, or the episode's last step, ends the episode."""
        traj = loop.trajectory
        if loop.timestep.last() or loop.step_index >= loop.system.episode_steps:
            traj.states[traj.steps] = loop.x
            nonfinite = not bool(np.all(np.isfinite(loop.x)))
            traj.nonfinite = nonfinite
            loop.failed = nonfinite
            loop.done = True
            return
        traj.states[loop.step_index] = loop.x
        if not np.all(np.isfinite(loop.x)):
            traj.nonfinite = True
            loop.done = True
            loop.failed = True


class Light:
    """Steps the task and the physics directly, makes the observation when read, keeps and times nothing."""

    def start(self, loop, episode) -> None:
        raise RuntimeError("a light loop continues a snapshot: use resume()")

    def resume(self, loop, snapshot, episode, start) -> None:
        physics = loop.env.physics
        physics.restore(snapshot.physics)
        if start is None:
            loop.x = snapshot.x
            loop._observation = snapshot.observation
        else:  # the plant moved: its observation is made again when read
            loop.x = readonly(np.array(start, dtype=float))
            loop._observation = None
            physics.set_state_vector(loop.x)
            physics.forward()
        loop.env.task.resume(snapshot.episode if episode is None else episode, snapshot.step)
        loop.timestep = None

    def observation(self, loop) -> Mapping:
        if loop._observation is None:
            loop._observation = frozen(loop.env.task.get_observation(loop.env.physics))
        return loop._observation

    def tick(self) -> float:
        return 0.0

    def solve(self, loop, solver, x, u_prev, warm, age, i) -> Plan:
        """Shown the observation made, or one made for it (not kept: a policy may never read it)."""
        observation = loop._observation
        if observation is None:
            observation = loop.env.task.get_observation(loop.env.physics)
        return solver(x, u_prev, warm, age, dm_env.TimeStep(dm_env.StepType.MID, None, None, observation))

    def fed(self, loop, i, since) -> None:
        pass

    def advance(self, loop, action) -> float | None:
        """As ``control.Environment.step``, without a ``TimeStep``; the state read off the physics."""
        env = loop.env
        task = env.task
        physics = env.physics
        try:
            task.before_step(action, physics)
            physics.step(env._n_sub_steps)
        except PhysicsError:
            return None
        task.after_step(physics)
        reward = task.get_reward(physics)
        loop._observation = None
        loop.x = readonly(loop.system.measure(physics))
        return reward

    def delivered(self, loop, made, plan, now, started) -> None:
        pass

    def sensed(self, loop, sensed) -> None:
        pass

    def played(self, loop, i, forced, in_flight, u, u_planned, correction, x_predicted) -> None:
        pass

    def failed(self, loop) -> None:
        pass

    def ended(self, loop, i, start) -> None:
        """A non-finite state, or the episode's end, ends the episode."""
        if not np.isfinite(loop.x).all():
            loop.failed = True
            loop.done = True
        elif loop.step_index >= loop.system.episode_steps:
            loop.done = True

    def settle(self, loop) -> None:
        self.ended(loop, loop.step_index, 0.0)


RECORDING: Mode = Recording()
LIGHT: Mode = Light()
