"""Sums that decide: exactly rounded, independent of order, with a rule for overflow (etmpc.common.numerics),
and the learned policy's decision value built on them."""

import math
from pathlib import Path
from decimal import Decimal, localcontext
from fractions import Fraction

import numpy as np
import pytest

from etmpc.policies.learned import LogisticPolicy, Normalisation, PolicyFileError
from etmpc.common.numerics import cholesky, dot, fsum, matvec, norm
from etmpc.policies import AugmentedState

INF = math.inf


def _exact_sum_rounded(terms) -> float:
    """The independent truth: the terms as exact rationals, added, rounded once by Python's float()."""
    return float(sum(Fraction(t) for t in terms))


def test_a_dot_product_is_the_exact_sum_of_its_rounded_products_in_any_order():
    rng = np.random.default_rng(7)
    for _ in range(200):
        n = int(rng.integers(1, 20))
        # Wide dynamic range, and pairs of products that nearly cancel: where a BLAS kernel's order shows.
        u = rng.normal(size=n) * 10.0 ** rng.integers(-12, 12, size=n)
        v = rng.normal(size=n) * 10.0 ** rng.integers(-12, 12, size=n)
        a, b = np.concatenate([u, u]), np.concatenate([v, -v * (1 + 1e-12 * rng.normal(size=n))])
        n = 2 * n
        products = [float(x) * float(y) for x, y in zip(a, b)]  # Python's IEEE multiplication
        expected = _exact_sum_rounded(products)
        assert dot(a, b) == expected
        order = rng.permutation(n)
        assert dot(a[order], b[order]) == expected


def test_matvec_and_norm_are_rows_of_dots():
    rng = np.random.default_rng(3)
    m, x = rng.normal(size=(3, 5)), rng.normal(size=5)
    assert matvec(m, x).tolist() == [dot(row, x) for row in m]
    np.testing.assert_allclose(matvec(m, x), m @ x, rtol=1e-14)
    assert norm(x) == math.sqrt(_exact_sum_rounded([v * v for v in x.tolist()]))


@pytest.mark.parametrize(
    "terms, expected",
    [
        ([INF, 1.0, -3.0], INF),
        ([-INF, 1e308, 1e308], -INF),
        ([1.5e308, 1.5e308], INF),  # finite terms whose exact sum is beyond the double range
        ([-1.5e308, -1.5e308, 1.0], -INF),
        ([1e308, 1e308, -1e308], 1e308),  # a partial overflows, the exact sum does not
        ([1e308, -1e308, 5.0, 1e-300], 5.0),
    ],
)
def test_special_and_overflowing_sums_follow_one_rule(terms, expected):
    assert fsum(terms) == expected
    assert fsum(terms[::-1]) == expected


@pytest.mark.parametrize("terms", [[INF, -INF], [1.0, INF, 2.0, -INF], [math.nan, 1.0]])
def test_opposite_infinities_or_nan_have_no_value(terms):
    assert math.isnan(fsum(terms)) and math.isnan(fsum(terms[::-1]))


# -- the learned policy's decision value -----------------------------------------------------------
def _policy(theta, greedy=True) -> LogisticPolicy:
    """A battery policy on the paper's features: r = [x_i, x_k, i - k], so phi = [r (3), r^2 (3), 1]."""
    n = 3
    normalisation = Normalisation(np.zeros(n), np.ones(n), np.zeros(n), np.ones(n))
    return LogisticPolicy(np.asarray(theta, dtype=float), normalisation, "battery", features="paper", greedy=greedy)


STATE = AugmentedState(np.array([0.5]), np.array([0.25]), 2, np.array([0.45]))  # phi = [0.5, 0.25, 2, 0.25, 0.0625, 4, 1]


def test_the_decision_value_is_the_exactly_rounded_logit():
    theta = [0.1, -1 / 3, 1e-17, 7.0, -2.5, 0.125, -1.0]
    phi = [0.5, 0.25, 2.0, 0.25, 0.0625, 4.0, 1.0]
    policy = _policy(theta)
    assert policy.decision_value(policy.phi(STATE)) == _exact_sum_rounded([t * p for t, p in zip(theta, phi)])


