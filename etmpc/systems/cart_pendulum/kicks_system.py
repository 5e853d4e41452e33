"""The ``kicks`` task as the control loop sees it: an MPC that knows the rail, a feedback that follows
the plan, and the price of a computation set where re-planning has a cost worth weighing.

* **MPC** (Gauss-Newton SQP, full multiple shooting, N = 20, compiled): the paper's analytic model
  (RK4, 2 steps per interval) and the residuals ``[3 sin(beta/2), 0.3 eta, 0.03 omega, 0.003 u,
  0.01 du, 5 max(0, |eta| - 2)]`` per stage (the last keeps the plan 0.5 m from the bumpers),
  ``[9 sin(beta/2), eta, 0.3 omega, 0.3 v, 5 max(0, |eta| - 2)]`` at the end; ``|u| <= 25`` N. With
  a weaker pull to the rail's middle (0.1 eta, as first tried) the cart drifted to a bumper, where a
  pole leaning towards it cannot be caught: falls then made most of the cost. A solve counts as
  converged at constraint violation <= 1e-5 and Lagrangian gradient <= 1e-3 (the SQP's tolerances
  1e-6 and 1e-4, times 10). Warm started from the kept plan; a cold start (the first plan, after a
  fall, or after a plan kept to its end) begins with the state held and zero inputs: a rollout of zero
  inputs lets the pole fall in the guess, and the SQP then found plans that swing it over the top.
* **Feedback** while a plan is kept: a time-varying LQR along the plan (``PlanFeedback``), from the
  predictor's linearisation at each planned step, ``Q = diag(1, 1, 10, 1)``, ``R = 0.1``. The pole is
  kicked far from upright, where one gain linearised at upright would not do.
* **Objective** (lower is better): the episode's cost (``kicks.py``) plus 0.1 per computation: about
  what a solve costs against 1 for a step with the pole 1.2 rad off, so that ``every:1`` is not free.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace
from functools import cached_property

import casadi as ca
import dm_env
import numpy as np

from etmpc.control.lqr import PlanFeedback
from etmpc.control.mpc import FeedbackWeights, GaussNewtonMPC, SolverSettings
from etmpc.control.plan import Plan
from etmpc.systems.base import Benchmark
from etmpc.systems.cart_pendulum import kicks
from etmpc.systems.cart_pendulum.model import NU, NX, STATE_NAMES, AnalyticModel


@dataclass(frozen=True)
class Config:
    """The kicks task's controller and price."""

    horizon: int = 20
    force_limit_n: float = 25.0
    rail_margin_m: float = 0.5  # the MPC keeps the cart this far inside the bumpers
    position_weight: float = 0.3  # on eta in each stage's residual: weaker, and the cart drifts to a bumper
    terminal_position_weight: float = 1.0
    feedback_state_weights: tuple[float, ...] = (1.0, 1.0, 10.0, 1.0)  # Q of the TV-LQR (and W of threshold:X: sqrt Q)
    feedback_input_weight: float = 0.1  # R
    recompute_price: float = 0.1
    rk4_substeps: int = 2
    plant: str = "mismatched"
    solver: SolverSettings = field(default_factory=lambda: SolverSettings(
        tolerance=1e-6, dual_tolerance=1e-4, max_iterations=30, block=1, cold_start="hold", warm_from_expired=False,
        sqp_options=(("merit_memory", 1), ("max_iter_ls", 8))))


