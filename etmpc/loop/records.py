"""What one episode did (:class:`Trajectory`), what one continued play did (:class:`Continuation`), and
what a recording keeps of one episode (:class:`EpisodeRecord`: small and picklable, built on the worker
that played the episode and sent to the process that writes the file, such as
:class:`etmpc.views.recording.Recorder`), with the step each plan's solve started (:func:`plan_starts`)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, is_dataclass
from typing import Any, Protocol, runtime_checkable

import numpy as np

from etmpc.common.numerics import norm
from etmpc.control.plan import Plan
from etmpc.systems.base import System
from etmpc.systems.options import of as task_options
from etmpc.systems.options import shown
from etmpc.systems.space import Space


def computation_cost(computations, price: float):
    """The price of ``computations`` (a count, a flag, or an array of either, elementwise) at ``price``
    each: the one place etmpc prices a recompute. A policy's reward is the task's minus this."""
    return price * computations


# -- what one episode did --------------------------------------------------------------------------
@dataclass
class Trajectory:
    """Everything one episode did, step by step (arrays preallocated for the full episode)."""

    states: np.ndarray  # (T + 1, nx) the plant's state; rows past `steps` stay NaN
    applied: np.ndarray  # (T, nu) input sent to the plant
    planned: np.ndarray  # (T, nu) the plan's input for that step
    correction: np.ndarray  # (T, nu) LQR correction before clipping
    predicted: np.ndarray  # (T, nx) the plan's prediction x_hat_i
    plan_age: np.ndarray  # (T,) i - k at the decision
    recompute: np.ndarray  # (T,) a_i: a recompute was started (includes forced ones)
    forced: np.ndarray  # (T,) the plan had run out (or there was none)
    level: np.ndarray  # (T,) what was computed: 0 keep, 1 one SQP iteration, 2 a full solve (etmpc.control.timing)
    work: np.ndarray  # (T,) the recompute's priced work: 1 per solve, or its SQP iterations on a task with levels
    in_flight: np.ndarray  # (T,) a solve was under way at the decision: the policy was not asked
    rewards: np.ndarray  # (T,) the environment's reward for the step
    # The timings are CPU seconds of the loop's thread (etmpc.loop.closed.cpu_clock), not wall time.
    solve_time_s: np.ndarray  # (T,) CPU time of the MPC's solve (NaN where none happened)
    step_time_s: np.ndarray  # (T,) CPU time of the whole step, solve included
    feedback_time_s: np.ndarray  # (T,) CPU time of the input: the plan's, plus the LQR correction, clipped
    decide_time_s: np.ndarray  # (T,) CPU time of the policy's decision (0 where the loop did not ask it)
    plans: list[tuple[int, Plan]] = field(default_factory=list)  # (step made for, plan), successful or used
    arrivals: list[int] = field(default_factory=list)  # the step each of plans came into force (its made step + latency)
    starts: list[int] = field(default_factory=list)  # the step each of plans' recompute started (its made step, or earlier)
    # with a sensor that is not exact (etmpc.control.sensing): its reading per step (NaN where nothing was read)
    # and the filter's estimate, beside the plant's states; None with an exact sensor
    measurements: np.ndarray | None = None
    estimates: np.ndarray | None = None
    nis: np.ndarray | None = None  # (T + 1,) the reading's normalised innovation squared (0 where nothing was read)
    steps: int = 0
    solver_failures: int = 0
    nonfinite: bool = False  # the episode ended early on a non-finite state or input

    @classmethod
    def empty(cls, steps: int, nx: int, nu: int, sensing: bool = False) -> Trajectory:
        nan = lambda *shape: np.full(shape, np.nan)  # noqa: E731
        return cls(
            states=nan(steps + 1, nx),
            applied=nan(steps, nu),
            planned=nan(steps, nu),
            correction=nan(steps, nu),
            predicted=nan(steps, nx),
            plan_age=np.zeros(steps, int),
            recompute=np.zeros(steps, bool),
            forced=np.zeros(steps, bool),
            level=np.zeros(steps, np.int8),
            work=np.zeros(steps),
            in_flight=np.zeros(steps, bool),
            rewards=np.zeros(steps),
            solve_time_s=nan(steps),
            step_time_s=nan(steps),
            feedback_time_s=np.zeros(steps),
            decide_time_s=np.zeros(steps),
            measurements=nan(steps + 1, nx) if sensing else None,
            estimates=nan(steps + 1, nx) if sensing else None,
            nis=nan(steps + 1) if sensing else None,
        )

    def cpu_seconds(self) -> dict[str, float]:
        """The controller's CPU time in this episode, summed over its steps (the loop thread's: a
        machine-dependent figure, which other processes sharing the cores inflate less than wall time, but still
        inflate: compare figures played on an idle machine): the MPC's
        ``solve``s, the ``feedback`` (the LQR), the policy's ``decide``s (a rollout's simulations included)."""
        n = self.steps
        return {
            "solve": float(np.nansum(self.solve_time_s[:n])),
            "feedback": float(self.feedback_time_s[:n].sum()),
            "decide": float(self.decide_time_s[:n].sum()),
        }

    @property
    def recomputes(self) -> int:
        return int(self.recompute[: self.steps].sum())

    @property
    def total_work(self) -> float:
        """The work priced over the episode: the recomputes, or their SQP iterations on a task with levels."""
        return float(self.work[: self.steps].sum())

    def policy_rewards(self, recompute_price: float) -> np.ndarray:
        """Per-step rewards the policy maximises: the environment's, minus the price of each recompute's work."""
        return self.rewards[: self.steps] - computation_cost(self.work[: self.steps], recompute_price)

    def policy_return(self, recompute_price: float) -> float:
        """The policy's return: rewards minus the price of every recompute's work."""
        return float(self.rewards[: self.steps].sum() - computation_cost(self.total_work, recompute_price))


@dataclass(eq=False)
class Continuation:
    """What one :func:`play_on` did, step by step, for a caller that picks it up again later (the
    oracle's memo): what each step added to the return, whether it computed, and the controller's
    state after it (``x``, the plan, its age, ``u_prev``). Summed from 0.0 in order, ``added[k:]``
    gives exactly what a play on from the state after step ``k - 1`` returns."""

    start: int  # the step it started at
    added: list[float] = field(default_factory=list)
    recomputed: list[bool] = field(default_factory=list)
    levels: list[int] = field(default_factory=list)  # what each step computed, on a task with compute levels
    after: list[tuple] = field(default_factory=list)

    def return_from(self, k: int) -> float:
        """The return from its ``k``-th step on, summed as :func:`play_on` sums it."""
        total = 0.0
        for added in self.added[k:]:
            total += added
        return total


# -- what a recording keeps of one episode ------------------------------------------------------------
def plan_starts(made, arrivals, forced, shift: int = 0) -> np.ndarray:
    """The step each plan's solve started at, from the step it was made for (``made``), the step it came
    into force (``arrivals``) and the forced steps. ``shift``: the latency's intervals if the
    controller compensates the delay, else 0."""
    made = np.asarray(made, dtype=np.int64)
    if shift == 0 or len(made) == 0:
        return made.copy()
    arrivals, forced = np.asarray(arrivals, dtype=np.int64), np.asarray(forced, bool)
    at = np.minimum(made, len(forced) - 1)
    instant = (arrivals == made) & (made < len(forced)) & forced[at]  # made before the interval
    return np.where(instant, made, made - shift)


def seen_from(starts, arrivals) -> np.ndarray:
    """The first step whose decision sees each plan: a late plan arrives before the decision of its
    arrival step, one made at the decision (no latency) is seen from the next step on."""
    starts, arrivals = np.asarray(starts, dtype=np.int64), np.asarray(arrivals, dtype=np.int64)
    return arrivals + (starts == arrivals)


@dataclass(frozen=True, eq=False)
class EpisodeRecord:
    """What a recording keeps of one episode: small, picklable, built on the worker that ran it."""

    identity: dict
    state_names: tuple[str, ...]
    input_names: tuple[str, ...]
    error_weights: np.ndarray
    states: np.ndarray  # (S + 1, nx)
    planned: np.ndarray  # (S, nu)
    correction: np.ndarray  # (S, nu)
    applied: np.ndarray  # (S, nu)
    recompute: np.ndarray  # (S,) bool
    forced: np.ndarray  # (S,) bool
    rewards: np.ndarray  # (S,)
    prediction_error: np.ndarray  # (S,), NaN at step 0
    level: np.ndarray  # (S,) int8: what was computed, 0 keep, 1 one SQP iteration, 2 a full solve
    work: np.ndarray  # (S,) the recompute's priced work: 1 per solve, or its SQP iterations (compute levels)
    in_flight: np.ndarray  # (S,) bool: a solve was under way at the step's decision
    plans: list = field(default_factory=list)  # (step made for, states (N+1, nx), inputs (N, nu), forecasts {name: (N,)})
    arrivals: tuple = ()  # parallel to plans: the step each came into force
    starts: tuple = ()  # parallel to plans: the step each one's solve started (plan_starts)
    timed: bool = False  # the task has time in the loop: a latency or compute levels (etmpc.control.timing)
    signals: dict = field(default_factory=dict)  # name -> (>= S,)
    input_bounds: tuple = ()  # (u_min (nu,), u_max (nu,)), or () if the system has none
    announced: tuple = ()  # a self-trigger's (step a plan was made, steps it announced it would be kept)
    space: Space | None = None  # the system's 3-D view of the episode (etmpc.views.space), or None
    # with a sensor that is not exact: its readings (NaN where none) and the filter's estimates, (S + 1, nx) each
    measurements: np.ndarray | None = None
    estimates: np.ndarray | None = None

    @property
    def steps(self) -> int:
        return len(self.rewards)

    @classmethod
    def from_trajectory(
        cls, system: System, traj: Trajectory, identity: dict, episode: Any, announce: Callable[[Plan], int] | None = None
    ) -> EpisodeRecord:
        """``announce``: a self-triggering policy's ``announce(plan)``, to record what it announced
        at each solve (it is a function of the plan alone, so asking again gives the same answer)."""
        n = traj.steps
        bounds = (np.asarray(system.u_min, float), np.asarray(system.u_max, float))
        latency, levels = system.latency, bool(system.compute_levels)
        timed = levels or not latency.instant
        shift = latency.intervals if latency.compensate else 0
        arrivals = _arrivals(traj)
        # Only a task with time in the loop says so: the paper's tasks keep the identity they had.
        timing = dict(latency=latency.describe(), compute_levels=levels) if timed else {}
        # and only a task played with options (etmpc.systems.options) says which: the others' identity stays as it was
        options = task_options(system.config) if hasattr(system, "config") and is_dataclass(system.config) else {}
        if options:
            timing["options"] = shown(tuple(options.items()))
        return cls(
            identity=dict(
                identity,
                domain=system.domain,
                task=system.task,
                objective_sense=system.objective_sense,
                recompute_price=float(system.recompute_price),
                control_interval_s=float(system.control_interval_s),
                **timing,
            ),
            state_names=tuple(system.state_names),
            input_names=tuple(system.input_names),
            error_weights=np.asarray(system.error_weights, float),
            states=traj.states[: n + 1].copy(),
            planned=traj.planned[:n].copy(),
            correction=traj.correction[:n].copy(),
            applied=traj.applied[:n].copy(),
            recompute=traj.recompute[:n].copy(),
            forced=traj.forced[:n].copy(),
            rewards=traj.rewards[:n].copy(),
            prediction_error=prediction_errors(traj, system.error_weights, shift),
            level=traj.level[:n].copy(),
            work=traj.work[:n].astype(float),
            in_flight=traj.in_flight[:n].copy(),
            plans=[(k, p.states, p.inputs, {name: np.asarray(v) for name, v in p.forecasts.items()}) for k, p in traj.plans],
            signals={name: np.asarray(v, float) for name, v in system.signals(episode).items()},
            input_bounds=bounds if np.all(np.isfinite(bounds)) else (),  # none drawn for an unbounded input
            announced=tuple((int(k), int(announce(p))) for k, p in traj.plans) if announce is not None else (),
            measurements=None if traj.measurements is None else traj.measurements[: n + 1].copy(),
            estimates=None if traj.estimates is None else traj.estimates[: n + 1].copy(),
            arrivals=tuple(int(a) for a in arrivals),
            starts=tuple(int(s) for s in _starts(traj, arrivals, shift)),
            timed=timed,
            space=system.space,
        )


def _arrivals(traj) -> list[int]:
    """The step each plan came into force (a trajectory without arrivals: the step it was made for)."""
    return list(traj.arrivals) if len(traj.arrivals) == len(traj.plans) else [k for k, _ in traj.plans]


def _starts(traj, arrivals, shift: int) -> list[int]:
    """The step each plan's recompute started: the loop's record of it (``Trajectory.starts``), or, for
    a trajectory without one, :func:`plan_starts`' inference."""
    if len(getattr(traj, "starts", ())) == len(traj.plans):
        return list(traj.starts)
    return list(plan_starts([k for k, _ in traj.plans], arrivals, traj.forced[: traj.steps], shift))


def prediction_errors(traj, error_weights, shift: int = 0) -> np.ndarray:
    """``‖W (x_i − x̂_i)‖`` per step, ``x̂_i`` from the plan in force before step i's decision (a late
    plan that arrived for step i included; ``shift``: as :func:`plan_starts`)."""
    errors = np.full(traj.steps, np.nan)
    arrivals = _arrivals(traj)
    seen = seen_from(_starts(traj, arrivals, shift), arrivals)
    plans = iter(zip(seen, traj.plans))
    current, upcoming = None, next(plans, None)
    w = np.asarray(error_weights, float)
    for i in range(traj.steps):
        while upcoming is not None and upcoming[0] <= i:  # the plans the decision of step i sees
            current, upcoming = upcoming[1], next(plans, None)
        if current is not None:
            k, plan = current
            errors[i] = norm(w * (traj.states[i] - plan.state_at(i - k)))  # the threshold policy's measure
    return errors


@runtime_checkable
class EpisodeSink(Protocol):
    """What receives the episodes a run records: a recording being written (a Rerun file or a live viewer,
    :class:`etmpc.views.recording.Recorder`). Evaluation and learning are given what opens one at a path,
    a ``Callable[[Path], EpisodeSink]`` (``recorder=``), or one already open (``evaluate(record=...)``), and
    know nothing of what it draws."""

    def log_episode(self, record: EpisodeRecord) -> object:
        """Write one episode."""

    def close(self, keep: bool = True) -> None:
        """Finish the file (``keep``), or remove what was written of it."""

    def __enter__(self) -> EpisodeSink: ...

    def __exit__(self, exc_type, *exc) -> None:
        """Close it, keeping the file only if nothing was raised."""
