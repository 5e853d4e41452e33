"""The ``kicks`` task as the control loop sees it: an MPC that follows the cart's current reference and
knows the rail, a feedback that follows the plan, and the price of a recompute.

* **MPC** (Gauss-Newton SQP, full multiple shooting, N = 20, compiled): the paper's analytic model
  (RK4, 2 steps per interval), the reference ``r`` as the OCP's parameter, and the residuals
  ``[3 sin(beta/2), eta - r, 0.03 omega, 0.03 u, 0.01 du, 5 max(0, |eta| - 2)]`` per stage (the last
  keeps the plan 0.5 m from the bumpers), ``[9 sin(beta/2), 3 (eta - r), 0.3 omega, 0.3 v,
  5 max(0, |eta| - 2)]`` at the end; ``|u| <= 25`` N. The plan carries the reference it was made for
  as ``Plan.forecasts`` (``cart_reference_m``), so recordings draw it and a learned policy compares
  it with the current one. A solve counts as converged at constraint violation <= 1e-5 and
  Lagrangian gradient <= 1e-3 (the SQP's tolerances 1e-6 and 1e-4, times 10). Warm started from the
  kept plan; a cold start (the first plan, after a fall, or after a plan kept to its end) begins
  with the state held and zero inputs: a rollout of zero inputs lets the pole fall in the guess, and
  the SQP then found plans that swing it over the top. Input weight 0.03 (0.003 first): the stiffer
  MPC moved the cart harder, and under the plant's mismatch that made falls.
* **Feedback** while a plan is kept: a time-varying LQR along the plan (``PlanFeedback``), from the
  predictor's linearisation at each planned step, ``Q = diag(1, 1, 10, 1)``, ``R = 0.1``. The pole is
  kicked far from upright, where one gain linearised at upright would not do.
* **Objective** (lower is better): the episode's cost (``kicks.py``) plus 0.1 per recompute.
* **Lookahead** 10 steps (``Benchmark.lookahead``) for the rollout meter and DPI's labels: with 20 (2
  s, a jump every 2.5 s on average) the random timing of later jumps made the two answers' sampled
  returns differ by more than the price, and the rollout recomputed at about half its decisions.
* **Exogenous features** for the learned policy: the reference now, the kept plan's, their
  difference and its size. An event trigger on the state error sees a jump only once the cart lags; these see it
  at once.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TypeAlias

import casadi as ca
import dm_env
import numpy as np

from etmpc.common.declared import Checked, setting
from etmpc.control.mpc import FeedbackWeights, SolverSettings
from etmpc.control.settings import horizon_setting, input_weight_setting, levels_setting, rk4_setting, weight_setting
from etmpc.control.sensing import FilterSettings, Sensor
from etmpc.control.timing import Latency
from etmpc.systems.capabilities import ShieldRule
from etmpc.systems.plants import plant_setting
from etmpc.systems.cart_pendulum import kicks
from etmpc.systems.cart_pendulum.model import NU, NX, STATE_NAMES, AnalyticModel
from etmpc.systems.cart_pendulum.system import MAX_FORCE_N
from etmpc.systems.tracking_system import TrackingSystem


REFERENCE = "cart_reference_m"  # the observation's current reference, and the plan's forecast of it

# What the learned policy's default ("error") feature set adds for this task (etmpc.policies.learned).
EXOGENOUS_FEATURES = (
    "cart_reference_m",  # the reference now
    "planned_cart_reference_m",  # the reference the kept plan was made for
    "cart_reference_change_m",  # the reference now minus the plan's: 0 until it jumps
    "cart_reference_change_abs_m",
)


def exogenous_features(s) -> np.ndarray:
    """The values of :data:`EXOGENOUS_FEATURES` at augmented state ``s`` (it carries the kept plan
    and the current observation)."""
    now, planned = float(s.observation[REFERENCE]), float(s.plan.forecasts[REFERENCE][0])
    return np.array([now, planned, now - planned, abs(now - planned)])


#: The filter's process noise per interval (m, m/s, rad, rad/s), where a sensor is set (kicks_noisy's).
PROCESS_STD = (0.000625, 0.025, 0.000625, 0.125)


@dataclass(frozen=True)
class Config(Checked):
    """The kicks task's controller and price."""

    horizon: int = horizon_setting(20)
    force_limit_n: float = setting(25.0, above=0, high=MAX_FORCE_N, unit="N", why="the cart force's bound")
    rail_margin_m: float = setting(  # the MPC keeps the cart this far inside the bumpers
        0.5, low=0, below=kicks.BUMPERS.position_m, unit="m", why="the MPC keeps the cart this far inside the bumpers"
    )
    position_weight: float = weight_setting(1.0, "on eta - r in each stage's residual")
    terminal_position_weight: float = weight_setting(3.0, "on eta - r in the terminal residual")
    input_weight: float = weight_setting(0.03, "on the force in each stage's residual")
    # Q of the TV-LQR (and W of threshold:X: sqrt Q)
    feedback_state_weights: tuple[float, ...] = weight_setting((1.0, 1.0, 10.0, 1.0), "the TV-LQR's Q", lengths=(NX,))
    feedback_input_weight: float = input_weight_setting(0.1, "the TV-LQR's R")
    recompute_price: float = 0.1
    rk4_substeps: int = rk4_setting(2)
    plant: str = plant_setting()
    latency: Latency = Latency()  # how long a solve takes (etmpc.control.timing); none: the paper's loop
    compute_levels: bool = levels_setting(False)  # a decision is keep, one SQP iteration or a full solve
    # the kicks and the reference's jumps (the world's: kicks.Disturbances), as options
    disturbances: kicks.Disturbances = kicks.Disturbances()
    # what the controller measures, and its filter (etmpc.control.sensing): the exact state by default
    sensor: Sensor = Sensor()
    # the filter's process noise per state and interval (m, m/s, rad, rad/s): the plant's mismatch with the
    # predictor and the kicks (jumps of the pole's rate), chosen on training episodes for kicks_noisy's sensor
    # (etmpc study estimators, docs/results/estimators.md)
    estimator: FilterSettings = FilterSettings(process_std=PROCESS_STD)
    solver: SolverSettings = field(
        default_factory=lambda: SolverSettings(
            tolerance=1e-6,
            dual_tolerance=1e-4,
            max_iterations=30,
            block=1,
            cold_start="hold",
            warm_from_expired=False,
            sqp_options=(("merit_memory", 1), ("max_iter_ls", 8)),
        )
    )


