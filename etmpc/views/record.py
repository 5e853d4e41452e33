"""What a recording keeps of one episode: :class:`EpisodeRecord`, small and picklable, built on the
worker that played the episode and sent to the process that writes the file
(:class:`etmpc.views.recording.Recorder`)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from etmpc.common.numerics import norm
from etmpc.views.solves import plan_starts, seen_from


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
    work: np.ndarray  # (S,) the computation's priced work: 1 per solve, or its SQP iterations (compute levels)
    in_flight: np.ndarray  # (S,) bool: a solve was under way at the step's decision
    plans: list = field(default_factory=list)  # (step made for, states (N+1, nx), inputs (N, nu), forecasts {name: (N,)})
    arrivals: tuple = ()  # parallel to plans: the step each came into force
    starts: tuple = ()  # parallel to plans: the step each one's solve started (etmpc.views.solves.plan_starts)
    timed: bool = False  # the task has time in the loop: a latency or compute levels (etmpc.control.timing)
    signals: dict = field(default_factory=dict)  # name -> (>= S,)
    input_bounds: tuple = ()  # (u_min (nu,), u_max (nu,)), or () if the system has none
    announced: tuple = ()  # a self-trigger's (step a plan was made, steps it announced it would be kept)
    space: object = None  # the system's etmpc.systems.space.Space: a 3-D view of the episode (etmpc.views.space), or None

    @property
    def steps(self) -> int:
        return len(self.rewards)

    @classmethod
    def from_trajectory(cls, system, traj, identity: dict, episode, announce=None) -> EpisodeRecord:
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
            arrivals=tuple(int(a) for a in arrivals),
            starts=tuple(int(s) for s in _starts(traj, arrivals, shift)),
            timed=timed,
            space=getattr(system, "space", None),
        )


def _arrivals(traj) -> list[int]:
    """The step each plan came into force (a trajectory without arrivals: the step it was made for)."""
    return list(traj.arrivals) if len(traj.arrivals) == len(traj.plans) else [k for k, _ in traj.plans]


def _starts(traj, arrivals, shift: int) -> list[int]:
    """The step each plan's computation started: the loop's record of it (``Trajectory.starts``), or, for
    a trajectory without one, :func:`etmpc.views.solves.plan_starts`' inference."""
    if len(getattr(traj, "starts", ())) == len(traj.plans):
        return list(traj.starts)
    return list(plan_starts([k for k, _ in traj.plans], arrivals, traj.forced[: traj.steps], shift))


def prediction_errors(traj, error_weights, shift: int = 0) -> np.ndarray:
    """``‖W (x_i − x̂_i)‖`` per step, ``x̂_i`` from the plan in force before step i's decision (a late
    plan that arrived for step i included; ``shift``: as :func:`etmpc.views.solves.plan_starts`)."""
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
