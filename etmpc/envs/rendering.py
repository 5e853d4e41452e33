"""What a trigger environment draws (``render_mode="rgb_array"`` or ``"human"``), one frame of the
current step, and the window ``"human"`` shows it in.

* A task with a 3-D scene (it names a ``camera``: the cart pendulum's, the reacher's, the quadrotor's
  tasks) is drawn by MuJoCo from that camera, as ``etmpc render`` draws it (``etmpc.views.video``),
  headless under ``MUJOCO_GL=egl`` (what ``import etmpc`` chooses unless told otherwise). The frame is
  drawn from a copy of the plant's physics (:class:`SceneFrames`), so drawing never touches the
  simulation the loop plays: the rewards and observations are the same bits, drawn or not.
* A task without one (the battery) is drawn as a chart of the episode so far (:class:`ChartFrames`,
  matplotlib's Agg canvas): each state as measured and as the plan in force predicts it, each input
  applied, the task's exogenous signals (the battery's price and production), and a tick at every
  recompute.

``"human"`` shows the same frames in a window (Tk), in real time (one frame per control interval),
but at least :data:`HUMAN_MIN_FPS` frames a second (the battery's interval is 10 s). It needs a screen:
without one it is not among the environment's ``render_modes`` and asking for it is one clear error.
"""

from __future__ import annotations

import os
import sys
import time
import warnings

from typing import TYPE_CHECKING, Any

import numpy as np

from etmpc.common.checks import BadType, BadValue
from etmpc.common.display import check_display, render
from etmpc.common.errors import EtmpcError
from etmpc.common.wording import unit_label

if TYPE_CHECKING:  # imported where first drawn, not when etmpc.envs is
    import tkinter

    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from PIL import ImageTk

RENDER_MODES = ("rgb_array", "human")
HUMAN_MIN_FPS = 10.0  # "human" shows a task whose control interval is longer than 0.1 s faster than real time
WIDTH, HEIGHT = 640, 480  # a frame's size unless told: etmpc render's
# The process that drew a scene with OpenGL here. A process forked from it inherits this mark, and no OpenGL
# context of its own works there: MuJoCo's first frame would hang (measured: EGL, Mesa's llvmpipe), so it is
# refused in one line instead. Spawned processes start without it.
_GL_PROCESS: int | None = None


def display() -> bool:
    """Whether a window can be shown: a screen (macOS, Windows) or an X or Wayland display named."""
    if sys.platform in ("darwin", "win32"):
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def render_modes() -> list[str]:
    """The render modes an environment offers on this machine: ``"human"`` only where a window can be shown."""
    return [mode for mode in RENDER_MODES if mode != "human" or display()]


def check_render(render_mode, width, height) -> None:
    """A render mode this machine offers and a frame's size (whole numbers >= 1), or one clear error."""
    if render_mode is not None and render_mode not in RENDER_MODES:
        raise BadValue(f"render_mode must be None, 'rgb_array' or 'human', got {render_mode!r}")
    if render_mode == "human" and not display():
        raise EtmpcError(
            "render_mode='human' needs a display, and DISPLAY is not set (no screen here): "
            "use render_mode='rgb_array' and keep the frames (gymnasium.wrappers.RecordVideo), or run where there is a screen"
        )
    for name, size in (("width", width), ("height", height)):
        if isinstance(size, bool) or not isinstance(size, (int, np.integer)):
            raise BadType(f"{name}: a frame's size in pixels is a whole number, got {type(size).__name__} {size!r}")
        if size < 1:
            raise BadValue(f"{name}: a frame's size in pixels is at least 1, got {size}")


def frames_for(system, physics, width: int, height: int):
    """What draws ``system``'s frames: its 3-D scene (``physics``, the plant's), or a chart where it has none."""
    if system.camera is None:
        return ChartFrames(system, width, height)
    return SceneFrames(system.camera, physics, width, height)


