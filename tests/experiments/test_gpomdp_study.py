"""The ``gpomdp`` study's own logic against independent truth: its logged training is ``etmpc train``'s (the same
parameters as :func:`etmpc.learning.jobs.train_block`), its cross-fitted baselines are the leave-one-out ones computed
by brute force, its paired gains are computed by hand, and ``fix + best`` takes each factor from the row that scored
best."""

from __future__ import annotations

import numpy as np
import pytest

from etmpc.experiments.studies import gpomdp as study
from etmpc.experiments.studies.gpomdp_probe import estimates, spread, train_logged
from etmpc.learning import gpomdp
from etmpc.learning.jobs import _learner_to_json, normalisation_states, train_block
from etmpc.policies.learned import LogisticPolicy, Normalisation


@pytest.mark.parametrize("scale", ["none", "advantage"])
def test_logged_training_trains_what_etmpc_train_trains(scale):
    task = "battery/trading"
    normalisation = Normalisation.fit(np.concatenate([normalisation_states(task, i, "paper") for i in range(2)]))
    policy = LogisticPolicy.initial(normalisation, task, {}, "paper").to_json()
    learner = _learner_to_json(gpomdp.Learner.start(np.array(policy["theta"]), gpomdp.Settings(scale=scale), 100))
    ours, log = train_logged(task, policy, learner, 3, 0, 3)
    theirs, stats = train_block(task, policy, learner, 3, 0, 3)
    assert ours == theirs
    assert log["episodes"] == 3 and log["return"] == pytest.approx(np.mean([s["return"] for s in stats]), rel=1e-12)
    assert log["drift"] == pytest.approx(np.linalg.norm(np.subtract(ours["theta"], policy["theta"])), rel=1e-12)
    assert log["drift"] <= log["path"] * (1 + 1e-12)


def _episodes(rng, count=6, p=3, length=8):
    episodes = []
    for _ in range(count):
        steps = np.sort(rng.choice(length, 5, replace=False))
        episodes.append(
            {
                "features": rng.normal(size=(5, p)).tolist(),
                "recompute": rng.integers(0, 2, 5).astype(bool).tolist(),
                "keep_probability": rng.uniform(0.1, 0.9, 5).tolist(),
                "steps": steps.tolist(),
                "rewards": rng.normal(size=length).tolist(),
            }
        )
    return episodes


def test_cross_fitted_baselines_are_each_episodes_leave_one_out_fit():
    rng = np.random.default_rng(11)
    episodes, gamma = _episodes(rng), 0.9
    returns = [gpomdp.rewards_to_go(np.array(e["rewards"]), gamma) for e in episodes]
    for baseline in ("none", "mean", "state"):
        found = estimates(episodes, gamma, baseline)
        for k, e in enumerate(episodes):
            phi, steps = np.array(e["features"]), np.array(e["steps"])
            others = [j for j in range(len(episodes)) if j != k]
            if baseline == "mean":
                b = np.mean([returns[j] for j in others], axis=0)[steps]
            elif baseline == "state":  # the learner's own fit, over the other episodes only
                learner = gpomdp.Learner.start(np.zeros(3), gpomdp.Settings(discount=gamma), 8)
                for j in others:
                    learner.value_gram += np.array(episodes[j]["features"]).T @ np.array(episodes[j]["features"])
                    learner.value_target += np.array(episodes[j]["features"]).T @ returns[j][episodes[j]["steps"]]
                b = phi @ learner.value_weights()
            else:
                b = None
            reference = gpomdp.gradient(phi, np.array(e["recompute"]), np.array(e["keep_probability"]), steps, returns[k], b)
            np.testing.assert_allclose(found[k], reference, rtol=1e-10, atol=1e-12)


