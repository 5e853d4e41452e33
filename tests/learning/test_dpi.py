"""DPI's classifier and the learned policy's feature sets, against independent truth."""

import json

import numpy as np
import pytest

from etmpc.learning import dpi
from etmpc.cli import main
from etmpc.policies.features import feature_size, raw_features
from etmpc.policies.learned import LogisticPolicy, Normalisation, load_policy
from etmpc.control.plan import Plan
from etmpc.policies import AugmentedState


def test_fit_recovers_the_parameters_of_a_logistic_model():
    """Labels drawn from sigma(theta . phi) with unit weights: the maximum-likelihood fit is consistent."""
    rng = np.random.default_rng(0)
    n, theta = 20000, np.array([1.5, -2.0, 0.5])
    phi = np.column_stack([rng.normal(size=(n, 2)), np.ones(n)])
    keep = rng.random(n) < 1 / (1 + np.exp(-phi @ theta))
    advantage = np.where(keep, 1.0, -1.0)  # |advantage| = 1: plain logistic regression
    fitted = dpi.fit(phi, advantage, ridge=0.0)
    np.testing.assert_allclose(fitted, theta, atol=0.08)


def test_a_weight_counts_as_that_many_copies_of_a_decision():
    rng = np.random.default_rng(1)
    phi = np.column_stack([rng.normal(size=(40, 3)), np.ones(40)])
    counts = rng.integers(1, 4, size=40)
    signs = np.where(rng.random(40) < 0.5, 1.0, -1.0)
    weighted = dpi.fit(phi, signs * counts, ridge=1e-3)
    copies = dpi.fit(np.repeat(phi, counts, axis=0), np.repeat(signs, counts), ridge=1e-3)
    # Weights are normalised to mean 1 and the loss is a mean, (1/n) sum (c_i / mean c) l_i =
    # (1/N) sum c_i l_i: the loss of the N = sum c rows with each row repeated c_i times.
    np.testing.assert_allclose(weighted, copies, atol=1e-5)


def test_the_fit_follows_the_costly_mistakes():
    """Two decisions in the same state with opposite labels: the one that costs more wins."""
    phi = np.array([[1.0, 1.0], [1.0, 1.0]])
    theta = dpi.fit(phi, np.array([+3.0, -1.0]), ridge=0.0)
    assert 1 / (1 + np.exp(-phi[0] @ theta)) == pytest.approx(0.75, abs=1e-4)  # weighted MLE: 3 / (3 + 1)


def _plan(inputs, states, price, production):
    return Plan(
        np.array(inputs, float)[:, None],
        np.array(states, float)[:, None],
        0.0,
        0.0,
        True,
        forecasts={"price_eur_kwh": np.array(price, float), "production_kw": np.array(production, float)},
    )


def test_error_features_of_the_battery_are_worked_by_hand():
    plan = _plan([100.0, -50.0, 0.0], [0.5, 0.49, 0.5, 0.5], [0.06, 0.04, 0.05], [10.0, 20.0, 30.0])
    # Today's forecasts (index 0: now) against the plan's over the two steps it has left: [0.04, 0.05], [20, 30].
    observation = {
        "price_eur_kwh": 0.08,
        "net_production_kw": 5.0,
        "price_forecast_eur_kwh": [0.08, 0.02, 0.07],
        "production_forecast_kw": [5.0, 26.0, 40.0],
    }
    s = AugmentedState(np.array([0.47]), np.array([0.5]), 1, plan.state_at(1), plan, observation)
    r = raw_features("error", "battery", s)
    # error, age, price, production, planned price, planned production, their differences, trade value,
    # RMS revision of the price forecast ([+0.04, -0.03]) and of the production's ([-15, -4]), and the
    # price revisions times the plan's remaining trades [-50, 0]
    expected = [
        0.47 - 0.49,
        1,
        0.08,
        5.0,
        0.04,
        20.0,
        0.08 - 0.04,
        5.0 - 20.0,
        (0.08 - 0.05) * -50.0 * 10 / 3600,
        np.sqrt((0.04**2 + 0.03**2) / 2),
        np.sqrt((15.0**2 + 4.0**2) / 2),
        0.04 * -50.0 * 10 / 3600,
    ]
    np.testing.assert_allclose(r, expected, rtol=1e-12)
    assert feature_size(1, "error", "battery") == 2 * len(expected) + 1
    np.testing.assert_array_equal(raw_features("paper", "battery", s), [0.47, 0.5, 1])


