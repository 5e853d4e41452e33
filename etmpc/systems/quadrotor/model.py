"""The analytic quadrotor: the MPC's predictor and the plan's linearisation.

State ``x = [x, y, z, roll, pitch, yaw, vx, vy, vz, p, q, r]``: the position (m, world frame, z up),
the attitude as Z-Y-X Euler angles (rad: the body is turned by yaw about z, then pitch about the new
y, then roll about the newest x), the velocity (m/s, world frame) and the body rates (rad/s, body
frame); input ``u``: the four rotors' thrusts (N). A rigid body of mass ``m`` and principal inertia
``J`` with no air, no rotor dynamics and no gusts:

    p' = v,    v' = R(roll, pitch, yaw) [0, 0, sum(u)] / m - [0, 0, g],
    (roll, pitch, yaw)' = W(roll, pitch) w,    J w' = tau(u) - w x J w,
    tau(u) = [a (-u0 - u1 + u2 + u3),  a (-u0 + u1 + u2 - u3),  c (-u0 + u1 - u2 + u3)],

with the rotors in an X at ``a = arm / sqrt(2)`` along each body axis (rotor0 front right, then
clockwise seen from above) and ``c`` the drag torque per newton of thrust. ``models/quadrotor.xml``
shares these conventions; its default plant is heavier, has more inertia, rotor lag and air (see its
header), and its ``matched`` setting is this model (``tests/systems/quadrotor/test_quadrotor.py``
shows MuJoCo and this ODE agree there).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import casadi as ca

from etmpc.control.discretise import RK4Model

STATE_NAMES = (
    "x_m",
    "y_m",
    "z_m",
    "roll_rad",
    "pitch_rad",
    "yaw_rad",
    "vx_m_s",
    "vy_m_s",
    "vz_m_s",
    "roll_rate_rad_s",
    "pitch_rate_rad_s",
    "yaw_rate_rad_s",
)
INPUT_NAMES = ("thrust0_n", "thrust1_n", "thrust2_n", "thrust3_n")
NX, NU = 12, 4
GRAVITY_M_S2 = 9.81


@dataclass(frozen=True)
class Parameters:
    """The analytic model's vehicle (a Crazyflie 2.x's public figures; see ``models/quadrotor.xml``)."""

    mass_kg: float = 0.027
    inertia_kg_m2: tuple[float, float, float] = (1.4e-5, 1.4e-5, 2.17e-5)
    arm_m: float = 0.0397  # from the centre to a rotor
    drag_torque_m: float = 0.0251  # a rotor's drag torque per newton of its thrust (km / kf)
    max_thrust_n: float = 0.149  # per rotor: thrust-to-weight 2.25

    @property
    def hover_thrust_n(self) -> float:
        """Each rotor's thrust that holds the model's weight."""
        return self.mass_kg * GRAVITY_M_S2 / 4


def rotation(roll, pitch, yaw):
    """The body-to-world rotation of Z-Y-X Euler angles (a CasADi matrix; numbers work too)."""
    cr, sr, cp, sp, cy, sy = ca.cos(roll), ca.sin(roll), ca.cos(pitch), ca.sin(pitch), ca.cos(yaw), ca.sin(yaw)
    return ca.vertcat(
        ca.horzcat(cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr),
        ca.horzcat(sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr),
        ca.horzcat(-sp, cp * sr, cp * cr),
    )


def torques(u, p: Parameters = Parameters()):
    """The body torques (N m) of the rotors' thrusts ``u``."""
    a, c = p.arm_m / math.sqrt(2), p.drag_torque_m
    return ca.vertcat(a * (-u[0] - u[1] + u[2] + u[3]), a * (-u[0] + u[1] + u[2] - u[3]), c * (-u[0] + u[1] - u[2] + u[3]))


def ode(x, u, p: Parameters = Parameters()):
    """``dx/dt`` of the quadrotor (see the module's docstring); works on CasADi symbols and on numbers."""
    roll, pitch, yaw = x[3], x[4], x[5]
    w = x[9:12]
    thrust = u[0] + u[1] + u[2] + u[3]
    acceleration = rotation(roll, pitch, yaw)[:, 2] * thrust / p.mass_kg - ca.vertcat(0, 0, GRAVITY_M_S2)
    sr, cr, tp, cp = ca.sin(roll), ca.cos(roll), ca.tan(pitch), ca.cos(pitch)
    euler_rates = ca.vertcat(w[0] + sr * tp * w[1] + cr * tp * w[2], cr * w[1] - sr * w[2], (sr * w[1] + cr * w[2]) / cp)
    j = ca.vertcat(*p.inertia_kg_m2)
    jw = j * w
    gyroscopic = ca.vertcat(w[1] * jw[2] - w[2] * jw[1], w[2] * jw[0] - w[0] * jw[2], w[0] * jw[1] - w[1] * jw[0])
    angular_acceleration = (torques(u, p) - gyroscopic) / j
    return ca.vertcat(x[6:9], euler_rates, acceleration, angular_acceleration)


@dataclass(frozen=True)
class AnalyticModel(RK4Model):
    """The MPC's predictor: the quadrotor's ODE discretised with RK4 over one control interval."""

    params: Parameters = Parameters()
    dt_s: float = 0.05
    rk4_substeps: int = 2
    NX, NU = NX, NU

    def rate(self, x, u):
        return ode(x, u, self.params)
