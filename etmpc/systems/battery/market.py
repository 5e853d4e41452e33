"""Drawing the time-varying parameters of a trading episode: true values and every forecast.

Everything is drawn in advance from the episode's generator, in a fixed order, so a stored episode
(:class:`Episode`) holds the whole realisation and a replay needs no randomness.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, fields
from itertools import accumulate

import numpy as np

from etmpc.systems.battery.parameters import SECONDS_PER_HOUR, Battery, Market, Signal


def ou_path(
    rng: np.random.Generator, steps: int, dt_s: float, time_constant_s: float, std: float, rows: int | None = None
) -> np.ndarray:
    """Stationary Ornstein-Uhlenbeck samples at ``dt_s`` spacing, exactly discretised.

    ``o_0 ~ N(0, std^2)``, ``o_{k+1} = rho o_k + std sqrt(1 - rho^2) xi_k`` with ``rho = exp(-dt/tau)``.
    With ``rows``, draws that many independent paths (shape ``(rows, steps)``).
    """
    rho = math.exp(-dt_s / time_constant_s)  # libm's, not numpy's vectorised exp (which differs by CPU)
    shape = (steps,) if rows is None else (rows, steps)
    xi = rng.standard_normal(shape)
    xi[..., 1:] *= np.sqrt(1.0 - rho * rho)
    path = np.empty(shape)
    path[..., 0] = xi[..., 0]
    for k in range(1, steps):
        path[..., k] = rho * path[..., k - 1] + xi[..., k]
    return std * path


def event_levels(rng: np.random.Generator, times_s: np.ndarray, low: float, high: float, mean_duration_s: float) -> np.ndarray:
    """A level redrawn ``U(low, high)`` at the end of each exponentially distributed event.

    The first event is already running at ``times_s[0]``; by memorylessness its remaining duration
    has the same exponential law, so the process is stationary from the start.
    """
    levels = np.empty(times_s.shape)
    end = times_s[0] + rng.exponential(mean_duration_s)
    level = rng.uniform(low, high)
    for k, t in enumerate(times_s):
        while t >= end:
            end += rng.exponential(mean_duration_s)
            level = rng.uniform(low, high)
        levels[k] = level
    return levels


def draw_signal(
    rng: np.random.Generator, signal: Signal, start_s: float, steps: int, dt_s: float, forecast_steps: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(true, base, forecasts)`` for steps ``0..steps-1`` of an episode starting ``start_s`` into
    the clock hour; ``forecasts[k, j]`` is the forecast made at ``k`` for ``k + j`` (``[k, 0]`` is the
    true value at ``k``)."""
    times_s = start_s + dt_s * np.arange(steps)
    hours = np.floor(times_s / SECONDS_PER_HOUR).astype(int)
    hourly = rng.uniform(signal.hourly_low, signal.hourly_high, size=hours[-1] + 1)[hours]
    base = hourly + event_levels(rng, times_s, signal.event_low, signal.event_high, signal.event_mean_duration_s)
    true = base + ou_path(rng, steps, dt_s, signal.ou_time_constant_s, signal.ou_std)
    lead = np.arange(forecast_steps)
    noise = ou_path(rng, forecast_steps, dt_s, signal.forecast_time_constant_s, 1.0, rows=steps)
    forecasts = base[:, None] + signal.forecast_std_per_step * lead * noise
    forecasts[:, 0] = true
    return true, base, forecasts


@dataclass(frozen=True, eq=False)
class Episode:
    """Everything random about one trading episode, drawn in advance: a test-set row.

    Signals have one row per observation (``steps + 1``: the last is seen at the final timestep);
    forecasts are ``(steps + 1, forecast_steps)``, ``[k, j]`` made at ``k`` for ``k + j``.
    """

    initial_soc: float
    start_s: float  # seconds into the clock hour at step 0
    production_kw: np.ndarray
    production_base_kw: np.ndarray
    production_forecast_kw: np.ndarray
    price_eur_kwh: np.ndarray
    price_base_eur_kwh: np.ndarray
    price_forecast_eur_kwh: np.ndarray

    def __post_init__(self):
        for f in fields(self)[2:]:
            getattr(self, f.name).flags.writeable = False  # observations hand out views of these

    @property
    def steps(self) -> int:
        return self.production_kw.shape[0] - 1

    @classmethod
    def draw(
        cls, rng: np.random.Generator, battery: Battery = Battery(), market: Market = Market(), steps: int | None = None
    ) -> Episode:
        steps = battery.episode_steps if steps is None else steps
        initial_soc = float(rng.uniform(market.initial_soc_low, market.initial_soc_high))
        start_s = float(rng.uniform(0.0, SECONDS_PER_HOUR))
        signals = [
            draw_signal(rng, signal, start_s, steps + 1, battery.interval_s, market.forecast_steps)
            for signal in (market.production, market.price)
        ]
        return cls(initial_soc, start_s, *signals[0], *signals[1])

    def arrays(self) -> dict[str, np.ndarray]:
        return {f.name: np.asarray(getattr(self, f.name), dtype=float) for f in fields(self)}

    @classmethod
    def from_arrays(cls, arrays: dict[str, np.ndarray]) -> Episode:
        names = [f.name for f in fields(cls)]
        missing = [name for name in names if name not in arrays]
        if missing:
            raise ValueError(f"bad episode arrays: missing {', '.join(missing)}")
        values = {name: np.array(arrays[name], dtype=float) for name in names}
        rows = values["production_kw"].shape
        signals, forecasts = names[2:], ("production_forecast_kw", "price_forecast_eur_kwh")
        if (
            values["initial_soc"].shape != ()
            or len(rows) != 1
            or any(values[name].shape[0] != rows[0] or values[name].ndim != (2 if name in forecasts else 1) for name in signals)
        ):
            raise ValueError("bad episode arrays: inconsistent shapes " + str({n: values[n].shape for n in names}))
        return cls(float(values["initial_soc"]), float(values["start_s"]), *(values[name] for name in signals))


