"""LQR feedback on the prediction error: python-control's ``dlqr``, with the same bits on every machine.

``dlqr`` (LAPACK underneath) gives a gain whose last bits depend on the BLAS/LAPACK kernel the CPU
selects: the cart pendulum's gain moved by up to 150 units in the last place between
``OPENBLAS_CORETYPE=Haswell``, ``Prescott`` and ``SkylakeX``, and with it every trajectory. So the
gain is computed twice: by python-control (the design, with its timebase rules), and in 60-digit
arithmetic (``mpmath``, pure Python: the same on every machine) by the zero-order-hold discretisation
(the matrix exponential of ``[[A, B], [0, 0]] dt``) and the structure-preserving doubling algorithm
for the discrete Riccati equation. The second, rounded once to doubles, is the gain used; the two
must agree to ``AGREEMENT`` (relative), or the construction fails.

The doubling algorithm computes the Riccati recursion from ``P = Q`` in ``2^k`` steps at its k-th
iteration, so it converges to the same (minimal) solution as ``dlqr`` also when a mode is neither
penalised nor fed back (the cart's position: its gain is exactly 0, where ``dlqr`` gives 1e-17).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import TYPE_CHECKING

import mpmath
import numpy as np

from etmpc.common.checks import BadValue
from etmpc.common.numerics import matvec

if TYPE_CHECKING:
    import control as ct

DIGITS = 60  # working precision of the exact computation
AGREEMENT = 1e-9  # python-control's gain and the exact one, relative to the gain's largest entry
_MAX_DOUBLINGS = 60  # 2^60 Riccati steps: far beyond convergence for any stabilisable system


def state_space(*args, **kwargs) -> ct.StateSpace:
    """python-control's ``ss`` (its arguments), imported when a system is first made, not when etmpc or a
    task's class is: importing python-control takes about 2 s (it imports scipy.signal and matplotlib)."""
    import control as ct

    return ct.ss(*args, **kwargs)


def discrete_lqr_gain(system: ct.StateSpace, Q: np.ndarray, R: np.ndarray, dt_s: float | None = None) -> np.ndarray:
    """Gain ``K`` of ``u = -K x`` for a discrete-time system, the same on every machine.

    A continuous-time ``system`` is first discretised with a zero-order hold over ``dt_s``; a
    discrete one must already carry a timebase (handing continuous matrices to a discrete Riccati
    solver gives a wrong gain, a known defect of the paper's original code).
    """
    import control as ct  # as in state_space

    Q, R = np.atleast_2d(np.asarray(Q, dtype=float)), np.atleast_2d(np.asarray(R, dtype=float))
    if system.isctime(strict=True):
        if dt_s is None:
            raise ValueError("a continuous-time system needs dt_s for its zero-order-hold discretisation")
        discrete, hold = system.sample(dt_s, method="zoh"), float(dt_s)
    elif system.isdtime(strict=True):
        discrete, hold = system, None
    else:
        raise ValueError("the system's timebase is unspecified; give dt=0 (continuous) or dt>0 (discrete)")
    try:  # weights a user set (options) may give no stabilising gain: one line, naming them
        designed, _, _ = ct.dlqr(discrete, Q, R)
        designed = np.asarray(designed)
        exact = _exact_gain(_key(system.A), _key(system.B), _key(Q), _key(R), hold)
    except (np.linalg.LinAlgError, ArithmeticError, ValueError) as exc:
        said = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise BadValue(f"the LQR's weights {_weights(Q, R)} give no stabilising gain ({said[:160]})") from None
    if not (np.all(np.isfinite(designed)) and np.all(np.isfinite(exact))):
        raise BadValue(f"the LQR's weights {_weights(Q, R)} give a gain that is not finite")
    scale = max(float(np.max(np.abs(designed))), np.finfo(float).tiny)
    if np.max(np.abs(exact - designed)) > AGREEMENT * scale:
        raise ArithmeticError(f"the exact LQR gain {exact.tolist()} disagrees with python-control's {designed.tolist()}")
    return exact


