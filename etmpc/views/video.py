"""Video of a played episode: each state drawn from the MuJoCo scene, encoded as an MP4 (H.264).

Views only receive: this module draws states it is given (``etmpc.views.render`` plays the
episode). It may import ``etmpc.common``.

A system with a 3-D scene names its ``camera`` and puts a state back into its physics with ``show``
(the cart pendulum: the exact inverse of how its task reports the state, then ``mj_forward``); the
scene is drawn from that camera. One frame per state, so a full episode of 100 control
intervals gives 101 frames, shown at one frame per control interval (10 fps) unless told otherwise.

Videos are H.264 in yuv420p (plays everywhere; needs an even width and height), encoded with PyAV
into a temporary file beside the destination and renamed into place, so an interrupted render never
leaves a half-written file under the final name.

:func:`caption_frames` writes lines of text over the frames' top left corner, on a dark band (what
``etmpc render`` shows of time in the loop: ``etmpc.views.solves.frame_captions``).
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from fractions import Fraction
from pathlib import Path

import av
import numpy as np

from etmpc.common.display import check_display  # noqa: F401 (the video's API too)
from etmpc.common.display import render
from etmpc.common.errors import EtmpcError
from etmpc.common.outputs import atomic_path


def check_scene(system) -> None:
    """A system has a scene when it names a ``camera`` (it can ``show(physics, x)`` a state)."""
    if system.camera is None:
        raise EtmpcError(f"{system.name!r} has no 3-D scene to render")


def check_size(width: int, height: int) -> None:
    """yuv420p halves the chroma resolution: both sides must be even (and positive)."""
    if width < 2 or height < 2 or width % 2 or height % 2:
        raise ValueError(f"video size must be even and positive for H.264/yuv420p, got {width}x{height}")


def check_framebuffer(physics, width: int, height: int) -> None:
    """A frame must fit the scene's offscreen framebuffer (``<visual><global offwidth offheight/>`` in
    its model file): said in one line, before any work (MuJoCo's own refusal is a paragraph)."""
    limits = physics.model.vis.global_
    if width > limits.offwidth or height > limits.offheight:
        raise EtmpcError(
            f"--width {width} --height {height} is larger than this scene's offscreen framebuffer "
            f"({limits.offwidth}x{limits.offheight}, set by <global offwidth offheight> in its model file): "
            f"render at most {limits.offwidth}x{limits.offheight}"
        )


def iter_frames(system, env, states: np.ndarray, width: int, height: int) -> Iterator[np.ndarray]:
    """Each state put into the physics by the system (``system.show``) and drawn from its camera."""
    check_scene(system)
    physics = env.physics
    for x in np.asarray(states, dtype=float):
        if not np.all(np.isfinite(x)):
            raise ValueError(f"cannot render a non-finite state {x}")
        system.show(physics, x)
        yield render(physics, height, width, system.camera)


def render_frames(system, env, states: np.ndarray, width: int = 640, height: int = 480) -> list[np.ndarray]:
    """One RGB frame, uint8 ``(height, width, 3)``, per row of ``states`` (the system's ``x``).

    Leaves ``env.physics`` at the last state: reset the environment before playing it again.
    """
    return list(iter_frames(system, env, states, width, height))


def caption_frames(frames: Iterable[np.ndarray], captions: Iterable[list[tuple[str, tuple]]]) -> Iterator[np.ndarray]:
    """Each frame with its caption, lines of ``(text, RGB)``, drawn over its top left corner on a dark
    band (Pillow's own font, sized to the frame's height); a frame without lines is left as it is."""
    from PIL import Image, ImageDraw, ImageFont

    font = None
    for frame, lines in zip(frames, captions):
        if not lines:
            yield frame
            continue
        image = Image.fromarray(np.asarray(frame, dtype=np.uint8)).convert("RGBA")
        if font is None:
            try:  # a scalable font (Pillow >= 10.1 with FreeType), else Pillow's small bitmap one
                font = ImageFont.load_default(size=max(8, image.height // 30))
            except (TypeError, ImportError, OSError):
                font = ImageFont.load_default()
            size = font.getbbox("Ag")[3]
            pitch = size + max(2, size // 4)
        band = Image.new("RGBA", image.size, (0, 0, 0, 0))
        draw = ImageDraw.Draw(band)
        width = max(draw.textlength(text, font=font) for text, _ in lines)
        draw.rectangle((0, 0, int(width) + 2 * pitch // 3, len(lines) * pitch + pitch // 3), fill=(0, 0, 0, 150))
        for row, (text, colour) in enumerate(lines):
            draw.text((pitch // 3, pitch // 4 + row * pitch), text, fill=tuple(colour) + (255,), font=font)
        yield np.asarray(Image.alpha_composite(image, band).convert("RGB"))


def write_video(frames: Iterable[np.ndarray], path: str | Path, fps: float) -> int:
    """Encode uint8 RGB frames (all the same even size) as an H.264/yuv420p MP4 at ``path``;
    returns the number of frames. ``path`` only ever holds a complete video (or what it held before)."""
    path = Path(path)
    if not (np.isfinite(fps) and fps > 0):
        raise ValueError(f"fps must be a positive number, got {fps}")
    frames = iter(frames)
    first = next(frames, None)
    if first is None:
        raise ValueError("no frames to write")
    height, width = np.shape(first)[:2]
    check_size(width, height)
    count = 0
    with atomic_path(path) as tmp:
        with av.open(str(tmp), "w", format="mp4") as container:
            stream = container.add_stream("libx264", rate=Fraction(fps).limit_denominator(1001))
            stream.width, stream.height, stream.pix_fmt = width, height, "yuv420p"
            for frame in _chain(first, frames):
                frame = np.asarray(frame)
                if frame.shape != (height, width, 3) or frame.dtype != np.uint8:
                    raise ValueError(f"frame {count} is {frame.dtype} {frame.shape}, expected uint8 {(height, width, 3)}")
                container.mux(stream.encode(av.VideoFrame.from_ndarray(frame, format="rgb24")))
                count += 1
            container.mux(stream.encode())  # flush the encoder
    return count


def _chain(first: np.ndarray, rest: Iterator[np.ndarray]) -> Iterator[np.ndarray]:
    yield first
    yield from rest
