"""The LQR gain against an independent discrete Riccati solution."""

import control as ct
import numpy as np
import pytest
from scipy.linalg import expm, solve_discrete_are

from etmpc.systems.cart_pendulum.model import AnalyticModel
from etmpc.control.lqr import discrete_lqr_gain


def test_gain_matches_scipy_riccati_on_the_zoh_model(cart_system):
    A, B = AnalyticModel().linearised_upright()
    dt = 0.1
    block = expm(np.block([[A, B], [np.zeros((1, 5))]]) * dt)  # zero-order hold, by hand
    Ad, Bd = block[:4, :4], block[:4, 4:]
    Q, R = np.diag([0, 1, 10, 10]), np.array([[0.1]])
    P = solve_discrete_are(Ad, Bd, Q, R)
    K = np.linalg.solve(R + Bd.T @ P @ Bd, Bd.T @ P @ Ad)
    np.testing.assert_allclose(cart_system.feedback.gain, K, rtol=1e-8)
    # Q puts no weight on the cart position, so that mode stays at 1 (the cart may drift); every
    # other mode of the linear model is stabilised.
    magnitudes = np.sort(np.abs(np.linalg.eigvals(Ad - Bd @ K)))
    assert magnitudes[-1] == pytest.approx(1.0, abs=1e-9) and np.all(magnitudes[:-1] < 0.9)


def test_continuous_system_needs_a_sampling_time():
    sys = ct.ss([[0.0]], [[1.0]], [[1.0]], [[0.0]])
    with pytest.raises(ValueError, match="dt_s"):
        discrete_lqr_gain(sys, [[1.0]], [[1.0]])
    # A discrete scalar integrator x+ = x - 0.1 u (the battery's SoC error form) is accepted as is.
    K = discrete_lqr_gain(ct.ss([[1.0]], [[-0.1]], [[1.0]], [[0.0]], dt=0.1), [[1.0]], [[0.1]])
    assert K.shape == (1, 1) and K[0, 0] < 0


def test_correction_opposes_the_error(cart_system):
    # The pole leans further towards +x than planned: push the cart towards +x.
    assert cart_system.feedback.correction(np.array([0, 0, 0.1, 0]), np.zeros(4))[0] > 0
