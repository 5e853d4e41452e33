"""Whether MuJoCo can draw here (the check every drawing makes first), and a frame drawn with a failure to
draw said in one line: ``etmpc render``, the recordings' video, the Gymnasium environments' ``render``."""

from __future__ import annotations

import os

from etmpc.common.errors import EtmpcError


def check_display() -> None:
    """An on-screen backend without a screen cannot render: said before any work (GLFW would
    print warnings, then fail deep in MuJoCo)."""
    backend = os.environ.get("MUJOCO_GL", "").lower().strip()
    if backend in ("glfw", "glx") and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        raise EtmpcError(f"MUJOCO_GL={backend} needs a display and DISPLAY is not set: render headless with MUJOCO_GL=egl")


def render(physics, height: int, width: int, camera):
    """``physics.render(height, width, camera_id=camera)``; a failure to make an OpenGL context is said in
    one line (MuJoCo's own is a paragraph, or a bare ``AttributeError``)."""
    import mujoco

    try:
        return physics.render(height, width, camera_id=camera)
    except (mujoco.FatalError, RuntimeError, ImportError, OSError, AttributeError) as exc:
        # AttributeError: PyOpenGL without the platform library MUJOCO_GL asks for (osmesa, egl).
        reason = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise EtmpcError(
            f"cannot render with MUJOCO_GL={os.environ.get('MUJOCO_GL', '')}: {reason} (headless machines need "
            "MUJOCO_GL=egl, or osmesa with libOSMesa installed)"
        ) from None
