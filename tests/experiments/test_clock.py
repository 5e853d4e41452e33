"""The stage clock of ``etmpc reproduce`` (etmpc.experiments.clock): each stage timed once, kept across
invocations, never timed from files an earlier invocation made, and the report's table of where the time
went computed from the kept seconds."""

import time

import pytest

from etmpc.experiments.clock import FILE, StageClock, time_table


def test_a_stage_is_timed_once_and_kept_for_later_invocations(tmp_path):
    clock = StageClock(tmp_path)
    started = time.perf_counter()
    with clock.stage("fixed policies", tmp_path / "baselines.json"):
        time.sleep(0.05)
        (tmp_path / "baselines.json").write_text("{}")
    elapsed = time.perf_counter() - started
    seconds = clock.read()["fixed policies"]
    assert 0.05 <= seconds <= elapsed
    with StageClock(tmp_path).stage("fixed policies", tmp_path / "baselines.json"):  # a later invocation: not timed again
        time.sleep(0.01)
    assert StageClock(tmp_path).read() == {"fixed policies": seconds}


def test_a_stage_made_before_its_time_was_kept_is_not_timed_and_an_interrupted_one_not_kept(tmp_path):
    (tmp_path / "learned_default.json").write_text("{}")
    clock = StageClock(tmp_path)
    with clock.stage("DPI evaluation", tmp_path / "learned_default.json"):
        pass  # finds its file: the instant it takes is not the stage's time
    with pytest.raises(KeyboardInterrupt):
        with clock.stage("rollout", tmp_path / "headroom_rollout.json"):
            raise KeyboardInterrupt
    assert clock.read() == {"DPI evaluation": None}
    assert (tmp_path / FILE).is_file()


def test_the_table_gives_each_tasks_minutes_total_and_share_of_the_run():
    systems = {
        "reacher": {"stage_seconds": {"fixed policies": 60.0, "DPI training": 30.0, "DPI evaluation": 30.0}},
        "quadrotor": {"stage_seconds": {"fixed policies": 120.0, "PPO training": 240.0}},
        "battery": {"stage_seconds": {"fixed policies": None, "learner mine": 120.0}},
        "untimed": {},  # a run made before stage times were kept: no row
    }
    table = "\n".join(time_table(systems))
    header = "| task | fixed policies | DPI | PPO | other learners | total | share |"
    assert header in table
    # 120 s of 600 timed: 20 %; 360 s: 60 %; 120 s: 20 %, with its untimed stage flagged.
    assert "| reacher | 1.0 | 1.0 | – | – | 2.0 | 20 % |" in table
    assert "| quadrotor | 2.0 | – | 4.0 | – | 6.0 | 60 % |" in table
    assert "| battery | not timed | – | – | 2.0 | ≥ 2.0 | 20 % |" in table
    assert "untimed" not in table
    assert "Costliest: quadrotor, 6.0 min of 10.0 (stages an earlier invocation made" in table
    assert time_table({"a": {}, "b": {"stage_seconds": {}}}) == []