# Each Market signal's arrays in an Episode: (true, base, forecast).
SIGNAL_ARRAYS = {
    "production": ("production_kw", "production_base_kw", "production_forecast_kw"),
    "price": ("price_eur_kwh", "price_base_eur_kwh", "price_forecast_eur_kwh"),
}


def sample_future(rng: np.random.Generator, episode: Episode, known_rows: int, battery: Battery, market: Market) -> Episode:
    """A copy of ``episode`` whose rows ``known_rows..`` are redrawn from the task's generators,
    conditioned only on what a controller has seen by row ``k = known_rows - 1`` (``1 <= known_rows
    <= steps + 1``): the true values and forecast rows up to ``k``, and the clock.

    Rows ``< known_rows`` are the input's, bit for bit; nothing at or after ``known_rows`` is read.
    Per signal, from row ``k`` on:

    * **base now** ``b = forecast[k, 1]``, the lead-1 forecast (the true value if there is no lead 1).
      An approximation: the lead-1 forecast is the base plus noise of std ``forecast_std_per_step``,
      small beside the event levels; the earlier rows' information about the base is not used either.
    * **OU deviation** ``o = true[k] - b``, continued exactly: ``o+ = rho o + ou_std sqrt(1 - rho^2) xi``,
      ``rho = exp(-dt / ou_time_constant_s)``; ``true = base + o``.
    * **hourly level** of the current clock hour from its posterior given ``b = hourly + event``, both
      uniform: ``U[max(h_lo, b - e_hi), min(h_hi, b - e_lo)]``; if noise in ``b`` empties that interval,
      the feasible hourly level nearest to it. The event level is ``b - hourly``. Each later clock hour
      draws a new hourly level ``U(h_lo, h_hi)``.
    * **events**: the current one lasts a further ``Exp(event_mean_duration_s)`` from the clock time
      of row ``k`` (memoryless), then each new event draws ``U(e_lo, e_hi)`` and lasts ``Exp(mean)``;
      ``base = hourly + event``.
    * **forecast rows** as :func:`draw_signal` makes them: the row's base held plus
      ``forecast_std_per_step * j * z_j``, ``z`` a fresh unit OU path along the lead; ``[r, 0]`` is the
      true value.
    """
    steps, dt_s = episode.steps, battery.interval_s
    if not 1 <= known_rows <= steps + 1:
        raise ValueError(f"known_rows must be in 1..{steps + 1}, got {known_rows}")
    k, new = known_rows - 1, steps + 1 - known_rows
    now_s = episode.start_s + dt_s * k
    times_s = episode.start_s + dt_s * np.arange(known_rows, steps + 1)
    hours = (np.floor(times_s / SECONDS_PER_HOUR) - np.floor(now_s / SECONDS_PER_HOUR)).astype(int)  # 0: this hour
    arrays: dict[str, np.ndarray] = {}
    for name, names in SIGNAL_ARRAYS.items():
        signal: Signal = getattr(market, name)
        true, base, forecast = (np.array(getattr(episode, a)) for a in names)
        if new:
            b = float(forecast[k, 1] if forecast.shape[1] > 1 else true[k])
            low, high = max(signal.hourly_low, b - signal.event_high), min(signal.hourly_high, b - signal.event_low)
            if low < high:
                hourly = rng.uniform(low, high)
            else:  # a point, or empty (b beyond h + e): the feasible hourly level nearest to b's
                hourly = low if b < signal.hourly_low + signal.event_low else high
            hourly_levels = np.concatenate(([hourly], rng.uniform(signal.hourly_low, signal.hourly_high, hours[-1])))
            ends_s = [now_s + rng.exponential(signal.event_mean_duration_s)]
            while ends_s[-1] <= times_s[-1]:
                ends_s.append(ends_s[-1] + rng.exponential(signal.event_mean_duration_s))
            events = np.concatenate(([b - hourly], rng.uniform(signal.event_low, signal.event_high, len(ends_s) - 1)))
            base[known_rows:] = hourly_levels[hours] + events[np.searchsorted(ends_s, times_s, side="right")]
            rho = math.exp(-dt_s / signal.ou_time_constant_s)
            xi = signal.ou_std * np.sqrt(1.0 - rho * rho) * rng.standard_normal(new)
            deviation = list(accumulate(xi.tolist(), lambda o, x: rho * o + x, initial=true[k] - b))[1:]
            true[known_rows:] = base[known_rows:] + deviation
            lead = np.arange(forecast.shape[1])
            noise = ou_path(rng, forecast.shape[1], dt_s, signal.forecast_time_constant_s, 1.0, rows=new)
            forecast[known_rows:] = base[known_rows:, None] + signal.forecast_std_per_step * lead * noise
            forecast[known_rows:, 0] = true[known_rows:]
        arrays.update(zip(names, (true, base, forecast)))
    # the keys are SIGNAL_ARRAYS' names, the Episode's array fields: mypy checks a ** mapping against every field
    return dataclasses.replace(episode, **arrays)  # type: ignore[arg-type]
