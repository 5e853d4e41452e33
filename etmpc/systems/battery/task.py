"""The battery-trading domain: a plain-numpy physics under dm-control's ``control.Environment``.

No MuJoCo here: :class:`Physics` is the battery (state of charge, one 10 s interval per step) and
:class:`Trading` owns the episode (prices, production, forecasts) and the reward, exactly as a
dm-control suite task does for a MuJoCo model. Load it like the cart pendulum::

    env = etmpc.suite.load("battery", "trading", task_kwargs={"random": 0})

**Action** ``[trade_kw, computing]``: the trade (``> 0`` sells, ``< 0`` buys), limited to
``+-0.1 C / delta`` = 360 kW, and the fraction of the interval the controller's computer runs
(1 when the MPC computes this step, else 0), which draws ``eta_c = 0.1`` kW from the battery.
Both are **clamped to the action spec's bounds**, as MuJoCo clamps a limited actuator (a trade
beyond 360 kW is 360 kW; ``computing`` outside ``[0, 1]`` is 0 or 1, so no action charges the
battery for free or draws more than the computer's power). A non-finite value or an action of
another shape raises ``ValueError``.

**Dynamics** ``x+ = x - delta/C (u - P + eta_c a)`` (delta in hours). The paper prints ``- eta_c a``
inside the bracket, which would make computing charge the battery; computing consumes energy, so the
sign here is ``+`` (docs/paper.md). The state of charge never leaves
``[0, 1]``: a trade that would empty or overfill the battery is **curtailed** to what it can deliver
or absorb, and only the executed trade is paid. If even the largest trade cannot keep it in range
(a net production beyond the trade limit), the surplus is spilled or the deficit is unserved
(:meth:`Physics.unbalanced_energy_kwh`); with the default generators this does not happen.

**Reward** ``lambda_k u_k delta`` (EUR) for the executed trade, plus the value of the stored energy
``lambda_bar C x_T`` at the last step, with ``lambda_bar = E[lambda]`` (the paper's terminal value;
docs/paper.md). Higher is better.

**Observation**: the state of charge, the current net production and price, and the forecasts of
both for the next 20 intervals (the first value of each is the current true value).

There is no scene to render: ``physics.render`` raises ``NotImplementedError``; record a run to
Rerun instead (``etmpc evaluate --task battery --record FILE.rrd``).
"""

from __future__ import annotations

import collections
import math
from dataclasses import asdict

import numpy as np
from dm_control.rl import control
from dm_control.utils import containers
from dm_env import specs

from etmpc.systems.battery.market import SIGNAL_ARRAYS, Episode, sample_future
from etmpc.systems.battery.parameters import SECONDS_PER_HOUR, Battery, Market, Signal
from etmpc.systems.episodes import GAUSSIAN_BOUND_STD, EpisodeTask, Random, add_task, build_environment

SUITE = containers.TaggedTasks()


