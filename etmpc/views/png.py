"""PNGs written atomically: a reader sees the old file or the whole new one (matplotlib, headless Agg)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from etmpc.common.outputs import atomic_path  # noqa: E402


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
