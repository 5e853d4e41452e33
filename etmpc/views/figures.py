"""Figures drawn from trajectories (matplotlib, headless Agg backend). Controllers never import this.

* :func:`forecast_figure`: the paper's Figure 1 for the battery: true production and price over an
  episode, with the forecasts each MPC computation was given (dashed, from the computation's cross
  onward), one column per policy.
* :func:`draw_trajectory` / :func:`write_trajectory_png`: one episode, as in the paper's reference
  implementation: every state with every plan's prediction (dashed) and the recompute steps, the
  applied and planned inputs with their bounds, and the episode's exogenous signals.
* :func:`draw_policy_bars` / :func:`write_policy_bars_png`: the paper's Figure 3, the mean objective
  per policy from ``etmpc evaluate --json`` documents, with the learned policy's seeds as one bar.
* :func:`draw_performance_profile` / :func:`write_performance_profile_png`: the scorecard's
  performance profiles (``etmpc score --figure``).

PNGs are written atomically (a temporary file renamed into place).
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path, PurePosixPath

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from matplotlib.patches import Patch  # noqa: E402

from etmpc.common.errors import EtmpcError  # noqa: E402
from etmpc.loop import Trajectory  # noqa: E402
from etmpc.policies.specs import find  # noqa: E402
from etmpc.common.outputs import atomic_path  # noqa: E402
from etmpc.common.sense import cost_or_profit, higher_or_lower  # noqa: E402
from etmpc.views.blueprint import objective_unit  # noqa: E402

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
                    (k + lead) * dt_s,
                    forecast,
                    ls="--",
                    lw=0.9,
                    color=color,
                    label="forecast at a computation" if i == 0 else None,
                )
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
    """An axis label with the unit for a state, input or signal name (its words if unknown)."""
    return _LABELS.get(name, name.replace("_", " "))


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
                label="plan's prediction (one per computation)" if p == 0 else None,
            )
        markers = [
            *ax.plot(
                decided * dt,
                traj.states[decided, i],
                ls="none",
                marker="o",
                ms=4.5,
                mfc="none",
                mec="tab:blue",
                label="recompute (policy)" if decided.size else None,
                gid="recompute",
                zorder=4,
            ),
            *ax.plot(
                forced * dt,
                traj.states[forced, i],
                ls="none",
                marker="s",
                ms=4.5,
                color="tab:red",
                label="recompute (forced: no plan left)" if forced.size else None,
                gid="forced",
                zorder=4,
            ),
        ]
        for line in markers:  # whole at the axes' edges, and no part of the layout (an empty one would upset it)
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
        for bound, label in ((system.u_min[i], "bounds"), (system.u_max[i], None)):
            ax.axhline(bound, color="grey", ls=":", lw=1.0, label=label, gid="bound")
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
        title = f"{system.domain}: {steps} steps, {traj.recomputes} computations ({forced.size} forced)"
    fig.suptitle(title, fontsize=11)
    fig.tight_layout()
    return fig


def write_trajectory_png(
    path, system, traj: Trajectory, title: str | None = None, signals: Mapping[str, np.ndarray] | None = None
) -> Path:
    """:func:`draw_trajectory` written atomically to ``path`` (PNG)."""
    return save_png_atomically(draw_trajectory(system, traj, title, signals), path)


# -- the paper's Figure 3: the objective per policy ----------------------------------------------
# rl:<run dir>/seed<S>/last.json: the final policy of one training seed (etmpc train's layout).
_LEARNED = re.compile(r"^rl:(?:(?P<run>.*)/)?seed(?P<seed>\d+)/last\.json$")


@dataclass(frozen=True)
class Bar:
    """One bar of :func:`draw_policy_bars`: a policy, or the seeds of one training run together."""

    label: str
    mean: float  # objective: the policy's mean, or the mean over seeds of their means
    error: float  # std over the repeats' means, or over the seeds' means (0: none)
    recomputes: float  # mean per episode (over seeds for a group)
    policies: tuple[str, ...]  # the specs drawn by this bar
    stochastic: bool
    bound: bool = False  # an oracle: an upper bound that knows the future, not a policy


def _check_evaluations(evaluations: Sequence[dict], sources: Sequence[str] | None) -> list[str]:
    """Check the documents are evaluations of one task on one test set; return their names."""
    if not evaluations:
        raise EtmpcError("no evaluation to draw")
    names = list(sources) if sources is not None else [f"evaluation {i + 1}" for i in range(len(evaluations))]
    for name, doc in zip(names, evaluations):
        if not (
            isinstance(doc, dict)
            and isinstance(doc.get("policies"), dict)
            and doc["policies"]
            and "domain" in doc
            and "task" in doc
        ):
            raise EtmpcError(f"{name} is not an `etmpc evaluate --json` document (no domain, task or policies)")
        for spec, summary in doc["policies"].items():
            missing = [
                key
                for key in ("objective_mean", "objective_std_repeats", "objective_sense", "recomputes_mean", "episodes")
                if not isinstance(summary, dict) or key not in summary
            ]
            if missing:
                raise EtmpcError(f"{name}: policy {spec!r} has no {', '.join(missing)}")
    first, name0 = evaluations[0], names[0]
    what = lambda doc: f"{doc['domain']}/{doc['task']}"  # noqa: E731
    for name, doc in zip(names[1:], evaluations[1:]):
        if what(doc) != what(first):
            raise EtmpcError(f"mismatched tasks: {name0} evaluates {what(first)}, {name} {what(doc)}")
        sha = lambda d: (d.get("test_set") or {}).get("sha256")  # noqa: E731
        if sha(doc) != sha(first):
            raise EtmpcError(f"mismatched test sets: {name0} and {name} were evaluated on different test sets")
    episodes = {(name, summary["episodes"]) for name, doc in zip(names, evaluations) for summary in doc["policies"].values()}
    if len({n for _, n in episodes}) > 1:
        shown = ", ".join(f"{name}: {n}" for name, n in sorted(episodes))
        raise EtmpcError(f"mismatched test-set episodes ({shown}): the means would be over different episodes")
    return names


def policy_bars(evaluations: Sequence[dict], group_learned: bool = True, sources: Sequence[str] | None = None) -> list[Bar]:
    """The bars :func:`draw_policy_bars` draws, in the order the policies first appear."""
    names = _check_evaluations(evaluations, sources)
    summaries: dict[str, dict] = {}
    for name, doc in zip(names, evaluations):
        for spec, summary in doc["policies"].items():
            if spec in summaries and summaries[spec] != summary:
                raise EtmpcError(f"policy {spec!r} appears in more than one evaluation with different results ({name})")
            summaries[spec] = summary
    runs: dict[str, list[str]] = {}  # training run dir -> its seeds' specs
    if group_learned:
        for spec in summaries:
            match = _LEARNED.match(spec)
            if match:
                runs.setdefault(match["run"] or ".", []).append(spec)
    bars, drawn = [], set()
    for spec, summary in summaries.items():
        if spec in drawn:
            continue
        match = _LEARNED.match(spec) if group_learned else None
        if match:
            members = runs[match["run"] or "."]
            means = np.array([summaries[m]["objective_mean"] for m in members], dtype=float)
            recomputes = np.array([summaries[m]["recomputes_mean"] for m in members], dtype=float)
            n = len(members)
            label = f"learned ({n} seed{'s' if n > 1 else ''})"
            if len(runs) > 1:
                label = f"learned {_short_path(match['run'] or '.')}\n({n} seed{'s' if n > 1 else ''})"
            error = float(np.std(means, ddof=1)) if n > 1 else float(summary["objective_std_repeats"])
            bars.append(Bar(label, float(np.mean(means)), error, float(np.mean(recomputes)), tuple(members), True))
            drawn.update(members)
        else:
            kind = find(spec)  # None: a policy object's own name
            learned = kind is not None and kind.name == "rl"
            label = f"rl:{_short_path(spec.partition(':')[2])}" if learned else spec
            bound = is_upper_bound(spec)
            bars.append(
                Bar(
                    label + ("\n(upper bound)" if bound else ""),
                    float(summary["objective_mean"]),
                    float(summary["objective_std_repeats"]),
                    float(summary["recomputes_mean"]),
                    (spec,),
                    learned,
                    bound,
                )
            )
            drawn.add(spec)
    return bars


def is_upper_bound(spec: str) -> bool:
    """Whether ``spec`` is an upper bound's (``oracle:``): it knows the episode's future, never a contender."""
    kind = find(spec)
    return kind is not None and kind.upper_bound


def _short_path(path: str, parts: int = 3) -> str:
    pieces = PurePosixPath(path).parts
    return path if len(pieces) <= parts else "…/" + "/".join(pieces[-parts:])


def draw_policy_bars(evaluations: Sequence[dict], group_learned: bool = True, sources: Sequence[str] | None = None):
    """The paper's Figure 3: one bar per policy (its mean objective over the test set), from one or
    more ``etmpc evaluate --json`` documents of the same task and test set.

    Error bars: the std over the repeats' means (``objective_std_repeats``, non-zero only for a
    stochastic policy evaluated with ``--repeats`` > 1). With ``group_learned``, the policies
    ``rl:…/seed<S>/last.json`` of one training run are one bar "learned (N seeds)": the mean over
    seeds, with the std over seeds as its error bar. Each bar is annotated with its mean and its mean
    computations per episode. ``sources`` names the documents in error messages.
    """
    bars = policy_bars(evaluations, group_learned, sources)
    first = evaluations[0]
    sense = next(iter(first["policies"].values()))["objective_sense"]
    episodes = next(iter(first["policies"].values()))["episodes"]
    means = np.array([b.mean for b in bars])
    errors = np.array([b.error for b in bars])
    x = np.arange(len(bars))
    fig, ax = plt.subplots(figsize=(max(7.0, 1.45 * len(bars) + 3.0), 4.8))
    colors = ["tab:gray" if b.bound else "tab:orange" if b.stochastic else "tab:blue" for b in bars]
    container = ax.bar(x, np.nan_to_num(means), width=0.65, color=colors, alpha=0.85, gid="policy_bars")
    for rect, bar in zip(container.patches, bars):
        rect.set_gid(bar.label)
    spread = errors > 0  # error bars only where there is a spread (a deterministic policy's is 0)
    if spread.any():
        ax.errorbar(
            x[spread], means[spread], yerr=errors[spread], fmt="none", ecolor="black", elinewidth=1.2, capsize=5, gid="spread"
        )

    finite = np.isfinite(means)
    low, high = (np.min((means - errors)[finite]), np.max((means + errors)[finite])) if finite.any() else (0.0, 1.0)
    span = high - low
    zoomed = bool(finite.any() and low > 0 and 0 < span < 0.5 * low)  # all positive and close: show the differences
    pad = span if span > 0 else abs(high) or 1.0
    if zoomed:
        ax.set_ylim(low - 0.5 * pad, high + 0.45 * pad)
    else:
        ax.set_ylim(min(0.0, low - 0.1 * pad), max(0.0, high + 0.3 * pad))
    for xi, bar in zip(x, bars):
        if not np.isfinite(bar.mean):
            ax.annotate("no finite run", (xi, 0), ha="center", va="bottom", fontsize=8)
            continue
        up = bar.mean >= 0 or zoomed
        y = bar.mean + bar.error if up else bar.mean - bar.error
        ax.annotate(
            f"{bar.mean:.5g}\n{bar.recomputes:.1f} recomp./ep",
            (xi, y),
            xytext=(0, 4 if up else -4),
            textcoords="offset points",
            ha="center",
            va="bottom" if up else "top",
            fontsize=8,
            gid="recomputes",
        )

    ax.set_xticks(x)
    long = any(len(b.label) > 12 for b in bars)
    ax.set_xticklabels([b.label for b in bars], rotation=20 if long else 0, ha="right" if long else "center", fontsize=9)
    unit = objective_unit(first["domain"], first["task"])
    what = cost_or_profit(sense) + ("" if unit in ("-", "rad²") else f" ({unit})")
    ax.set_ylabel(f"mean {what} per episode\n({higher_or_lower(sense)} is better{'; axis not from 0' if zoomed else ''})")
    ax.set_title(f"{first['domain']}/{first['task']}: objective per policy ({episodes} test-set episodes)", fontsize=11)
    ax.grid(axis="y", alpha=0.3)
    ax.set_axisbelow(True)
    handles = []
    if any(not b.stochastic and not b.bound for b in bars):
        handles.append(Patch(color="tab:blue", alpha=0.85, label="fixed policy"))
    if any(b.bound for b in bars):
        handles.append(Patch(color="tab:gray", alpha=0.85, label="oracle: upper bound\n(knows the future; not a policy)"))
    if any(b.stochastic and not b.bound for b in bars):
        handles.append(Patch(color="tab:orange", alpha=0.85, label="learned (stochastic) policy"))
    if spread.any():
        grouped = any(len(b.policies) > 1 for b in bars)
        handles.append(
            Line2D(
                [],
                [],
                color="black",
                marker="_",
                ms=10,
                lw=1.2,
                label="± std over repeats' means" + ("\n(over seeds for a group)" if grouped else ""),
            )
        )
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)
    fig.tight_layout()
    return fig


def write_policy_bars_png(
    path, evaluations: Sequence[dict], group_learned: bool = True, sources: Sequence[str] | None = None
) -> Path:
    """:func:`draw_policy_bars` written atomically to ``path`` (PNG)."""
    return save_png_atomically(draw_policy_bars(evaluations, group_learned, sources), path)


def draw_performance_profile(curves: Mapping[str, np.ndarray], thresholds: np.ndarray, tasks: Sequence[str]):
    """The scorecard's performance profiles: per trigger, the share of episodes (averaged over tasks)
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


def save_png_atomically(fig, path, dpi: int = 120) -> Path:
    """Write ``fig`` as a PNG next to ``path`` and rename it into place: a reader sees the old file
    or the whole new one. The figure is closed either way."""
    path = Path(path)
    try:
        with atomic_path(path) as tmp:
            fig.savefig(tmp, dpi=dpi, format="png")
    finally:
        plt.close(fig)
    return path