def test_terms_of_one_infinity_are_a_sure_answer_on_every_machine():
    keep = _policy([1e308, 0, 0, 0, 0, 1e308, 0])  # terms 5e307 and 4e308 = +inf: no -inf among them
    rng = np.random.default_rng(0)
    assert keep.decision_value(keep.phi(STATE)) == INF and not keep.decide(STATE, rng)
    assert not _policy(keep.theta, greedy=False).decide(STATE, rng)  # pi(keep) = 1: no draw recomputes
    recompute = _policy([0, 0, -1e308, 0, 0, -1e308, 0])
    assert recompute.decision_value(recompute.phi(STATE)) == -INF and recompute.decide(STATE, rng)


def test_finite_terms_whose_sum_overflows_are_infinite_by_its_sign():
    policy = _policy([0, 0, 1e308 / 1.5, 0, 0, 1e308 / 4, 0])  # terms 1.33e308 and 1e308, both finite
    assert policy.decision_value(policy.phi(STATE)) == INF


def test_terms_of_both_infinities_are_an_error_whatever_their_order():
    # +inf (1e308 x 4) and -inf (-1e308 x 2): a BLAS dot gives nan or -inf depending on the CPU's kernel.
    for theta in ([0, 0, -1e308, 0, 0, 1e308, 0], [0, 0, 1e308, 0, 0, -1e308, 0]):
        policy = _policy(theta)
        with pytest.raises(PolicyFileError, match="not a number"):
            policy.decide(STATE, np.random.default_rng(0))


def test_greedy_keeps_at_a_logit_of_exactly_zero():
    policy = _policy([0, 0, 0, 0, 0, 0, 0])  # pi(keep) = 1/2: not below one half, so keep
    assert policy.decision_value(policy.phi(STATE)) == 0.0 and not policy.decide(STATE, None)
    tiny = _policy([0, 0, 0, 0, 0, 0, -1e-300])  # exp rounds this to pi(keep) = 1/2; the logit says recompute
    assert tiny.decide(STATE, None)


def _file(tmp_path, **changes) -> Path:
    """A battery policy file (paper features: 7 weights) with ``changes`` (``normalisation_std=...`` for a
    normalisation field), written as JSON text (``json.dumps`` writes an int of 400 digits as it is)."""
    import json

    data = _policy([0.1, -0.2, 0.3, 0.0, 0.5, -0.6, -1.0]).to_json()
    for name, value in changes.items():
        if name.startswith("normalisation_"):
            data["normalisation"][name.removeprefix("normalisation_")] = value
        else:
            data[name] = value
    path = tmp_path / "policy.json"
    path.write_text(json.dumps(data))
    return path


