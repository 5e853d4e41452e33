"""Figures drawn from trajectories (matplotlib, headless Agg backend). Controllers never import this.

* :func:`forecast_figure`: the paper's Figure 1 for the battery: true production and price over an
  episode, with the forecasts each MPC computation was given (dashed, from the computation's cross
  onward), one column per policy.
"""

from __future__ import annotations

from collections.abc import Sequence

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from etmpc.loop import Trajectory  # noqa: E402

# (forecast name in Plan.forecasts, episode attribute of the true values, axis label)
_SIGNALS = (
    ("production_kw", "production_kw", "net production (kW)"),
    ("price_eur_kwh", "price_eur_kwh", "price (EUR/kWh)"),
)


def forecast_figure(episode, runs: Sequence[tuple[str, Trajectory]], dt_s: float, mean_price: float | None = None):
    """One column per ``(policy name, trajectory)`` of the same battery ``episode``."""
    fig, axes = plt.subplots(len(_SIGNALS), len(runs), figsize=(5.5 * len(runs), 6.0), sharex=True, squeeze=False)
    for col, (name, traj) in enumerate(runs):
        steps = traj.steps
        for row, (key, attribute, label) in enumerate(_SIGNALS):
            ax = axes[row, col]
            true = np.asarray(getattr(episode, attribute))[:steps]
            ax.plot(np.arange(steps) * dt_s, true, color="black", lw=1.4, label="true")
            for i, (k, plan) in enumerate(traj.plans):
                forecast = np.asarray(plan.forecasts[key])
                lead = np.arange(forecast.size)
                color = plt.cm.viridis(i / max(1, len(traj.plans) - 1))
                ax.plot((k + lead) * dt_s, forecast, ls="--", lw=0.9, color=color,
                        label="forecast at a computation" if i == 0 else None)
                ax.plot(k * dt_s, forecast[0], marker="x", ms=6, color=color)
            if key == "price_eur_kwh" and mean_price is not None:
                ax.axhline(mean_price, color="grey", lw=0.8, ls=":", label="mean price (value of storage)")
            ax.set_ylabel(label)
            ax.grid(alpha=0.3)
        axes[0, col].set_title(f"{name}: {traj.recomputes} computations")
        axes[-1, col].set_xlabel("time (s)")
    axes[0, 0].legend(loc="best", fontsize=8)
    axes[-1, 0].legend(loc="best", fontsize=8)
    fig.tight_layout()
    return fig
