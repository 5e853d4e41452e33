"""The sensor model and the extended Kalman filter, against independent truths: the Riccati equation's
steady state (python-control's ``dlqe``), the empirical error of many runs of a linear system for which the
filter is optimal, and the chi-square law of the normalised innovation."""

import casadi as ca
import control as ct
import numpy as np
import pytest

from etmpc.common.checks import BadValue
from etmpc.control.sensing import Belief, ExtendedKalmanFilter, FilterSettings, Readings, Sensor, episode_key

DT = 0.1
A = np.array([[1.0, DT], [0.0, 1.0]])  # a double integrator: position and velocity
B = np.array([[DT**2 / 2], [DT]])
PROCESS_STD = np.array([0.01, 0.05])
NOISE_STD = 0.05  # on the position, the only state measured


def _linear_model() -> ca.Function:
    x, u = ca.SX.sym("x", 2), ca.SX.sym("u", 1)
    return ca.Function("F", [x, u], [ca.mtimes(ca.DM(A), x) + ca.mtimes(ca.DM(B), u)])


def _filter(**sensor) -> ExtendedKalmanFilter:
    settings = FilterSettings(process_std=tuple(PROCESS_STD), initial_std=(1.0, 1.0))
    sensor = {"noise_std": (NOISE_STD, 0.0), "measured": (True, False)} | sensor
    return ExtendedKalmanFilter(_linear_model(), Sensor(**sensor), settings)


def test_the_filters_covariance_reaches_the_riccati_equations_steady_state():
    kf = _filter()
    seen = np.array([True, False])
    belief = kf.start(np.array([0.0, np.nan]), seen)
    for _ in range(400):
        prior_mean, prior = kf.predict(belief, np.zeros(1))
        belief = kf.correct(prior_mean, prior, np.array([0.0, np.nan]), seen)
    _, riccati, _ = ct.dlqe(A, np.eye(2), np.array([[1.0, 0.0]]), np.diag(PROCESS_STD**2), np.array([[NOISE_STD**2]]))
    np.testing.assert_allclose(prior, riccati, rtol=1e-9)  # the predicted covariance is the DARE's solution


def test_on_a_linear_system_the_error_has_the_covariance_the_filter_states():
    """Many runs of the double integrator, with the noise the filter assumes: the estimate's error, averaged over
    runs, has mean 0 and the covariance the filter reports (within sampling error), and the normalised
    innovation squared averages the number of entries read (1)."""
    runs, steps = 2000, 40
    rng = np.random.default_rng(20261202)
    kf, seen = _filter(), np.array([True, False])
    errors, nis = [], []
    for _ in range(runs):
        x = rng.normal(0.0, 1.0, 2)  # the prior the filter starts from: mean 0, std 1
        belief = kf.start(np.array([x[0] + NOISE_STD * rng.standard_normal(), np.nan]), seen)
        for k in range(steps):
            u = np.array([np.sin(0.3 * k)])
            x = A @ x + B @ u + PROCESS_STD * rng.standard_normal(2)
            belief = kf.step(belief, u, np.array([x[0] + NOISE_STD * rng.standard_normal(), np.nan]), seen)
            if k >= steps - 10:
                nis.append(belief.nis)
        errors.append(x - belief.mean)
    errors = np.array(errors)
    empirical = np.cov(errors.T)
    stated = belief.covariance  # the same for every run: the gain does not depend on the readings
    assert np.all(np.abs(errors.mean(axis=0)) < 4 * np.sqrt(np.diag(stated) / runs))
    # a variance estimated from n samples has a relative standard error sqrt(2 / n) = 3.2 %: 12 % is 3.8 of them
    np.testing.assert_allclose(np.diag(empirical), np.diag(stated), rtol=0.12)
    assert abs(empirical[0, 1] - stated[0, 1]) < 0.12 * np.sqrt(stated[0, 0] * stated[1, 1])
    assert np.mean(nis) == pytest.approx(1.0, abs=0.05)  # chi-square with 1 degree of freedom: mean 1


def test_a_lost_reading_only_predicts_and_the_uncertainty_grows():
    kf, seen = _filter(), np.array([True, False])
    belief = kf.start(np.array([0.2, np.nan]), seen)
    lost = kf.step(belief, np.zeros(1), np.full(2, np.nan), np.array([False, False]))
    mean, covariance = kf.predict(belief, np.zeros(1))
    np.testing.assert_array_equal(lost.mean, mean)
    np.testing.assert_array_equal(lost.covariance, covariance)
    assert np.isnan(lost.innovation).all() and lost.nis == 0.0
    assert np.all(np.diag(lost.covariance) > np.diag(belief.covariance) - 1e-15)