class SceneFrames:
    """A task's 3-D scene from its camera: the plant's state copied into a physics of its own, then drawn."""

    def __init__(self, camera: str, physics, width: int, height: int):
        check_display()  # an on-screen MUJOCO_GL without a screen: said now, in one line
        limits = physics.model.vis.global_
        if width > limits.offwidth or height > limits.offheight:
            raise BadValue(
                f"width={width}, height={height} is larger than this scene's offscreen framebuffer "
                f"({limits.offwidth}x{limits.offheight}, <global offwidth offheight> in its model file)"
            )
        self.camera, self.width, self.height = camera, width, height
        # a copy of the plant's physics (dm_control's, untyped), sharing its model: made at the first frame
        self._scene: Any = None

    def frame(self, core) -> np.ndarray:
        import mujoco

        physics = core.loop.env.physics
        if self._scene is None or self._scene.model.ptr is not physics.model.ptr:  # another model: another copy
            self.close()
            _claim_opengl()
            self._scene = physics.copy(share_model=True)
        scene = self._scene
        mujoco.mj_copyData(scene.data.ptr, scene.model.ptr, physics.data.ptr)
        mujoco.mj_forward(scene.model.ptr, scene.data.ptr)  # the bodies' positions of this state, as drawn
        return render(scene, self.height, self.width, self.camera)

    def close(self) -> None:
        if self._scene is not None:
            self._scene.free()  # its OpenGL context
            self._scene = None


def _claim_opengl() -> None:
    """Mark this process as one that draws with OpenGL; refuse in one line where it was forked from one."""
    global _GL_PROCESS
    if _GL_PROCESS not in (None, os.getpid()):
        raise EtmpcError(
            "this process was forked from one that had drawn with OpenGL, and OpenGL does not work in it (the frame "
            "would never come): start the environments' processes with spawn: gymnasium.make_vec(ID, num_envs=N, "
            "vectorization_mode='async', vector_kwargs={'context': 'spawn'})"
        )
    _GL_PROCESS = os.getpid()


