"""Whether MuJoCo can draw here: the check every drawing makes first (``etmpc render``, the recordings'
video, the Gymnasium environments' ``render``)."""

from __future__ import annotations

import os

from etmpc.common.errors import EtmpcError


def check_display() -> None:
    """An on-screen backend without a screen cannot render: said before any work (GLFW would
    print warnings, then fail deep in MuJoCo)."""
    backend = os.environ.get("MUJOCO_GL", "").lower().strip()
    if backend in ("glfw", "glx") and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        raise EtmpcError(f"MUJOCO_GL={backend} needs a display and DISPLAY is not set: render headless with MUJOCO_GL=egl")
