"""Choosing a task's shield rule: the safest rule, then the best objective, from what each policy did on the
validation episodes (played here by a stand-in that returns made-up outcomes per spec)."""

import numpy as np
import pytest

from etmpc.learning import shields
from etmpc.systems.capabilities import ShieldRule

TASK = "cart_pendulum/kicks"  # a cost: lower objectives are better


def _choose(monkeypatch, outcomes: dict, grid):
    """``outcomes``: spec -> (objective, failures) on every episode."""
    asked = []

    def played(pool, domain, specs, entropy, episodes, tick):
        asked.append((domain, entropy, episodes))
        return [np.tile([*outcomes[spec], 10.0], (episodes, 1)) for spec in specs]

    monkeypatch.setattr(shields, "episode_outcomes", played)
    result = shields.choose(TASK, ["rl:a", "sb3:b"], "every:3", grid, 4, pool=None)
    assert asked == [(TASK, shields.VALIDATION_ENTROPY, 4)]  # the validation stream, never the test set
    return result


def test_the_safest_rule_within_the_budget_wins_then_the_best_objective(monkeypatch):
    grid = shields.rules((5, 10), (None, 0.5))
    assert [rule.text for rule in grid] == ["5", "5:0.5", "10", "10:0.5"]
    outcomes = {"every:3": (30.0, 0.1), "rl:a": (28.0, 0.3), "sb3:b": (27.0, 0.2)}  # unshielded: 27.5 on average
    outcomes |= {
        "shield:5:rl:a": (27.6, 0.1),
        "shield:5:sb3:b": (27.8, 0.05),  # 27.7, worst 0.1: within 1 % of 27.5
        "shield:5:0.5:rl:a": (27.6, 0.0),
        "shield:5:0.5:sb3:b": (27.9, 0.1),  # 27.75, worst 0.1: as safe, dearer
        "shield:10:rl:a": (28.0, 0.3),
        "shield:10:sb3:b": (27.0, 0.0),  # 27.5, worst 0.3: cheapest, least safe
        "shield:10:0.5:rl:a": (28.5, 0.0),
        "shield:10:0.5:sb3:b": (28.5, 0.0),  # 28.5, worst 0: safest, but costs 3.6 %
    }
    result = _choose(monkeypatch, outcomes, grid)
    assert result["chosen"] == "5" and result["budget"] == shields.BUDGET and result["safe"]  # 0.1 <= the schedule's 0.1
    assert result["unshielded"]["worst_failures"] == 0.3 and result["schedule"]["failures"] == 0.1
    rows = {row["rule"]: row for row in result["rules"]}
    assert rows["5"]["objective"] == pytest.approx(27.7) and rows["10"]["worst_failures"] == 0.3
    # the same table with a larger budget buys the safest rule
    assert shields.pick(result, budget=0.05)["chosen"] == "10:0.5"


def test_no_rule_within_the_budget_or_none_safer_than_no_shield_chooses_none(monkeypatch):
    outcomes = {"every:3": (30.0, 0.0), "rl:a": (28.0, 0.3), "sb3:b": (27.0, 0.2)}
    outcomes |= {"shield:5:rl:a": (29.0, 0.1), "shield:5:sb3:b": (29.5, 0.0)}  # 29.25: costs 6 %
    outcomes |= {"shield:9:rl:a": (27.6, 0.3), "shield:9:sb3:b": (27.5, 0.1)}  # within 1 %, but the worse still 0.3
    result = _choose(monkeypatch, outcomes, [ShieldRule(5), ShieldRule(9)])
    assert result["chosen"] is None and not result["safe"]  # unshielded, 0.3 > the schedule's 0


def test_an_outcome_is_the_episodes_objective_failures_and_recomputes():
    """Played for real: ``every:3`` recomputes 50 times in a 150-step kicks episode, and its objective is
    what training_return says of the same episode."""
    from etmpc.evaluation.backends import make_backend
    from etmpc.learning.jobs import episode_outcomes, training_return

    with make_backend("local", 1) as pool:
        (rows,) = episode_outcomes(pool, TASK, ["every:3"], shields.VALIDATION_ENTROPY, 2)
    assert rows.shape == (2, 3) and list(rows[:, 2]) == [50.0, 50.0]
    assert list(rows[:, 0]) == [training_return(TASK, "every:3", shields.VALIDATION_ENTROPY, i) for i in range(2)]
    assert all(f >= 0 and f == int(f) for f in rows[:, 1])  # falls: a count
