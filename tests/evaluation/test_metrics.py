"""etmpc.evaluation.metrics: the statistics as pure functions of score arrays, each checked against an
independent truth: a hand-sorted trimmed mean, a brute-force count over episodes, exact rational
arithmetic, a bootstrap interval's coverage on data whose mean is known."""

from __future__ import annotations

import math
import statistics
from fractions import Fraction

import numpy as np
import pytest

from etmpc.evaluation import metrics


# -- the sense --------------------------------------------------------------------------------------
def test_oriented_makes_higher_better_and_is_exact():
    costs = np.array([3.0, 1.0, 2.0])
    assert list(metrics.oriented(costs, "min")) == [-3.0, -1.0, -2.0]
    assert metrics.oriented(costs, "max") is costs
    assert metrics.oriented([1.0, 2.0], "min").tolist() == [-1.0, -2.0]  # a list becomes an array
    assert metrics.oriented(2.5, "min") == -2.5 and isinstance(metrics.oriented(2.5, "min"), float)
    rng = np.random.default_rng(1)
    a, b = rng.normal(size=200), rng.normal(size=200)
    b[:5] = a[:5]  # ties: the difference is +0.0, never -0.0
    for sense, expected in (("min", b - a), ("max", a - b)):
        got = metrics.oriented(a, sense) - metrics.oriented(b, sense)
        assert got.tobytes() == expected.tobytes()  # bit for bit, the sign of a zero included
    assert metrics.sign("max") == 1.0 and metrics.sign("min") == -1.0
    with pytest.raises(ValueError, match="'min' or 'max'"):
        metrics.oriented(1.0, "lower")


def test_best_is_the_largest_profit_or_the_smallest_cost_the_first_of_a_tie():
    means = {"a": 2.0, "b": 1.0, "c": 2.0, "d": 1.0}
    assert metrics.best(means, "max", key=means.get) == "a"
    assert metrics.best(means, "min", key=means.get) == "b"
    assert metrics.higher_or_lower("max") == "higher" and metrics.higher_or_lower("min") == "lower"
    with pytest.raises(ValueError):
        metrics.best(means, "MIN", key=means.get)


# -- per task ---------------------------------------------------------------------------------------
def test_the_exact_mean_is_the_correctly_rounded_rational_mean():
    rng = np.random.default_rng(2)
    for _ in range(50):
        values = rng.normal(0, 1e3, rng.integers(1, 40)) * 10.0 ** rng.integers(-8, 8)
        exact = sum(map(Fraction, values.tolist()), Fraction(0))
        assert metrics.exact_mean(values) == float(exact) / len(values)  # fsum is exact, one division rounds


def test_the_normalized_score_is_0_at_the_baseline_and_100_at_the_reference():
    rng = np.random.default_rng(3)
    baseline = rng.uniform(1.0, 2.0, 25)
    reference = baseline - rng.uniform(0.0, 0.3, 25)  # better on every episode
    gap = metrics.exact_mean(baseline - reference)
    assert metrics.normalized_score(baseline, baseline, gap) == 0.0
    assert metrics.normalized_score(reference, baseline, gap) == 100.0  # exactly: 100 m / m
    assert list(metrics.normalized_scores(baseline, baseline, gap)) == [0.0] * 25
    trigger = rng.uniform(1.0, 2.0, 25)
    by_hand = [100 * (b - c) / gap for b, c in zip(baseline, trigger)]
    np.testing.assert_allclose(metrics.normalized_scores(trigger, baseline, gap), by_hand, rtol=1e-14)
    assert metrics.normalized_score(trigger, baseline, gap) == pytest.approx(np.mean(by_hand), rel=1e-12)


def test_the_ci_is_1_96_standard_errors_and_needs_two_values():
    values = [1.0, 4.0, 2.5, 7.0]
    assert metrics.mean_ci95(values) == pytest.approx(1.96 * statistics.stdev(values) / 2.0, rel=1e-14)
    assert math.isnan(metrics.mean_ci95([3.0])) and math.isnan(metrics.mean_ci95([]))
    assert metrics.mean_ci95([2.0, 2.0, 2.0]) == 0.0


def test_the_improvement_share_counts_episodes_above_0_ties_half():
    scores = [5.0, -1.0, 0.0, 0.0, 2.0, -3.0, 1.0]
    by_count = (sum(s > 0 for s in scores) + 0.5 * sum(s == 0 for s in scores)) / len(scores)
    assert metrics.improvement_share(scores) == by_count
    assert metrics.episode_improvement(scores).tolist() == [1.0, 0.0, 0.5, 0.5, 1.0, 0.0, 1.0]


