"""The learned logistic policy with compute levels (keep, one SQP iteration, a full solve): its two-stage
decision against the formula written out here, its file, and the refusals; the keep-or-solve policies
(the shipped files) as they were."""

import json

import numpy as np
import pytest

from etmpc.cli import main
from etmpc.control.timing import ITERATE, KEEP, SOLVE
from etmpc.policies import AugmentedState, parse_policy
from etmpc.policies.learned import LogisticPolicy, Normalisation, PolicyFileError, load_policy
from etmpc.systems import has_levels
from tests.conftest import REPO

LEVELS, KICKS, LATE = "cart_pendulum/kicks_levels", "cart_pendulum/kicks", "cart_pendulum/kicks_late"


def _policy(seed: int, greedy: bool, domain: str = LEVELS) -> LogisticPolicy:
    """A two-stage policy on the paper's features (r = [x, x_plan, age], 9 components: 19 parameters)."""
    rng = np.random.default_rng(seed)
    normalisation = Normalisation(rng.normal(size=9), rng.uniform(0.5, 2, 9), rng.uniform(0, 1, 9), rng.uniform(0.5, 2, 9))
    return LogisticPolicy(
        rng.normal(size=19), normalisation, domain, {}, features="paper", greedy=greedy, theta_level=rng.normal(size=19)
    )


def _state(rng) -> tuple[AugmentedState, np.ndarray]:
    """A random augmented state and its raw features, written out: [x_i, x_k, i - k]."""
    x, planned, age = rng.normal(size=4), rng.normal(size=4), int(rng.integers(1, 20))
    return AugmentedState(x, planned, age, rng.normal(size=4)), np.concatenate([x, planned, [age]])


def _phi(policy: LogisticPolicy, r: np.ndarray) -> np.ndarray:
    n = policy.normalisation
    return np.concatenate([(r - n.mean) / n.std, (r * r - n.mean_sq) / n.std_sq, [1.0]])


def _sigma(z: float) -> float:
    return 1.0 / (1.0 + np.exp(-z))


def test_the_greedy_two_stage_policy_decides_as_its_formula():
    """Keep when theta . phi >= 0; else a full solve when theta_level . phi > 0, else one SQP iteration."""
    policy, rng = _policy(0, greedy=True), np.random.default_rng(1)
    seen = []
    for _ in range(400):
        s, r = _state(rng)
        phi = _phi(policy, r)
        expected = KEEP if phi @ policy.theta >= 0 else SOLVE if phi @ policy.theta_level > 0 else ITERATE
        answer = policy.decide(s, None)  # greedy: draws nothing
        assert type(answer) is int and answer == expected
        seen.append(answer)
    assert set(seen) == {KEEP, ITERATE, SOLVE}


def test_the_sampled_two_stage_policy_draws_keep_then_the_level():
    """pi(keep) = sigma(theta . phi), pi(iterate) = (1 - pi(keep)) (1 - p_solve), pi(solve) = (1 - pi(keep)) p_solve
    with p_solve = sigma(theta_level . phi): the frequencies over many draws at one state."""
    policy, rng = _policy(2, greedy=False), np.random.default_rng(3)
    s, r = _state(rng)
    phi = _phi(policy, r)
    policy = policy.with_theta(policy.theta - phi * (phi @ policy.theta) / (phi @ phi))  # pi(keep | s) = 1/2 here
    p_keep, p_solve = _sigma(phi @ policy.theta), _sigma(phi @ policy.theta_level)
    draws = np.random.default_rng(4)
    n = 20000
    counts = np.bincount([policy.decide(s, draws) for _ in range(n)], minlength=3) / n
    expected = [p_keep, (1 - p_keep) * (1 - p_solve), (1 - p_keep) * p_solve]
    np.testing.assert_allclose(counts, expected, atol=4 * np.sqrt(0.25 / n))
    assert policy.keep_probability(s) == pytest.approx(p_keep) and policy.solve_probability(s) == pytest.approx(p_solve)


