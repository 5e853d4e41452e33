"""The cart pendulum's plant: the MJCF model (``models/cart_pendulum.xml``) and its MuJoCo physics.

Shared by the domain's tasks (``balance`` in ``task.py``, ``kicks`` in ``kicks.py``). The physics holds
a held angular disturbance (``userdata[0]``, the balance task's) that enters as the generalised force
``M(q) e_hinge w`` before every physics step, and optional bumpers at the ends of a rail (the kicks
task's): a spring-damper force on the slider when the cart passes ``+-position``.

Two plant settings (see the MJCF header for the numbers):
  * ``"mismatched"`` (default): the MJCF as written: hinge damping, cart damping and drive armature,
    a pole inertia that is not the ideal rod's; the analytic model does not know these.
  * ``"matched"``: those differences removed by name, so MuJoCo integrates the same ODE as the
    MPC's analytic model (``tests/tasks/cart_pendulum/test_cart_pendulum_model.py`` shows they agree).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import mujoco
import numpy as np
from dm_control import mjcf
from dm_control.rl import control

from etmpc.systems.plants import Physics as PlantPhysics
from etmpc.systems.plants import load_plant
from etmpc.systems.cart_pendulum.model import Parameters


@dataclass(frozen=True)
class Bumpers:
    """Spring-damper bumpers at the ends of a rail: past ``|eta| = position_m`` the slider feels
    ``-stiffness (eta - +-position) - damping v``."""

    position_m: float = 2.5
    stiffness_n_m: float = 1000.0
    damping_n_s_m: float = 40.0


def _matched(root: mjcf.RootElement) -> None:
    """Remove the MJCF's deliberate differences from the analytic model (edits by MJCF name)."""
    p = Parameters()
    root.find("joint", "hinge").damping = 0.0
    slider = root.find("joint", "slider")
    slider.damping = 0.0
    slider.armature = 0.0
    rod = p.pole_mass_kg * (2 * p.pole_half_length_m) ** 2 / 12  # uniform rod about its centre
    pole = root.find("body", "pole")
    pole.inertial.diaginertia = [rod, rod, 1e-6]
    pole.inertial.mass = p.pole_mass_kg
    root.find("body", "cart").inertial.mass = p.cart_mass_kg


def load_model(
    plant: str = "mismatched", timestep_s: float | None = None, bumpers: Bumpers | None = None, reference: bool = False
) -> mjcf.RootElement:
    """The MJCF, with the plant setting's edits; ``timestep_s`` replaces the physics step,
    ``bumpers`` draws the rail's bumpers (their force is the physics', see :meth:`Physics.step`), and
    ``reference`` adds a marker on the rail where the cart should be (a mocap body: it shows the
    reference, :meth:`Physics.set_reference`, and does not act on the cart)."""
    root = load_plant("cart_pendulum.xml", plant, _matched, timestep_s)
    if bumpers is not None:  # where the cart's end meets them (the cart is 0.5 m long)
        for side in (-1, 1):
            root.worldbody.add(
                "geom",
                name=f"bumper_{'left' if side < 0 else 'right'}",
                type="box",
                material="rail",
                pos=[side * (bumpers.position_m + 0.25 + 0.05), 0, 0],
                size=[0.05, 0.2, 0.2],
            )
    if reference:
        marker = root.worldbody.add("body", name="reference", mocap=True, pos=[0, 0, 0])
        marker.add("geom", name="reference", type="box", pos=[0, -0.2, -0.06], size=[0.03, 0.03, 0.2], rgba=[0.95, 0.8, 0.1, 1])
    return root