def test_a_belief_is_read_only():
    belief = _filter().start(np.array([0.1, np.nan]), np.array([True, False]))
    with pytest.raises(ValueError):
        belief.mean[0] = 1.0


@pytest.mark.parametrize(
    "covariance",
    [
        np.array([[4e-4, 1e-4, 0.0], [1e-4, 9e-4, 0.0], [0.0, 0.0, 1e-2]]),
        np.array([[1.0, 1.0, 0.0], [1.0, 1.0, 0.0], [0.0, 0.0, 0.0]]),  # singular: no Cholesky factor
    ],
)
def test_states_drawn_from_a_belief_have_its_mean_and_covariance(covariance):
    mean, nan = np.array([0.3, -1.0, 2.0]), np.full(3, np.nan)
    belief = Belief(mean, covariance, nan, nan)
    rng = np.random.default_rng(5)
    draws = np.array([belief.sample(rng) for _ in range(20000)])
    # standard errors: sqrt(var / n) for the mean, about sqrt(2 / n) * var for the covariance
    np.testing.assert_allclose(draws.mean(axis=0), mean, atol=5 * np.sqrt(np.diag(covariance).max() / 20000))
    np.testing.assert_allclose(np.cov(draws.T), covariance, atol=5 * np.sqrt(2 / 20000) * np.diag(covariance).max())
    again = Belief(mean, covariance, nan, nan).sample(np.random.default_rng(5))
    np.testing.assert_array_equal(again, draws[0])  # the generator's draws only


def test_the_default_sensor_is_exact_and_a_noisy_one_is_not():
    assert Sensor().exact
    assert Sensor(noise_std=(0.0,), bias=(0.0,), quantum=(0.0,), measured=(True,)).exact
    assert not Sensor(noise_std=(0.01,)).exact
    assert not Sensor(measured=(True, False)).exact
    assert not Sensor(dropout=0.1).exact


def test_a_reading_adds_bias_and_noise_rounds_and_hides_what_is_not_measured():
    sensor = Sensor(noise_std=(0.1, 0.0, 0.2), bias=(1.0, 0.0, 0.0), quantum=(0.0, 0.5, 0.0), measured=(True, True, False))
    readings = Readings(noise=np.array([[1.0, 3.0, -2.0]]), dropped=np.array([False]))
    y, seen = sensor.read(np.array([2.0, 0.7, 5.0]), readings, 0)
    np.testing.assert_array_equal(seen, [True, True, False])
    assert y[0] == pytest.approx(2.0 + 1.0 + 0.1)
    assert y[1] == 0.5  # 0.7 rounded to the nearest 0.5 (no noise on it)
    assert np.isnan(y[2])
    dropped = Readings(noise=np.zeros((1, 3)), dropped=np.array([True]))
    y, seen = sensor.read(np.array([2.0, 0.7, 5.0]), dropped, 0)
    assert not seen.any() and np.isnan(y).all()


def test_the_filter_counts_rounding_as_noise():
    sensor = Sensor(noise_std=(0.3,), quantum=(0.6,))
    np.testing.assert_allclose(sensor.measurement_variance(2), [0.09 + 0.03, 0.09 + 0.03])


class _Episode:
    def __init__(self, **arrays):
        self._arrays = arrays

    def arrays(self):
        return self._arrays


def test_an_episodes_draws_are_its_own_whoever_reads_them():
    a = _Episode(kick=np.arange(5.0), reference=np.ones(5))
    same = _Episode(reference=np.ones(5), kick=np.arange(5.0).astype(">f8"))  # another order, big-endian bytes
    other = _Episode(kick=np.arange(5.0) + 1e-12, reference=np.ones(5))
    assert episode_key(a) == episode_key(same) != episode_key(other)
    sensor = Sensor(noise_std=(0.1,), dropout=0.2, seed=3)
    first, again = sensor.readings(a, 50, 4), sensor.readings(same, 50, 4)
    np.testing.assert_array_equal(first.noise, again.noise)
    np.testing.assert_array_equal(first.dropped, again.dropped)
    assert not np.array_equal(first.noise, sensor.readings(other, 50, 4).noise)
    assert not np.array_equal(first.noise, Sensor(noise_std=(0.1,), seed=4).readings(a, 50, 4).noise)
    assert first.noise.shape == (51, 4) and 0 < first.dropped.sum() < 51


