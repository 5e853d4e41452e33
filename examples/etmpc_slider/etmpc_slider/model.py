"""The analytic slider: the MPC's predictor and the plan's linearisation.

State ``x = [p, v]`` (position along the rail from the spring's rest point, m; velocity, m/s); input
``u = [f]`` (the motor's force, N). A block of mass ``m`` on a spring ``k`` with viscous damping ``c``:

    m pddot = f - k p - c pdot.

``slider.xml`` shares these conventions; its default plant has a stiffer spring and more damping
than this model (see its header), and its ``matched`` setting is this model (``tests/test_slider.py``
shows MuJoCo and this ODE agree there).
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca

from etmpc.control.discretise import RK4Model

STATE_NAMES = ("position_m", "velocity_m_s")
INPUT_NAMES = ("force_n",)
NX, NU = 2, 1


@dataclass(frozen=True)
class Parameters:
    """The analytic model's block, spring and damper."""

    mass_kg: float = 1.0
    stiffness_n_m: float = 4.0
    damping_n_s_m: float = 0.4


def ode(x, force, p: Parameters = Parameters()):
    """``dx/dt`` of the slider (see the module's docstring); works on CasADi symbols and on numbers."""
    return ca.vertcat(x[1], (force[0] - p.stiffness_n_m * x[0] - p.damping_n_s_m * x[1]) / p.mass_kg)


def holding_force(reference_m, p: Parameters = Parameters()):
    """The force (N) that holds the block at rest at ``reference_m`` in this model: ``k p``."""
    return p.stiffness_n_m * reference_m


@dataclass(frozen=True)
class AnalyticModel(RK4Model):
    """The MPC's predictor: the slider's ODE discretised with RK4 over one control interval."""

    params: Parameters = Parameters()
    dt_s: float = 0.05
    rk4_substeps: int = 1
    NX, NU = NX, NU

    def rate(self, x, u):
        return ode(x, u, self.params)