class KicksSystem:
    Config = Config
    domain = "cart_pendulum"
    task = "kicks"
    name = "cart_pendulum/kicks"
    objective_sense = "min"
    episode_steps = kicks.EPISODE_STEPS
    control_interval_s = kicks.CONTROL_DT_S
    state_names = STATE_NAMES
    input_names = ("force_n",)
    benchmark = Benchmark(
        prices=(0.01, 0.03, 0.1, 0.3, 1.0),
        sweep_thresholds=(0.1, 0.2, 0.3, 0.45, 0.6, 1.0, 1.5, 2.0, 3.0, 4.0),
        report_thresholds=(0.3, 0.6, 1.0, 2.0),
    )
    failure_name = "falls"  # per episode, beside the mean objective
    camera = "track"

    def __init__(self, config: Config = Config()):
        self.config = config
        self.horizon = config.horizon
        self.recompute_price = config.recompute_price
        self.model = AnalyticModel(dt_s=kicks.CONTROL_DT_S, rk4_substeps=config.rk4_substeps)
        self.u_min, self.u_max = np.array([-config.force_limit_n]), np.array([config.force_limit_n])
        self.error_weights = np.sqrt(np.asarray(config.feedback_state_weights))
        self.feedback = PlanFeedback()

    @cached_property
    def mpc(self) -> GaussNewtonMPC:
        x, u, du = ca.SX.sym("x", NX), ca.SX.sym("u", NU), ca.SX.sym("du", NU)
        eta, v, beta, omega = x[0], x[1], x[2], x[3]
        inside = kicks.BUMPERS.position_m - self.config.rail_margin_m
        stage = ca.Function("stage_residual", [x, u, du], [ca.vertcat(
            3 * ca.sin(beta / 2), self.config.position_weight * eta, 0.03 * omega, 0.003 * u, 0.01 * du,
            5 * ca.fmax(0, ca.fabs(eta) - inside))])
        terminal = ca.Function("terminal_residual", [x], [ca.vertcat(
            9 * ca.sin(beta / 2), self.config.terminal_position_weight * eta, 0.3 * omega, 0.3 * v,
            5 * ca.fmax(0, ca.fabs(eta) - inside))])
        weights = FeedbackWeights(self.config.feedback_state_weights, (self.config.feedback_input_weight,))
        return GaussNewtonMPC(self.model.discrete, stage, terminal, self.config.horizon, self.u_min, self.u_max,
                              self.config.solver, name="cart_pendulum_kicks_mpc", feedback=weights)

    # -- the loop ---------------------------------------------------------------------------------------
    def make_env(self, random=None):
        return kicks.make_environment(random=random, plant=self.config.plant)

    def state(self, timestep: dm_env.TimeStep) -> np.ndarray:
        obs = timestep.observation
        return np.array([obs[name] for name in STATE_NAMES], dtype=float)

    def measure(self, physics) -> np.ndarray:
        return physics.state()

    def plan(self, x: np.ndarray, u_prev: np.ndarray, warm: Plan | None, age: int, timestep: dm_env.TimeStep) -> Plan:
        return self.mpc.solve(x, u_prev, warm, age)

    def action(self, u: np.ndarray, recompute: bool) -> np.ndarray:
        return u

    # -- test sets, recordings, rollouts ----------------------------------------------------------------
    def draw_episode(self, rng: np.random.Generator) -> kicks.KickEpisode:
        return kicks.KickEpisode.draw(rng)

    def episode_parameters(self) -> dict:
        return {"initial_state_low": kicks.INITIAL_STATE_LOW.tolist(), "initial_state_high": kicks.INITIAL_STATE_HIGH.tolist(),
                "kicks_per_s": kicks.KICKS_PER_S, "kick_rad_s": list(kicks.KICK_RAD_S), "steps": kicks.EPISODE_STEPS,
                "bumpers": asdict(kicks.BUMPERS), "fall_rad": kicks.FALL_RAD, "fall_cost": kicks.FALL_COST}

    def episode_from_arrays(self, arrays: dict[str, np.ndarray]) -> kicks.KickEpisode:
        return kicks.KickEpisode.from_arrays(arrays)

    def signals(self, episode: kicks.KickEpisode) -> dict[str, np.ndarray]:
        return {"kick_rad_s": episode.kick}

    def sample_future(self, episode: kicks.KickEpisode, step: int, rng: np.random.Generator) -> kicks.KickEpisode:
        """``episode`` with the kicks of intervals ``step..`` redrawn: at the decision of step ``step``
        the controller has felt only the earlier ones (kicks are memoryless)."""
        kick = np.array(episode.kick)
        kick[step:] = kicks.draw_kicks(rng, kick.size - step)
        return kicks.KickEpisode(episode.initial_state, kick)

    def truncation_value(self, x: np.ndarray) -> float:
        return 0.0

    def failures(self, rewards: np.ndarray) -> int:
        """Falls in an episode."""
        return kicks.falls(rewards)

    # -- the scene, and etmpc bench -----------------------------------------------------------------------
    def show(self, physics, x: np.ndarray) -> None:
        physics.set_state_vector(x)
        physics.forward()

    def plan_cost(self, x: np.ndarray, u_prev: np.ndarray, timestep: dm_env.TimeStep, inputs: np.ndarray) -> float:
        """The OCP's objective of an input sequence, rolled out through the predictor."""
        return self.mpc.objective(x, u_prev, inputs)

    def reference_solvers(self) -> list:
        return []

    def interpreted(self) -> KicksSystem:
        return KicksSystem(replace(self.config, solver=replace(self.config.solver, compiled=False)))