@pytest.mark.parametrize(
    "settings, message",
    [
        ({"noise_std": (-0.1,)}, "noise_std"),
        ({"quantum": (float("nan"),)}, "quantum"),
        ({"bias": (float("inf"),)}, "bias"),
        ({"dropout": 1.0}, "dropout"),
    ],
)
def test_a_bad_sensor_is_refused_naming_what_is_wrong(settings, message):
    with pytest.raises(BadValue, match=message):
        Sensor(**settings)


def test_per_state_values_must_match_the_model():
    with pytest.raises(BadValue, match="one value per state"):
        ExtendedKalmanFilter(_linear_model(), Sensor(noise_std=(0.1, 0.2, 0.3)))
    with pytest.raises(BadValue, match="process_std"):
        FilterSettings(process_std=(0.0,))


def _pendulum() -> ca.Function:
    """A nonlinear model (a damped pendulum on a cart, Euler-discretised) with states that couple."""
    x, u = ca.SX.sym("x", 4), ca.SX.sym("u", 1)
    xdot = ca.vertcat(x[1], u[0] - 0.1 * x[1], x[3], 9.81 * ca.sin(x[2]) - 0.05 * x[3] + ca.cos(x[2]) * u[0])
    return ca.Function("F", [x, u], [x + 0.02 * xdot])


def _textbook_step(model: ca.Function, q: np.ndarray, r: np.ndarray, mean, cov, u, y, seen):
    """The EKF's step as textbooks write it, in NumPy: the gain with an inverse, the covariance in the short
    form ``(I - K H) P`` (equal to Joseph's at the optimal gain); only the model's Jacobian is CasADi's."""
    x = ca.SX.sym("x", mean.size)
    a = np.asarray(ca.Function("A", [x], [ca.jacobian(model(x, u), x)])(mean))
    mean, cov = np.asarray(model(mean, u)).ravel(), a @ cov @ a.T + np.diag(q)
    h = np.eye(mean.size)[seen]
    s = h @ cov @ h.T + np.diag(r[seen])
    gain = cov @ h.T @ np.linalg.inv(s)
    nu = y[seen] - mean[seen]
    return mean + gain @ nu, (np.eye(mean.size) - gain @ h) @ cov, float(nu @ np.linalg.inv(s) @ nu)


def test_the_filter_is_the_textbook_ekf_on_a_nonlinear_model():
    sensor = Sensor(noise_std=(0.01, 0.0, 0.02, 0.0), quantum=(0.0, 0.0, 0.01, 0.0), measured=(True, False, True, False))
    settings = FilterSettings(process_std=(1e-3, 1e-2, 1e-3, 2e-2), initial_std=(0.5, 1.0, 0.3, 1.0))
    ekf = ExtendedKalmanFilter(_pendulum(), sensor, settings)
    q, r = ekf.process_std**2, sensor.measurement_variance(4)
    rng = np.random.default_rng(3)
    seen = np.array([True, False, True, False])
    y = np.array([0.1, np.nan, 0.3, np.nan])
    belief = ekf.start(y, seen)
    mean, cov = belief.mean, belief.covariance
    for step in range(60):
        u = rng.normal(size=1)
        read = seen if step % 7 else np.array([False, False, True, False])  # another set of entries now and then
        y = np.where(read, rng.normal(size=4) * 0.2, np.nan)
        belief = ekf.step(belief, u, y, read)
        mean, cov, nis = _textbook_step(_pendulum(), q, r, mean, cov, u, y, read)
        np.testing.assert_allclose(belief.mean, mean, rtol=1e-10, atol=1e-13)
        np.testing.assert_allclose(belief.covariance, cov, rtol=1e-9, atol=1e-15)
        assert belief.nis == pytest.approx(nis, rel=1e-9)
        np.testing.assert_array_equal(belief.covariance, belief.covariance.T)  # symmetric to the bit
        assert np.all(np.linalg.eigvalsh(belief.covariance) > 0)


