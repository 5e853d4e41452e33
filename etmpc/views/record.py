"""What a recording keeps of one episode: :class:`EpisodeRecord`, small and picklable, built on the
worker that played the episode and sent to the process that writes the file
(:class:`etmpc.views.recording.Recorder`)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from etmpc.common.numerics import norm


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
    plans: list = field(default_factory=list)  # (step, states (N+1, nx), inputs (N, nu), forecasts {name: (N,)})
    signals: dict = field(default_factory=dict)  # name -> (>= S,)
    input_bounds: tuple = ()  # (u_min (nu,), u_max (nu,)), or () if the system has none
    announced: tuple = ()  # a self-trigger's (step a plan was made, steps it announced it would be kept)

    @property
    def steps(self) -> int:
        return len(self.rewards)

    @classmethod
    def from_trajectory(cls, system, traj, identity: dict, episode, announce=None) -> EpisodeRecord:
        """``announce``: a self-triggering policy's ``announce(plan)``, to record what it announced
        at each solve (it is a function of the plan alone, so asking again gives the same answer)."""
        n = traj.steps
        bounds = (np.asarray(system.u_min, float), np.asarray(system.u_max, float))
        return cls(
            identity=dict(
                identity,
                domain=system.domain,
                task=system.task,
                objective_sense=system.objective_sense,
                recompute_price=float(system.recompute_price),
                control_interval_s=float(system.control_interval_s),
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
            prediction_error=prediction_errors(traj, system.error_weights),
            plans=[(k, p.states, p.inputs, {name: np.asarray(v) for name, v in p.forecasts.items()}) for k, p in traj.plans],
            signals={name: np.asarray(v, float) for name, v in system.signals(episode).items()},
            input_bounds=bounds if np.all(np.isfinite(bounds)) else (),  # none drawn for an unbounded input
            announced=tuple((int(k), int(announce(p))) for k, p in traj.plans) if announce is not None else (),
        )


def prediction_errors(traj, error_weights) -> np.ndarray:
    """``‖W (x_i − x̂_i)‖`` per step, ``x̂_i`` from the plan in force before step i's decision."""
    errors = np.full(traj.steps, np.nan)
    plans = iter(traj.plans)
    current, upcoming = None, next(plans, None)
    w = np.asarray(error_weights, float)
    for i in range(traj.steps):
        if current is not None:
            k, plan = current
            errors[i] = norm(w * (traj.states[i] - plan.state_at(i - k)))  # the threshold policy's measure
        while upcoming is not None and upcoming[0] <= i:  # a plan made at step i is in force from i on
            current, upcoming = upcoming, next(plans, None)
    return errors
