"""The quadrotor's plant: the MJCF model (``models/quadrotor.xml``) and its MuJoCo physics.

Two plant settings (see the MJCF header for the numbers):
  * ``"mismatched"`` (default): the MJCF as written: a heavier body with more inertia, rotors that
    lag their commands, and air;
  * ``"matched"``: those differences removed by name, so MuJoCo integrates the MPC's analytic model
    (``tests/systems/quadrotor/test_quadrotor.py`` shows they agree).

The gust is a force on the drone's centre (``xfrc_applied``, part of ``mjData``, so a snapshot keeps
it) that the task sets before each interval. The target is a mocap body the task moves.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np
from dm_control import mjcf

from etmpc.systems.plants import Physics as PlantPhysics
from etmpc.systems.plants import finite_control, load_plant
from etmpc.systems.quadrotor.model import GRAVITY_M_S2, NU, Parameters

ROTORS = ("rotor0", "rotor1", "rotor2", "rotor3")


def _matched(root: mjcf.RootElement) -> None:
    """Remove the MJCF's deliberate differences from the analytic model (edits by MJCF name)."""
    p = Parameters()
    inertial = root.find("body", "drone").inertial
    inertial.mass = p.mass_kg
    inertial.diaginertia = list(p.inertia_kg_m2)
    for rotor in ROTORS:
        actuator = root.find("actuator", rotor)
        actuator.dyntype = "none"
        actuator.dynprm = None
    root.option.density = 0.0


def load_model(plant: str = "mismatched", timestep_s: float | None = None) -> mjcf.RootElement:
    """The MJCF, with the plant setting's edits; ``timestep_s`` replaces the physics step."""
    return load_plant("quadrotor.xml", plant, _matched, timestep_s)


def euler(quaternion: np.ndarray) -> np.ndarray:
    """Z-Y-X Euler angles ``[roll, pitch, yaw]`` (rad) of a unit quaternion ``[w, x, y, z]``.

    By the C library's scalar functions (:mod:`math`), not NumPy's: NumPy picks vectorised ``arctan2`` and
    ``arcsin`` by the CPU (Intel's SVML on AVX-512), whose last bits differ from one machine to another."""
    w, x, y, z = (float(v) for v in quaternion)
    roll = math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = math.asin(min(max(2 * (w * y - z * x), -1.0), 1.0))
    yaw = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return np.array([roll, pitch, yaw])


def quaternion(angles: np.ndarray) -> np.ndarray:
    """The unit quaternion ``[w, x, y, z]`` of Z-Y-X Euler angles ``[roll, pitch, yaw]``."""
    half = [float(a) / 2 for a in angles]  # scalar maths, as in euler()
    cr, sr = math.cos(half[0]), math.sin(half[0])
    cp, sp = math.cos(half[1]), math.sin(half[1])
    cy, sy = math.cos(half[2]), math.sin(half[2])
    return np.array(
        [cr * cp * cy + sr * sp * sy, sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy, cr * cp * sy - sr * sp * cy]
    )


class Physics(PlantPhysics):
    """The quadrotor's physics with named accessors (snapshots and stepping: :class:`~etmpc.systems.plants.Physics`)."""

    def _reload_from_data(self, data):  # called by dm-control whenever the model is (re)bound
        super()._reload_from_data(data)
        m = self.model
        self._drone = m.name2id("drone", "body")
        self._target = m.body_mocapid[m.name2id("target", "body")]
        self._lagged = bool(np.any(m.actuator_dyntype != mujoco.mjtDyn.mjDYN_NONE))

    # -- vocabulary -------------------------------------------------------------------------------
    def position(self) -> np.ndarray:
        """The drone's centre ``(x, y, z)`` (m)."""
        return self.data.qpos[:3].copy()

    def target(self) -> np.ndarray:
        """Where the target body is drawn ``(x, y, z)`` (m)."""
        return self.data.mocap_pos[self._target].copy()

    def set_target(self, target_m: np.ndarray) -> None:
        self.data.mocap_pos[self._target] = target_m

    def gust(self) -> np.ndarray:
        """The force (N, world frame) the gust applies now."""
        return self.data.xfrc_applied[self._drone, :3].copy()

    def set_gust(self, force_n: np.ndarray) -> None:
        self.data.xfrc_applied[self._drone, :3] = force_n

    def weight_n(self) -> float:
        """The drone's weight (N) in this plant."""
        return float(self.model.body_subtreemass[self._drone]) * GRAVITY_M_S2

    def thrusts(self) -> np.ndarray:
        """The rotors' thrusts (N) acting now: the lagged ones, or the commands where rotors do not lag."""
        return self.data.act.copy() if self._lagged else self.data.ctrl.copy()

    def state(self) -> np.ndarray:
        """``[x, y, z, roll, pitch, yaw, vx, vy, vz, p, q, r]`` in the analytic model's order."""
        q, v = self.data.qpos, self.data.qvel
        return np.concatenate([q[:3], euler(q[3:7]), v[:6]])

    def set_state_vector(self, x: np.ndarray) -> None:
        """Put state ``x`` into the physics (the rotors' lag keeps its state: :meth:`set_thrusts`)."""
        self.data.qpos[:3] = x[:3]
        self.data.qpos[3:7] = quaternion(np.asarray(x[3:6], dtype=float))
        self.data.qvel[:6] = x[6:12]

    def set_thrusts(self, thrust_n: np.ndarray) -> None:
        """The rotors' present thrusts (the lag's state; the commands where rotors do not lag)."""
        if self._lagged:
            self.data.act[:] = thrust_n
        self.data.ctrl[:] = thrust_n

    def set_control(self, control_) -> None:
        """The rotors' commanded thrusts (N): four finite numbers (MuJoCo clamps them to ``ctrlrange``)."""
        self.data.ctrl[:] = finite_control(control_, NU, "the quadrotor", "rotor thrusts", "thrusts")
