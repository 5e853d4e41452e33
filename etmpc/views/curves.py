"""Curves: the learning curve of a training run (the paper's Figure 2) and the trade-off curve of a
sweep (control objective against computations), drawn from their JSON summaries."""

from __future__ import annotations

from pathlib import Path

import numpy as np

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
    ax.set_ylabel(f"test-set objective ({'higher' if summary['objective_sense'] == 'max' else 'lower'} is better)")
    learner = {"gpomdp": "GPOMDP", "dpi": "DPI"}.get(summary.get("algorithm", "gpomdp"), summary.get("algorithm"))
    ax.set_title(f"{summary['domain']}: {learner} learning curve ({summary.get('features', 'paper')} features)")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    save_png_atomically(fig, path, dpi=110)


def draw_pareto(pareto: dict):
    """Control objective against computations per episode: every periodic schedule as a grey dot and
    the periodic front (the schedules no other beats) as a line, the event triggers as a dashed line
    of points; at each price, coloured by price, the rollout (diamond), learned (square) and
    self-triggering (triangle) policies as filled points and the oracle bound as a hollow circle."""
    import matplotlib.pyplot as plt

    points, sense = pareto["points"], pareto["objective_sense"]
    prices = pareto["settings"]["prices"]
    first = [p for p in points if p["price"] == prices[0]]
    fig, ax = plt.subplots(figsize=(8, 5.2), layout="constrained")
    periodic = [p for p in first if p["kind"] == "periodic"]
    ax.plot([p["computations"] for p in periodic], [p["control_objective"] for p in periodic], "o", color="0.55",
            markersize=4, label="periodic every:T", gid="periodic-points")
    for kind, style, label in (("periodic", dict(color="black", marker="o", linestyle="-"), "the periodic front"),
                               ("event", dict(color="tab:blue", marker="x", linestyle="--"), "event trigger threshold:X")):
        rows = sorted((p for p in first if p["kind"] == kind and p.get("on_front", True)), key=lambda p: p["computations"])
        ax.plot([p["computations"] for p in rows], [p["control_objective"] for p in rows], label=label, gid=kind, **style)
    colours = plt.get_cmap("viridis")(np.linspace(0.0, 0.9, len(prices)))
    for colour, price in zip(colours, prices, strict=True):
        for kind, marker, face, name in (("rollout", "D", colour, "rollout"), ("learned", "s", colour, "learned (DPI)"),
                                         ("self", "^", colour, "self-trigger"), ("oracle", "o", "none", "oracle bound")):
            rows = [p for p in points if p["price"] == price and p["kind"] == kind]
            if not rows:
                continue
            label = f"{name}, price {price:g}"
            ax.scatter([p["computations"] for p in rows], [p["control_objective"] for p in rows], marker=marker, s=60,
                       facecolors=face, edgecolors=colour, linewidths=1.5, label=label, gid=f"{kind}@{price!r}", zorder=3)
    ax.set_xlabel("computations per episode")
    ax.set_ylabel(f"control objective ({'lower' if sense == 'min' else 'higher'} is better)")
    ax.set_title(f"{pareto['domain']}: the trade-off, {pareto['episodes']} test-set episodes (oracle: an upper bound)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, ncols=2, loc="best")
    return fig