class Physics(PlantPhysics):
    """Cart-pendulum physics with named accessors and the held angular disturbance."""

    bumpers: Bumpers | None = None  # set by a task with a rail (kicks): see step()

    def _reload_from_data(self, data):  # called by dm-control whenever the model is (re)bound
        super()._reload_from_data(data)
        m = self.model
        self._slider = (m.jnt_qposadr[m.name2id("slider", "joint")], m.jnt_dofadr[m.name2id("slider", "joint")])
        self._hinge = (m.jnt_qposadr[m.name2id("hinge", "joint")], m.jnt_dofadr[m.name2id("hinge", "joint")])
        self._hinge_unit = np.zeros(m.nv)
        self._hinge_unit[self._hinge[1]] = 1.0
        self._force = np.zeros(m.nv)
        self._reference = m.body_mocapid[m.name2id("reference", "body")] if m.nmocap else -1

    # -- vocabulary -------------------------------------------------------------------------------
    def cart_position(self) -> float:
        return float(self.data.qpos[self._slider[0]])

    def cart_velocity(self) -> float:
        return float(self.data.qvel[self._slider[1]])

    def pole_angle(self) -> float:
        return float(self.data.qpos[self._hinge[0]])

    def pole_angular_velocity(self) -> float:
        return float(self.data.qvel[self._hinge[1]])

    def state(self) -> np.ndarray:
        """``[eta, v, beta, omega]`` in the analytic model's order."""
        q, v = self.data.qpos, self.data.qvel
        return np.array([q[self._slider[0]], v[self._slider[1]], q[self._hinge[0]], v[self._hinge[1]]])

    def set_state_vector(self, x: np.ndarray) -> None:
        self.data.qpos[self._slider[0]], self.data.qvel[self._slider[1]] = x[0], x[1]
        self.data.qpos[self._hinge[0]], self.data.qvel[self._hinge[1]] = x[2], x[3]

    def add_angular_velocity(self, delta_rad_s: float) -> None:
        """A kick: the pole's angular velocity jumps by ``delta_rad_s``."""
        self.data.qvel[self._hinge[1]] += delta_rad_s

    def disturbance(self) -> float:
        """Angular disturbance of the current control interval (rad/s^2)."""
        return float(self.data.userdata[0])

    def set_reference(self, position_m: float) -> None:
        """Move the rail's reference marker (a model loaded with ``reference=True``) to ``position_m``."""
        if self._reference >= 0:
            self.data.mocap_pos[self._reference, 0] = position_m

    def set_disturbance(self, w_rad_s2: float) -> None:
        self.data.userdata[0] = w_rad_s2

    def set_control(self, control_) -> None:
        """The force on the cart (N): one finite number (MuJoCo clamps it to ``ctrlrange``)."""
        force = np.asarray(control_, dtype=float)
        if force.size != 1:
            raise ValueError(f"the cart pendulum's action is one force, got an action of shape {force.shape}")
        value = float(force.reshape(()))
        if not math.isfinite(value):
            raise ValueError(f"the cart pendulum's force must be finite, got {value}")
        self.data.ctrl[0] = value

    # -- stepping ---------------------------------------------------------------------------------
    def step(self, nstep: int = 1) -> None:
        """Advance ``nstep`` physics steps, refreshing ``qfrc_applied = M(q) e_hinge w`` (plus the
        bumpers' force) before each.

        ``mj_step1`` after a step brings the mass matrix (and the rest of mjData) up to the new state,
        as dm-control's legacy stepping does for RK4: the disturbance's force needs ``M(q)`` there.
        Without a disturbance (``w = 0``) only the last step needs it, because ``mj_step`` computes all
        it uses from the state itself: the same numbers, bit for bit, with a tenth of the passes. A new
        MuJoCo warning (a diverging state) raises ``PhysicsError`` as ``check_invalid_state`` does;
        this is the hot loop of every rollout, so the check is inlined.
        """
        m, d = self.model.ptr, self.data.ptr
        w = d.userdata[0]
        force = d.qfrc_applied
        warnings_before = self._warnings.tolist()
        if w:
            push = self._hinge_unit * w
            for _ in range(nstep):
                mujoco.mj_mulM(m, d, force, push)  # M(q) (e_hinge w): the same numbers as (M(q) e_hinge) w
                if self.bumpers is not None:
                    force[self._slider[1]] += self._bumper_force(d.qpos, d.qvel)
                mujoco.mj_step(m, d)
                mujoco.mj_step1(m, d)
        elif self.bumpers is None:
            force[:] = 0.0
            mujoco.mj_step(m, d, nstep)
            mujoco.mj_step1(m, d)
        else:
            qpos, qvel, slider = d.qpos, d.qvel, self._slider[1]
            for _ in range(nstep):
                force[:] = 0.0
                force[slider] += self._bumper_force(qpos, qvel)
                mujoco.mj_step(m, d)
            mujoco.mj_step1(m, d)
        warnings_after = self._warnings.tolist()
        if warnings_after != warnings_before:
            self._invalid_state(warnings_before, warnings_after)

    def _bumper_force(self, qpos: np.ndarray | None = None, qvel: np.ndarray | None = None) -> float:
        """The bumpers' force on the slider now (N): 0 on the rail, a spring-damper past its ends
        (``qpos``, ``qvel``: mjData's own arrays, if the caller has them at hand)."""
        b = self.bumpers
        assert b is not None, "the bumpers' force is asked for only where the rail has them"
        qpos = self.data.qpos if qpos is None else qpos
        qvel = self.data.qvel if qvel is None else qvel
        eta = float(qpos[self._slider[0]])
        over = abs(eta) - b.position_m
        if over <= 0.0:
            return 0.0
        return -math.copysign(b.stiffness_n_m * over, eta) - b.damping_n_s_m * float(qvel[self._slider[1]])

    def touches_bumper(self) -> bool:
        return self.bumpers is not None and abs(self.cart_position()) > self.bumpers.position_m

    def _invalid_state(self, before: list[int], after: list[int]) -> None:
        """What ``check_invalid_state`` does when MuJoCo warned during a step."""
        names = [name for name, b, a in zip(mujoco.mjtWarning.__members__, before, after) if a > b]
        message = f"Physics state is invalid. Warning(s) raised: {', '.join(names)}"
        if self._warnings_cause_exception:
            raise control.PhysicsError(message)
        logging.warning(message)
