"""The robustness curve (``etmpc robustness``) as a figure: per policy, its mean objective and, against a baseline,
its paired improvement, each with its 95 % CI, across the values of one option (matplotlib, headless Agg)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from etmpc.views.png import save_png_atomically  # noqa: E402


def _position(values: list[str]) -> tuple[np.ndarray, bool]:
    """The x of each value: the number itself where every value is one number, else its index."""
    try:
        return np.array([float(v) for v in values]), True
    except ValueError:
        return np.arange(len(values), dtype=float), False


def draw_robustness(document: dict):
    levels = document["levels"]
    values = [level["value"] for level in levels]
    x, numeric = _position(values)
    against = document["against"]
    panels = ["objective"] + (["improvement_pct"] if against else []) + ["failures"]
    panels = [p for p in panels if all(level["policies"][s].get(p) is not None for level in levels for s in document["policies"])]
    fig, axes = plt.subplots(1, len(panels), figsize=(4.6 * len(panels), 3.6), squeeze=False)
    better = "higher" if document["objective_sense"] == "max" else "lower"
    titles = {
        "objective": f"objective ({better} is better)",
        "improvement_pct": f"improvement over {against} (%)",
        "failures": "failures per episode",
    }
    for ax, panel in zip(axes[0], panels):
        for colour, spec in enumerate(document["policies"]):
            if panel == "improvement_pct" and spec == against:
                continue
            mean = np.array([level["policies"][spec][panel] for level in levels], dtype=float)
            ci_key = {"objective": "objective_ci95", "improvement_pct": "improvement_ci95", "failures": "failures_ci95"}[panel]
            ci = np.array([level["policies"][spec].get(ci_key) or 0.0 for level in levels], dtype=float)
            label = spec if len(spec) < 40 else spec[:37] + "..."
            ax.errorbar(x, mean, yerr=ci, marker="o", capsize=3, color=f"C{colour}", label=label)
        if panel == "improvement_pct":
            ax.axhline(0.0, color="grey", lw=0.8)
        ax.set_title(titles[panel], fontsize=10)
        ax.set_xlabel(document["option"] + (f" ({document['unit']})" if document.get("unit") else ""))
        if not numeric:
            ax.set_xticks(x, values, rotation=30, fontsize=7)
        ax.grid(alpha=0.3)
    axes[0][0].legend(fontsize=7)
    fig.suptitle(f"{document['task']}: {levels[0]['episodes']} test-set episodes per value, 95 % CIs", fontsize=10)
    fig.tight_layout()
    return fig


def write_robustness_png(document: dict, path: Path) -> Path:
    """The curve drawn into ``path``, atomically (a reader sees the old figure or the whole new one)."""
    return save_png_atomically(draw_robustness(document), path)
