"""``etmpc study safety``: the paired arithmetic against hand-computed cases, the audit stream apart from every
other stream and the stored test sets, the tasks and rows it audits (the leaderboard's own), its refusals, and a
tiny run end to end."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from etmpc.cli import main
from etmpc.evaluation import testsets
from etmpc.experiments.studies.safety import policies, safety_tasks
from etmpc.experiments.studies.safety_stats import TARGET, outcome, paired
from etmpc.learning import config
from etmpc.systems import make_system, stored_seed
from tests.conftest import REPO

LEARNER = np.array([[1.0, 1, 10], [2.0, 0, 12], [3.0, 2, 14], [4.0, 0, 16]])  # objective, failures, recomputes
FIXED = np.array([[2.0, 0, 20], [2.0, 0, 20], [2.0, 1, 20], [2.0, 0, 20]])


def test_one_policys_failures_by_hand():
    found = outcome(LEARNER)
    assert found["failures"] == 0.75 and found["failed_episodes"] == 2 and found["worst_episode_failures"] == 2
    assert found["objective"] == 2.5 and found["recomputes"] == 13
    squares = 0.25**2 + 0.75**2 + 1.25**2 + 0.75**2  # about the mean 0.75: 2.75
    assert found["failures_ci95"] == pytest.approx(1.96 * math.sqrt(squares / 3) / 2, rel=1e-12)


def test_the_paired_difference_by_hand():
    """Failures differ by 1, 0, 1, 0: mean 0.5, sd sqrt(1/3), the CI's half 1.96 sqrt(1/3) / 2 = 0.5658; the
    objective (a cost) gains -(1, 0, -1, -2) on the schedule's mean 2: -25 %, sd sqrt(5/3)."""
    found = paired(LEARNER, FIXED, "min")
    assert found["failures_difference"] == 0.5
    assert found["failures_difference_ci95"] == pytest.approx(1.96 * math.sqrt(1 / 3) / 2, rel=1e-12)
    assert found["failures_difference_upper"] == pytest.approx(0.5 + 1.96 * math.sqrt(1 / 3) / 2, rel=1e-12)
    assert found["meets_target"] is False
    assert found["objective_gain_percent"] == pytest.approx(-25.0, rel=1e-12)
    assert found["objective_gain_percent_ci95"] == pytest.approx(50 * 1.96 * math.sqrt(5 / 3) / 2, rel=1e-12)
    assert found["recomputes_difference"] == -7
    assert found["failed_episodes_difference"] == 0.25  # episodes with any: 1, 0, 1, 0 against 0, 0, 1, 0
    assert found["failed_episodes_difference_ci95"] == pytest.approx(1.96 * 0.5 / 2, rel=1e-12)  # sd of 1, 0, 0, 0
    low, high = found["failures_difference_bootstrap"]
    assert 0 <= low <= 0.5 <= high <= 1  # the resampled means of 0s and 1s
    assert paired(LEARNER, FIXED, "min")["failures_difference_bootstrap"] == [low, high]  # seeded


def test_a_profit_is_oriented_and_equal_failures_meet_the_target():
    found = paired(LEARNER[:, [0, 0, 2]] * [1, 0, 1], LEARNER[:, [0, 0, 2]] * [1, 0, 1] - [1, 0, 0], "max")
    assert found["objective_gain_percent"] == pytest.approx(100 / 1.5, rel=1e-12)  # 1 more on a mean profit of 1.5
    assert found["failures_difference_upper"] == 0 and found["failures_difference_bootstrap"] == [0, 0]
    assert found["meets_target"] is True
    rare = np.zeros((1000, 3)) + [1, 0, 1]
    rare[:20, 1] = 1  # 20 more failures in 1000 episodes: 0.02 + 1.96 sqrt(0.02 * 0.98 * 1000 / 999) / sqrt(1000)
    assert paired(rare, np.zeros((1000, 3)) + [1, 0, 1], "min")["failures_difference_upper"] == pytest.approx(
        0.02 + 1.96 * math.sqrt(0.02 * 0.98 * 1000 / 999 / 1000), rel=1e-12
    )
    assert paired(rare, np.zeros((1000, 3)) + [1, 0, 1], "min")["meets_target"] is True  # 0.0287 <= TARGET
    assert TARGET == 0.05


