"""A continuous model made discrete for the MPC's predictor: explicit Runge-Kutta 4 with the input
held over the interval. Works on CasADi symbols and on numbers alike."""

from __future__ import annotations


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
