"""Choosing a task's shield rule: the safest rule, then the best objective, from what each policy did on the
validation episodes (played here by a stand-in that returns made-up outcomes per spec)."""

import numpy as np
import pytest

from etmpc.common.errors import EtmpcError
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


def test_a_grid_reads_a_deviation_only_beside_a_margin_and_each_rule_is_written_as_a_spec_reads_it():
    grid = shields.rules((10,), (None, 0.25), (None, 1.0, 2))
    assert [rule.text for rule in grid] == ["10", "10:0.25", "10:0.25:1", "10:0.25:2"]
    assert grid[2] == ShieldRule(10, 0.25, 1.0)
    with pytest.raises(EtmpcError, match="comes after its margin"):
        ShieldRule(10, None, 1.0)


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


def _certify_table(monkeypatch, failures: dict, objectives: dict, grid, bound: float):
    """Play made-up episodes: ``failures[spec]`` per episode, ``objectives[spec]`` on every episode."""

    def played(pool, domain, specs, entropy, episodes, tick):
        return [np.column_stack([np.full(episodes, objectives[s]), failures[s], np.full(episodes, 10.0)]) for s in specs]

    monkeypatch.setattr(shields, "episode_outcomes", played)
    episodes = len(failures["every:3"])
    return shields.certify(shields.choose(TASK, ["rl:a"], "every:3", grid, episodes, pool=None), bound=bound)


def _upper(extra, z: float, bound: float) -> float:
    """The upper bound certify should give, computed here: the spread at least a Bernoulli's at the bound."""
    extra = np.asarray(extra, float)
    p = min(bound, 0.5)
    return extra.mean() + z * max(extra.std(ddof=1), np.sqrt(p * (1 - p))) / np.sqrt(len(extra))


def test_certify_keeps_the_rules_whose_paired_upper_bound_is_within_the_bound_then_the_best_objective(monkeypatch):
    from scipy.stats import norm

    schedule = np.tile([0, 1, 0, 0, 0, 0, 1, 0], 4).astype(float)  # 32 episodes
    extra = {
        "none": np.tile([1, 0, 1, 0, 2, 0, 0, 1], 4),  # unshielded: the cheapest, 5 more falls in 8 episodes
        "5": np.tile([0, 0, 1, 0, 0, 0, 0, 0], 4),  # 1 more fall in 8
        "5:0.5": np.zeros(32),  # as safe as the schedule, episode by episode
    }
    failures = {"every:3": schedule, "rl:a": schedule + extra["none"]}
    failures |= {"shield:5:rl:a": schedule + extra["5"], "shield:5:0.5:rl:a": schedule + extra["5:0.5"]}
    objectives = {"every:3": 30.0, "rl:a": 26.0, "shield:5:rl:a": 27.0, "shield:5:0.5:rl:a": 28.0}
    grid = shields.rules((5,), (None, 0.5))
    z = norm.ppf(1 - 0.05 / (2 * 3))  # three candidates: none, 5, 5:0.5

    result = _certify_table(monkeypatch, failures, objectives, grid, bound=0.5)
    bounds = {rule: _upper(gap, z, 0.5) for rule, gap in extra.items()}
    assert result["selection"]["upper_bounds"] == pytest.approx(bounds)
    assert bounds["5:0.5"] < bounds["5"] < 0.5 < bounds["none"]  # 0.21 and 0.34 within 0.5; 0.94 not
    assert result["certified"] == ["5", "5:0.5"] and result["chosen"] == "5" and result["safe"]  # 27 beats 28
    # a tighter bound leaves the rule that is as safe as the schedule; a looser one leaves no shield at all
    tight = shields.certify(result, bound=0.3)
    assert tight["selection"]["upper_bounds"]["5"] == pytest.approx(_upper(extra["5"], z, 0.3))  # 0.32
    assert tight["certified"] == ["5:0.5"] and tight["chosen"] == "5:0.5"
    loose = shields.certify(result, bound=2.0)
    assert loose["chosen"] is None and loose["certified"] == ["none", "5", "5:0.5"] and loose["safe"]


def test_certify_needs_enough_episodes_when_none_fails(monkeypatch):
    """No failure in a few episodes certifies nothing: the spread is taken as a failure's in 5 % of them."""
    for episodes, certified in ((20, False), (200, True)):
        nothing = np.zeros(episodes)
        failures = {"every:3": nothing, "rl:a": nothing, "shield:5:rl:a": nothing}
        objectives = {"every:3": 30.0, "rl:a": 26.0, "shield:5:rl:a": 27.0}
        result = _certify_table(monkeypatch, failures, objectives, [ShieldRule(5)], bound=0.05)
        assert result["safe"] is certified and result["chosen"] is None  # no shield: the cheaper, when certified


