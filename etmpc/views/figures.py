"""Figures drawn from trajectories (matplotlib, headless Agg backend). Controllers never import this.

* :func:`forecast_figure`: the paper's Figure 1 for the battery: true production and price over an
  episode, with the forecasts each MPC solve was given (dashed, from the solve's cross
  onward), one column per policy.
* :func:`draw_trajectory` / :func:`write_trajectory_png`: one episode, as in the paper's reference
  implementation: every state with every plan's prediction (dashed) and the recompute steps, the
  applied and planned inputs with their bounds, and the episode's exogenous signals.
* :func:`draw_policy_bars` / :func:`write_policy_bars_png`: the paper's Figure 3, the mean objective
  per policy from ``etmpc evaluate --json`` documents, with the learned policy's seeds as one bar
  (:mod:`etmpc.views.bars`, re-exported here).
* :func:`draw_performance_profile` / :func:`write_performance_profile_png`: the scorecard's
  performance profiles (``etmpc score --figure``).

PNGs are written atomically (a temporary file renamed into place).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from etmpc.loop import Trajectory  # noqa: E402
from etmpc.common.wording import unit_label  # noqa: E402
from etmpc.views.png import save_png_atomically  # noqa: E402
from etmpc.views.bars import (  # noqa: E402, F401 (the paper's Figure 3, re-exported)
    Bar,
    draw_policy_bars,
    is_clairvoyant,
    policy_bars,
    write_policy_bars_png,
)

# (forecast name in Plan.forecasts, episode attribute of the true values, axis label)
_SIGNALS = (("production_kw", "production_kw", "net production (kW)"), ("price_eur_kwh", "price_eur_kwh", "price (EUR/kWh)"))


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
                ax.plot(
                    (k + lead) * dt_s, forecast, ls="--", lw=0.9, color=color, label="forecast at a solve" if i == 0 else None
                )
                ax.plot(k * dt_s, forecast[0], marker="x", ms=6, color=color)
            if key == "price_eur_kwh" and mean_price is not None:
                ax.axhline(mean_price, color="grey", lw=0.8, ls=":", label="mean price (value of storage)")
            ax.set_ylabel(label)
            ax.grid(alpha=0.3)
        axes[0, col].set_title(f"{name}: {traj.recomputes} recomputes")
        axes[-1, col].set_xlabel("time (s)")
    axes[0, 0].legend(loc="best", fontsize=8)
    axes[-1, 0].legend(loc="best", fontsize=8)
    fig.tight_layout()
    return fig


# -- one episode: states, plans, inputs ------------------------------------------------------------
# Axis labels with units for the names systems use; other names get their words.
_LABELS = {
    "cart_position": "cart position (m)",
    "cart_velocity": "cart velocity (m/s)",
    "pole_angle": "pole angle (rad)",
    "pole_angular_velocity": "pole ang. vel. (rad/s)",
    "force_n": "force on cart (N)",
    "state_of_charge": "state of charge (fraction)",
    "trade_kw": "trade (kW, + sells)",
    "price_eur_kwh": "price (EUR/kWh)",
    "net_production_kw": "net production (kW)",
    "disturbance_rad_s2": "disturbance (rad/s²)",
}


def axis_label(name: str) -> str:
    """An axis label with the unit for a state, input or signal name: the ones above, else read from its unit
    suffix (:func:`etmpc.common.wording.unit_label`)."""
    return _LABELS.get(name) or unit_label(name)


def _held(values: np.ndarray, dt_s: float) -> tuple[np.ndarray, np.ndarray]:
    """A per-step value held over its interval, as ``steps-post`` data: the last value is repeated
    at the end of the last interval so that interval shows."""
    values = np.asarray(values, dtype=float)
    if values.size == 0:
        return np.zeros(0), np.zeros(0)
    return np.arange(values.size + 1) * dt_s, np.append(values, values[-1])


def draw_trajectory(system, traj: Trajectory, title: str | None = None, signals: Mapping[str, np.ndarray] | None = None):
    """One episode against time (s): a panel per state, per input and per exogenous signal.

    State panels: the realised state (solid, ``gid="realised"``); every plan the loop used
    (``traj.plans``) as a dashed line of its predicted states ``plan.states[j]`` at steps ``k + j``,
    clipped to the episode (``gid="plan"``, in plan order); the recompute steps as markers on the
    realised state, the policy's (``gid="recompute"``) and the forced ones (``gid="forced"``).
    Input panels: the applied input (solid, held over each interval, ``gid="applied"``), the plan's
    input (dashed, ``gid="planned"``) and the bounds (dotted, ``gid="bound"``). ``signals``
    (e.g. ``system.signals(episode)``, per step) get a panel each (``gid="signal"``).
    """
    dt, steps = float(system.control_interval_s), int(traj.steps)
    signals = dict(signals or {})
    nx, nu = len(system.state_names), len(system.input_names)
    panels = nx + nu + len(signals)
    fig, axes = plt.subplots(panels, 1, figsize=(9.5, 1.75 * panels + 1.0), sharex=True, squeeze=False)
    axes = axes[:, 0]
    t = np.arange(steps + 1) * dt
    decided = np.flatnonzero(traj.recompute[:steps] & ~traj.forced[:steps])
    forced = np.flatnonzero(traj.forced[:steps])
    colors = [plt.cm.viridis(i / max(1, len(traj.plans) - 1)) for i in range(len(traj.plans))]
    recomputes = (  # the steps marked on the realised state: (steps, gid, legend label, marker style)
        (decided, "recompute", "recompute (policy)", dict(marker="o", mfc="none", mec="tab:blue")),
        (forced, "forced", "recompute (forced: no plan left)", dict(marker="s", color="tab:red")),
    )

    for i, name in enumerate(system.state_names):
        ax = axes[i]
        ax.plot(t, traj.states[: steps + 1, i], color="black", lw=1.6, label="realised", gid="realised", zorder=3)
        for p, (k, plan) in enumerate(traj.plans):
            j = np.arange(min(plan.horizon, steps - k) + 1)
            ax.plot(
                (k + j) * dt,
                plan.states[j, i],
                ls="--",
                lw=0.8,
                color=colors[p],
                alpha=0.85,
                gid="plan",
                label="plan's prediction (one per recompute)" if p == 0 else None,
            )
        for at, gid, label, style in recomputes:
            for line in ax.plot(
                at * dt, traj.states[at, i], ls="none", ms=4.5, label=label if at.size else None, gid=gid, zorder=4, **style
            ):  # whole at the axes' edges, and no part of the layout (an empty one would upset it)
                line.set_clip_on(False)
                line.set_in_layout(False)
        ax.set_ylabel(axis_label(name))

    for i, name in enumerate(system.input_names):
        ax = axes[nx + i]
        ax.plot(
            *_held(traj.applied[:steps, i], dt), drawstyle="steps-post", color="black", lw=1.4, label="applied", gid="applied"
        )
        ax.plot(
            *_held(traj.planned[:steps, i], dt),
            drawstyle="steps-post",
            ls="--",
            color="tab:orange",
            lw=1.1,
            label="planned (before LQR correction)",
            gid="planned",
        )
        bounds: tuple[tuple[float, str | None], ...] = ((system.u_min[i], "bounds"), (system.u_max[i], None))
        for bound, bound_label in bounds:
            ax.axhline(bound, color="grey", ls=":", lw=1.0, label=bound_label, gid="bound")
        ax.set_ylabel(axis_label(name))

    for i, (name, values) in enumerate(signals.items()):
        ax = axes[nx + nu + i]
        ax.plot(
            *_held(np.asarray(values)[:steps], dt),
            drawstyle="steps-post",
            color="tab:green",
            lw=1.2,
            label="true (episode)",
            gid="signal",
        )
        ax.set_ylabel(axis_label(name))

    for ax in axes:
        ax.grid(alpha=0.3)
        ax.yaxis.set_label_coords(-0.085, 0.5)  # aligned whatever the tick labels' widths
    axes[0].legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)
    if nu:
        axes[nx].legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)
    if signals:
        axes[nx + nu].legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)
    axes[-1].set_xlabel("time (s)")
    axes[-1].set_xlim(0, max(steps, 1) * dt)
    if title is None:
        title = f"{system.domain}: {steps} steps, {traj.recomputes} recomputes ({forced.size} forced)"
    fig.suptitle(title, fontsize=11)
    fig.tight_layout()
    return fig


def write_trajectory_png(
    path, system, traj: Trajectory, title: str | None = None, signals: Mapping[str, np.ndarray] | None = None
) -> Path:
    """:func:`draw_trajectory` written atomically to ``path`` (PNG)."""
    return save_png_atomically(draw_trajectory(system, traj, title, signals), path)


def draw_performance_profile(curves: Mapping[str, np.ndarray], thresholds: np.ndarray, tasks: Sequence[str]):
    """The scorecard's performance profiles: per policy, the share of episodes (averaged over tasks)
    whose normalized score exceeds each threshold, with the two references' scores marked."""
    fig, ax = plt.subplots(figsize=(7.5, 4.5), layout="constrained")
    for policy, curve in curves.items():
        ax.step(thresholds, curve, where="post", label=policy)
    for x, name in ((0.0, "best periodic"), (100.0, "oracle")):
        ax.axvline(x, color="0.6", linestyle=":", linewidth=1)
        ax.text(x, 1.02, name, ha="center", va="bottom", fontsize=8, color="0.4", transform=ax.get_xaxis_transform())
    ax.set_xlabel("normalized score τ (0: the task's best periodic schedule, 100: the oracle over it)")
    ax.set_ylabel("share of episodes with score > τ")
    ax.set_ylim(-0.02, 1.02)
    ax.set_title(f"Performance profiles over {len(tasks)} task(s): {', '.join(tasks)}", fontsize=9, pad=20)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="lower left")
    return fig


def write_performance_profile_png(path, curves: Mapping[str, np.ndarray], thresholds: np.ndarray, tasks: Sequence[str]) -> Path:
    """:func:`draw_performance_profile` written atomically to ``path`` (PNG)."""
    return save_png_atomically(draw_performance_profile(curves, thresholds, tasks), path)
