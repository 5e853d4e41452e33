"""The loop itself: :class:`ClosedLoop`, one control interval per step (see :mod:`etmpc.loop`); what plays
it, episode by episode, is in :mod:`etmpc.loop.play`. Its collaborators: the solve in flight
(:mod:`etmpc.loop.flight`), what the controller sees (:mod:`etmpc.loop.sensed`), and the mode it plays in,
recording or light (:mod:`etmpc.loop.modes`)."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from functools import partial
from typing import Any

import dm_env
import numpy as np

from etmpc.common.checks import BadValue
from etmpc.common.frozen import readonly
from etmpc.control.plan import Plan
from etmpc.control.timing import ANSWERS, ITERATE, KEEP, SOLVE, iterations_of, level_of
from etmpc.loop.flight import Flight
from etmpc.loop.modes import LIGHT, RECORDING, Kept, cpu_clock
from etmpc.loop.records import computation_cost
from etmpc.loop.sensed import Sensed
from etmpc.loop.state import AugmentedState, Decision, DecisionContext, Snapshot
from etmpc.systems.base import System

__all__ = ["ClosedLoop", "cpu_clock"]  # cpu_clock: the clock of the trajectory's timings (etmpc.loop.modes)


def _input(system: System, plan: Plan, age: int, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(u, u_planned, correction, x_predicted)``: the plan's input plus the LQR correction, clipped."""
    u_planned = plan.input_at(age)
    x_predicted = plan.state_at(age)
    correction = np.zeros(u_planned.shape) if age == 0 else system.feedback.correction(x, x_predicted, plan, age)
    # np.minimum(np.maximum(.)) is np.clip's arithmetic without its Python-level overhead.
    return np.minimum(np.maximum(u_planned + correction, system.u_min), system.u_max), u_planned, correction, x_predicted


