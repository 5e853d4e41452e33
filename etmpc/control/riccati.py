"""The time-varying LQR along a plan: the discrete Riccati recursion on the predictor's linearisation
at each planned step, written once for both MPC routes (:mod:`etmpc.control.sqpmethod`,
:mod:`etmpc.control.condensing`)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import casadi as ca
import numpy as np


@dataclass(frozen=True)
class FeedbackWeights:
    """Weights of the time-varying LQR computed along each plan (``Plan.gains``): the discrete Riccati
    recursion on the predictor's linearisation at each planned ``(x_k, u_k)``, from ``terminal`` (the
    weight of ``x_N``; default 10 Q) backwards. A correction then follows the plan's own dynamics."""

    Q: tuple[float, ...]  # diagonal state weights
    R: tuple[float, ...]  # diagonal input weights
    terminal_factor: float = 10.0


def riccati_step(weights: FeedbackWeights, nx: int, nu: int) -> ca.Function:
    """``riccati(P, A, B) -> (K, P_prev)``: one step back, ``K = (R + B'PB)^-1 B'PA`` and
    ``P_prev = Q + A'P(A - BK)`` (symmetrised)."""
    P, A, B = ca.SX.sym("P", nx, nx), ca.SX.sym("A", nx, nx), ca.SX.sym("B", nx, nu)
    Q, R = ca.DM(np.diag(weights.Q)), ca.DM(np.diag(weights.R))
    K = ca.solve(R + B.T @ P @ B, B.T @ P @ A)
    P_next = Q + A.T @ P @ (A - B @ K)
    return ca.Function("riccati", [P, A, B], [K, 0.5 * (P_next + P_next.T)])


def gains_along(
    linearisation: Callable[[int], tuple[ca.MX, ca.MX] | list[ca.MX]], horizon: int, weights: FeedbackWeights, nx: int, nu: int
) -> ca.MX:
    """The gains ``K_k`` (row-major, ``N nu nx`` values, a CasADi column) of the TV-LQR whose
    linearisation at step ``k`` is ``linearisation(k) -> (A_k, B_k)`` (asked from the last step back),
    from ``P_N = terminal_factor Q``."""
    riccati = riccati_step(weights, nx, nu)
    P_k: ca.DM | ca.MX = ca.DM(np.diag(weights.Q)) * weights.terminal_factor
    backwards: list[ca.MX] = []  # K_{N-1}, .., K_0
    for k in range(horizon - 1, -1, -1):
        A_k, B_k = linearisation(k)
        K_k, P_k = riccati.call([P_k, A_k, B_k])
        backwards.append(ca.reshape(K_k.T, nu * nx, 1))  # K_k row by row
    return ca.vertcat(*reversed(backwards))
