"""The ``jumps`` task as the control loop sees it: an MPC that reaches for the current target, a
feedback that follows the plan, and the price of a recompute.

* **MPC** (Gauss-Newton SQP, full multiple shooting, N = 20, compiled): the analytic arm
  (``model.py``, RK4, 2 steps per interval) and the target ``p`` as the OCP's parameter; residuals
  ``[e / 0.3, 0.02 qdot, 0.01 u, 0.02 du]`` per stage, ``e = fingertip - p`` (m), and
  ``[2 e / 0.3, 0.1 qdot]`` at the end; ``|u_i| <= 2`` N m. The plan carries the target it was made
  for as ``Plan.forecasts`` (``target_x_m``, ``target_y_m``, N values each), so recordings draw it
  and a learned policy compares it with the current one. A Levenberg-Marquardt term ``1e-3 I`` in
  the Gauss-Newton Hessian (it changes the path, not the optimum), the Lagrangian gradient's
  tolerance 1e-5 and at most 300 iterations: with ``1e-4``, 1e-4 and 150 (first tried), 70 of 3780
  closed-loop solves (``every:1`` and ``every:4`` on 30 test-set episodes) did not converge, mostly
  solves for a far target after a jump; now 2 of 3751. The damping slows the last iterations near
  a small optimum, hence the tighter gradient tolerance (at 1e-4 the objective stopped up to 3e-6
  from Ipopt's, relative). A solve counts as converged at constraint violation <= 1e-5 and
  Lagrangian gradient <= 1e-4 (10 times the SQP's tolerances).
* **Feedback** while a plan is kept: a time-varying LQR along the plan (``PlanFeedback``), from the
  predictor's linearisation at each planned step, ``Q = diag(10, 10, 1, 1)``, ``R = diag(0.1, 0.1)``.
  ``threshold:X`` weighs the prediction error by ``sqrt(Q)``.
* **Objective** (lower is better): the episode's cost (``task.py``: the sum of ``d^2 / (d^2 +
  0.1^2)`` over 100 steps, about 29 for a controller that recomputes every step) plus 0.1 per
  recompute: there ``every:3`` is the best periodic schedule (30 test-set episodes; ``every:2``
  up to 0.05, ``every:3`` from 0.07 to 0.12, ``every:4`` at 0.15 and 0.2, ``every:5`` from 0.25 to
  0.4). At 0.1 the oracle gains 9.6 % +- 3.3 % over the periodic front at its own rate and
  ``rollout:every:3:4:10`` 12.8 % +- 3.0 % (95 % CI; ``etmpc discriminate --task reacher``); every
  ``threshold:X`` level does worse than the front (by 4 to 39 %): a state error does not show a jump.
* **Lookahead** 10 steps (``Benchmark.lookahead``) for the rollout meter and DPI's labels. With 20,
  a target jumps about once in each simulated future (every 2.5 s on average), and the random
  timing of those later jumps adds noise to both answers' returns: ``rollout:every:3:4:20`` gained
  6.7 % +- 2.1 % where the 10-step rollout gains 12.8 % +- 3.0 %, and each decision costs twice as
  many simulated steps, mostly MPC solves for a far target.
* **Exogenous features** for the learned policy: the target now, the target of the kept plan,
  their difference and its length. An event trigger on the state error cannot see a jump; these can.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TypeAlias

import casadi as ca
import numpy as np

from etmpc.common.declared import Checked, setting
from etmpc.control.sensing import FilterSettings, Sensor
from etmpc.control.mpc import SolverSettings
from etmpc.control.settings import horizon_setting, input_weight_setting, levels_setting, rk4_setting, weight_setting
from etmpc.control.timing import Latency
from etmpc.systems.gauss_newton import TRACKING_SOLVER, TrackedFeatures
from etmpc.systems.plants import plant_setting
from etmpc.systems.reacher import task as reacher_task
from etmpc.systems.reacher.model import INPUT_NAMES, NU, NX, STATE_NAMES, AnalyticModel, fingertip
from etmpc.systems.tracking_system import TrackingSystem

TARGET = ("target_x_m", "target_y_m")  # the observation's current target, and the plan's forecasts of it

# What the learned policy's default ("error") feature set adds for the reacher (etmpc.policies.learned): the
# target now, the one the kept plan reaches for, their difference and its length.
EXOGENOUS = TrackedFeatures(TARGET)
EXOGENOUS_FEATURES = EXOGENOUS.names


MAX_TORQUE_NM, MAX_SCALE_M = 100.0, 10.0  # the largest torque bound and distance scale an option may set


@dataclass(frozen=True)
class Config(Checked):
    """The reacher's controller and price."""

    horizon: int = horizon_setting(20)
    torque_limit_nm: float = setting(2.0, above=0, high=MAX_TORQUE_NM, unit="N m", why="each joint torque's bound")
    distance_scale_m: float = setting(  # stage residual e / 0.3
        0.3, low=1e-3, high=MAX_SCALE_M, unit="m", why="the stage residual is the fingertip's distance over this"
    )
    terminal_distance_factor: float = weight_setting(2.0, "the terminal residual's distance, times this")
    velocity_weight: float = weight_setting(0.02, "on the joint rates in each stage's residual")
    terminal_velocity_weight: float = weight_setting(0.1, "on the joint rates in the terminal residual")
    torque_weight: float = weight_setting(0.01, "on the torques in each stage's residual")
    torque_change_weight: float = weight_setting(0.02, "on the torques' change in each stage's residual")
    # Q of the TV-LQR (and W of threshold:X: sqrt Q)
    feedback_state_weights: tuple[float, ...] = weight_setting((10.0, 10.0, 1.0, 1.0), "the TV-LQR's Q", lengths=(NX,))
    feedback_input_weights: tuple[float, ...] = input_weight_setting((0.1, 0.1), "the TV-LQR's R", lengths=(NU,))
    recompute_price: float = 0.1
    rk4_substeps: int = rk4_setting(2)
    plant: str = plant_setting()
    latency: Latency = Latency()  # how long a solve takes (etmpc.control.timing); none: the paper's loop
    compute_levels: bool = levels_setting(False)  # a decision is keep, one SQP iteration or a full solve
    # the target's jumps (the world's: task.Disturbances), as options
    disturbances: reacher_task.Disturbances = reacher_task.Disturbances()
    # what the controller measures, and its filter (etmpc.control.sensing): the exact state by default
    sensor: Sensor = Sensor()
    estimator: FilterSettings = FilterSettings()
    solver: SolverSettings = TRACKING_SOLVER


