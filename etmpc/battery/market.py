"""Drawing the time-varying parameters of a trading episode: true values and every forecast.

Everything is drawn in advance from the episode's generator, in a fixed order, so a stored episode
holds the whole realisation and a replay needs no randomness (see :class:`etmpc.battery.env.Episode`).
"""

from __future__ import annotations

import numpy as np

from etmpc.battery.parameters import SECONDS_PER_HOUR, Signal


def ou_path(rng: np.random.Generator, steps: int, dt_s: float, time_constant_s: float, std: float,
            rows: int | None = None) -> np.ndarray:
    """Stationary Ornstein-Uhlenbeck samples at ``dt_s`` spacing, exactly discretised.

    ``o_0 ~ N(0, std^2)``, ``o_{k+1} = rho o_k + std sqrt(1 - rho^2) xi_k`` with ``rho = exp(-dt/tau)``.
    With ``rows``, draws that many independent paths (shape ``(rows, steps)``).
    """
    rho = np.exp(-dt_s / time_constant_s)
    shape = (steps,) if rows is None else (rows, steps)
    xi = rng.standard_normal(shape)
    xi[..., 1:] *= np.sqrt(1.0 - rho * rho)
    path = np.empty(shape)
    path[..., 0] = xi[..., 0]
    for k in range(1, steps):
        path[..., k] = rho * path[..., k - 1] + xi[..., k]
    return std * path


def event_levels(rng: np.random.Generator, times_s: np.ndarray, low: float, high: float,
                 mean_duration_s: float) -> np.ndarray:
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


def draw_signal(rng: np.random.Generator, signal: Signal, start_s: float, steps: int, dt_s: float,
                forecast_steps: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
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