KERNEL_PROBE = """
import numpy as np, casadi as ca, hashlib
from etmpc.control.sensing import ExtendedKalmanFilter, FilterSettings, Sensor
x, u = ca.SX.sym("x", 4), ca.SX.sym("u", 1)
xdot = ca.vertcat(x[1], u[0], x[3], 9.81 * ca.sin(x[2]) + ca.cos(x[2]) * u[0])
ekf = ExtendedKalmanFilter(ca.Function("F", [x, u], [x + 0.02 * xdot]), Sensor(noise_std=(0.01,)), FilterSettings())
rng, seen = np.random.default_rng(0), np.ones(4, bool)
belief = ekf.start(rng.normal(size=4), seen)
for _ in range(200):
    belief = ekf.step(belief, rng.normal(size=1), rng.normal(size=4), seen)
print(hashlib.sha256(belief.mean.tobytes() + belief.covariance.tobytes()).hexdigest())
"""


@pytest.mark.parametrize("coretype", ["Prescott", "SkylakeX"])
def test_a_belief_is_the_same_to_the_bit_whatever_blas_kernel_runs(coretype):
    """The filter's algebra is not BLAS's: under another OpenBLAS kernel (and NumPy's baseline loops) 200 steps
    of the filter end in the same bytes. (On a CPU without AVX-512, OpenBLAS refuses SkylakeX and keeps its
    own choice: the check is then weaker, not wrong.)"""
    import os
    import subprocess
    import sys

    run = lambda env: subprocess.run([sys.executable, "-c", KERNEL_PROBE], env=env, capture_output=True, text=True, check=True)  # noqa: E731
    default = run(os.environ.copy()).stdout
    other = os.environ | {"OPENBLAS_CORETYPE": coretype, "NPY_DISABLE_CPU_FEATURES": "X86_V3 X86_V4 AVX512_ICL AVX512_SPR"}
    assert run(other).stdout == default


def _run_filter(ekf: ExtendedKalmanFilter, steps: int = 100) -> Belief:
    rng, seen = np.random.default_rng(1), np.array([True, False, True, False])
    belief = ekf.start(np.where(seen, rng.normal(size=4), np.nan), seen)
    for step in range(steps):
        read = seen if step % 5 else np.zeros(4, bool)  # a lost reading now and then
        belief = ekf.step(belief, rng.normal(size=1), np.where(read, 0.1 * rng.normal(size=4), np.nan), read)
    return belief


def test_the_filter_as_c_and_in_casadis_virtual_machine_gives_the_same_bits(monkeypatch):
    """The measured entries' correction and the prediction run as generated C; without a compiler they run in
    CasADi's virtual machine, with a warning, and every belief is the same to the last bit."""
    sensor = Sensor(noise_std=(0.01, 0.0, 0.02, 0.0), measured=(True, False, True, False))
    native = _run_filter(ExtendedKalmanFilter(_pendulum(), sensor))
    interpreted = _run_filter(ExtendedKalmanFilter(_pendulum(), sensor, compiled=False))
    monkeypatch.setenv("CC", "/nonexistent/cc")
    with pytest.warns(RuntimeWarning, match="virtual machine"):
        without_compiler = _run_filter(ExtendedKalmanFilter(_pendulum(), sensor))
    for belief in (interpreted, without_compiler):
        for name in ("mean", "covariance", "innovation", "reading", "nis"):
            np.testing.assert_array_equal(getattr(belief, name), getattr(native, name))


def test_a_filter_driven_far_from_its_model_stays_finite():
    """A filter whose covariance has lost its positivity (a quadrotor model near its Euler angles' singularity
    drives it to 1e22 and rounding does the rest) still corrects to finite numbers, as an LU solve does: the
    innovation's covariance is factored without a square root (a Cholesky factor would be NaN here)."""
    kf = _filter(noise_std=(0.05, 0.05), measured=(True, True))
    indefinite = np.array([[1.0, 2.0], [2.0, 1.0]])  # eigenvalues 3 and -1
    y, seen = np.array([0.3, -0.2]), np.array([True, True])
    belief = kf.correct(np.zeros(2), indefinite, y, seen)
    s = indefinite + NOISE_STD**2 * np.eye(2)
    gain = indefinite @ np.linalg.inv(s)
    np.testing.assert_allclose(belief.mean, gain @ y, rtol=1e-12)
    assert belief.nis == pytest.approx(y @ np.linalg.solve(s, y), rel=1e-12)
    assert np.isfinite(belief.covariance).all()
