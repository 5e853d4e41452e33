"""The ``waypoints`` task as the control loop sees it: an MPC that flies to the current waypoint, a
feedback that follows the plan, and the price of a recompute. The numbers are the ``Config``'s below.

* **MPC** (N = 20 (1 s), compiled): the condensed Gauss-Newton SQP (:mod:`etmpc.control.condensed`:
  the thrusts alone are the variables, each QP dense and solved by DAQP), the analytic rigid body
  (``model.py``, RK4, 2 steps per interval) as predictor, the waypoint ``p`` as the OCP's parameter.
  Residuals per stage: ``e / 0.3`` (``e = position - p``, m), a soft floor (a softplus of the height
  below 0.3 m, 5 cm wide, times 10 / 0.3), ``0.1 v``, ``0.5 angles``, ``0.3 rates``,
  ``0.1 (u - hover) / max`` and ``1.0 du / max``; at the end ``[2 e / 0.3, floor, 0.3 v, 0.3 angles,
  0.05 rates]``; ``0.02 <= u_i <= 0.149`` N. ``hover`` is the model's (its mass), not the plant's. The
  plan carries the waypoint it was made for as ``Plan.forecasts`` (``target_x_m``, ``target_y_m``,
  ``target_z_m``).
* **Feedback** while a plan is kept: a time-varying LQR along the plan (``PlanFeedback``), from the
  predictor's linearisation at each planned step, ``Q = diag(10 I3, 3 I3, 1 I3, 0.3 I3)``
  (position, angles, velocity, rates), ``R = 5000 I4`` (N^-2). ``threshold:X`` weighs the prediction
  error by ``sqrt(Q)``.
* **Objective** (lower is better): the episode's cost (``task.py``) plus the price per recompute.
* **Exogenous features** for the learned policy: the waypoint now, the kept plan's, their
  difference and its length (:func:`etmpc.systems.gauss_newton.tracked_change`). Gusts are not
  observed: a policy sees them only as the drone's drift from its plan.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, TypeAlias

import casadi as ca
import numpy as np

from etmpc.common.declared import Checked, setting
from etmpc.control.mpc import SolverSettings
from etmpc.control.sensing import FilterSettings, Sensor
from etmpc.control.settings import horizon_setting, input_weight_setting, levels_setting, rk4_setting, weight_setting
from etmpc.control.timing import Latency
from etmpc.systems.capabilities import ShieldRule
from etmpc.systems.gauss_newton import TrackedFeatures
from etmpc.systems.plants import plant_setting
from etmpc.systems.quadrotor import task as quadrotor_task
from etmpc.systems.quadrotor.model import INPUT_NAMES, NU, NX, STATE_NAMES, AnalyticModel, Parameters
from etmpc.systems.space import Space
from etmpc.systems.tracking_system import TrackingSystem

TARGET = ("target_x_m", "target_y_m", "target_z_m")  # the observation's current waypoint, and the plan's forecasts of it

# The recordings' 3-D view (etmpc.views.space): the flight, each plan's, the waypoint, the gust (the
# strongest gust's peak drawn 0.5 m long) and the geofence, from the floor up.
_FENCE = quadrotor_task.FENCE_HALF_WIDTH_M
SPACE = Space(
    position=STATE_NAMES[:3],
    target=TARGET,
    force=("gust_x_n", "gust_y_n", None),
    box=((-_FENCE, -_FENCE, 0.0), (_FENCE, _FENCE, quadrotor_task.FENCE_HEIGHT_M)),
    force_scale=0.5 / max(quadrotor_task.GUST_PEAK_N),
)

# What the learned policy's default ("error") feature set adds for the quadrotor (etmpc.policies.learned): the
# waypoint now, the one the kept plan flies to, their difference and its length.
EXOGENOUS = TrackedFeatures(TARGET)
EXOGENOUS_FEATURES = EXOGENOUS.names


MAX_SCALE_M = 10.0  # the largest distance scale an option may set (the geofence is 4 m wide)


@dataclass(frozen=True)
class Config(Checked):
    """The quadrotor's controller and price."""

    horizon: int = horizon_setting(20)
    distance_scale_m: float = setting(  # stage residual e / 0.3
        0.3, low=1e-3, high=MAX_SCALE_M, unit="m", why="the stage residual is the distance to the waypoint over this"
    )
    terminal_distance_factor: float = weight_setting(2.0, "the terminal residual's distance, times this")
    velocity_weight: float = weight_setting(0.1, "on the velocity in each stage's residual")
    terminal_velocity_weight: float = weight_setting(0.3, "on the velocity in the terminal residual")
    angle_weight: float = weight_setting(0.5, "on the attitude in each stage's residual")
    terminal_angle_weight: float = weight_setting(0.3, "on the attitude in the terminal residual")
    rate_weight: float = weight_setting(0.3, "on the body rates in each stage's residual")
    terminal_rate_weight: float = weight_setting(0.05, "on the body rates in the terminal residual")
    thrust_weight: float = weight_setting(0.1, "on (u - hover) / max in each stage's residual")
    clearance_m: float = setting(  # the MPC keeps the drone above this height: a soft constraint
        0.3, low=0, below=quadrotor_task.FENCE_HEIGHT_M, unit="m", why="the MPC keeps the drone above this height (soft)"
    )
    clearance_weight: float = weight_setting(10.0, "on the shortfall below the clearance (smoothed over 5 cm) / 0.3")
    idle_thrust_n: float = setting(  # the least thrust the MPC plans per rotor (the plant's rotors may stop)
        0.02, low=0, below=Parameters().max_thrust_n, unit="N", why="the least thrust the MPC plans per rotor"
    )
    thrust_change_weight: float = weight_setting(1.0, "on du / max in each stage's residual")
    feedback_state_weights: tuple[float, ...] = weight_setting(  # Q (and W of threshold:X: sqrt Q)
        (10.0,) * 3 + (3.0,) * 3 + (1.0,) * 3 + (0.3,) * 3, "the TV-LQR's Q", lengths=(NX,)
    )
    feedback_input_weights: tuple[float, ...] = input_weight_setting((5000.0,) * 4, "the TV-LQR's R", lengths=(NU,))
    recompute_price: float = 0.5
    rk4_substeps: int = rk4_setting(2)
    plant: str = plant_setting()
    latency: Latency = Latency()  # how long a solve takes (etmpc.control.timing); none: the paper's loop
    compute_levels: bool = levels_setting(False)  # a decision is keep, one SQP iteration or a full solve
    # the waypoint changes and the gusts (the world's: task.Disturbances), as options
    disturbances: quadrotor_task.Disturbances = quadrotor_task.Disturbances()
    # what the controller measures, and its filter (etmpc.control.sensing): the exact state by default
    sensor: Sensor = Sensor()
    # the filter's process noise per interval (position m, attitude rad, velocity m/s, rates rad/s), where a sensor
    # is set: chosen on training episodes for waypoints_noisy's sensor (etmpc study estimators)
    estimator: FilterSettings = FilterSettings(process_std=(0.02,) * 6 + (0.4,) * 6)
    # The condensed Gauss-Newton SQP (etmpc.control.condensed): converged when a step moves no thrust by more
    # than 0.3 % of its range, and at most 10 QPs by DAQP (a plan that has not converged by then is flown: each
    # iterate descends from the warm start); the Gauss-Newton Hessian regularised by 1e-3 I. Against solving to
    # 0.1 % with up to 100 QPs, the closed loop's objective is 0.01 % higher and the slowest solves 3x faster
    # (docs/solvers.md).
    solver: SolverSettings = SolverSettings(route="condensed", max_iterations=10, regularisation=1e-3, step_tolerance=3e-3)