def test_unpaired_outcomes_are_refused():
    with pytest.raises(ValueError):
        paired(LEARNER, FIXED[:3], "min")


def test_the_safety_tasks_are_those_that_read_a_margin_to_a_failure():
    kicks = [f"cart_pendulum/{t}" for t in ("kicks", "kicks_late", "kicks_levels", "kicks_noisy")]
    assert safety_tasks() == [*kicks, "quadrotor/waypoints", "quadrotor/waypoints_noisy"]


@pytest.mark.parametrize("task", safety_tasks())
def test_the_rows_audited_are_the_stored_leaderboards(task):
    board = json.loads((REPO / "docs" / "leaderboard.json").read_text())
    learned = [e["specs"][task] for e in board["entries"] if e["kind"] == "learned" and task in e["specs"]]
    best = next(e["specs"][task] for e in board["entries"] if e["name"] == "best periodic")
    assert [spec for _, spec in policies(task)] == [best, *learned]


def test_the_audit_stream_is_none_of_the_others():
    streams = [config.TRAIN_ENTROPY, config.NORMALISATION_ENTROPY, config.SELECTION_ENTROPY, config.VALIDATION_ENTROPY]
    seeds = {stored_seed(task) for task in safety_tasks()}
    assert config.AUDIT_ENTROPY not in streams and config.AUDIT_ENTROPY not in seeds


def _drawn(system, entropy: int, index: int) -> dict:
    """Episode ``index`` of ``entropy``'s stream, as etmpc.learning.jobs draws it."""
    rng = np.random.default_rng(np.random.SeedSequence(entropy, spawn_key=(index, 0)))
    return system.draw_episode(rng).arrays()


@pytest.mark.parametrize("task", safety_tasks())
def test_audit_episodes_differ_from_validation_and_test_episodes(task):
    system = make_system(task)
    stored = testsets.load(testsets.default_path(system.domain, system.task), system.domain, system.task)
    for i in range(5):
        audit = _drawn(system, config.AUDIT_ENTROPY, i)
        for other in (_drawn(system, config.VALIDATION_ENTROPY, i), {k: v[i] for k, v in stored.arrays.items()}):
            assert set(other) == set(audit)
            assert any(not np.array_equal(audit[k], other[k]) for k in audit)
        assert not np.array_equal(audit["initial_state"], _drawn(system, config.AUDIT_ENTROPY, i + 1)["initial_state"])


@pytest.mark.parametrize(
    "argv, said",
    [
        (["--task", "battery/trading"], "not a safety task"),
        (["--task", "no/such"], "unknown task"),
        (["--episodes", "1"], "at least 2"),
    ],
)
def test_bad_input_is_refused_in_one_line(tmp_path, capsys, argv, said):
    assert main(["study", "safety", *argv, "--out", str(tmp_path), "--work", str(tmp_path / "work")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and said in err
    assert not list(tmp_path.iterdir())


def test_two_episodes_of_one_task_end_to_end(tmp_path, capsys):
    argv = ["study", "safety", "--task", "cart_pendulum/kicks", "--episodes", "2", "--workers", "1"]
    assert main([*argv, "--out", str(tmp_path), "--work", str(tmp_path / "work")]) == 0
    document = json.loads((tmp_path / "safety.json").read_text())
    task = document["tasks"]["cart_pendulum/kicks"]
    assert task["episodes"] == 2 and [r["row"] for r in task["rows"]] == ["DPI (shipped)", "PPO (shipped)"]
    kept = sorted(p.name for p in (tmp_path / "work" / "cart_pendulum" / "kicks").iterdir())
    assert kept == ["best-fixed.json", "dpi-shipped.json", "ppo-shipped.json"]
    assert "## `cart_pendulum/kicks`" in (tmp_path / "safety.md").read_text()
    again = (tmp_path / "safety.json").read_text()
    assert main([*argv, "--out", str(tmp_path), "--work", str(tmp_path / "work")]) == 0  # continued: nothing played
    assert (
        json.loads((tmp_path / "safety.json").read_text())["tasks"]["cart_pendulum/kicks"]["rows"]
        == json.loads(again)["tasks"]["cart_pendulum/kicks"]["rows"]
    )