@pytest.mark.parametrize(
    "changes, says",
    [
        ({"theta": [1e308, -1e308] * 3 + [1e308]}, "theta[0] is 1e+308, beyond the +-1e+06 it may be"),
        ({"theta": [0.0] * 6 + [-(10**400)]}, "theta[6] is -1000000000000000000..., not a finite number"),
        # NaN is not JSON: the strict reader refuses it before any field is looked at
        ({"theta": [0.0, float("nan")] + [0.0] * 5}, "cannot be read (NaN is not a JSON number (strict JSON writes null))"),
        ({"theta": [0.0] * 6 + [True]}, "theta[6] is True, not a number"),
        ({"theta": "0.1"}, "theta is not a list of numbers (str)"),
        ({"normalisation_std": [1.0, 0.0, 1.0]}, "normalisation.std[1] is 0.0, below the 1e-12 it may be"),
        ({"normalisation_std_sq": [1e-300, 1.0, 1.0]}, "normalisation.std_sq[0] is 1e-300, below the 1e-12 it may be"),
        ({"normalisation_mean": [0.0, 0.0, -1e308]}, "normalisation.mean[2] is -1e+308, beyond the +-1e+100 it may be"),
        ({"normalisation": [1, 2]}, "normalisation is not an object of mean, std, mean_sq and std_sq"),
    ],
)
def test_a_policy_file_of_absurd_or_non_finite_numbers_is_refused_when_read_naming_the_file_and_the_field(
    tmp_path, capsys, changes, says
):
    """Weights of +-1e308 played until a state made their terms +inf and -inf, then stopped the run; an
    integer too large for a double was an OverflowError traceback. Both are refused when the file is read."""
    from etmpc.cli import main
    from etmpc.policies.learned import load_policy

    path = _file(tmp_path, **changes)
    with pytest.raises(PolicyFileError) as raised:
        load_policy(path, "battery", nx=1)
    assert str(raised.value).startswith(f"policy file {path}") and str(raised.value).endswith(says)
    assert main(["evaluate", "--task", "battery", "--policy", f"rl:{path}", "--episodes", "1", "--workers", "1"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and says in err and "Traceback" not in err


def test_a_policy_file_at_its_bounds_decides_at_every_state_within_1e100(tmp_path):
    """The bounds leave every term of the logit finite for raw features within +-1e100, so the decision is
    a probability in [0, 1] there, never an error; and a logit of +-inf is still one."""
    from etmpc.policies.learned import MAX_SCALE, MAX_WEIGHT, MIN_SCALE, load_policy, sigmoid

    path = _file(
        tmp_path,
        theta=[MAX_WEIGHT, -MAX_WEIGHT] * 3 + [MAX_WEIGHT],
        normalisation_mean=[-MAX_SCALE, MAX_SCALE, -MAX_SCALE],
        normalisation_std=[MIN_SCALE] * 3,
        normalisation_mean_sq=[-MAX_SCALE] * 3,
        normalisation_std_sq=[MIN_SCALE] * 3,
    )
    policy = load_policy(path, "battery", nx=1)
    for raw in ([1e100, -1e100, 1e100], [-1e100, 1e100, 0.0], [0.0, 0.0, 3.0]):
        logit = policy.decision_value(policy.normalisation.features(np.array(raw)))
        assert math.isfinite(logit) and 0.0 <= sigmoid(logit) <= 1.0
    assert [sigmoid(z) for z in (INF, 1e308, -1e308, -INF)] == [1.0, 1.0, 0.0, 0.0]


def test_the_battery_gain_is_the_closed_form_riccati_solution_correctly_rounded(battery_system):
    """The scalar discrete Riccati equation x+ = x + b u, Q, R has P = (Q b^2 + sqrt(Q^2 b^4 + 4 b^2 Q R)) / (2 b^2)
    and K = b P / (R + b^2 P): here in 50-digit decimal arithmetic, independent of the mpmath code."""
    from etmpc.systems.battery.parameters import Battery

    with localcontext() as ctx:
        ctx.prec = 50
        b, q, r = -Decimal(Battery().soc_per_kw), Decimal(1), Decimal(0.1)
        p = (q * b**2 + (q**2 * b**4 + 4 * b**2 * q * r).sqrt()) / (2 * b**2)
        k = b * p / (r + b**2 * p)
    assert battery_system.feedback.gain[0, 0] == float(k)


def test_an_unpenalised_unfed_mode_has_a_gain_of_exactly_zero(cart_system):
    """Q puts no weight on the cart position and nothing else depends on it: its gain is 0, not 1e-17."""
    assert cart_system.feedback.gain[0, 0] == 0.0


def test_the_cholesky_factor_is_lapacks_to_rounding_and_a_semidefinite_matrix_keeps_a_zero_column():
    rng = np.random.default_rng(11)
    for n in (1, 4, 12):
        m = rng.normal(size=(n, n))
        a = m @ m.T + n * np.eye(n)
        root = cholesky(a)
        assert np.array_equal(root, np.tril(root))
        np.testing.assert_allclose(root, np.linalg.cholesky(a), rtol=1e-13, atol=1e-13)
        np.testing.assert_allclose(root @ root.T, a, rtol=1e-13)
    np.testing.assert_array_equal(cholesky([[4.0, 2.0], [2.0, 1.0]]), [[2.0, 0.0], [1.0, 0.0]])  # rank 1
