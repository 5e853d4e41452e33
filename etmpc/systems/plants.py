"""A MuJoCo plant from its MJCF file in ``models/``, under a plant setting: ``mismatched`` (the file as it
is, unlike the MPC's predictor on purpose) or ``matched`` (edited to agree with the predictor, which a
test then checks: it pins down the sign conventions), and :class:`Physics`, what every MuJoCo plant's
physics shares: snapshots of the whole ``mjData``, dm-control's RK4 stepping with its check inlined, and
frames whose shadow map is sized to them."""

from __future__ import annotations

import copy
import logging
import math
from collections.abc import Callable
from typing import Any
from pathlib import Path

import mujoco
import numpy as np
from dm_control import mjcf
from dm_control.mujoco import Physics as MjPhysics
from dm_control.rl import control

from etmpc.common.declared import setting
from etmpc.common.errors import UnknownNameError
from etmpc.common.resources import model_path

PLANTS = ("mismatched", "matched")
#: Shadow-map texels per pixel of a frame's longer side, and the fewest: a 640x480 frame gets the models'
#: 4096 (their ``<quality shadowsize>``, never exceeded), a 64x48 one 512. MuJoCo draws the whole map at
#: every frame, so with the model's map a small frame cost as much as a large one on a CPU's OpenGL.
SHADOW_TEXELS_PER_PIXEL, SHADOW_TEXELS_MIN = 4, 512


def plant_setting(default: str = "mismatched") -> Any:
    """A task's plant setting, as an option."""
    return setting(default, choices=PLANTS, why="the MuJoCo plant as it is, or matched to the MPC's predictor")


def load_plant(
    file: str | Path, plant: str, matched: Callable[[mjcf.RootElement], None], timestep_s: float | None = None
) -> mjcf.RootElement:
    """The MJCF ``file`` (a name in etmpc's ``models/``, or a path: a plugin's own), edited by
    ``matched(root)`` under the ``matched`` setting; ``timestep_s`` replaces the physics step."""
    if plant not in PLANTS:
        raise UnknownNameError(f"unknown plant setting {plant!r}; valid: {', '.join(PLANTS)}")
    root = mjcf.from_path(str(file if isinstance(file, Path) else model_path(file)))
    if plant == "matched":
        matched(root)
    if timestep_s is not None:
        root.option.timestep = timestep_s
    return root


def finite_control(control_, size: int, owner: str, inputs: str, values: str):
    """``control_`` as ``size`` finite floats, for a plant's ``set_control``; else a ``ValueError`` naming
    ``owner``'s action: "the reacher's action is 2 torques, got an action of shape (3,)", "the reacher's
    torques must be finite, got [...]" (``owner`` "the reacher", ``inputs`` "torques", ``values`` "torques")."""
    control_ = np.asarray(control_, dtype=float)
    if control_.size != size:
        raise ValueError(f"{owner}'s action is {size} {inputs}, got an action of shape {control_.shape}")
    control_ = control_.reshape(size)
    if not np.all(np.isfinite(control_)):
        raise ValueError(f"{owner}'s {values} must be finite, got {control_.tolist()}")
    return control_


class Physics(MjPhysics):
    """A MuJoCo plant's physics: a task's subclass adds its named accessors (its vocabulary)."""

    # -- snapshots (rollouts) ---------------------------------------------------------------------
    def snapshot(self) -> mujoco.MjData:
        """A copy of the whole ``mjData`` (state, mocap bodies, applied forces, every derived quantity)."""
        return copy.copy(self.data.ptr)

    def restore(self, snapshot: mujoco.MjData) -> None:
        """Put back a snapshot, taken here or in a twin physics of the same model, exactly."""
        mujoco.mj_copyData(self.data.ptr, self.model.ptr, snapshot)

    # -- stepping ---------------------------------------------------------------------------------
    def step(self, nstep: int = 1) -> None:
        """Advance ``nstep`` physics steps, as dm-control's legacy stepping does for RK4 (``mj_step``,
        then ``mj_step1`` to bring mjData up to the new state), with its invalid-state check inlined
        (this is the hot loop of every rollout)."""
        m, d = self.model.ptr, self.data.ptr
        warnings_before = self._warnings.tolist()
        mujoco.mj_step(m, d, nstep)  # mj_step computes all it uses from the state: mj_step1 is needed after the last only
        mujoco.mj_step1(m, d)
        warnings_after = self._warnings.tolist()
        if warnings_after != warnings_before:
            names = [name for name, b, a in zip(mujoco.mjtWarning.__members__, warnings_before, warnings_after) if a > b]
            message = f"Physics state is invalid. Warning(s) raised: {', '.join(names)}"
            if self._warnings_cause_exception:
                raise control.PhysicsError(message)
            logging.warning(message)

    # -- drawing ----------------------------------------------------------------------------------
    def render(self, height: int = 240, width: int = 320, camera_id=-1, **kwargs) -> np.ndarray:
        """dm-control's ``render``, with the shadow map sized to the frame (:data:`SHADOW_TEXELS_PER_PIXEL`, at
        most the model's ``shadowsize``): the rendering context, which holds the map, is made at the first frame,
        and made again, larger, when a later frame wants a larger map. Only the shadows' resolution changes."""
        quality = self.model.vis.quality  # its shadowsize stays the model file's: set only while a context is made
        most = int(quality.shadowsize)
        wanted = min(most, max(SHADOW_TEXELS_MIN, 2 ** math.ceil(math.log2(SHADOW_TEXELS_PER_PIXEL * max(height, width, 1)))))
        with self._contexts_lock:
            if self._contexts is not None and self._contexts.mujoco.ptr.shadowSize < wanted:
                self._free_rendering_contexts()
            if self._contexts is None:
                quality.shadowsize = wanted
                try:
                    self._make_rendering_contexts()
                finally:
                    quality.shadowsize = most
        return super().render(height, width, camera_id=camera_id, **kwargs)
