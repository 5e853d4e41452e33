"""The battery-trading system as the control loop sees it: plant, economic MPC, LQR and profit.

**Failures**, "curtailed": the intervals whose trade the battery could not execute as commanded, because
it ran empty or full (``task.py``: a trade is curtailed to what the battery can deliver or absorb, and
only the executed trade is paid), by more than ``CURTAILMENT_TOLERANCE`` of the trade limit (1 %:
3.6 kW, 0.01 kWh over a 10 s interval). For the operator it is a sale or purchase promised and not
delivered. The tolerance leaves out the computer's own draw (0.1 kW), which the MPC does not predict,
so a plan that empties the battery exactly falls short by that much whenever it computes. The
executed trade is the battery's charge balance, ``u = P - eta_c a + (x - x+) C / delta``: from the
played trajectory's charges and recomputes and the episode's net production.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TypeAlias
from functools import cached_property

import dm_env
import numpy as np

from etmpc.systems.battery import task as battery_env
from etmpc.systems.battery.mpc import EconomicMPC
from etmpc.systems.battery.parameters import Battery, Market
from etmpc.systems.battery.reference import LinprogReference
from etmpc.common.declared import Checked
from etmpc.common.errors import EtmpcError
from etmpc.control.lqr import ErrorFeedback, discrete_lqr_gain, state_space
from etmpc.control.plan import Plan
from etmpc.control.settings import horizon_setting, input_weight_setting, weight_setting
from etmpc.systems.base import SystemBase


# What the learned policy's default ("error") feature set adds for the battery (etmpc.policies.learned).
EXOGENOUS_FEATURES = (
    "price_eur_kwh",  # lambda_i, now
    "net_production_kw",  # P_i, now
    "planned_price_eur_kwh",  # what the kept plan assumed for lambda_i
    "planned_production_kw",  # what it assumed for P_i
    "price_error_eur_kwh",  # lambda_i minus the plan's assumption
    "production_error_kw",
    "trade_value_eur",  # (lambda_i - lambda_bar) u_plan,i delta: today's worth of the trade the plan makes now
    "price_forecast_revision_eur_kwh",  # RMS over the plan's remaining steps: today's price forecast minus the plan's
    "production_forecast_revision_kw",  # the same for the production forecast
    # sum over them of (today's forecast - the plan's) u_plan delta: what the plan's trades gained or lost
    "plan_value_revision_eur",
)
_MEAN_PRICE, _INTERVAL_H = Market().price.mean, Battery().interval_h
CURTAILMENT_TOLERANCE = 0.01  # of the trade limit: a trade curtailed by more is a failure (see the module's docstring)


def exogenous_features(s) -> np.ndarray:
    """The values of :data:`EXOGENOUS_FEATURES` at augmented state ``s`` (it carries the kept plan
    and the current observation). The trade's value is against the mean price ``lambda_bar``, the
    value the MPC gives stored energy: > 0 when the plan's trade now beats keeping the energy.

    A plan that has run out (age N: the loop must recompute, and no policy is asked, but the trigger
    environment still observes it) assumed nothing for now: its last forecast stands in, as
    :meth:`~etmpc.control.plan.Plan.input_at` holds its last input."""
    obs, plan = s.observation, s.plan
    age = min(s.age, plan.horizon - 1)
    price, production = float(obs["price_eur_kwh"]), float(obs["net_production_kw"])
    planned_price = float(plan.forecasts["price_eur_kwh"][age])
    planned_production = float(plan.forecasts["production_kw"][age])
    trade_value = (price - _MEAN_PRICE) * float(plan.input_at(age)[0]) * _INTERVAL_H
    # The forecasts now against those the plan was made with, over the steps it has left (index 0: now).
    left = plan.horizon - age
    price_revision = np.asarray(obs["price_forecast_eur_kwh"][:left]) - plan.forecasts["price_eur_kwh"][age : age + left]
    production_revision = np.asarray(obs["production_forecast_kw"][:left]) - plan.forecasts["production_kw"][age : age + left]
    value_revision = float(np.dot(price_revision, plan.inputs[age : age + left, 0])) * _INTERVAL_H
    return np.array(
        [
            price,
            production,
            planned_price,
            planned_production,
            price - planned_price,
            production - planned_production,
            trade_value,
            float(np.sqrt(np.mean(price_revision**2))),
            float(np.sqrt(np.mean(production_revision**2))),
            value_revision,
        ]
    )


@dataclass(frozen=True)
class Config(Checked):
    """The paper's settings for the battery (docs/paper.md, "The paper's settings, and what it leaves open")."""

    horizon: int = horizon_setting(20)  # N
    lqr_state_weight: float = weight_setting(1.0, "the LQR's Q on the state-of-charge error")  # dimensionless
    lqr_input_weight: float = input_weight_setting(0.1, "the LQR's R on the correction, per kW^2")
    recompute_price: float = 0.0  # a recompute's cost is physical: eta_c is drawn from the battery
    battery: Battery = Battery()
    market: Market = Market()


