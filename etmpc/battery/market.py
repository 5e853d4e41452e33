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


def sample_future(rng: np.random.Generator, episode, known_rows: int, battery, market):
    """A copy of ``episode`` (an :class:`etmpc.battery.env.Episode`) whose rows ``known_rows..`` are
    redrawn from the task's generators, conditioned only on what a controller has seen by row
    ``k = known_rows - 1``: the true values and the forecast rows up to ``k``, and the clock.

    Per signal, conditioned on row ``k``:

    * the base now is estimated as the lead-1 forecast ``forecast[k, 1]`` (an approximation: its noise,
      ``forecast_std_per_step``, is small beside the event levels; the true value if there is no lead 1);
    * the OU deviation ``o = true[k] - base`` continues exactly, ``o+ = rho o + std sqrt(1 - rho^2) xi``;
    * the current hour's hourly level is drawn from its posterior given ``base = hourly + event`` with
      both uniform: uniform on ``[max(h_lo, base - e_hi), min(h_hi, base - e_lo)]``; the event level is
      the rest. The current event lasts a further ``Exp(mean)`` (memoryless), then new events follow;
      each new clock hour draws a new hourly level;
    * forecast rows are made as :func:`draw_signal` makes them.

    Rows ``< known_rows`` are the input's, bit for bit; nothing at or after ``known_rows`` is read.
    """
    from etmpc.battery.env import Episode

    steps = episode.steps
    if not 1 <= known_rows <= steps + 1:
        raise ValueError(f"known_rows must be in 1..{steps + 1}, got {known_rows}")
    arrays = {name: np.array(value) for name, value in episode.arrays().items()}
    if known_rows == steps + 1:
        return Episode.from_arrays(arrays)
    k, dt = known_rows - 1, battery.interval_s
    new = steps + 1 - known_rows  # rows to draw
    times_s = episode.start_s + dt * np.arange(known_rows, steps + 1)
    for prefix, signal in (("production", market.production), ("price", market.price)):
        true_name = f"{prefix}_{'kw' if prefix == 'production' else 'eur_kwh'}"
        base_name = true_name.replace(prefix, f"{prefix}_base", 1)
        forecast_name = true_name.replace(prefix, f"{prefix}_forecast", 1)
        forecast = arrays[forecast_name]
        base_now = forecast[k, 1] if forecast.shape[1] > 1 else arrays[true_name][k]
        # The hourly level of the current hour, from its posterior; the event level is the rest.
        low = max(signal.hourly_low, base_now - signal.event_high)
        high = min(signal.hourly_high, base_now - signal.event_low)
        hourly = rng.uniform(low, high) if high > low else float(np.clip(base_now - 0.5 * (signal.event_low + signal.event_high),
                                                                        signal.hourly_low, signal.hourly_high))
        event = base_now - hourly
        # Events after row k: the current one lasts a further Exp(mean); each new hour redraws the hourly level.
        hour_now = np.floor((episode.start_s + dt * k) / SECONDS_PER_HOUR)
        base = np.empty(new)
        end = episode.start_s + dt * k + rng.exponential(signal.event_mean_duration_s)
        hours = {hour_now: hourly}
        for r, t in enumerate(times_s):
            while t >= end:
                end += rng.exponential(signal.event_mean_duration_s)
                event = rng.uniform(signal.event_low, signal.event_high)
            hour = np.floor(t / SECONDS_PER_HOUR)
            if hour not in hours:
                hours[hour] = rng.uniform(signal.hourly_low, signal.hourly_high)
            base[r] = hours[hour] + event
        # The OU deviation, continued exactly from its value now.
        rho = np.exp(-dt / signal.ou_time_constant_s)
        xi = rng.standard_normal(new) * signal.ou_std * np.sqrt(1.0 - rho * rho)
        deviation = np.empty(new)
        o = arrays[true_name][k] - base_now
        for r in range(new):
            o = rho * o + xi[r]
            deviation[r] = o
        true = base + deviation
        lead = np.arange(forecast.shape[1])
        noise = ou_path(rng, forecast.shape[1], dt, signal.forecast_time_constant_s, 1.0, rows=new)
        rows = base[:, None] + signal.forecast_std_per_step * lead * noise
        rows[:, 0] = true
        arrays[true_name][known_rows:] = true
        arrays[base_name][known_rows:] = base
        forecast[known_rows:] = rows
    return Episode.from_arrays(arrays)
