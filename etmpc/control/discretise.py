"""A continuous model made discrete for the MPC's predictor: explicit Runge-Kutta 4 with the input
held over the interval. Works on CasADi symbols and on numbers alike."""

from __future__ import annotations

from functools import cached_property

import casadi as ca
import numpy as np


def rk4(f, x, u, dt_s: float, substeps: int):
    """Explicit Runge-Kutta 4 over ``dt_s`` in ``substeps`` equal steps, with the input held (zero-order hold)."""
    h = dt_s / substeps
    for _ in range(substeps):
        k1 = f(x, u)
        k2 = f(x + h / 2 * k1, u)
        k3 = f(x + h / 2 * k2, u)
        k4 = f(x + h * k3, u)
        x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return x


class RK4Model:
    """A predictor made from a continuous ODE: a subclass (a frozen dataclass with fields ``dt_s`` and
    ``rk4_substeps``) names the sizes ``NX``, ``NU`` and writes ``rate(x, u)``, ``dx/dt`` in CasADi;
    it gets ``continuous`` (``f(x, u) -> xdot``), ``discrete`` (``F(x, u) -> x+``: :func:`rk4` over one
    control interval, the MPC's model) and ``predict`` (the same on numbers)."""

    NX: int
    NU: int
    dt_s: float
    rk4_substeps: int

    def rate(self, x, u):
        raise NotImplementedError

    @cached_property
    def continuous(self) -> ca.Function:
        """``f(x, u) -> dx/dt``."""
        x, u = ca.SX.sym("x", self.NX), ca.SX.sym("u", self.NU)
        return ca.Function("f", [x, u], [self.rate(x, u)], ["x", "u"], ["xdot"])

    @cached_property
    def discrete(self) -> ca.Function:
        """``F(x, u) -> x+``: one control interval."""
        x, u = ca.SX.sym("x", self.NX), ca.SX.sym("u", self.NU)
        return ca.Function("F", [x, u], [rk4(self.rate, x, u, self.dt_s, self.rk4_substeps)], ["x", "u"], ["x_next"])

    def predict(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        return np.asarray(self.discrete(x, u)).ravel()
