"""The OCP as a value: what every route of the Gauss-Newton MPC solves (:mod:`etmpc.control.route`).

    min  sum_{k<N} |r(x_k, u_k, u_k - u_{k-1})|^2 + |r_N(x_N)|^2
    s.t. x_0 = x_measured,  x_{k+1} = F(x_k, u_k),  u_min <= u_k <= u_max

The dynamics ``F`` are the predictor over one control interval (the discretisation: a model's ODE made
discrete by :mod:`etmpc.control.discretise`, or a model discrete already); the costs are the stage and
terminal residuals; the bounds are on the inputs; ``N`` is the horizon. With ``parameters > 0`` both
residuals take that many more values last (a reference, a target), given at each solve.

How the OCP is transcribed (multiple shooting, condensing onto the inputs) is a route's business, not
the OCP's: the OCP only rolls its dynamics out and prices an input sequence, which every route and the
tasks' own checks read.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import casadi as ca
import numpy as np


@dataclass(frozen=True, eq=False)
class OCP:
    """A nonlinear least-squares OCP: ``model(x, u) -> x+`` (one interval), ``stage_residual(x, u, du[, p])``,
    ``terminal_residual(x[, p])``, the horizon ``N``, the input bounds ``(nu,)`` (floats) and how many
    parameters ``p`` both residuals take last (0: none). Built once by the MPC from its system."""

    model: ca.Function
    stage_residual: ca.Function
    terminal_residual: ca.Function
    horizon: int
    u_min: np.ndarray
    u_max: np.ndarray
    parameters: int = 0

    @cached_property
    def nx(self) -> int:
        """The state's size (asked of the model once: a route reads it at every solve)."""
        return int(self.model.size1_in(0))

    @cached_property
    def nu(self) -> int:
        """The input's size."""
        return int(self.model.size1_in(1))

    def rollout(self, x0: np.ndarray, inputs: np.ndarray) -> np.ndarray:
        """The predicted states ``(len(inputs) + 1, nx)`` from ``x0`` under ``inputs``."""
        states = [np.asarray(x0, dtype=float)]
        for u in inputs:
            states.append(np.asarray(self.model(states[-1], u)).ravel())
        return np.array(states)

    def objective(self, x: np.ndarray, u_prev: np.ndarray, inputs: np.ndarray, parameters: np.ndarray | None = None) -> float:
        """The objective of an input sequence ``(N, nu)``, rolled out through the predictor from ``x``
        (single shooting: no variable but the inputs)."""
        extra = np.zeros(0) if parameters is None else np.asarray(parameters, float)
        return float(self._objective(x, u_prev, np.asarray(inputs, float).reshape(self.horizon, self.nu).T, extra))

    @cached_property
    def _objective(self) -> ca.Function:
        """``objective(x, u_prev, U (nu, N), p)``: made when first asked for."""
        xs, up = ca.SX.sym("x", self.nx), ca.SX.sym("u_prev", self.nu)
        us, extra = ca.SX.sym("u", self.nu, self.horizon), ca.SX.sym("p", self.parameters)
        total: ca.SX | int = 0
        state, previous = xs, up
        for k in range(self.horizon):
            total += ca.sumsqr(self.stage_residual(*self.with_parameters(extra, state, us[:, k], us[:, k] - previous)))
            previous = us[:, k]
            state = self.model(state, us[:, k])
        total += ca.sumsqr(self.terminal_residual(*self.with_parameters(extra, state)))
        return ca.Function("objective", [xs, up, us, extra], [total])

    def with_parameters(self, extra: ca.SX, *args: ca.SX) -> tuple[ca.SX, ...]:
        """A residual's arguments: ``args``, and the parameters last if the OCP has any."""
        return (*args, extra) if self.parameters else args