def test_the_scaled_estimates_are_over_the_advantages_rms():
    episodes = _episodes(np.random.default_rng(2))
    gamma = 0.975
    plain = estimates(episodes, gamma, "none")
    advantages = np.concatenate([gpomdp.rewards_to_go(np.array(e["rewards"]), gamma)[e["steps"]] for e in episodes])
    np.testing.assert_allclose(estimates(episodes, gamma, "none", scale=True), plain / np.sqrt(np.mean(advantages**2)))


def test_the_spread_of_a_known_sample():
    g = np.array([[1.0, 0.0], [3.0, 0.0], [2.0, 0.0]])  # the bias: mean 2, sd 1
    s = spread(g, ("x", "bias"), 0.5, 100)
    assert s["step"] == pytest.approx(0.5 * np.sqrt((1 + 9 + 4) / 3))
    assert s["bias_drift"] == 0.0 and s["bias_noise"] == 0.0
    s = spread(g[:, ::-1], ("x", "bias"), 0.5, 100)
    assert s["bias_drift"] == pytest.approx(0.5 * 2 * 100) and s["bias_noise"] == pytest.approx(0.5 * 1 * 10)
    assert s["walk"] == pytest.approx(0.5 * 1 * 10)
    assert [z["name"] for z in s["significant"]] == ["bias"]  # z = 2 / (1 / sqrt 3) = 3.46


def test_paired_gain_by_hand():
    fixed = np.array([[1.0, 0, 30], [2.0, 0, 30]])
    policy = np.array([[0.9, 0, 40], [2.1, 0, 50]])
    cost = study.paired(policy, fixed, "min")  # gains 0.1, -0.1 over a mean of 1.5
    assert cost["gain"] == pytest.approx(0.0, abs=1e-12) and cost["recomputes"] == 45.0
    assert cost["ci95"] == pytest.approx(1.96 * np.std([0.1, -0.1], ddof=1) / np.sqrt(2) * 100 / 1.5)
    profit = study.paired(policy, fixed, "max")
    assert profit["gain"] == pytest.approx(0.0, abs=1e-12)
    assert study.paired(fixed * 1.1, fixed, "max")["gain"] == pytest.approx(10.0)


def test_fix_plus_best_takes_each_factor_from_the_best_row():
    def row(mean, **changes):
        return {"mean": mean, "settings": dict(study.PAPER, **changes)}

    rows = {
        "paper": row(-1.0),
        "features error": row(0.5, features="error"),
        "baseline state": row(-2.0, baseline="state"),
        "baseline mean": row(-0.5, baseline="mean"),
        "short discount": row(-3.0, discount=0.7),
    }
    settings = study.settings_of("fix + best", rows)
    assert settings == dict(study.PAPER, features="error", baseline="mean", scale="advantage", learning_rate=0.005)
    assert study.settings_of("alpha x10", rows) == dict(study.PAPER, learning_rate=0.5)


def test_a_longer_row_continues_the_run_and_the_shorter_row_keeps_its_parameters(tmp_path, monkeypatch):
    """Trained to 2 episodes, then continued to 4: the parameters at 2 are kept as they were, and the run at 4 is the
    one trained straight to 4 (every draw keyed by seed and episode)."""
    from etmpc.evaluation.backends import make_backend

    monkeypatch.setattr(study, "SEEDS", (0,))
    monkeypatch.setattr(study, "BLOCK", 1)
    monkeypatch.setattr(study, "EPISODES", 2)
    settings = dict(study.PAPER, learning_rate=0.5)
    with make_backend("local", 1) as pool:
        short = study.train("battery/trading", settings, tmp_path / "a", pool)
        at_two = study.at(short, 2)
        longer = study.train("battery/trading", dict(settings, episodes=4), tmp_path / "a", pool)
        straight = study.train("battery/trading", dict(settings, episodes=4), tmp_path / "b", pool)
    assert study.at(longer, 2) == at_two and study.at(longer, 4) == study.at(straight, 4) != at_two
    assert len(study.summary_log(longer, 2)) == 2 and len(study.summary_log(longer, 4)) == 4
