"""Curves: the learning curve of a training run (the paper's Figure 2), drawn from its summary."""

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
