"""The paper's analytic cart-pendulum model: the MPC's predictor and the LQR's linearisation.

State ``x = [eta, v, beta, omega]`` (cart position m, cart velocity m/s, pole angle from upright rad,
angular velocity rad/s); input ``u`` = horizontal force on the cart (N). A positive angle tips the
pole towards +x and a positive force pushes the cart towards +x (the MJCF in ``models/`` shares
these conventions; ``tests/tasks/cart_pendulum/test_cart_pendulum_model.py`` pins them against MuJoCo).

One symbolic definition (CasADi SX) serves the predictor, the plant comparison and the
linearisation; callers that want numbers evaluate the CasADi functions.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import casadi as ca
import numpy as np

from etmpc.control.discretise import RK4Model

STATE_NAMES = ("cart_position", "cart_velocity", "pole_angle", "pole_angular_velocity")
NX, NU = 4, 1


@dataclass(frozen=True)
class Parameters:
    """Physical parameters of the paper (section 4.1.1)."""

    pole_mass_kg: float = 0.1  # m
    pole_half_length_m: float = 1.0  # l: pivot to the pole's centre of mass (rod length 2 l)
    total_mass_kg: float = 1.1  # M: cart plus pole
    gravity_m_s2: float = 9.81  # g

    @property
    def cart_mass_kg(self) -> float:
        return self.total_mass_kg - self.pole_mass_kg


def ode(x, u, w=0.0, p: Parameters = Parameters()):
    """Right-hand side ``dx/dt`` of the paper's equations (cartpend:pos .. cartpend:omega).

    ``w`` is the unmeasured angular disturbance (rad/s^2), added to ``omega_dot`` as the paper's
    reference code does. Works on CasADi symbols and on plain numbers.
    """
    m, l, M, g = p.pole_mass_kg, p.pole_half_length_m, p.total_mass_kg, p.gravity_m_s2
    v, beta, omega = x[1], x[2], x[3]
    sin, cos = ca.sin(beta), ca.cos(beta)
    push = u + m * l * omega**2 * sin
    v_dot = (m * g * sin * cos - 4.0 / 3.0 * push) / (m * cos**2 - 4.0 / 3.0 * M)
    omega_dot = (M * g * sin - cos * push) / (4.0 / 3.0 * M * l - m * l * cos**2) + w
    return ca.vertcat(v, v_dot, omega, omega_dot)


@dataclass(frozen=True)
class AnalyticModel(RK4Model):
    """The MPC's predictor: the paper's ODE discretised with RK4 over one control interval."""

    params: Parameters = Parameters()
    dt_s: float = 0.1
    rk4_substeps: int = 1
    NX, NU = NX, NU

    def rate(self, x, u):
        """``dx/dt`` with no disturbance: what the MPC predicts."""
        return ode(x, u, 0.0, self.params)

    @cached_property
    def continuous(self) -> ca.Function:
        """``f(x, u, w) -> dx/dt``."""
        x, u, w = ca.SX.sym("x", NX), ca.SX.sym("u", NU), ca.SX.sym("w")
        return ca.Function("f", [x, u, w], [ode(x, u, w, self.params)], ["x", "u", "w"], ["xdot"])

    def linearised_upright(self) -> tuple[np.ndarray, np.ndarray]:
        """Continuous-time ``(A, B)`` of the ODE at the upright equilibrium ``x = 0, u = 0``.

        Equals the paper's eq. (cartpend:lqr) for the error dynamics.
        """
        x, u = ca.SX.sym("x", NX), ca.SX.sym("u", NU)
        xdot = ode(x, u, 0.0, self.params)
        jac = ca.Function("linearisation", [x, u], [ca.jacobian(xdot, x), ca.jacobian(xdot, u)])
        A, B = jac(np.zeros(NX), np.zeros(NU))
        return np.asarray(A), np.asarray(B)


def paper_lqr_matrices(p: Parameters = Parameters()) -> tuple[np.ndarray, np.ndarray]:
    """Eq. (cartpend:lqr) exactly as printed in the paper, for checking the linearisation."""
    m, l, M, g = p.pole_mass_kg, p.pole_half_length_m, p.total_mass_kg, p.gravity_m_s2
    A = np.array([[0, 1, 0, 0], [0, 0, -m * g / (4 / 3 * M - m), 0], [0, 0, 0, 1], [0, 0, M * g / (l * (4 / 3 * M - m)), 0]])
    B = np.array([[0], [1 / (M - 3 / 4 * m)], [0], [-1 / (l * (4 / 3 * M - m))]])
    return A, B
