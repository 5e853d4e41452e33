"""The command line: tables, JSON, and one-line errors with exit code 2."""

import json
import os
import subprocess
import sys

import pytest

from etmpc.cli import main


@pytest.mark.parametrize(
    "argv, message",
    [
        (["evaluate", "--task", "cartpole", "--policy", "always"], "unknown task 'cartpole'"),
        (["evaluate", "--task", "cart_pendulum", "--policy", "sometimes"], "unknown policy 'sometimes'"),
        (["evaluate", "--task", "cart_pendulum", "--policy", "every:0"], "period"),
        (["evaluate", "--task", "cart_pendulum", "--policy", "threshold:-1"], "threshold"),
        (["evaluate", "--task", "cart_pendulum", "--policy", "always", "--test-set", "/no/such.npz"], "not found"),
        (["evaluate", "--task", "cart_pendulum", "--policy", "always", "--episodes", "0"], "--episodes"),
        (["evaluate", "--task", "cart_pendulum", "--policy", "always", "--episodes", "101"], "1..100"),
        (["evaluate", "--task", "cart_pendulum", "--policy", "always", "--json", "/"], "directory"),
        (["evaluate", "--task", "cart_pendulum"], "--policy"),
        (["frobnicate"], "invalid choice"),
        (["evaluate", "--task", "battery", "--policy", "every:x"], "every"),
        (["evaluate", "--task", "battery", "--policy", "always", "--episodes", "101"], "1..100"),
        (["bench", "--task", "battery", "--task", "pendulum"], "unknown task 'pendulum'"),
        (["bench", "--episodes", "0"], "--episodes"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(capsys, argv, message):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("etmpc: error:") and message in err
    assert "Traceback" not in err


def test_evaluate_writes_table_and_json(tmp_path, capsys):
    out = tmp_path / "sub" / "r.json"
    assert (
        main(
            [
                "evaluate",
                "--task",
                "cart_pendulum",
                "--policy",
                "never",
                "--policy",
                "every:10",
                "--episodes",
                "2",
                "--workers",
                "1",
                "--json",
                str(out),
            ]
        )
        == 0
    )
    table = capsys.readouterr().out
    data = json.loads(out.read_text())
    assert set(data["policies"]) == {"never", "every:10"}
    for spec, summary in data["policies"].items():
        assert f"{summary['objective_mean']:.5f}" in table and summary["recomputes_mean"] in (5.0, 10.0)


def test_evaluate_battery_reports_profit(capsys):
    assert (
        main(["evaluate", "--task", "battery", "--policy", "always", "--policy", "never", "--episodes", "2", "--workers", "1"])
        == 0
    )
    out = capsys.readouterr().out
    assert "battery/trading: objective (higher is better)" in out and "never" in out


def test_console_script_error_has_no_traceback():
    result = subprocess.run(
        [sys.executable, "-m", "etmpc.cli", "evaluate", "--task", "cart_pendulum", "--policy", "every:0"],
        capture_output=True,
        text=True,
    )
    assert result.returncode == 2 and "Traceback" not in result.stderr and result.stderr.count("\n") == 1


def test_bench_reports_consistent_figures():
    from etmpc.evaluation.bench import run_bench

    figures = run_bench("cart_pendulum", episodes=1, references=False)
    assert figures["mpc_solve"]["samples"] == 100  # one solve per step under `always`
    assert 0 < figures["mpc_solve"]["median_ms"] <= figures["mpc_solve"]["p90_ms"]
    assert figures["rest_of_step"]["samples"] == 300 and figures["solver_failures"] == 0  # always, every:3, never
    assert set(figures["episodes_per_second"]) == {"always", "every:3", "never"}
    rollout = figures["rollout_step"]
    assert rollout["samples"] == 5 and rollout["median_us"] > 0
    assert rollout["steps_per_second"] == pytest.approx(1e6 / rollout["median_us"])
    before = figures["interpreted"]  # the same OCPs solved as before compiling: the same optimum
    assert before["ours"]["samples"] == before["interpreted"]["samples"] == 200
    assert before["objective_gap_relative"]["max_abs"] < 1e-6
    budget = figures["step_budget"]  # every:3's steps, split: the parts make the whole
    assert budget["steps"] == 100 and min(budget["solve_ms"], budget["plant_ms"]) > 0
    assert budget["solve_ms"] + budget["plant_ms"] + budget["rest_ms"] == pytest.approx(budget["step_ms"])
    floor = budget["solve_ms"] + budget["plant_ms"]
    assert budget["batch_bound"]["one_core"] == pytest.approx(budget["step_ms"] / floor)
    assert budget["batch_bound"]["every_core"] == pytest.approx(budget["cores"] * budget["batch_bound"]["one_core"])


def test_the_plant_clock_times_one_environment_and_leaves_it_as_it_was():
    from etmpc.evaluation.bench import _PlantClock
    from etmpc.systems import system_key

    env, other = (system_key("cart_pendulum").make().make_env() for _ in range(2))
    env.reset(), other.reset()
    before = env.physics.data.time
    with _PlantClock(env) as clock:
        env.physics.step(7)
        other.physics.step(7)  # a twin's steps are not this environment's
        timed = clock.seconds
        other.physics.step(1000)
    assert timed > 0 and clock.seconds == timed  # only env's steps counted
    assert env.physics.data.time == pytest.approx(before + 7 * env.physics.model.opt.timestep)  # the steps were taken
    assert "step" not in vars(env.physics)  # the class's own step again


def test_a_reader_that_stops_early_ends_the_command_quietly():
    # `etmpc tasks | head -1`: the pipe closes under the command; it stops, as `ls | head` does, with no
    # error line (it said "etmpc: error: Broken pipe") and the shell's code for SIGPIPE
    read_end, write_end = os.pipe()
    os.close(read_end)  # the reader is gone before the first line is written
    try:
        result = subprocess.run([sys.executable, "-m", "etmpc.cli", "tasks"], stdout=write_end, stderr=subprocess.PIPE, text=True)
    finally:
        os.close(write_end)
    assert result.stderr == "" and result.returncode == 141
