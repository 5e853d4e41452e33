"""The analytic model against MuJoCo and against the paper; pins the sign conventions."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from etmpc.systems.cart_pendulum import task as cp_env
from etmpc.systems.cart_pendulum.model import AnalyticModel, Parameters, ode, paper_lqr_matrices


def analytic_trajectory(x0, inputs, disturbances, dt=cp_env.CONTROL_DT_S):
    """The paper's ODE integrated to 1e-11 by scipy (independent of CasADi's RK4 and of MuJoCo)."""
    states, x = [np.asarray(x0, float)], np.asarray(x0, float)
    for u, w in zip(inputs, disturbances):
        rhs = lambda t, y: np.asarray(ode(y, u, w), dtype=float).ravel()  # noqa: E731
        x = solve_ivp(rhs, (0, dt), x, method="DOP853", rtol=1e-11, atol=1e-12).y[:, -1]
        states.append(x)
    return np.array(states)


def plant_trajectory(plant, x0, inputs, disturbances):
    environment = cp_env.make_environment(plant=plant)
    padded = np.zeros(cp_env.EPISODE_STEPS)
    padded[: len(disturbances)] = disturbances
    environment.task.use_episode(cp_env.Episode(np.asarray(x0, float), padded))
    environment.reset()
    states = [environment.physics.state()]
    for u in inputs:
        environment.step([u])
        states.append(environment.physics.state())
    return np.array(states)


CASES = [  # (initial state, input pattern)
    ([0.0, 0.0, 0.1, 0.0], "zero"),
    ([0.0, 0.5, -0.6, 0.8], "random"),
    ([0.3, -1.0, 0.78, -1.0], "random"),
    ([0.0, 0.2, 0.05, 0.1], "bang"),
]


def _inputs(pattern, rng, steps=20):
    return {"zero": np.zeros(steps), "random": rng.uniform(-10, 10, steps), "bang": np.tile([25.0, -25.0], steps // 2)}[pattern]


@pytest.mark.parametrize("x0, pattern", CASES)
def test_matched_plant_follows_the_analytic_model(x0, pattern):
    """Matched MuJoCo (RK4, 0.025 s) vs the ODE solved to 1e-11 over 2 s, no disturbance.

    Tolerance 1e-5 absolute on every state (seen: ~2e-6): RK4's error at 0.025 s on these
    dynamics. A sign error, or a wrong mass or inertia, shows up as 1e-2 or more.
    """
    rng = np.random.default_rng(int(1000 * abs(x0[2])))
    inputs = _inputs(pattern, rng)
    expected = analytic_trajectory(x0, inputs, np.zeros(inputs.size))
    actual = plant_trajectory("matched", x0, inputs, np.zeros(inputs.size))
    np.testing.assert_allclose(actual, expected, rtol=0, atol=1e-5)


@pytest.mark.parametrize("x0, pattern", CASES)
def test_matched_plant_with_disturbance(x0, pattern):
    """The same with w ~ N(0, 1) per interval. The plant applies M(q) e_hinge w refreshed before each
    0.025 s physics step (the MJCF's timestep) and held over its RK4 stages, so the cart coupling m l cos(beta) w
    lags by up to one physics step: an O(dt) effect of ~1e-3 over 2 s (seen: <= 1.2e-3). Tolerance
    5e-3; leaving w out of the plant, or giving it the wrong sign, is off by > 5e-2.
    """
    rng = np.random.default_rng(int(1000 * abs(x0[2])) + 1)
    inputs, disturbances = _inputs(pattern, rng), rng.normal(size=20)
    expected = analytic_trajectory(x0, inputs, disturbances)
    actual = plant_trajectory("matched", x0, inputs, disturbances)
    np.testing.assert_allclose(actual, expected, rtol=0, atol=5e-3)
    undisturbed = analytic_trajectory(x0, inputs, np.zeros(20))
    assert np.max(np.abs(actual - undisturbed)) > 5e-2


def test_sign_conventions():
    """A push towards +x accelerates the cart towards +x and tips the pole back (towards -x);
    a pole tipped towards +x falls further that way. Same in the model and the plant."""
    model = AnalyticModel()
    x_push = model.predict(np.zeros(4), 5.0)
    assert x_push[1] > 0 and x_push[3] < 0
    x_fall = model.predict(np.array([0, 0, 0.1, 0]), 0.0)
    assert x_fall[3] > 0
    plant = plant_trajectory("matched", np.zeros(4), [5.0], [0.0])[-1]
    assert np.sign(plant[1]) == np.sign(x_push[1]) and np.sign(plant[3]) == np.sign(x_push[3])


def test_disturbance_is_the_angular_acceleration():
    """Over one interval from rest, w changes omega by about w * dt and the cart barely moves:
    the generalised force M(q) e_hinge w accelerates the hinge alone."""
    x0 = np.zeros(4)
    quiet = plant_trajectory("matched", x0, [0.0], [0.0])[-1]
    pushed = plant_trajectory("matched", x0, [0.0], [2.0])[-1]
    np.testing.assert_allclose(pushed, analytic_trajectory(x0, [0.0], [2.0])[-1], atol=2e-4)
    assert abs((pushed - quiet)[3] - 2.0 * cp_env.CONTROL_DT_S) < 0.02  # ~ w * dt, gravity adds a little


def test_mismatched_plant_differs_from_the_model():
    x0, inputs, dist = [0.0, 0.5, 0.3, -0.5], np.full(10, 3.0), np.zeros(10)
    expected = analytic_trajectory(x0, inputs, dist)
    actual = plant_trajectory("mismatched", x0, inputs, dist)
    assert np.max(np.abs(actual - expected)) > 1e-2


def test_linearisation_equals_the_papers_lqr_model():
    A, B = AnalyticModel().linearised_upright()
    A_paper, B_paper = paper_lqr_matrices(Parameters())
    np.testing.assert_allclose(A, A_paper, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(B, B_paper, rtol=1e-12, atol=1e-12)


def test_predictor_is_rk4_of_the_ode():
    """One RK4 step of 0.1 s stays within 1e-3 of the exact ODE solution on typical states."""
    model = AnalyticModel()
    for x0, u in [([0, 0.5, 0.4, -0.8], 10.0), ([0, -1, -0.7, 1.0], -20.0)]:
        exact = analytic_trajectory(x0, [u], [0.0])[-1]
        assert np.max(np.abs(model.predict(np.array(x0, float), u) - exact)) < 1e-3


def test_mismatch_table_orders_the_settings():
    from etmpc.systems.cart_pendulum.mismatch import table

    matched, mismatched = table(samples=40, seed=1)
    assert matched["plant"] == "matched" and mismatched["plant"] == "mismatched"
    assert np.all(matched["max"] < 1e-3)  # the predictor's RK4 step only
    assert np.all(mismatched["rms"] > 10 * matched["rms"])
