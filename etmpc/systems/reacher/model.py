"""The analytic two-link arm: the MPC's predictor and the plan's linearisation.

State ``x = [q1, q2, q1dot, q2dot]`` (shoulder angle from +x and elbow angle relative to the upper
arm, counter-clockwise seen from above, rad; their rates, rad/s); input ``u = [tau1, tau2]`` (joint
torques, N m). The arm lies in a horizontal plane, so gravity does not act on the joints. Two
uniform rods of mass ``m_i`` and length ``l_i`` (centre of mass mid-rod, inertia ``m_i l_i^2 / 12``
about it), viscous damping ``b`` at each joint:

    M(q2) qddot + h(q2, qdot) + b qdot = tau,
    M = [[a1 + 2 a2 cos q2, a3 + a2 cos q2], [a3 + a2 cos q2, a3]],
    h = a2 sin q2 [-(2 q1dot q2dot + q2dot^2), q1dot^2],
    a1 = I1 + I2 + m1 lc1^2 + m2 (l1^2 + lc2^2),  a2 = m2 l1 lc2,  a3 = I2 + m2 lc2^2.

``models/reacher.xml`` shares these conventions; its default plant is heavier, stiffer to turn and
more damped than this model (see its header), and its ``matched`` setting is this model
(``tests/tasks/reacher/test_reacher.py`` shows MuJoCo and this ODE agree there).
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from etmpc.control.discretise import RK4Model

STATE_NAMES = ("shoulder_angle_rad", "elbow_angle_rad", "shoulder_velocity_rad_s", "elbow_velocity_rad_s")
INPUT_NAMES = ("shoulder_torque_nm", "elbow_torque_nm")
NX, NU = 4, 2


@dataclass(frozen=True)
class Parameters:
    """The analytic model's arm."""

    upper_arm_mass_kg: float = 1.0
    forearm_mass_kg: float = 1.0
    upper_arm_length_m: float = 0.5
    forearm_length_m: float = 0.5
    inertia_factor: float = 1.0  # rotational inertia about each centre, in units of the uniform rod's m l^2 / 12
    joint_damping_n_m_s: float = 0.05


def ode(x, tau, p: Parameters = Parameters()):
    """``dx/dt`` of the arm (see the module's docstring); works on CasADi symbols and on numbers."""
    m1, m2, l1, l2 = p.upper_arm_mass_kg, p.forearm_mass_kg, p.upper_arm_length_m, p.forearm_length_m
    lc1, lc2 = l1 / 2, l2 / 2
    i1, i2 = p.inertia_factor * m1 * l1**2 / 12, p.inertia_factor * m2 * l2**2 / 12
    a1 = i1 + i2 + m1 * lc1**2 + m2 * (l1**2 + lc2**2)
    a2, a3 = m2 * l1 * lc2, i2 + m2 * lc2**2
    q2, dq1, dq2 = x[1], x[2], x[3]
    c2, s2 = ca.cos(q2), ca.sin(q2)
    m11, m12, m22 = a1 + 2 * a2 * c2, a3 + a2 * c2, a3
    f1 = tau[0] + a2 * s2 * (2 * dq1 * dq2 + dq2**2) - p.joint_damping_n_m_s * dq1
    f2 = tau[1] - a2 * s2 * dq1**2 - p.joint_damping_n_m_s * dq2
    det = m11 * m22 - m12 * m12  # > 0: M is positive definite
    return ca.vertcat(dq1, dq2, (m22 * f1 - m12 * f2) / det, (m11 * f2 - m12 * f1) / det)


def fingertip(x, p: Parameters = Parameters()):
    """The fingertip's position ``(x, y)`` (m) in the plane; works on CasADi symbols and on numbers."""
    l1, l2 = p.upper_arm_length_m, p.forearm_length_m
    return ca.vertcat(l1 * ca.cos(x[0]) + l2 * ca.cos(x[0] + x[1]), l1 * ca.sin(x[0]) + l2 * ca.sin(x[0] + x[1]))


@dataclass(frozen=True)
class AnalyticModel(RK4Model):
    """The MPC's predictor: the arm's ODE discretised with RK4 over one control interval."""

    params: Parameters = Parameters()
    dt_s: float = 0.1
    rk4_substeps: int = 2
    NX, NU = NX, NU

    def rate(self, x, u):
        return ode(x, u, self.params)

    def fingertip(self, x: np.ndarray) -> np.ndarray:
        return np.asarray(fingertip(np.asarray(x, float), self.params), dtype=float).ravel()