class ChartFrames:
    """A task without a 3-D scene drawn as a chart of its episode so far (see the module's docstring)."""

    def __init__(self, system, width: int, height: int):
        self.system, self.width, self.height = system, width, height
        self._canvas: FigureCanvasAgg | None = None  # made at the first frame (_build)
        self._signals: tuple[object, dict] = (None, {})

    def _build(self, signals: dict) -> None:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
        from matplotlib.transforms import blended_transform_factory

        system, dpi = self.system, 100
        figure = Figure(figsize=(self.width / dpi, self.height / dpi), dpi=dpi, layout="constrained")
        panels = [("state", n) for n in system.state_names] + [("input", n) for n in system.input_names]
        panels += [("signal", n) for n in signals]
        axes = figure.subplots(len(panels), 1, sharex=True, squeeze=False)[:, 0]
        self._panels = []
        for ax, (kind, name) in zip(axes, panels):
            ax.set_xlim(0, system.episode_steps)
            ax.set_ylabel(unit_label(name), fontsize=7)
            ax.tick_params(labelsize=6)
            ax.grid(True, linewidth=0.3)
            ticks = blended_transform_factory(ax.transData, ax.transAxes)  # x a step, y a fraction of the panel
            self._panels.append(
                (
                    kind,
                    name,
                    ax,
                    ax.plot([], [], color="C0", linewidth=1.2, drawstyle="steps-post" if kind == "input" else "default")[0],
                    ax.plot([], [], color="C1", linewidth=1.0, linestyle="--")[0],  # the plan in force (a state's)
                    ax.plot([], [], color="C3", linewidth=0.8, transform=ticks)[0],  # a tick at each recompute
                )
            )
        axes[-1].set_xlabel("control interval", fontsize=7)
        self._title = figure.suptitle("", fontsize=8)
        self._canvas = FigureCanvasAgg(figure)

    def frame(self, core) -> np.ndarray:
        system, loop = self.system, core.loop
        if self._signals[0] is not core.episode:
            self._signals = (core.episode, system.signals(core.episode))
        signals = self._signals[1]
        if self._canvas is None:
            self._build(signals)
        canvas = self._canvas
        assert canvas is not None  # made by _build
        traj, k, plan = loop.trajectory, loop.step_index, loop.plan
        computed = np.flatnonzero(traj.recompute[:k])
        ticks_x = np.repeat(computed, 3).astype(float)
        ticks_x[2::3] = np.nan
        ticks_y = np.tile([0.0, 0.12, np.nan], computed.size)
        steps = np.arange(k + 1)
        states, inputs = 0, 0
        for kind, name, ax, line, planned, ticks in self._panels:
            if kind == "state":
                line.set_data(steps, traj.states[: k + 1, states])
                if plan is not None:  # its states[0] is at the step it was made for, age steps ago
                    planned.set_data(k - loop.age + np.arange(plan.horizon + 1), np.asarray(plan.states)[:, states])
                else:
                    planned.set_data([], [])
                states += 1
            elif kind == "input":  # u_j holds over [j, j + 1)
                line.set_data(steps, np.append(traj.applied[:k, inputs], np.nan))
                inputs += 1
            else:
                line.set_data(steps, np.asarray(signals[name], dtype=float)[: k + 1])
            ticks.set_data(ticks_x, ticks_y)
            ax.relim()
            if ax.dataLim.height >= 0:  # some data (a null box's height is -inf)
                ax.autoscale_view(scalex=False)
            else:  # none yet (the first step's input): an empty panel's limits, whatever the last episode's were
                ax.set_ylim(0.0, 1.0, auto=True)
        made = f"{computed.size} recompute" + ("" if computed.size == 1 else "s")
        self._title.set_text(f"{system.name}: step {k} of {system.episode_steps}, {made}")
        with warnings.catch_warnings():  # a frame too small for the panels' labels is drawn without the layout
            warnings.filterwarnings("ignore", "constrained_layout not applied", UserWarning)
            canvas.draw()
        return np.asarray(canvas.buffer_rgba())[..., :3].copy()

    def close(self) -> None:
        self._canvas = None


class Window:
    """``"human"``: frames shown in a window (Tk), paced to ``fps`` (at least :data:`HUMAN_MIN_FPS`). Closed by
    its user, it stays closed: the environment goes on without showing."""

    def __init__(self, title: str, fps: float):
        self.title, self.period = title, 1.0 / max(fps, HUMAN_MIN_FPS)
        self._root: tkinter.Tk | None = None  # the window, made at the first frame shown
        self._label: tkinter.Label | None = None  # the frame's place in it
        self._image: ImageTk.PhotoImage | None = None  # the frame shown (kept: Tk does not hold it)
        self._dismissed, self._due = False, 0.0

    def show(self, frame: np.ndarray) -> None:
        import tkinter

        from PIL import Image, ImageTk

        if self._dismissed:
            return
        if self._root is None:
            try:
                self._root = tkinter.Tk()
            except tkinter.TclError as exc:
                raise EtmpcError(f"render_mode='human' cannot open a window: {str(exc).strip()}") from None
            self._root.title(self.title)
            self._root.protocol("WM_DELETE_WINDOW", self._dismiss)
            self._label = tkinter.Label(self._root)
            self._label.pack()
        assert self._label is not None  # made with the window
        wait = self._due - time.monotonic()
        if wait > 0:
            time.sleep(wait)
        self._due = max(self._due, time.monotonic()) + self.period
        self._image = ImageTk.PhotoImage(Image.fromarray(frame), master=self._root)  # kept: Tk does not hold it
        self._label.configure(image=self._image)
        self._root.update()

    def _dismiss(self) -> None:
        self._dismissed = True
        self.close()

    def close(self) -> None:
        if self._root is not None:
            root, self._root, self._label, self._image = self._root, None, None, None
            root.destroy()