def test_a_levels_policy_file_round_trips(tmp_path):
    policy = _policy(5, greedy=True)
    policy.save(tmp_path / "p.json")
    data = json.loads((tmp_path / "p.json").read_text())
    assert data["version"] == 3 and data["theta_level"] == policy.theta_level.tolist()
    loaded = load_policy(tmp_path / "p.json", LEVELS, nx=4)
    assert loaded.levels and loaded.greedy and loaded.to_json() == policy.to_json()
    np.testing.assert_array_equal(loaded.theta_level, policy.theta_level)
    rng = np.random.default_rng(6)
    for _ in range(50):
        s, _ = _state(rng)
        assert loaded.decide(s, None) == policy.decide(s, None)
    # Through the spec, on its own task only.
    assert parse_policy(f"rl:{tmp_path / 'p.json'}", LEVELS).levels
    initial = LogisticPolicy.initial(policy.normalisation, LEVELS, {}, "paper", greedy=False, levels=True)
    assert initial.levels and initial.theta_level[-1] > 0  # at first a computation is mostly a full solve


@pytest.mark.parametrize(
    "change, says",
    [
        (dict(domain=KICKS), "decides keep, one SQP iteration or a full solve (compute levels), but task cart_pendulum/kicks's"),
        (dict(version=2), "theta_level (compute levels) comes with format version 3"),
        (dict(theta_level=[0.0] * 18), "theta_level is not 19 finite numbers"),
        (dict(theta_level=[0.0] * 18 + [float("nan")]), "NaN is not a JSON number (strict JSON writes null)"),
    ],
)
def test_a_bad_or_misplaced_levels_file_is_one_line(tmp_path, change, says):
    data = dict(_policy(7, greedy=True).to_json(), **change)
    (tmp_path / "p.json").write_text(json.dumps(data))
    with pytest.raises(PolicyFileError, match=r"^policy file .*") as raised:
        load_policy(tmp_path / "p.json", data["domain"], nx=4)
    assert says in str(raised.value) and "\n" not in str(raised.value)


def test_a_keep_or_solve_file_for_a_task_with_levels_is_refused_and_version_3_needs_theta_level(tmp_path, capsys):
    binary = _policy(8, greedy=True).to_json()
    del binary["theta_level"]
    binary["version"] = 2
    (tmp_path / "binary.json").write_text(json.dumps(binary))
    with pytest.raises(
        PolicyFileError, match="decides keep or solve, but task cart_pendulum/kicks_levels's decisions are keep, one"
    ):
        load_policy(tmp_path / "binary.json", LEVELS, nx=4)
    assert (
        main(["evaluate", "--task", LEVELS, "--policy", f"rl:{tmp_path / 'binary.json'}", "--episodes", "1", "--workers", "1"])
        == 2
    )
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "decides keep or solve" in err
    (tmp_path / "v3.json").write_text(json.dumps(dict(binary, version=3)))
    with pytest.raises(PolicyFileError, match="comes with format version 3, and only with it"):
        load_policy(tmp_path / "v3.json")


def test_shipped_keep_or_solve_policies_read_and_decide_as_before():
    """Format version 2, no theta_level, written back as they are read; bool decisions; the kicks policy
    passes the levels check on kicks_late (keep or solve, as kicks)."""
    assert not has_levels(KICKS) and not has_levels(LATE) and has_levels(LEVELS)
    rng = np.random.default_rng(9)
    for path in sorted((REPO / "policies").glob("*/*/learned.json")):
        data = json.loads(path.read_text())
        if has_levels(data["domain"]):  # a levels task's own policy: format 3 (the other tests)
            assert data["version"] == 3 and "theta_level" in data
            continue
        policy = load_policy(path, data["domain"])
        assert data["version"] == 2 and "theta_level" not in data and not policy.levels
        assert policy.to_json() == data
        phi = np.concatenate([rng.normal(size=policy.theta.size - 1), [1.0]])
        policy.phi = lambda s, phi=phi: phi
        assert policy.decide(None, None) is (policy.decision_value(phi) < 0.0)
    kicks = load_policy(REPO / "policies" / "cart_pendulum" / "kicks" / "learned.json", KICKS, nx=4)
    assert (
        not kicks.levels
        and parse_policy(f"rl:{REPO / 'policies' / 'cart_pendulum' / 'kicks' / 'learned.json'}", LATE).domain == KICKS
    )
