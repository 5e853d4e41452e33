"""The reacher's plant: the MJCF model (``models/reacher.xml``) and its MuJoCo physics.

Two plant settings (see the MJCF header for the numbers):
  * ``"mismatched"`` (default): the MJCF as written: heavier links, 1.2 times the rods' rotational
    inertia and more joint damping than the analytic model knows;
  * ``"matched"``: those differences removed by name, so MuJoCo integrates the MPC's analytic model
    (``tests/tasks/reacher/test_reacher.py`` shows they agree).

The target is a mocap body: the task moves it (``set_target``) to show where the fingertip should
go; it does not act on the arm.
"""

from __future__ import annotations

import math

import numpy as np
from dm_control import mjcf

from etmpc.systems.plants import Physics as PlantPhysics
from etmpc.systems.plants import finite_control, load_plant
from etmpc.systems.reacher.model import NU, Parameters


def _matched(root: mjcf.RootElement) -> None:
    """Remove the MJCF's deliberate differences from the analytic model (edits by MJCF name)."""
    p = Parameters()
    links = (("upper_arm", p.upper_arm_mass_kg, p.upper_arm_length_m), ("forearm", p.forearm_mass_kg, p.forearm_length_m))
    for body, mass, length in links:
        rod = p.inertia_factor * mass * length**2 / 12  # uniform rod about its centre
        inertial = root.find("body", body).inertial
        inertial.mass = mass
        inertial.diaginertia = [1e-6, rod, rod]
    for joint in ("shoulder", "elbow"):
        root.find("joint", joint).damping = p.joint_damping_n_m_s


def load_model(plant: str = "mismatched", timestep_s: float | None = None) -> mjcf.RootElement:
    """The MJCF, with the plant setting's edits; ``timestep_s`` replaces the physics step."""
    return load_plant("reacher.xml", plant, _matched, timestep_s)


class Physics(PlantPhysics):
    """The reacher's physics with named accessors (snapshots and stepping: :class:`~etmpc.systems.plants.Physics`)."""

    def _reload_from_data(self, data):  # called by dm-control whenever the model is (re)bound
        super()._reload_from_data(data)
        m = self.model
        joints = [m.name2id(name, "joint") for name in ("shoulder", "elbow")]
        self._qpos = np.array([m.jnt_qposadr[j] for j in joints])
        self._qvel = np.array([m.jnt_dofadr[j] for j in joints])
        self._target = m.body_mocapid[m.name2id("target", "body")]
        self._links = (
            float(np.linalg.norm(m.body_pos[m.name2id("forearm", "body")])),
            float(np.linalg.norm(m.site_pos[m.name2id("fingertip", "site")])),
        )

    # -- vocabulary -------------------------------------------------------------------------------
    def joint_angles(self) -> np.ndarray:
        """``[q1, q2]`` (rad), unwrapped."""
        return self.data.qpos[self._qpos].copy()

    def joint_velocities(self) -> np.ndarray:
        return self.data.qvel[self._qvel].copy()

    def fingertip(self) -> np.ndarray:
        """The fingertip's ``(x, y)`` (m), from the joint angles (no kinematics pass needed)."""
        q = self.data.qpos
        q1, q12 = q[self._qpos[0]], q[self._qpos[0]] + q[self._qpos[1]]
        l1, l2 = self._links
        return np.array([l1 * math.cos(q1) + l2 * math.cos(q12), l1 * math.sin(q1) + l2 * math.sin(q12)])

    def target(self) -> np.ndarray:
        """Where the target body is drawn ``(x, y)`` (m)."""
        return self.data.mocap_pos[self._target, :2].copy()

    def set_target(self, target_m: np.ndarray) -> None:
        self.data.mocap_pos[self._target, :2] = target_m

    def state(self) -> np.ndarray:
        """``[q1, q2, q1dot, q2dot]`` in the analytic model's order."""
        return np.concatenate([self.data.qpos[self._qpos], self.data.qvel[self._qvel]])

    def set_state_vector(self, x: np.ndarray) -> None:
        self.data.qpos[self._qpos] = x[:2]
        self.data.qvel[self._qvel] = x[2:]

    def set_control(self, control_) -> None:
        """The joint torques (N m): two finite numbers (MuJoCo clamps them to ``ctrlrange``)."""
        self.data.ctrl[:] = finite_control(control_, NU, "the reacher", "torques", "torques")
