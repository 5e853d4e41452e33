"""The base of a task whose MPC tracks what it observes: a least-squares OCP (:class:`GaussNewtonMPC`)
whose parameters (a reference, a target) are read off each observation, and a time-varying LQR along
each plan while it is kept (:class:`PlanFeedback`). The kicks task and the reacher are two; a task
writes its residuals, its feedback weights and the names of what it tracks, and gets the rest:

* ``plan``: the OCP solved at the observed parameters; the plan carries them as its forecasts (one
  value per step), so recordings draw what it was made for and a policy compares it with now;
* ``plan_cost`` and ``interpreted`` for ``etmpc bench``;
* ``feedback``: :class:`PlanFeedback`, the gains each plan carries.

This module may import ``etmpc.common`` and ``etmpc.control``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from functools import cached_property
from typing import Any

import casadi as ca
import dm_env
import numpy as np
from dm_control.rl import control

from etmpc.control.lqr import PlanFeedback
from etmpc.control.mpc import FeedbackWeights, GaussNewtonMPC, SolverSettings
from etmpc.control.plan import Plan
from etmpc.systems.base import SystemBase

# The SQP of the tracking tasks (the reacher, the quadrotor): a Gauss-Newton Hessian regularised by 1e-3 I, a
# non-monotone line search (merit_memory 1, at most 8 steps), full multiple shooting, to 1e-6 (primal), 1e-5 (dual).
TRACKING_SOLVER = SolverSettings(
    tolerance=1e-6,
    dual_tolerance=1e-5,
    max_iterations=300,
    block=1,
    regularisation=1e-3,
    sqp_options=(("merit_memory", 1), ("max_iter_ls", 8)),
)


def system_mpc(system, stage_residual: ca.Function, terminal_residual: ca.Function, name: str, **options) -> GaussNewtonMPC:
    """``system``'s Gauss-Newton MPC: its predictor over one interval (``system.model.discrete``), its
    Config's horizon and solver settings and its input bounds, with the residuals given and the
    compiled solver named ``name``; ``options`` are :class:`GaussNewtonMPC`'s others (``parameters``,
    ``feedback``)."""
    config = system.config
    mpc = GaussNewtonMPC(
        system.model.discrete,
        stage_residual,
        terminal_residual,
        config.horizon,
        system.u_min,
        system.u_max,
        config.solver,
        name=name,
        **options,
    )
    if system.counts_iterations:  # every solve is SQP iterations counted one by one: their code, built now
        mpc.prepare_iterations()
    return mpc


def tracked_change(s, tracked: tuple[str, ...]) -> np.ndarray:
    """Exogenous features of a tracking task at augmented state ``s`` (it carries the kept plan and the
    current observation): the ``tracked`` values now, the ones the kept plan was made for, their
    difference, and its length (0 until the tracked values change)."""
    obs, forecasts, age = s.observation, s.plan.forecasts, s.age
    now = np.array([float(obs[name]) for name in tracked])
    j = min(age, len(forecasts[tracked[0]]) - 1)
    planned = np.array([float(forecasts[name][j]) for name in tracked])
    change = now - planned
    return np.array([*now, *planned, *change, float(np.hypot.reduce(change))])


@dataclass(frozen=True)
class TrackedFeatures:
    """What a tracking task's exogenous features are (the learned policy's "error" set adds them): for
    ``tracked`` ``("target_x_m", "target_y_m")``, the names ``target_x_m, target_y_m`` (now),
    ``planned_target_x_m, ...`` (what the kept plan was made for), ``target_change_x_m, ...`` (now minus the
    plan's) and ``target_change_m`` (its length: 0 until the tracked values change); called on an augmented
    state, their values (:func:`tracked_change`). A system sets ``exogenous_features`` to it and
    ``exogenous_feature_names`` to its :attr:`names`."""

    tracked: tuple[str, ...]

    @property
    def names(self) -> tuple[str, ...]:
        parts = [name.split("_", 1) for name in self.tracked]  # target | x_m
        return (
            *self.tracked,
            *(f"planned_{name}" for name in self.tracked),
            *(f"{first}_change_{rest}" for first, rest in parts),
            f"{parts[0][0]}_change_m",
        )

    def __call__(self, s) -> np.ndarray:
        return tracked_change(s, self.tracked)


class GaussNewtonSystem(SystemBase):
    """A tracking task: a subclass sets :attr:`tracked` and :attr:`mpc_name`, builds ``self.model``
    (``model.discrete``, the predictor over one interval) and ``self.u_min``/``self.u_max`` in its
    ``__init__``, names its task module's ``make_environment``, and writes :meth:`residuals` and
    :meth:`feedback_weights`. Its ``Config`` has a ``solver`` (:class:`~etmpc.control.mpc.SolverSettings`)
    and a ``plant``."""

    tracked: tuple[str, ...] = ()  # observation entries that are the OCP's parameters, in order
    mpc_name: str = "mpc"  # the compiled solver's name (its cache file)
    feedback = PlanFeedback()
    # The task module's make_environment(random=, plant=, ...), as a staticmethod: make_env builds it at the
    # Config's plant setting.
    make_environment: Callable[..., control.Environment] | None = None

    def __init__(self, config: Any = None) -> None:
        """What a subclass's constructor takes, as :meth:`interpreted` calls it: its ``Config`` (None: the
        default one). The subclass sets ``self.config``, its model and its input bounds there; this one sets
        nothing (a subclass need not call it)."""

    def make_env(self, random: np.random.Generator | np.random.RandomState | int | None = None) -> control.Environment:
        """The dm-control environment: the task's ``make_environment`` at this Config's ``plant`` (and its
        ``disturbances``, where the Config has them: the task's options of its world)."""
        if self.make_environment is None:
            raise NotImplementedError(f"{type(self).__name__} names no make_environment")
        disturbances = getattr(self.config, "disturbances", None)
        if disturbances is None:
            return self.make_environment(random=random, plant=self.config.plant)
        return self.make_environment(random=random, plant=self.config.plant, disturbances=disturbances)

    def residuals(self) -> tuple[ca.Function, ca.Function]:
        """``stage_residual(x, u, du, p)`` and ``terminal_residual(x, p)``, ``p`` the tracked values."""
        raise NotImplementedError

    def feedback_weights(self) -> FeedbackWeights:
        """Q and R of the LQR along each plan (the gains ``PlanFeedback`` applies): the Config's
        ``feedback_state_weights`` and ``feedback_input_weights``, unless the task says otherwise."""
        return FeedbackWeights(self.config.feedback_state_weights, self.config.feedback_input_weights)

    @cached_property
    def mpc(self) -> GaussNewtonMPC:
        stage, terminal = self.residuals()
        return system_mpc(self, stage, terminal, self.mpc_name, parameters=len(self.tracked), feedback=self.feedback_weights())

    def observed(self, timestep: dm_env.TimeStep) -> np.ndarray:
        """The tracked values now, as observed: the OCP's parameter vector."""
        obs = timestep.observation
        return np.array([obs[name] for name in self.tracked], dtype=float)

    def plan(self, x: np.ndarray, u_prev: np.ndarray, warm: Plan | None, age: int, timestep: dm_env.TimeStep) -> Plan:
        """A full solve; on a task that prices or delays by SQP iterations, counted iteration by
        iteration (:meth:`GaussNewtonMPC.iterate`: the same optimum within tolerance)."""
        p = self.observed(timestep)
        if self.counts_iterations:
            plan = self.mpc.iterate(x, u_prev, warm, age, parameters=p, limit=self.config.solver.max_iterations)
        else:
            plan = self.mpc.solve(x, u_prev, warm, age, parameters=p)
        return self._tracking(plan, p)

    def iterate(
        self, x: np.ndarray, u_prev: np.ndarray, warm: Plan | None, age: int, timestep: dm_env.TimeStep, limit: int = 1
    ) -> Plan:
        """At most ``limit`` SQP iterations from ``warm`` shifted by ``age``, stopping when converged (one: a
        real-time iteration)."""
        p = self.observed(timestep)
        return self._tracking(self.mpc.iterate(x, u_prev, warm, age, parameters=p, limit=limit), p)

    def predict(self, x: np.ndarray, inputs: np.ndarray) -> np.ndarray:
        """The predictor's states from ``x`` under ``inputs`` (for delay compensation)."""
        return self.mpc.rollout(x, inputs)

    def _tracking(self, plan: Plan, p: np.ndarray) -> Plan:
        """The plan with the tracked values it was made for as its forecasts (one value per step)."""
        return replace(plan, forecasts={name: np.full(self.horizon, p[i]) for i, name in enumerate(self.tracked)})

    def plan_cost(self, x: np.ndarray, u_prev: np.ndarray, timestep: dm_env.TimeStep, inputs: np.ndarray) -> float:
        """The OCP's objective of an input sequence, rolled out through the predictor."""
        return self.mpc.objective(x, u_prev, inputs, self.observed(timestep))

    def interpreted(self) -> GaussNewtonSystem:
        """The same task with its MPC solved as before it was compiled (for etmpc bench)."""
        return type(self)(replace(self.config, solver=replace(self.config.solver, compiled=False)))