class KicksSystem(TrackingSystem):
    Config: TypeAlias = Config
    domain = "cart_pendulum"
    task = "kicks"
    state_names = STATE_NAMES
    input_names = ("force_n",)
    tracked = (REFERENCE,)  # the cart's current reference (m), as observed: the OCP's parameter
    mpc_name = "cart_pendulum_kicks_mpc"
    make_environment = staticmethod(kicks.make_environment)
    exogenous_feature_names: tuple[str, ...] = EXOGENOUS_FEATURES  # what the learned policy's "error" features add
    exogenous_features = staticmethod(exogenous_features)
    failure_name = "falls"  # per episode, beside the mean objective
    safety_margin = staticmethod(kicks.fall_margin)  # rad before a fall, one interval on (shield:)
    margin_unit = "rad"
    # shield:BASE's rule (etmpc study shields, docs/results/shields.md): none, since on validation episodes no rule
    # made the shipped learners fall less without costing them more than the budget (a recompute forced near a fall
    # made falls no rarer under this model mismatch); shield:AGE[:MARGIN[:DEVIATION]]:BASE still works
    shield: ShieldRule | None = None
    camera = "track"

    def __init__(self, config: Config | None = None):
        super().__init__(config)
        self.model = AnalyticModel(dt_s=kicks.CONTROL_DT_S, rk4_substeps=self.config.rk4_substeps)
        self.u_min = np.array([-self.config.force_limit_n])
        self.u_max = np.array([self.config.force_limit_n])

    def residuals(self) -> tuple[ca.Function, ca.Function]:
        c = self.config
        x, u, du, r = ca.SX.sym("x", NX), ca.SX.sym("u", NU), ca.SX.sym("du", NU), ca.SX.sym("r", 1)
        eta, v, beta, omega = x[0], x[1], x[2], x[3]
        inside = kicks.BUMPERS.position_m - c.rail_margin_m
        stage = ca.Function(
            "stage_residual",
            [x, u, du, r],
            [
                ca.vertcat(
                    3 * ca.sin(beta / 2),
                    c.position_weight * (eta - r),
                    0.03 * omega,
                    c.input_weight * u,
                    0.01 * du,
                    5 * ca.fmax(0, ca.fabs(eta) - inside),
                )
            ],
        )
        terminal = ca.Function(
            "terminal_residual",
            [x, r],
            [
                ca.vertcat(
                    9 * ca.sin(beta / 2),
                    c.terminal_position_weight * (eta - r),
                    0.3 * omega,
                    0.3 * v,
                    5 * ca.fmax(0, ca.fabs(eta) - inside),
                )
            ],
        )
        return stage, terminal

    def feedback_weights(self) -> FeedbackWeights:
        return FeedbackWeights(self.config.feedback_state_weights, (self.config.feedback_input_weight,))

    def reference(self, timestep: dm_env.TimeStep) -> np.ndarray:
        """The cart's current reference (m), as observed, as the MPC's parameter vector."""
        return self.observed(timestep)

    # -- failures (episodes are drawn, resampled and described by the task: kicks.Kicks) -----------------
    failures_in_rewards = staticmethod(kicks.falls)  # falls in an episode
