"""etmpc.evaluation.compare: paired gains over a reference, whatever the objective's sense."""

import numpy as np

from etmpc.evaluation.compare import paired


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