def _weights(Q: np.ndarray, R: np.ndarray) -> str:
    """``Q = diag(0, 1), R = diag(0.1)`` (the matrices themselves where they are not diagonal)."""
    shown = lambda M: (
        f"diag({', '.join(f'{v:g}' for v in np.diag(M))})" if np.array_equal(M, np.diag(np.diag(M))) else str(M.tolist())
    )  # noqa: E731
    return f"Q = {shown(Q)}, R = {shown(R)}"


def _key(matrix) -> tuple:
    """A hashable, exact copy of a matrix (for the cache)."""
    matrix = np.atleast_2d(np.asarray(matrix, dtype=float))
    return matrix.shape, tuple(matrix.ravel().tolist())


def _mp(key: tuple):
    (rows, cols), values = key
    return mpmath.matrix([[mpmath.mpf(values[i * cols + j]) for j in range(cols)] for i in range(rows)])


@lru_cache(maxsize=32)
def _exact_gain(a: tuple, b: tuple, q: tuple, r: tuple, hold: float | None) -> np.ndarray:
    with mpmath.workdps(DIGITS):
        A, B, Q, R = (_mp(k) for k in (a, b, q, r))
        n, m = B.rows, B.cols
        if hold is not None:  # zero-order hold: expm([[A, B], [0, 0]] dt) = [[Ad, Bd], [0, I]]
            M = mpmath.zeros(n + m, n + m)
            for i in range(n):
                for j in range(n + m):
                    M[i, j] = (A[i, j] if j < n else B[i, j - n]) * mpmath.mpf(hold)
            E = mpmath.expm(M)
            A = E[0:n, 0:n]
            B = E[0:n, n : n + m]
        # Structure-preserving doubling: A_k -> 0, H_k -> P (H_k is the Riccati recursion's 2^k-th step).
        I = mpmath.eye(n)
        Ak, G, H = A, B * mpmath.inverse(R) * B.T, Q
        tolerance = mpmath.mpf(10) ** (-(DIGITS - 10))
        for _ in range(_MAX_DOUBLINGS):
            W = mpmath.inverse(I + G * H)
            A_next, G_next, H_next = Ak * W * Ak, G + Ak * W * G * Ak.T, H + Ak.T * H * W * Ak
            change = mpmath.mnorm(H_next - H, 1)
            Ak, G, H = A_next, G_next, H_next
            if change <= tolerance * max(mpmath.mnorm(H, 1), 1):
                break
        else:
            raise ArithmeticError("the doubling algorithm for the Riccati equation did not converge (is (A, B) stabilisable?)")
        K = mpmath.inverse(R + B.T * H * B) * (B.T * H * A)
        return np.array([[float(K[i, j]) for j in range(n)] for i in range(m)])


@dataclass(frozen=True)
class ErrorFeedback:
    """``u_lqr = -K (x - x_planned)``: the correction added to the planned input while a plan is kept.

    Computed row by row with :func:`etmpc.common.numerics.matvec`, not ``@``: the input sent to the plant must
    not depend on the machine's BLAS kernel (it would move every trajectory in its last bits)."""

    gain: np.ndarray  # (nu, nx)

    def correction(self, x: np.ndarray, x_planned: np.ndarray, plan=None, age: int = 0) -> np.ndarray:
        return -matvec(self.gain, x - x_planned)


@dataclass(frozen=True)
class PlanFeedback:
    """``u_lqr = -K_j (x - x_planned)`` with the gains the plan carries (``Plan.gains``, a time-varying
    LQR along it: see ``etmpc.control.mpc.FeedbackWeights``), ``j`` the plan's age (its last past the
    horizon). Away from a fixed operating point (a swing, a reach), a gain linearised along the plan
    corrects where one linearised at a single point cannot."""

    def correction(self, x: np.ndarray, x_planned: np.ndarray, plan=None, age: int = 0) -> np.ndarray:
        gains = plan.gains
        return -matvec(gains[min(age, gains.shape[0] - 1)], x - x_planned)