def test_paired_differences_by_hand_in_both_senses():
    mine, theirs = [1.0, 3.0, 2.0, 2.0], [2.0, 1.0, 2.0, 1.5]
    diff = [a - b for a, b in zip(mine, theirs)]
    for sense, better in (("max", sum(d > 0 for d in diff)), ("min", sum(d < 0 for d in diff))):
        row = metrics.paired_differences(mine, theirs, sense)
        assert row == {
            "episodes": 4,
            "mean_difference": pytest.approx(statistics.mean(diff)),
            "ci95": pytest.approx(1.96 * statistics.stdev(diff) / 2.0),
            "better_episodes": better,
        }
    empty = metrics.paired_differences([], [], "min")
    assert empty["episodes"] == 0 and math.isnan(empty["mean_difference"]) and empty["better_episodes"] == 0


# -- over tasks -------------------------------------------------------------------------------------
def test_the_iqm_is_the_mean_of_the_hand_sorted_middle_half():
    tasks = [[9.0, -4.0, 1.0, 100.0], [3.0, 2.0, -50.0, 5.0]]  # 8 scores: drop 2 at each end
    every = sorted(x for t in tasks for x in t)  # -50 -4 | 1 2 3 5 | 9 100
    assert every[2:6] == [1.0, 2.0, 3.0, 5.0]
    assert metrics.iqm(tasks) == pytest.approx(11.0 / 4, rel=1e-15)


def test_the_probability_of_improvement_is_a_brute_force_count_over_episode_pairs():
    """Per task, each episode's trigger against the baseline on that episode (ties half), then the tasks' mean."""
    rng = np.random.default_rng(4)
    tasks = []
    for n in (5, 8, 3):
        baseline = rng.integers(0, 4, n).astype(float)  # integers: ties happen
        trigger = rng.integers(0, 4, n).astype(float)
        tasks.append((baseline, trigger))
    shares = []
    for baseline, trigger in tasks:
        wins = 0.0
        for b, c in zip(baseline, trigger):
            wins += 1.0 if c < b else 0.5 if c == b else 0.0
        shares.append(wins / len(baseline))
    scores = [metrics.normalized_scores(c, b, 1.7) for b, c in tasks]
    assert metrics.probability_of_improvement(scores) == pytest.approx(sum(shares) / len(shares), rel=1e-15)


def test_the_performance_profile_is_a_brute_force_share_above_each_threshold():
    tasks = [[0.0, 50.0, 100.0], [-10.0, 200.0]]
    thresholds = [-20.0, -10.0, 0.0, 60.0, 100.0, 200.0]
    brute = [sum(sum(s > t for s in task) / len(task) for task in tasks) / len(tasks) for t in thresholds]
    np.testing.assert_allclose(metrics.performance_profile(tasks, np.array(thresholds)), brute, rtol=0, atol=1e-15)
    assert np.isnan(metrics.performance_profile([], [0.0, 1.0])).all()


def test_the_stratified_interval_is_seeded_degenerate_where_it_must_be_and_resamples_within_tasks():
    rng = np.random.default_rng(5)
    tasks = [rng.normal(0, 1, 30), rng.normal(5, 2, 12)]
    low, high = metrics.iqm_ci95(tasks)
    assert low < metrics.iqm(tasks) < high and metrics.iqm_ci95(tasks) == (low, high)  # the same bits again
    assert all(map(math.isnan, metrics.iqm_ci95([np.ones(5), np.ones(1)])))  # one episode: no interval
    # Each task constant: any resample within a task gives the same means, so the interval is a point.
    constant = [np.full(6, 1.0), np.full(9, 4.0)]
    assert metrics.stratified_interval(constant, metrics._mean_of_means) == (2.5, 2.5)
    # Pooled, the resamples would mix the two tasks: stratified, P(improve) of all-better and all-worse is exactly 1/2.
    assert metrics.probability_of_improvement_ci95([np.full(4, 3.0), np.full(7, -2.0)]) == (0.5, 0.5)


def test_the_bootstrap_interval_covers_a_known_mean_about_95_times_in_100():
    rng = np.random.default_rng(6)
    covered = 0
    trials = 150
    for _ in range(trials):
        tasks = [rng.normal(0.0, 1.0, 40), rng.normal(0.0, 3.0, 40)]  # the mean of the tasks' means is 0
        low, high = metrics.stratified_interval(tasks, metrics._mean_of_means, resamples=1000)
        covered += low <= 0.0 <= high
    assert 0.88 <= covered / trials <= 0.99
