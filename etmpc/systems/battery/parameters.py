"""Every number of the battery-trading task, in one declarative place, with units.

The plant constants are the paper's (docs/paper.md, "The paper's settings"). The paper gives no
numbers for the generators of production and price; the ones below are chosen so that the trading
problem is neither trivial nor hopeless, and the reasons are written next to them. Change them by
building a new :class:`Market` (``dataclasses.replace``); a test set records the values it was drawn
with.

Scales, for orientation: a full-power trade (360 kW for 10 s) moves 1 kWh, 10 % of the capacity;
a net production of 100 kW held for 10 s moves 2.8 %; the computer's 0.1 kW draw moves 0.003 %.
"""

from __future__ import annotations

from dataclasses import MISSING, dataclass
from typing import Any

from etmpc.common.checks import BadValue
from etmpc.common.declared import Checked, setting

SECONDS_PER_HOUR = 3600.0
#: The largest values an option may set: a capacity, a power, a signal's level (kW or EUR/kWh), a duration, and
#: an episode's or a forecast's length (10,000 intervals: the work of a run grows with it).
MAX_ENERGY_KWH, MAX_POWER_KW, MAX_LEVEL, MAX_DURATION_S, MAX_STEPS = 1e6, 1e6, 1e6, 1e6, 10_000


@dataclass(frozen=True)
class Battery(Checked):
    """The storage and its market access: the paper's numbers (its eq. battery; docs/paper.md)."""

    capacity_kwh: float = setting(10.0, low=1e-3, high=MAX_ENERGY_KWH, unit="kWh", why="C, the storage's capacity")  # C
    interval_s: float = setting(  # delta: one control interval
        10.0, low=1e-3, high=SECONDS_PER_HOUR, unit="s", why="delta, one control interval"
    )
    trade_fraction_per_interval: float = setting(  # |u| <= 0.1 C / delta: 10 % of the capacity per interval
        0.1, above=0, high=1, why="the largest trade per interval, as a share of the capacity"
    )
    compute_power_kw: float = setting(  # eta_c: drawn from the battery while the MPC computes
        0.1, low=0, high=MAX_POWER_KW, unit="kW", why="eta_c, drawn from the battery while the MPC computes"
    )
    episode_steps: int = setting(100, low=1, high=MAX_STEPS, unit="intervals", why="an episode's length")

    @property
    def interval_h(self) -> float:
        """delta in hours, as it enters the dynamics and the revenue ``lambda u delta``."""
        return self.interval_s / SECONDS_PER_HOUR

    @property
    def trade_limit_kw(self) -> float:
        return self.trade_fraction_per_interval * self.capacity_kwh / self.interval_h

    @property
    def soc_per_kw(self) -> float:
        """delta / C: change of state of charge per kW held over one interval."""
        return self.interval_h / self.capacity_kwh


def level(why: str) -> Any:
    """A signal's level (kW or EUR/kWh, its unit), as an option: it says how episodes are drawn."""
    return setting(MISSING, low=-MAX_LEVEL, high=MAX_LEVEL, draws=True, why=why)


def duration(why: str, low: float = 1e-3) -> Any:
    """A signal's time constant or mean duration, as an option."""
    return setting(MISSING, low=low, high=MAX_DURATION_S, unit="s", draws=True, why=why)


