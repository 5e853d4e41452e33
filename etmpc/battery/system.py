"""The battery-trading system as the control loop sees it: plant, economic MPC, LQR and profit."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from functools import cached_property

import control as ct
import dm_env
import numpy as np

from etmpc.battery import env as battery_env
from etmpc.battery.mpc import EconomicMPC
from etmpc.battery.parameters import Battery, Market
from etmpc.battery.reference import LinprogReference
from etmpc.errors import EtmpcError
from etmpc.lqr import ErrorFeedback, discrete_lqr_gain
from etmpc.plan import Plan


@dataclass(frozen=True)
class Config:
    """The paper's settings for the battery (SPEC.md)."""

    horizon: int = 20  # N
    lqr_state_weight: float = 1.0  # Q on the state-of-charge error (dimensionless)
    lqr_input_weight: float = 0.1  # R on the correction, per kW^2
    recompute_price: float = 0.0  # the computation's cost is physical: eta_c is drawn from the battery
    battery: Battery = Battery()
    market: Market = Market()


class BatterySystem:
    domain = "battery"
    task = "trading"
    objective_sense = "max"  # the objective is the profit, EUR
    state_names = ("state_of_charge",)
    input_names = ("trade_kw",)

    def __init__(self, config: Config = Config()):
        if config.lqr_state_weight < 0 or config.lqr_input_weight <= 0:
            raise ValueError(f"LQR weights need Q >= 0 and R > 0, got Q={config.lqr_state_weight}, R={config.lqr_input_weight}")
        if config.horizon > config.market.forecast_steps:
            raise EtmpcError(f"horizon {config.horizon} exceeds the {config.market.forecast_steps} forecast values the task provides")
        self.config = config
        battery = config.battery
        self.episode_steps = battery.episode_steps
        self.control_interval_s = battery.interval_s
        self.recompute_price = config.recompute_price
        self.terminal_price = config.market.price.mean
        self.u_min = np.array([-battery.trade_limit_kw])
        self.u_max = np.array([battery.trade_limit_kw])
        self.error_weights = np.sqrt([config.lqr_state_weight])
        # The SoC error: eps+ = eps - delta/C u_lqr (SPEC.md), a discrete system with its timebase.
        soc_error = ct.ss([[1.0]], [[-battery.soc_per_kw]], [[1.0]], [[0.0]], dt=battery.interval_s)
        gain = discrete_lqr_gain(soc_error, np.array([[config.lqr_state_weight]]), np.array([[config.lqr_input_weight]]))
        self.feedback = ErrorFeedback(gain)

    @cached_property
    def mpc(self) -> EconomicMPC:
        return EconomicMPC(self.config.battery, self.config.horizon, self.terminal_price)

    def make_env(self, random=None):
        return battery_env.make_environment(random=random, battery=self.config.battery, market=self.config.market)

    def draw_episode(self, rng: np.random.Generator) -> battery_env.Episode:
        return battery_env.Episode.draw(rng, self.config.battery, self.config.market)

    def episode_parameters(self) -> dict:
        """What the episodes are drawn from (recorded in the test set)."""
        return {"battery": asdict(self.config.battery), "market": asdict(self.config.market)}

    def episode_from_arrays(self, arrays: dict[str, np.ndarray]) -> battery_env.Episode:
        return battery_env.Episode.from_arrays(arrays)

    def signals(self, episode: battery_env.Episode) -> dict[str, np.ndarray]:
        """The episode's true prices and net production, per step, for recordings."""
        return {"price_eur_kwh": episode.price_eur_kwh, "net_production_kw": episode.production_kw}

    def state(self, timestep: dm_env.TimeStep) -> np.ndarray:
        return np.array([timestep.observation["state_of_charge"]])

    def plan(self, x: np.ndarray, u_prev: np.ndarray, warm: Plan | None, age: int, timestep: dm_env.TimeStep) -> Plan:
        obs = timestep.observation
        return self.mpc.solve(float(x[0]), obs["production_forecast_kw"], obs["price_forecast_eur_kwh"])

    def action(self, u: np.ndarray, recompute: bool) -> np.ndarray:
        return np.array([u[0], 1.0 if recompute else 0.0])  # computing draws eta_c from the battery

    # -- for etmpc bench --------------------------------------------------------------------------
    def plan_cost(self, x: np.ndarray, u_prev: np.ndarray, timestep: dm_env.TimeStep, inputs: np.ndarray) -> float:
        """The OCP's minimised objective (negative profit, EUR) of an input sequence."""
        obs, n = timestep.observation, self.config.horizon
        return -self.mpc.profit(float(x[0]), obs["production_forecast_kw"][:n], obs["price_forecast_eur_kwh"][:n], np.ravel(inputs))

    def reference_solvers(self) -> list:
        return [LinprogReference(self.config.battery, self.config.horizon, self.terminal_price)]

    def compiled(self):
        return None  # the LP is solved inside HiGHS; there is nothing to compile
