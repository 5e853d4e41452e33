"""The cart-pendulum system as the control loop sees it: plant, MPC, LQR and costs together."""

from __future__ import annotations

import importlib.util
from dataclasses import dataclass, replace
from typing import TypeAlias
from functools import cached_property

import casadi as ca
import dm_env
import numpy as np

from etmpc.systems.cart_pendulum import task as cp_env
from etmpc.systems.cart_pendulum.model import NU, NX, STATE_NAMES, AnalyticModel
from etmpc.control.lqr import ErrorFeedback, discrete_lqr_gain, state_space
from etmpc.common.declared import Checked, setting
from etmpc.control.mpc import GaussNewtonMPC, SolverSettings
from etmpc.control.settings import horizon_setting, input_weight_setting, rk4_setting, weight_setting
from etmpc.systems.plants import plant_setting
from etmpc.control.plan import Plan
from etmpc.systems.base import SystemBase
from etmpc.systems.gauss_newton import system_mpc


MAX_FORCE_N = 1000.0  # the largest force bound an option may set: 40 times the paper's 25 N


@dataclass(frozen=True)
class Config(Checked):
    """The paper's settings for the cart pendulum (docs/paper.md, "The paper's settings, and what it leaves open")."""

    horizon: int = horizon_setting(20)  # N
    input_change_weight: float = weight_setting(1e-4, "D on (u_k - u_{k-1})^2")
    force_limit_n: float = setting(25.0, above=0, high=MAX_FORCE_N, unit="N", why="the cart force's bound")
    lqr_state_weights: tuple[float, ...] = weight_setting((0.0, 1.0, 10.0, 10.0), "the LQR's Q, its diagonal", lengths=(NX,))
    lqr_input_weight: float = input_weight_setting(0.1, "the LQR's R")
    recompute_price: float = 5e-5  # per recompute, in the policy cost R_k
    rk4_substeps: int = rk4_setting(1)  # RK4 steps of the MPC's predictor per 0.1 s interval (the paper: step 0.1 s)
    plant: str = plant_setting()  # "mismatched" or "matched"
    disturbances: cp_env.Disturbances = cp_env.Disturbances()  # the angular disturbance (the world's), as options
    solver: SolverSettings = SolverSettings()


class CartPendulumSystem(SystemBase):
    Config: TypeAlias = Config  # the settings it is built from (etmpc.systems.make_system)
    domain = "cart_pendulum"
    task = "balance"
    state_names = STATE_NAMES
    input_names = ("force_n",)
    failure_name = "off balance"  # steps ending with the pole > 0.1 rad from upright, but the initial recovery (task.py)

    def __init__(self, config: Config = Config()):
        self.config = config
        self.model = AnalyticModel(dt_s=cp_env.CONTROL_DT_S, rk4_substeps=config.rk4_substeps)
        self.u_min = np.array([-config.force_limit_n])
        self.u_max = np.array([config.force_limit_n])
        self.error_weights = np.sqrt(np.asarray(config.lqr_state_weights))
        A, B = self.model.linearised_upright()
        gain = discrete_lqr_gain(
            state_space(A, B, np.eye(NX), np.zeros((NX, NU))),
            np.diag(config.lqr_state_weights),
            np.array([[config.lqr_input_weight]]),
            dt_s=cp_env.CONTROL_DT_S,
        )
        self.feedback = ErrorFeedback(gain)

    @cached_property
    def mpc(self) -> GaussNewtonMPC:
        x, u, du = ca.SX.sym("x", NX), ca.SX.sym("u", NU), ca.SX.sym("du", NU)
        sqrt_d = np.sqrt(self.config.input_change_weight)
        stage = ca.Function("stage_residual", [x, u, du], [ca.vertcat(x[2], sqrt_d * du)])
        terminal = ca.Function("terminal_residual", [x], [x[2]])
        return system_mpc(self, stage, terminal, "cart_pendulum_mpc")

    def make_env(self, random=None):
        """The dm-control environment: the balance task at this Config's ``plant`` and ``disturbances``."""
        disturbances = getattr(self.config, "disturbances", None)  # a Config of another task's may lack them
        return cp_env.make_environment(random=random, plant=self.config.plant, disturbances=disturbances)

    def plan(self, x: np.ndarray, u_prev: np.ndarray, warm: Plan | None, age: int, timestep: dm_env.TimeStep) -> Plan:
        return self.mpc.solve(x, u_prev, warm, age)

    # -- failures ---------------------------------------------------------------------------------
    def failures(self, trajectory, episode) -> int:
        """Steps off balance (:func:`~etmpc.systems.cart_pendulum.task.off_balance_steps`), from the rewards."""
        return cp_env.off_balance_steps(trajectory.rewards[: trajectory.steps])

    # -- the scene, for etmpc render ----------------------------------------------------------------
    camera = "track"  # models/cart_pendulum.xml: rides with the cart (the "fixed" camera only turns towards it)

    # -- for etmpc bench --------------------------------------------------------------------------
    def plan_cost(self, x: np.ndarray, u_prev: np.ndarray, timestep: dm_env.TimeStep, inputs: np.ndarray) -> float:
        """The OCP objective of an input sequence, rolled out through the predictor."""
        inputs = np.ravel(inputs)
        states = self.mpc.rollout(x, inputs.reshape(-1, NU))
        du = np.diff(np.concatenate([np.ravel(u_prev), inputs]))
        return float(np.sum(states[:, 2] ** 2) + self.config.input_change_weight * np.sum(du**2))

    def reference_solvers(self) -> list:
        """do-mpc 5.1 (the paper's stack) on the same OCP, if the ``bench`` extra is installed."""
        if importlib.util.find_spec("do_mpc") is None:
            return []
        from etmpc.systems.cart_pendulum.dompc import DoMpcReference

        c = self.config
        return [DoMpcReference(self.model.discrete, c.horizon, c.input_change_weight, float(self.u_min[0]), float(self.u_max[0]))]

    def interpreted(self) -> CartPendulumSystem:
        """The same system with the MPC as it was solved before it was compiled: full multiple
        shooting, run by CasADi's virtual machine (for ``etmpc bench``)."""
        return CartPendulumSystem(replace(self.config, solver=replace(self.config.solver, block=1, compiled=False)))