@dataclass(frozen=True)
class Signal(Checked):
    """A time-varying parameter: ``base + OU``, and how it is forecast.

    * **base**: an hourly level (fixed per clock hour, drawn ``U(hourly_low, hourly_high)``; the spot
      price) plus an event level (drawn ``U(event_low, event_high)`` and held for an exponentially
      distributed duration of mean ``event_mean_duration_s``, then redrawn);
    * **true value** = base + an Ornstein-Uhlenbeck deviation of time constant ``ou_time_constant_s``
      and stationary standard deviation ``ou_std`` (exact discretisation, started stationary);
    * **forecast** made at step ``k`` for lead ``j``: the true value at ``j = 0``; for ``j >= 1`` the
      base at ``k`` held constant plus ``forecast_std_per_step * j * z_j``, where ``z`` is a second,
      unit OU process along lead time with time constant ``forecast_time_constant_s``. The forecast
      knows neither the coming events nor the current OU deviation.
    """

    unit: str  # a label for tables and figures: not an option
    hourly_low: float = level("the hourly level's low end")
    hourly_high: float = level("the hourly level's high end")
    event_low: float = level("an event level's low end")
    event_high: float = level("an event level's high end")
    event_mean_duration_s: float = duration("an event's mean duration (exponential): events are drawn one by one", low=1.0)
    ou_time_constant_s: float = duration("the Ornstein-Uhlenbeck deviation's time constant")
    ou_std: float = setting(
        MISSING, low=0, high=MAX_LEVEL, draws=True, why="the Ornstein-Uhlenbeck deviation's stationary standard deviation"
    )
    forecast_std_per_step: float = setting(
        MISSING, low=0, high=MAX_LEVEL, draws=True, why="the forecast's noise per step of lead time"
    )
    forecast_time_constant_s: float = duration("the forecast noise's time constant along lead time")

    def __post_init__(self):
        super().__post_init__()
        for low, high in (("hourly_low", "hourly_high"), ("event_low", "event_high")):
            if getattr(self, low) > getattr(self, high):
                raise BadValue(f"{low} {getattr(self, low)} is above {high} {getattr(self, high)}")

    @property
    def mean(self) -> float:
        """E[value]: the OU deviation and the forecast noise have mean zero."""
        return 0.5 * (self.hourly_low + self.hourly_high) + 0.5 * (self.event_low + self.event_high)


# Net production minus consumption on the battery's grid, kW (> 0: surplus flows into the battery).
# Events are loads and generators switching (+-100 kW, 28 % of a full-power trade) every 4 minutes on
# average, so about one change falls inside each 200 s MPC horizon: plans go stale for a reason.
PRODUCTION = Signal(
    unit="kW",
    hourly_low=0.0,
    hourly_high=0.0,  # no hourly level: the events and the OU are the signal
    event_low=-100.0,
    event_high=100.0,
    event_mean_duration_s=240.0,
    ou_time_constant_s=60.0,
    ou_std=15.0,
    forecast_std_per_step=2.0,
    forecast_time_constant_s=60.0,
)  # 38 kW at a 20-step forecast's last lead

# Balance-market price, EUR/kWh. The spot price (40-60 EUR/MWh) is fixed per clock hour; imbalance
# events move the balance price by up to +-30 EUR/MWh for two minutes on average, and a fast OU
# (30 s, 10 EUR/MWh) adds the noise of the balance market. Its mean, 0.05 EUR/kWh, is the terminal
# value of stored energy.
PRICE = Signal(
    unit="EUR/kWh",
    hourly_low=0.04,
    hourly_high=0.06,  # the spot price, fixed per clock hour
    event_low=-0.03,
    event_high=0.03,
    event_mean_duration_s=120.0,
    ou_time_constant_s=30.0,
    ou_std=0.01,
    forecast_std_per_step=0.001,
    forecast_time_constant_s=60.0,
)  # 0.019 EUR/kWh at the last lead


@dataclass(frozen=True)
class Market(Checked):
    """Everything random about a trading episode."""

    production: Signal = PRODUCTION
    price: Signal = PRICE
    forecast_steps: int = setting(  # values per forecast (k .. k+19): the paper's horizon N
        20, low=1, high=MAX_STEPS, unit="intervals", draws=True, why="values per forecast: at least the MPC's horizon"
    )
    initial_soc_low: float = setting(0.1, low=0, high=1, draws=True, why="x_0 ~ U(low, high): its low end")
    initial_soc_high: float = setting(0.9, low=0, high=1, draws=True, why="x_0 ~ U(low, high): its high end")
    # Each episode starts at a uniform time within the clock hour, so the 1000 s of about 28 % of
    # the episodes see the spot price change.

    def __post_init__(self):
        super().__post_init__()
        if self.initial_soc_low > self.initial_soc_high:
            raise BadValue(f"initial_soc_low {self.initial_soc_low} is above initial_soc_high {self.initial_soc_high}")