def test_error_features_of_the_cart_are_the_prediction_error_and_age():
    s = AugmentedState(np.array([1.0, 2.0, 3.0, 4.0]), np.zeros(4), 7, np.array([0.5, 2.5, 3.0, 3.0]))
    np.testing.assert_array_equal(raw_features("error", "cart_pendulum", s), [0.5, -0.5, 0.0, 1.0, 7.0])
    assert feature_size(4, "error", "cart_pendulum") == 11 and feature_size(4, "paper", "cart_pendulum") == 19


def test_policy_files_keep_their_feature_set_and_old_files_read_as_paper(tmp_path):
    rng = np.random.default_rng(0)
    policy = LogisticPolicy.initial(Normalisation.fit(rng.normal(size=(30, 5))), "cart_pendulum", {}, features="error")
    policy.save(tmp_path / "p.json")
    assert load_policy(tmp_path / "p.json", "cart_pendulum", nx=4).features == "error"
    old = LogisticPolicy.initial(Normalisation.fit(rng.normal(size=(30, 9))), "cart_pendulum", {}).to_json()
    old["version"] = 1
    del old["features"]
    (tmp_path / "old.json").write_text(json.dumps(old))
    assert load_policy(tmp_path / "old.json", "cart_pendulum", nx=4).features == "paper"
    bad = dict(policy.to_json(), features="telepathy")
    (tmp_path / "bad.json").write_text(json.dumps(bad))
    assert (
        main(
            [
                "evaluate",
                "--task",
                "cart_pendulum",
                "--policy",
                f"rl:{tmp_path / 'bad.json'}",
                "--episodes",
                "1",
                "--workers",
                "1",
            ]
        )
        == 2
    )


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--algorithm", "gpomdp", "--futures", "4"], "--algorithm dpi"),
        (["--algorithm", "dpi", "--horizon", "0"], "must be >= 1"),
        (["--algorithm", "reinforce"], "invalid choice"),
        (["--features", "telepathy"], "invalid choice"),
        (["--validation-episodes", "0"], "must be >= 1"),
    ],
)
def test_bad_learner_options_are_one_line_errors(capsys, tmp_path, argv, message):
    assert main(["train", "--task", "cart_pendulum", "--out", str(tmp_path / "run"), *argv]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err
    assert not (tmp_path / "run").exists()


@pytest.mark.slow
def test_a_dpi_run_does_not_depend_on_the_number_of_workers_and_chooses_on_validation(tmp_path):
    from etmpc.learning.train import TrainConfig, train

    config = TrainConfig(
        "battery",
        seeds=(0, 1),
        episodes=2,
        eval_every=1,
        eval_episodes=2,
        normalisation_episodes=2,
        algorithm="dpi",
        validation_episodes=3,
        dpi=dpi.Settings(futures=2, horizon=4, states_per_episode=3, bases=("always", "every:3"), selection_episodes=2),
    )
    one = train(config, tmp_path / "one", workers=1, progress=False)
    train(config, tmp_path / "two", workers=2, progress=False)
    read = lambda out: {p.relative_to(out).as_posix(): p.read_bytes() for p in sorted(out.rglob("*.json"))}  # noqa: E731
    assert read(tmp_path / "one") == read(tmp_path / "two")
    assert one.base in ("always", "every:3") and all(learner["iterations"] == 2 for learner in one.learners.values())
    assert all(len(learner["data"]) > 0 for learner in one.learners.values())
    selected = json.loads((tmp_path / "one" / "selected.json").read_text())
    # every iteration of every seed was a candidate, named SEED@EPISODES; the best on validation is shipped
    assert sorted(one.validation) == ["0@1", "0@2", "1@1", "1@2"]
    best = max(one.validation, key=one.validation.get)  # profit: higher is better
    seed, episodes = map(int, best.split("@"))
    assert selected["hyperparameters"]["seed"] == seed and selected["hyperparameters"]["episodes"] == episodes
    assert selected["decision"] == "greedy" and selected["hyperparameters"]["validation_objective"] == one.validation[best]
    assert (selected["hyperparameters"]["episodes_per_seed"], selected["hyperparameters"]["eval_every"]) == (2, 1)  # the recipe
    (entry,) = [e for e in one.learners[str(seed)]["history"] if e["episodes"] == episodes]
    assert selected["theta"] == entry["theta"]
    assert one.learners[str(seed)]["history"][-1]["theta"] == one.learners[str(seed)]["theta"]  # the last is the final one
    for s in (0, 1):  # each seed's own choice: the best of its iterations
        own = json.loads((tmp_path / "one" / f"seed{s}" / "selected.json").read_text())
        pick = max((name for name in one.validation if name.startswith(f"{s}@")), key=one.validation.get)
        assert own["hyperparameters"]["seed"] == s and own["hyperparameters"]["validation_objective"] == one.validation[pick]
        assert own["hyperparameters"]["episodes"] == int(pick.split("@")[1])
