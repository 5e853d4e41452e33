"""etmpc.evaluation.compare: paired gains over a reference, whatever the objective's sense."""

import numpy as np

from etmpc.evaluation.compare import against, format_against, paired


def _episodes(values) -> dict[int, float]:
    return dict(enumerate(values))


def test_paired_gains_follow_the_objectives_sense():
    reference = _episodes([1.0, 2.0, 3.0])
    assert paired(reference, reference, "max")["gain_percent"] == 0.0
    higher = paired(_episodes([1.2, 2.2, 3.2]), reference, "max")  # 0.2 over a mean of 2: +10 %, the same on every episode
    assert np.isclose(higher["gain_percent"], 10.0) and np.isclose(higher["gain_percent_ci95"], 0.0)
    assert higher["better_episodes"] == 3
    cheaper = paired(_episodes([0.8, 1.8, 2.8]), reference, "min")  # a cost 0.2 lower is a gain
    assert np.isclose(cheaper["gain_percent"], 10.0) and cheaper["better_episodes"] == 3


def test_only_the_common_episodes_are_paired():
    a, b = {0: 2.0, 1: 4.0, 5: 100.0}, {0: 1.0, 1: 2.0, 2: 50.0}
    row = paired(a, b, "max")  # episodes 0 and 1: differences 1 and 2 over a mean of 1.5
    assert row["episodes"] == 2 and np.isclose(row["mean_difference"], 1.5) and np.isclose(row["gain_percent"], 100.0)
    assert np.isclose(row["ci95"], 1.96 * np.std([1.0, 2.0], ddof=1) / np.sqrt(2))


def _evaluation(failures: dict[str, list[int] | None]) -> dict:
    """Two policies on four episodes, with their failures per episode (None: a task that counts none)."""
    runs, policies = [], {}
    for spec, counts in failures.items():
        for episode in range(4):
            run = {"policy": spec, "episode": episode, "finite": True, "objective": 1.0 + episode + (spec == "b")}
            run["failures"] = None if counts is None else counts[episode]
            runs.append(run)
        policies[spec] = {"objective_sense": "min", "objective_mean": 2.5, "recomputes_mean": 10.0}
        if counts is not None:
            policies[spec]["failure_name"] = "falls"
    return {"policies": policies, "runs": runs}


def test_failures_are_paired_against_the_reference_where_the_task_counts_them():
    evaluation = _evaluation({"a": [0, 0, 1, 0], "b": [2, 0, 4, 1]})
    row = against(evaluation, "a")["b"]
    differences = np.array([2, 0, 3, 1])  # b - a, episode by episode
    assert row["failures"]["failures_mean"] == 7 / 4
    assert np.isclose(row["failures"]["difference"], differences.mean())
    assert np.isclose(row["failures"]["ci95"], 1.96 * differences.std(ddof=1) / 2)
    table = format_against(evaluation, "a")
    assert "Δ failures ± CI" in table and f"{differences.mean():+.2f} ± {1.96 * differences.std(ddof=1) / 2:.2f}" in table
    assert "falls per episode against a's" in table
    plain = _evaluation({"a": None, "b": None})
    assert against(plain, "a")["b"]["failures"] is None and "failures" not in format_against(plain, "a")