class BatterySystem(SystemBase):
    Config: TypeAlias = Config  # the settings it is built from (etmpc.systems.make_system)
    exogenous_feature_names = EXOGENOUS_FEATURES  # what the learned policy's "error" features add
    exogenous_features = staticmethod(exogenous_features)
    domain = "battery"
    task = "trading"
    objective_sense = "max"  # the objective is the profit, EUR
    state_names = ("state_of_charge",)
    input_names = ("trade_kw",)
    failure_name = "curtailed"  # intervals whose commanded trade the empty or full battery cut by > 1 % of the limit

    def __init__(self, config: Config = Config()):
        if config.horizon > config.market.forecast_steps:
            raise EtmpcError(
                f"horizon {config.horizon} exceeds the {config.market.forecast_steps} forecast values the task provides"
            )
        self.config = config
        battery = config.battery
        self.episode_steps = battery.episode_steps
        self.control_interval_s = battery.interval_s
        self.terminal_price = config.market.price.mean
        self.u_min = np.array([-battery.trade_limit_kw])
        self.u_max = np.array([battery.trade_limit_kw])
        self.error_weights = np.sqrt([config.lqr_state_weight])
        # The SoC error: eps+ = eps - delta/C u_lqr (the paper's LQR, Q = 1, R = 0.1: docs/paper.md), a discrete
        # system with its timebase.
        soc_error = state_space([[1.0]], [[-battery.soc_per_kw]], [[1.0]], [[0.0]], dt=battery.interval_s)
        gain = discrete_lqr_gain(soc_error, np.array([[config.lqr_state_weight]]), np.array([[config.lqr_input_weight]]))
        self.feedback = ErrorFeedback(gain)

    @cached_property
    def mpc(self) -> EconomicMPC:
        return EconomicMPC(self.config.battery, self.config.horizon, self.terminal_price)

    def make_env(self, random=None):
        return battery_env.make_environment(random=random, battery=self.config.battery, market=self.config.market)

    def truncation_value(self, x: np.ndarray) -> float:
        """The stored energy at the mean price, as the task values it at the episode's end (EUR)."""
        return self.terminal_price * self.config.battery.capacity_kwh * float(x[0])

    def state(self, timestep: dm_env.TimeStep) -> np.ndarray:
        return np.array([timestep.observation["state_of_charge"]])

    def plan(self, x: np.ndarray, u_prev: np.ndarray, warm: Plan | None, age: int, timestep: dm_env.TimeStep) -> Plan:
        obs = timestep.observation
        return self.mpc.solve(float(x[0]), obs["production_forecast_kw"], obs["price_forecast_eur_kwh"])

    def action(self, u: np.ndarray, recompute: bool) -> np.ndarray:
        return np.array([u[0], 1.0 if recompute else 0.0])  # computing draws eta_c from the battery

    # -- failures ---------------------------------------------------------------------------------
    def curtailments_kw(self, trajectory, episode) -> np.ndarray:
        """Per step played, the commanded trade minus the executed one (kW): the battery's charge balance
        ``x+ = x - delta/C (u - P + eta_c a)`` solved for the executed ``u``, with ``a`` 1 where the step
        computed (:meth:`action`)."""
        n, battery = trajectory.steps, self.config.battery
        soc = trajectory.states[: n + 1, 0]
        net_in = episode.production_kw[:n] - battery.compute_power_kw * trajectory.recompute[:n]
        executed = net_in + (soc[:-1] - soc[1:]) / battery.soc_per_kw
        return trajectory.applied[:n, 0] - executed

    def failures(self, trajectory, episode) -> int:
        """Intervals curtailed by more than ``CURTAILMENT_TOLERANCE`` of the trade limit."""
        limit = CURTAILMENT_TOLERANCE * self.config.battery.trade_limit_kw
        return int(np.sum(np.abs(self.curtailments_kw(trajectory, episode)) > limit))

    # -- for etmpc bench --------------------------------------------------------------------------
    def plan_cost(self, x: np.ndarray, u_prev: np.ndarray, timestep: dm_env.TimeStep, inputs: np.ndarray) -> float:
        """The OCP's minimised objective (negative profit, EUR) of an input sequence."""
        obs, n = timestep.observation, self.config.horizon
        return -self.mpc.profit(
            float(x[0]), obs["production_forecast_kw"][:n], obs["price_forecast_eur_kwh"][:n], np.ravel(inputs)
        )

    def reference_solvers(self) -> list:
        return [LinprogReference(self.config.battery, self.config.horizon, self.terminal_price)]