class Physics(control.Physics):
    """The battery: state of charge and the last interval's trade, production and computing."""

    def __init__(self, battery: Battery = Battery()):
        self.battery = battery
        self._trade_limit_kw = battery.trade_limit_kw
        self._soc = 0.0
        self._time_s = 0.0
        self._commanded_kw = 0.0
        self._computing = 0.0
        self._production_kw = 0.0
        self._executed_kw = 0.0
        self._unbalanced_kwh = 0.0

    # -- vocabulary -------------------------------------------------------------------------------
    def state_of_charge(self) -> float:
        return self._soc

    def state(self) -> np.ndarray:
        return np.array([self._soc])

    def set_state_of_charge(self, soc: float) -> None:
        if not 0.0 <= soc <= 1.0:
            raise ValueError(f"state of charge must be in [0, 1], got {soc}")
        self._soc = float(soc)

    def set_net_production(self, production_kw: float) -> None:
        """Net production minus consumption over the coming interval (kW, > 0 flows into the battery)."""
        self._production_kw = float(production_kw)

    def net_production_kw(self) -> float:
        return self._production_kw

    def commanded_trade_kw(self) -> float:
        return self._commanded_kw

    def executed_trade_kw(self) -> float:
        """The trade of the last interval after curtailment: what is paid."""
        return self._executed_kw

    def computing(self) -> float:
        return self._computing

    def unbalanced_energy_kwh(self) -> float:
        """Energy of the last interval the battery could not take (> 0, spilled) or give (< 0)."""
        return self._unbalanced_kwh

    # -- snapshots (rollouts) ---------------------------------------------------------------------
    _STATE = ("_soc", "_time_s", "_commanded_kw", "_computing", "_production_kw", "_executed_kw", "_unbalanced_kwh")

    def snapshot(self) -> tuple[float, ...]:
        return tuple(getattr(self, name) for name in self._STATE)

    def restore(self, snapshot: tuple[float, ...]) -> None:
        for name, value in zip(self._STATE, snapshot, strict=True):
            setattr(self, name, value)

    # -- control.Physics --------------------------------------------------------------------------
    def set_control(self, control_: np.ndarray) -> None:
        """``[trade_kw, computing]``, each clamped to its bounds (see the module's docstring)."""
        try:
            trade_kw, computing = control_
            trade_kw, computing = float(trade_kw), float(computing)
        except (TypeError, ValueError):
            shape = np.shape(control_)
            raise ValueError(f"the battery's action is [trade_kw, computing], got an action of shape {shape}") from None
        if not math.isfinite(trade_kw + computing):
            raise ValueError(f"the battery's action must be finite, got [{trade_kw}, {computing}]")
        limit = self._trade_limit_kw
        self._commanded_kw = min(max(trade_kw, -limit), limit)
        self._computing = min(max(computing, 0.0), 1.0)

    def render(self, *args, **kwargs):
        raise NotImplementedError(
            "the battery has no scene to render; record the run to Rerun instead "
            "(etmpc evaluate --task battery --record FILE.rrd)"
        )

    def step(self, n_sub_steps: int = 1) -> None:
        b = self.battery
        limit, per_kw = b.trade_limit_kw, b.soc_per_kw
        for _ in range(n_sub_steps):
            x, net_in_kw = self._soc, self._production_kw - b.compute_power_kw * self._computing
            # x+ = x - per_kw (u - net_in): the trades that keep x+ in [0, 1] are [lowest, highest].
            highest, lowest = net_in_kw + x / per_kw, net_in_kw - (1.0 - x) / per_kw
            u = min(max(min(max(self._commanded_kw, lowest), highest), -limit), limit)  # commanded: within +-limit
            x_next = x - per_kw * (u - net_in_kw)
            self._soc = min(max(x_next, 0.0), 1.0)
            self._unbalanced_kwh = (x_next - self._soc) * b.capacity_kwh
            self._executed_kw = u
            self._time_s += b.interval_s

    def time(self) -> float:
        return self._time_s

    def timestep(self) -> float:
        return self.battery.interval_s

    def reset(self) -> None:
        self._soc = self._time_s = self._commanded_kw = self._computing = 0.0
        self._production_kw = self._executed_kw = self._unbalanced_kwh = 0.0

    def after_reset(self) -> None:
        pass


OBSERVATIONS = ("state_of_charge", "net_production_kw", "price_eur_kwh", "production_forecast_kw", "price_forecast_eur_kwh")