class ClosedLoop(Kept):
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

    ``records=False`` is the light mode (:data:`~etmpc.loop.modes.LIGHT`): the task and the physics are
    stepped directly, as ``control.Environment.step`` steps them, without a ``TimeStep`` (the state is read
    off the physics, ``system.measure``, and the task's observation is made only when a solve or a policy
    reads it), and nothing is recorded or timed (no :attr:`trajectory`). It starts from a snapshot
    (:meth:`resume`); a plant that fails sets :attr:`failed`. The mode is chosen once, here: :meth:`step`
    asks it (:class:`~etmpc.loop.modes.Mode`) what differs, and never branches on it.

    Time in the loop (:mod:`etmpc.control.timing`): on a task with a latency, a solve started at step
    ``k`` is :attr:`pending` until ``k + d``; the policy is not asked meanwhile (:attr:`in_flight`)
    and the plan comes into force with age ``d``. On a task with compute levels a decision is
    ``KEEP``, ``ITERATE`` or ``SOLVE`` (``True``/``False`` are a full solve/keep), and a recompute
    costs its SQP iterations. The solve in flight is :attr:`flight` (:mod:`etmpc.loop.flight`).

    Sensing (:mod:`etmpc.control.sensing`): :attr:`x` is always the plant's state (recorded, rewarded,
    judged for failures); :attr:`seen` is what the controller reads of it: :attr:`x` itself with an exact
    sensor, else the filter's estimate (:attr:`belief`'s mean) after this step's reading. The MPC plans from
    :attr:`seen`, the feedback corrects from it, and the policy is shown it (:attr:`sensed`, :mod:`etmpc.loop.sensed`).
    """

    def __init__(self, system: System, env: dm_env.Environment, records: bool = True):
        self.system = system
        self.env = env
        self.records = records
        self.mode = RECORDING if records else LIGHT  # chosen once: step asks it, never branches on it
        self.done = True
        self.failed = False
        # the last step's: the task's reward, whether it computed, what (a level), its work and its price
        self.reward = 0.0
        self.recomputed = False
        self.level = KEEP
        self.work = 0
        self.cost = 0.0
        self.levels = system.compute_levels
        self.sensed = Sensed(system, env)  # what the controller reads of the state (etmpc.control.sensing)
        self.flight = Flight(system)  # the solve in flight (etmpc.control.timing): latency and compute levels

    def reset(self, episode: Any = None) -> ClosedLoop:
        """Start an episode: a stored one if given, else one drawn by the task (a light loop refuses: it
        continues a snapshot)."""
        self.mode.start(self, episode)
        nu = self.system.u_min.shape[0]
        self._restart(None, 0, readonly(np.zeros(nu)), 0)
        self.flight.restart()
        self.sensed.new_episode()
        self._sense(None)
        self.mode.settle(self)
        return self

    def resume(self, snapshot: Snapshot, episode: Any = None, start: np.ndarray | None = None) -> ClosedLoop:
        """Continue ``snapshot`` (of a twin environment) in the light mode, from ``episode`` and ``start`` if given."""
        self.mode.resume(self, snapshot, episode, start)
        self._restart(snapshot.plan, snapshot.age, snapshot.u_prev, snapshot.step)
        self.sensed.resume(snapshot.belief, snapshot.seen)
        self.flight.restart(snapshot.pending, snapshot.plan is None)
        return self

    def _restart(self, plan: Plan | None, age: int, u_prev: np.ndarray, step: int) -> None:
        """The controller's memory at an episode's start or a snapshot's step: the plan in force, its age, the last input."""
        self.plan = plan
        self.age = age
        self.u_prev = u_prev
        self.step_index = step
        self.done = False
        self.failed = False

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
    def latency(self) -> Any:
        """The task's :class:`~etmpc.control.timing.Latency` (the solve in flight's, :attr:`flight`)."""
        return self.flight.latency

    @property
    def sensor(self) -> Any:
        """The task's sensor (:attr:`sensed`'s)."""
        return self.sensed.sensor

    @property
    def estimator(self) -> Any:
        """The task's filter, or None with an exact sensor (:attr:`sensed`'s)."""
        return self.sensed.estimator

    @property
    def seen(self) -> np.ndarray | None:
        """What the controller reads of the state now: :attr:`x`, or the filter's estimate (None before a reset)."""
        return self.sensed.seen

    @property
    def belief(self) -> Any:
        """The filter's :class:`~etmpc.control.sensing.Belief` after this step's reading; None with an exact sensor."""
        return self.sensed.belief

    @property
    def observation(self) -> Mapping:
        """What the task shows now (frozen); in the light mode made when first read."""
        return self.mode.observation(self)

    def augmented_state(self, context: bool = False, observes: bool = True) -> AugmentedState | None:
        """What a policy sees at this step's decision; ``None`` when the decision is forced. With
        ``context``, the loop's whole state too (for policies that simulate); without ``observes``,
        no observation (a policy that never reads it: the light mode then does not make it). Also
        ``None`` while a solve is in flight: the policy is not asked then."""
        if self.flight.forced(self.plan, self.age) or self.flight.pending is not None:
            return None
        return self.observed_state(context, observes)

    def observed_state(self, context: bool = False, observes: bool = True) -> AugmentedState | None:
        """The augmented state now, also when the decision is forced; ``None`` before the first plan."""
        if self.plan is None:
            return None
        plan = self.plan
        age = self.age
        belief = self.sensed.belief
        seen = self.sensed.seen
        assert seen is not None  # read at the episode's start (reset, resume), as the plan was made
        loop = (self.system, self.env, self.step_index, plan, age, self.u_prev, self.timestep, belief)
        ctx = DecisionContext(*loop) if context else None
        shown = self.observation if observes else None
        return AugmentedState(seen, plan.states[0], age, plan.state_at(age), plan, shown, ctx, belief)

    def step(self, recompute: Decision, started: float | None = None, solved: Plan | None = None) -> float:
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
        mode = self.mode
        start = mode.tick() if started is None else started  # the step's time counts from here (when recording)
        i = self.step_index
        # decide: forced (the plan runs out), none while a solve is in flight, else the policy's answer
        in_flight = self.flight.pending is not None
        forced = self.flight.forced(self.plan, self.age)
        level = SOLVE if forced else KEEP if in_flight else self._level(recompute)
        # maybe solve: in force now, or in flight until its delay is over
        work = 0 if level == KEEP else self._recompute(level, i, forced, solved, recompute)
        # feedback: the plan in force's input plus the LQR correction, clipped
        plan = self.plan
        seen = self.sensed.seen
        assert plan is not None and seen is not None  # the episode's first decision is forced: a plan is in force
        feedback_start = mode.tick()
        u, u_planned, correction, x_predicted = _input(self.system, plan, self.age, seen)
        mode.fed(self, i, feedback_start)
        # advance the plant (a non-finite input as a diverged plant)
        recomputed = level != KEEP
        reward = mode.advance(self, self.system.action(u, recomputed)) if np.isfinite(u).all() else None
        # bookkeeping
        self.recomputed = recomputed
        self.level = level
        self.work = work
        self.cost = computation_cost(work, self.system.recompute_price)
        if reward is None:  # the plant failed
            self.failed = True
            self.done = True
            mode.failed(self)
            self.reward = 0.0
            return self.reward - self.cost
        self.reward = reward
        mode.played(self, i, forced, in_flight, u, u_planned, correction, x_predicted)
        self._move_on(i, u, plan)
        mode.ended(self, i, start)
        return reward - self.cost

    def _recompute(self, level: int, i: int, forced: bool, solved: Plan | None, answer: Decision) -> int:
        """Start step ``i``'s recompute at ``level`` (its plan ``solved`` if the caller has it; ``answer``: the
        policy's, which says how many SQP iterations an ``ITERATE`` may make); its work."""
        limit = iterations_of(answer) if level == ITERATE else 1
        new = solved if solved is not None else self._compute(level, i, limit)
        if self.flight.start(new, i, self.plan):  # no delay: in force now; else in flight
            self._deliver(new, i, forced)
        return new.iterations if self.levels else 1  # its SQP iterations on a task with levels, else 1 per solve

    def _move_on(self, i: int, u: np.ndarray, plan: Plan) -> None:
        """After step ``i`` under ``plan``: the plan ages, ``u`` is the last input, the state is seen again, and
        a solve in flight that arrives now comes into force (a plant the task put back drops the plan)."""
        self.step_index = i + 1
        u.flags.writeable = False  # the loop's own new array (np.minimum's): shown as u_prev, never written again
        self.age = self.age + 1
        self.u_prev = u
        restarted = self.env.task.restarted
        self._sense(None if restarted else u)
        if restarted:  # the task put the plant back: the plan (and one in flight) no longer applies
            self.age = plan.horizon
            self.flight.restart()
            return
        landed = self.flight.arrives(self.step_index)
        if landed is not None:
            _, made, arrived, started = landed
            self._deliver(arrived, made, self.age >= plan.horizon, self.step_index, started)

    def _level(self, answer: Decision) -> int:
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
            self.plan = new
            self.age = now - made
            self.mode.delivered(self, made, new, now, made if started is None else started)

    def _compute(self, level: int, i: int, limit: int = 1) -> Plan:
        """A new plan from the state now (or, delay-compensated, from the state the kept plan predicts
        for when it will arrive): a full solve or at most ``limit`` SQP iterations (one: a real-time
        iteration); timed and a failure counted when recording."""
        warm = self.plan
        seen = self.sensed.seen
        assert seen is not None  # read at the episode's start (reset, resume)
        x, u_prev, age = self.flight.solve_from(seen, self.u_prev, warm, self.age)
        solver: Callable[..., Plan]
        if level == SOLVE:
            solver = self.system.plan
        else:
            iterate = self.system.iterate
            assert iterate is not None  # ITERATE is a level only on a task with compute levels, which offers iterate
            solver = iterate if limit == 1 else partial(iterate, limit=limit)  # an older task's iterate may take no limit
        return self.mode.solve(self, solver, x, u_prev, warm, age, i)

    def _sense(self, u: np.ndarray | None) -> None:
        """What the controller sees of the state now (:attr:`seen`, after the interval under ``u``; ``None``:
        the filter starts again); a reading is recorded with the estimate."""
        sensed = self.sensed
        if sensed.sense(self.x, u, self.step_index):
            self.mode.sensed(self, sensed)
