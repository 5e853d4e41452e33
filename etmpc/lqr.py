"""LQR feedback on the prediction error, from python-control's ``dlqr``."""

from __future__ import annotations

from dataclasses import dataclass

import control as ct
import numpy as np


def discrete_lqr_gain(system: ct.StateSpace, Q: np.ndarray, R: np.ndarray, dt_s: float | None = None) -> np.ndarray:
    """Gain ``K`` of ``u = -K x`` for a discrete-time system.

    A continuous-time ``system`` is first discretised with a zero-order hold over ``dt_s``; a
    discrete one must already carry a timebase (handing continuous matrices to a discrete Riccati
    solver gives a wrong gain, a known defect of the paper's original code).
    """
    if system.isctime(strict=True):
        if dt_s is None:
            raise ValueError("a continuous-time system needs dt_s for its zero-order-hold discretisation")
        system = system.sample(dt_s, method="zoh")
    elif not system.isdtime(strict=True):
        raise ValueError("the system's timebase is unspecified; give dt=0 (continuous) or dt>0 (discrete)")
    K, _, _ = ct.dlqr(system, np.atleast_2d(Q), np.atleast_2d(R))
    return np.asarray(K)


@dataclass(frozen=True)
class ErrorFeedback:
    """``u_lqr = -K (x - x_planned)``: the correction added to the planned input while a plan is kept."""

    gain: np.ndarray  # (nu, nx)

    def correction(self, x: np.ndarray, x_planned: np.ndarray) -> np.ndarray:
        return -self.gain @ (x - x_planned)
