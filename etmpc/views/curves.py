"""Curves: the learning curve of a training run (the paper's Figure 2) and the trade-off curve of a
sweep (control objective against recomputes), drawn from their JSON summaries."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from etmpc.common.sense import higher_or_lower
from etmpc.views.figures import save_png_atomically


def write_curve_png(path: Path, summary: dict, seeds: int) -> None:
    import matplotlib.pyplot as plt  # etmpc.views.figures, imported above, selected the Agg backend

    x = np.array([p["episodes"] for p in summary["points"]])
    mean = np.array([p["objective_mean"] for p in summary["points"]])
    std = np.array([p["objective_std"] for p in summary["points"]])
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.plot(x, mean, marker="o", label=f"mean over {seeds} seeds")
    ax.fill_between(x, mean - std, mean + std, alpha=0.25, label="± 1 std")
    ax.set_xlabel("training episodes")
    ax.set_ylabel(f"test-set objective ({higher_or_lower(summary['objective_sense'])} is better)")
    learner = {"gpomdp": "GPOMDP", "dpi": "DPI"}.get(summary.get("algorithm", "gpomdp"), summary.get("algorithm"))
    ax.set_title(f"{summary['domain']}: {learner} learning curve ({summary.get('features', 'paper')} features)")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    save_png_atomically(fig, path, dpi=110)


def draw_pareto(pareto: dict):
    """Control objective against recomputes per episode: every periodic schedule as a grey dot and
    the periodic front (the schedules no other beats) as a line, the event triggers as a dashed line
    of points; at each price, coloured by price, the rollout (diamond), learned (square) and
    self-triggering (triangle) policies as filled points and the oracle as a hollow circle."""
    import matplotlib.pyplot as plt

    points, sense = pareto["points"], pareto["objective_sense"]
    prices = pareto["settings"]["prices"]
    first = [p for p in points if p["price"] == prices[0]]
    fig, ax = plt.subplots(figsize=(8, 5.2), layout="constrained")
    periodic = [p for p in first if p["kind"] == "periodic"]
    ax.plot(
        [p["computations"] for p in periodic],
        [p["control_objective"] for p in periodic],
        "o",
        color="0.55",
        markersize=4,
        label="periodic every:T",
        gid="periodic-points",
    )
    for kind, color, marker, linestyle, label in (
        ("periodic", "black", "o", "-", "the periodic front"),
        ("event", "tab:blue", "x", "--", "event trigger threshold:X"),
    ):
        rows = sorted((p for p in first if p["kind"] == kind and p.get("on_front", True)), key=lambda p: p["computations"])
        computations = [p["computations"] for p in rows]
        objectives = [p["control_objective"] for p in rows]
        ax.plot(computations, objectives, label=label, gid=kind, color=color, marker=marker, linestyle=linestyle)
    colours = plt.get_cmap("viridis")(np.linspace(0.0, 0.9, len(prices)))
    for colour, price in zip(colours, prices, strict=True):
        for kind, marker, face, name in (
            ("rollout", "D", colour, "rollout"),
            ("learned", "s", colour, "learned (DPI)"),
            ("self", "^", colour, "self-trigger"),
            ("oracle", "o", "none", "oracle"),
        ):
            rows = [p for p in points if p["price"] == price and p["kind"] == kind]
            if not rows:
                continue
            label = f"{name}, price {price:g}"
            ax.scatter(
                [p["computations"] for p in rows],
                [p["control_objective"] for p in rows],
                marker=marker,
                s=60,
                facecolors=face,
                edgecolors=colour,
                linewidths=1.5,
                label=label,
                gid=f"{kind}@{price!r}",
                zorder=3,
            )
    ax.set_xlabel("recomputes per episode")
    ax.set_ylabel(f"control objective ({higher_or_lower(sense)} is better)")
    ax.set_title(f"{pareto['domain']}: the trade-off, {pareto['episodes']} test-set episodes (oracle: knows the future)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, ncols=2, loc="best")
    return fig


LEARNER_STYLES = {"dpi": ("DPI", "o", "C0"), "gpomdp": ("GPOMDP", "s", "C1"), "ppo": ("PPO (SB3)", "^", "C2")}


def write_efficiency_png(
    path: Path, task: str, reference: str, curves: dict[str, list[dict]], chosen: dict[str, dict] | None = None
) -> None:
    """Each learner's test-set gain over ``reference`` (%) against simulated environment steps (log
    axis): ``curves`` maps ``dpi``/``gpomdp``/``ppo`` to points ``{"simulated_steps", "gain_percent"}``
    (see :mod:`etmpc.experiments.efficiency`); ``chosen`` marks the policy each learner ships with its
    95 % CI (``{"simulated_steps", "gain_percent", "gain_percent_ci95"}``)."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    ax.axhline(0.0, color="0.4", lw=1, ls="--", label=f"best fixed ({reference})")
    for name, points in curves.items():
        if not points:
            continue
        label, marker, colour = LEARNER_STYLES.get(name, (name, "x", None))
        x = [max(p["simulated_steps"], 1) for p in points]
        ax.plot(x, [p["gain_percent"] for p in points], marker=marker, color=colour, label=label)
        pick = (chosen or {}).get(name)
        if pick is not None:
            ax.errorbar(
                [pick["simulated_steps"]],
                [pick["gain_percent"]],
                yerr=[pick["gain_percent_ci95"]],
                fmt="*",
                ms=13,
                color=colour,
                capsize=4,
                mec="k",
            )
    ax.set_xscale("log")
    ax.set_xlabel("simulated environment steps per learner run (loop and rollouts)")
    ax.set_ylabel("test-set gain over the best fixed schedule (%)")
    ax.set_title(f"{task}: sample efficiency (stars: the chosen policy, 95 % CI)")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    fig.tight_layout()
    save_png_atomically(fig, path, dpi=110)