class QuadrotorSystem(TrackingSystem):
    Config: TypeAlias = Config
    domain = "quadrotor"
    task = "waypoints"
    state_names = STATE_NAMES
    input_names = INPUT_NAMES
    tracked = TARGET  # the current waypoint (m), as observed: the OCP's parameters
    mpc_name = "quadrotor_waypoints_mpc"
    make_environment = staticmethod(quadrotor_task.make_environment)
    exogenous_feature_names = EXOGENOUS_FEATURES  # what the learned policy's "error" features add
    exogenous_features: Callable[[Any], np.ndarray] = EXOGENOUS
    failure_name = "outside geofence"  # steps ending outside the geofence or on the ground, per episode
    safety_margin = staticmethod(quadrotor_task.fence_margin)  # m to the fence or the ground, one interval on (shield:)
    margin_unit = "m"
    # shield:BASE's rule on 1,000 validation episodes (etmpc study shields): no rule is certified within 0.05 failures
    # per episode of every:7 (every:7's own crashes widen every interval), so the budget chose it: the safest rule
    # costing the learners at most 1 %; its deviation catches a flip on a kept plan a metre above the ground
    shield = ShieldRule(15, 0.25, 2)
    camera = "arena"
    space = SPACE  # the recordings' 3-D view of the flight

    def __init__(self, config: Config | None = None):
        super().__init__(config)
        self.params = Parameters()
        self.model = AnalyticModel(params=self.params, dt_s=quadrotor_task.CONTROL_DT_S, rk4_substeps=self.config.rk4_substeps)
        self.u_min = np.full(NU, self.config.idle_thrust_n)
        self.u_max = np.full(NU, self.params.max_thrust_n)

    def residuals(self) -> tuple[ca.Function, ca.Function]:
        c, p = self.config, self.params
        x, u, du, target = ca.SX.sym("x", NX), ca.SX.sym("u", NU), ca.SX.sym("du", NU), ca.SX.sym("target", 3)
        e = (x[:3] - target) / c.distance_scale_m
        # below the clearance: a softplus of the shortfall (smooth, so the Gauss-Newton Jacobian is), 5 cm wide
        low = c.clearance_weight * 0.05 * ca.log1p(ca.exp((c.clearance_m - x[2]) / 0.05)) / c.distance_scale_m
        thrust = (u - p.hover_thrust_n) / p.max_thrust_n
        stage = ca.Function(
            "stage_residual",
            [x, u, du, target],
            [
                ca.vertcat(
                    e,
                    low,
                    c.velocity_weight * x[6:9],
                    c.angle_weight * x[3:6],
                    c.rate_weight * x[9:12],
                    c.thrust_weight * thrust,
                    c.thrust_change_weight * du / p.max_thrust_n,
                )
            ],
        )
        terminal = ca.Function(
            "terminal_residual",
            [x, target],
            [
                ca.vertcat(
                    c.terminal_distance_factor * e,
                    low,
                    c.terminal_velocity_weight * x[6:9],
                    c.terminal_angle_weight * x[3:6],
                    c.terminal_rate_weight * x[9:12],
                )
            ],
        )
        return stage, terminal

    # -- failures (episodes are drawn, resampled and described by the task: task.Waypoints) --------------
    failures_in_rewards = staticmethod(quadrotor_task.failure_steps)  # steps ending outside the geofence or on the ground