def test_certify_says_when_nothing_is_certified_and_refuses_a_table_without_gaps(monkeypatch):
    schedule = np.zeros(8)
    failures = {"every:3": schedule, "rl:a": schedule + 1, "shield:5:rl:a": schedule + 1}
    objectives = {"every:3": 30.0, "rl:a": 26.0, "shield:5:rl:a": 27.0}
    result = _certify_table(monkeypatch, failures, objectives, [ShieldRule(5)], bound=0.05)
    assert result["certified"] == [] and result["chosen"] is None and not result["safe"]
    old = dict(result, unshielded={**result["unshielded"], "policies": {"rl:a": {"objective": 26.0}}})
    with pytest.raises(ValueError, match="no paired failure gaps"):
        shields.certify(old)


def test_where_nothing_is_certified_the_budget_chooses_and_says_so_and_a_stored_table_chooses_again_the_same(monkeypatch):
    """Long, rare failures (a quadrotor on the ground to the episode's end) may certify nothing: the budget's rule
    then stands, said not to be certified, with the bounds certification found."""
    schedule = np.zeros(40)
    schedule[[3, 17]] = 60  # the schedule crashed twice
    crashes = schedule.copy()
    crashes[[3, 17, 25]] = [0, 0, 70]  # the learner crashed once, elsewhere: fewer failures, a wide interval
    shielded = crashes.copy()
    shielded[25] = 30
    failures = {"every:3": schedule, "rl:a": crashes, "shield:5:rl:a": shielded, "shield:5:0.5:rl:a": shielded}
    objectives = {"every:3": 30.0, "rl:a": 26.0, "shield:5:rl:a": 26.1, "shield:5:0.5:rl:a": 29.0}
    result = _certify_table(monkeypatch, failures, objectives, shields.rules((5,), (None, 0.5)), bound=0.05)
    assert result["certified"] == []  # certify alone: no shield, not certified
    fallback = shields.certify_or_budget(result, bound=0.05)
    budget = shields.pick(result)
    assert budget["chosen"] == "5"  # within 1 % of 26.0 and safer than none; 5:0.5 costs 11 %
    assert fallback["chosen"] == "5" and not fallback["safe"] and fallback["certified"] == []
    assert fallback["selection"]["by"] == "budget" and fallback["selection"]["uncertified"]
    assert fallback["selection"]["upper_bounds"] == result["selection"]["upper_bounds"]
    assert shields.select(fallback) == fallback  # chosen again from the stored table, the same way
    # where something is certified, the fallback is certify itself
    certified = shields.certify_or_budget(result, bound=50.0)
    assert certified["selection"]["by"] == "certify" and certified == shields.certify(result, bound=50.0)


def test_a_rule_within_the_bound_that_leaves_a_learner_behind_the_schedule_is_not_certified(monkeypatch):
    """A shield that recomputes at nearly every step fails as seldom as the schedule but costs more than it: the
    schedule is then the safer and cheaper answer, so that rule is not certified; it is listed, and the page says so."""
    from etmpc.experiments.studies.shields import _task_section

    schedule = np.zeros(400)
    schedule[[5, 50]] = 1
    failures = {"every:3": schedule, "rl:a": schedule + (np.arange(400) % 4 == 0), "shield:5:rl:a": schedule.copy()}
    failures["shield:5:0.5:rl:a"] = schedule.copy()
    objectives = {"every:3": 30.0, "rl:a": 26.0, "shield:5:rl:a": 30.5, "shield:5:0.5:rl:a": 29.5}  # lower is better
    result = _certify_table(monkeypatch, failures, objectives, shields.rules((5,), (None, 0.5)), bound=0.05)
    assert result["selection"]["upper_bounds"]["5"] <= 0.05 and result["selection"]["upper_bounds"]["none"] > 0.05
    assert result["certified"] == ["5:0.5"] and result["chosen"] == "5:0.5"  # 29.5 beats the schedule's 30
    assert result["selection"]["behind_schedule"] == ["5"]  # as safe, but 30.5
    page = "\n".join(_task_section(TASK, result, "abc1234"))
    assert "does worse than `every:3` on mean objective (the learners' mean in brackets): `5` (30.500)" in page
    objectives["shield:5:0.5:rl:a"] = 31.0  # both behind: nothing is certified, and the budget's choice stands
    result = _certify_table(monkeypatch, failures, objectives, shields.rules((5,), (None, 0.5)), bound=0.05)
    assert result["certified"] == [] and result["selection"]["behind_schedule"] == ["5", "5:0.5"]
    assert shields.certify_or_budget(result)["chosen"] is None  # none within 1 % of the unshielded 26
