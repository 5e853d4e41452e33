"""The slider's plant: the MJCF model (``slider.xml``, shipped inside this package) and its MuJoCo physics.

Two plant settings (see the MJCF header for the numbers):
  * ``"mismatched"`` (default): the MJCF as written: a stiffer spring and more damping than the
    analytic model knows;
  * ``"matched"``: those differences removed by name, so MuJoCo integrates the MPC's analytic model
    (``tests/test_slider.py`` shows they agree).

The reference is a mocap body: the task moves it (``set_reference``) to show where the block should
go; it does not act on the block.
"""

from __future__ import annotations

import copy
from pathlib import Path

import mujoco
import numpy as np
from dm_control import mjcf
from dm_control.mujoco import Physics as MjPhysics

from etmpc.systems.plants import finite_control, load_plant
from etmpc_slider.model import NU, Parameters

MODEL_PATH = Path(__file__).with_name("slider.xml")  # package data: found beside this module, wherever installed


def _matched(root: mjcf.RootElement) -> None:
    """Remove the MJCF's deliberate differences from the analytic model (edits by MJCF name)."""
    p = Parameters()
    root.find("body", "block").inertial.mass = p.mass_kg
    joint = root.find("joint", "slide")
    joint.stiffness, joint.damping = p.stiffness_n_m, p.damping_n_s_m


def load_model(plant: str = "mismatched", timestep_s: float | None = None) -> mjcf.RootElement:
    """The MJCF, with the plant setting's edits; ``timestep_s`` replaces the physics step."""
    return load_plant(MODEL_PATH, plant, _matched, timestep_s)


class Physics(MjPhysics):
    """The slider's physics with named accessors (dm-control's own ``step``: RK4 steps, as it does them)."""

    def _reload_from_data(self, data):  # called by dm-control whenever the model is (re)bound
        super()._reload_from_data(data)
        m = self.model
        joint = m.name2id("slide", "joint")
        self._qpos, self._qvel = int(m.jnt_qposadr[joint]), int(m.jnt_dofadr[joint])
        self._reference = m.body_mocapid[m.name2id("reference", "body")]

    # -- vocabulary -------------------------------------------------------------------------------
    def position(self) -> float:
        """The block's position ``p`` (m) from the spring's rest point."""
        return float(self.data.qpos[self._qpos])

    def velocity(self) -> float:
        return float(self.data.qvel[self._qvel])

    def reference(self) -> float:
        """Where the reference marker is drawn (m along the rail)."""
        return float(self.data.mocap_pos[self._reference, 0])

    def set_reference(self, reference_m: float) -> None:
        self.data.mocap_pos[self._reference, 0] = reference_m

    def state(self) -> np.ndarray:
        """``[p, v]`` in the analytic model's order."""
        return np.array([self.data.qpos[self._qpos], self.data.qvel[self._qvel]])

    def set_state_vector(self, x: np.ndarray) -> None:
        self.data.qpos[self._qpos] = x[0]
        self.data.qvel[self._qvel] = x[1]

    def set_control(self, control_) -> None:
        """The motor's force (N): one finite number (MuJoCo clamps it to ``ctrlrange``)."""
        self.data.ctrl[:] = finite_control(control_, NU, "the slider", "force", "force")

    # -- snapshots (rollouts) ---------------------------------------------------------------------
    def snapshot(self) -> mujoco.MjData:
        """A copy of the whole ``mjData`` (state, reference, and every derived quantity)."""
        return copy.copy(self.data.ptr)

    def restore(self, snapshot: mujoco.MjData) -> None:
        """Put back a snapshot, taken here or in a twin physics of the same model, exactly."""
        mujoco.mj_copyData(self.data.ptr, self.model.ptr, snapshot)