class Trading(EpisodeTask):
    """Trade the battery's energy on the balance market; reward the profit (EUR).

    Each episode (initial charge, prices, production and every forecast) is drawn from ``random``
    on reset, or is a stored one queued with :meth:`use_episode` (see
    :class:`etmpc.systems.episodes.EpisodeTask`).
    """

    def __init__(self, random: Random = None, battery: Battery = Battery(), market: Market = Market(), steps: int | None = None):
        super().__init__(random)
        self.battery, self.market = battery, market
        self._steps = battery.episode_steps if steps is None else steps
        self.terminal_price = market.price.mean  # lambda_bar = E[lambda]: the value of stored energy
        self._step = 0

    def check_episode(self, episode: Episode) -> None:
        if episode.steps < self._steps:
            raise ValueError(f"episode has {episode.steps} steps, need {self._steps}")
        if episode.production_forecast_kw.shape[1] < self.market.forecast_steps:
            raise ValueError(
                f"episode forecasts have {episode.production_forecast_kw.shape[1]} values, need {self.market.forecast_steps}"
            )

    def draw_episode(self, random: np.random.Generator) -> Episode:
        return Episode.draw(random, self.battery, self.market, self._steps)

    def resample_episode(self, episode: Episode, step: int, random: np.random.Generator) -> Episode:
        """``episode`` with everything the controller has not seen at the decision of step ``step``
        redrawn from the task's generators (rows ``step + 1..``; see ``market.sample_future``)."""
        return sample_future(random, episode, step + 1, self.battery, self.market)

    def episode_parameters(self) -> dict:
        """What the episodes are drawn from (recorded in the test set)."""
        return {"battery": asdict(self.battery), "market": asdict(self.market)}

    def episode_ranges(self) -> dict:
        """What a stored episode may hold (checked before it is played): the initial charge and the start
        within the clock hour as drawn; each signal's base between its lowest and highest hourly plus event
        level, its true value within ``GAUSSIAN_BOUND_STD`` standard deviations of its OU deviation from that,
        and its forecasts within as many of their noise at the longest lead (or of the OU: lead 0 is the true value)."""
        market = self.market
        ranges = {"initial_soc": (market.initial_soc_low, market.initial_soc_high), "start_s": (0.0, SECONDS_PER_HOUR)}
        for name, (true, base, forecast) in SIGNAL_ARRAYS.items():
            signal: Signal = getattr(market, name)
            low, high = signal.hourly_low + signal.event_low, signal.hourly_high + signal.event_high
            ou = GAUSSIAN_BOUND_STD * signal.ou_std
            lead = max(ou, GAUSSIAN_BOUND_STD * signal.forecast_std_per_step * (market.forecast_steps - 1))
            ranges |= {base: (low, high), true: (low - ou, high + ou), forecast: (low - lead, high + lead)}
        return ranges

    def signals(self, episode: Episode) -> dict[str, np.ndarray]:
        """The episode's true prices and net production, per step, for recordings."""
        return {"price_eur_kwh": episode.price_eur_kwh, "net_production_kw": episode.production_kw}

    def initialize_episode(self, physics: Physics) -> None:
        episode = self.next_episode()
        self._step = 0
        physics.set_state_of_charge(episode.initial_soc)
        physics.set_net_production(episode.production_kw[0])

    def before_step(self, action, physics: Physics) -> None:
        physics.set_control(action)
        physics.set_net_production(self._episode.production_kw[self._step])
        self._step += 1

    def get_reward(self, physics: Physics) -> float:
        price = self._episode.price_eur_kwh[self._step - 1]  # the interval just traded
        revenue = price * physics.executed_trade_kw() * self.battery.interval_h
        if self._step == self._steps:
            revenue += self.terminal_price * self.battery.capacity_kwh * physics.state_of_charge()
        return revenue

    def get_termination(self, physics: Physics) -> float | None:
        return None if np.isfinite(physics.state_of_charge()) else 0.0

    def action_spec(self, physics: Physics) -> specs.BoundedArray:
        limit = self.battery.trade_limit_kw
        return specs.BoundedArray((2,), np.float64, [-limit, 0.0], [limit, 1.0], name="trade_kw,computing")

    def observation_spec(self, physics: Physics) -> collections.OrderedDict:
        n = self.market.forecast_steps
        shapes = {"production_forecast_kw": (n,), "price_forecast_eur_kwh": (n,)}
        return collections.OrderedDict((name, specs.Array(shapes.get(name, ()), np.float64, name=name)) for name in OBSERVATIONS)

    def get_observation(self, physics: Physics) -> collections.OrderedDict:
        e, k, n = self._episode, self._step, self.market.forecast_steps
        return collections.OrderedDict(
            (
                ("state_of_charge", np.float64(physics.state_of_charge())),
                ("net_production_kw", np.float64(e.production_kw[k])),
                ("price_eur_kwh", np.float64(e.price_eur_kwh[k])),
                ("production_forecast_kw", e.production_forecast_kw[k, :n]),
                ("price_forecast_eur_kwh", e.price_forecast_eur_kwh[k, :n]),
            )
        )


def make_environment(
    random: Random = None,
    battery: Battery = Battery(),
    market: Market = Market(),
    steps: int | None = None,
    environment_kwargs: dict | None = None,
) -> control.Environment:
    steps = battery.episode_steps if steps is None else steps
    task = Trading(random=random, battery=battery, market=market, steps=steps)
    return build_environment(Physics(battery), task, steps, battery.interval_s, environment_kwargs)


add_task(
    SUITE,
    "trading",
    make_environment,
    Battery().episode_steps,
    Battery().interval_s,
    "Trade a 10 kWh battery on the balance market: 100 intervals of 10 s by default.",
    episode=Episode,
)