class ReacherSystem(TrackingSystem):
    Config: TypeAlias = Config
    domain = "reacher"
    task = "jumps"
    state_names = STATE_NAMES
    input_names = INPUT_NAMES
    tracked = TARGET  # the current target (m), as observed: the OCP's parameters
    mpc_name = "reacher_jumps_mpc"
    make_environment = staticmethod(reacher_task.make_environment)
    exogenous_feature_names = EXOGENOUS_FEATURES  # what the learned policy's "error" features add
    exogenous_features = EXOGENOUS
    failure_name = "far from target"  # steps ending > 0.1 m from the target, per episode
    camera = "top"  # the scene shows the arm; the target stays where the physics has it

    def __init__(self, config: Config | None = None):
        super().__init__(config)
        self.model = AnalyticModel(dt_s=reacher_task.CONTROL_DT_S, rk4_substeps=self.config.rk4_substeps)
        self.u_max = np.full(NU, self.config.torque_limit_nm)
        self.u_min = -self.u_max

    def residuals(self) -> tuple[ca.Function, ca.Function]:
        c = self.config
        x, u, du, target = ca.SX.sym("x", NX), ca.SX.sym("u", NU), ca.SX.sym("du", NU), ca.SX.sym("target", 2)
        e = (fingertip(x, self.model.params) - target) / c.distance_scale_m
        stage = ca.Function(
            "stage_residual",
            [x, u, du, target],
            [ca.vertcat(e, c.velocity_weight * x[2:], c.torque_weight * u, c.torque_change_weight * du)],
        )
        terminal = ca.Function(
            "terminal_residual", [x, target], [ca.vertcat(c.terminal_distance_factor * e, c.terminal_velocity_weight * x[2:])]
        )
        return stage, terminal

    # -- failures (episodes are drawn, resampled and described by the task: task.Jumps) -----------------
    failures_in_rewards = staticmethod(reacher_task.far_steps)  # steps ending farther than 0.1 m from the target
