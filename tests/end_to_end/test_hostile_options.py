"""The command line against hostile options and policy specs: each is refused with exit code 2 and one line naming
it, before anything is built or played, with every file as it was (the harness of test_hostile.py)."""

from __future__ import annotations

import sys

import pytest


from tests.end_to_end.test_hostile import refused_in_one_line

KICKS = ["evaluate", "--task", "cart_pendulum/kicks", "--policy", "every:3", "--episodes", "1", "--workers", "1"]
BALANCE = ["evaluate", "--task", "cart_pendulum", "--policy", "every:3", "--episodes", "1", "--workers", "1"]
BATTERY = ["evaluate", "--task", "battery", "--policy", "every:3", "--episodes", "1", "--workers", "1"]
DEEP = "shield:3:" * 3000 + "always"

CASES = [
    # a solver is chosen from the project's list: no name reaches CasADi's plugin loader
    ("qpsol-planted", [*KICKS, "--option", "solver.qpsol=planted"], "option solver.qpsol: 'planted' is not one of"),
    ("qpsol-path", [*KICKS, "--option", "solver.qpsol=../../tmp/x"], "option solver.qpsol"),
    ("route-bogus", [*KICKS, "--option", "solver.route=bogus"], "option solver.route: 'bogus' is not one of"),
    ("cold-start-bogus", [*KICKS, "--option", "solver.cold_start=bogus"], "option solver.cold_start"),
    ("block-zero", [*KICKS, "--option", "solver.block=0"], "option solver.block: 0 is not a whole number in 1..100"),
    ("block-past-horizon", [*KICKS, "--option", "solver.block=30"], "solver.block: 30 is longer than the horizon"),
    ("plant-bogus", [*KICKS, "--option", "plant=../models/x"], "option plant"),
    # values no controller can have
    ("lqr-r-zero", [*BALANCE, "--option", "lqr_input_weight=0"], "option lqr_input_weight: 0.0 is not a number in"),
    ("lqr-q-negative", [*BALANCE, "--option", "lqr_state_weights=-1,-1,-1,-1"], "option lqr_state_weights"),
    ("lqr-q-zero", [*BALANCE, "--option", "lqr_state_weights=0,0,0,0"], "give no stabilising gain"),
    ("feedback-r-negative", [*KICKS, "--option", "feedback_input_weight=-1"], "option feedback_input_weight"),
    ("feedback-q-short", [*KICKS, "--option", "feedback_state_weights=1,1"], "option feedback_state_weights"),
    ("capacity-zero", [*BATTERY, "--option", "battery.capacity_kwh=0"], "option battery.capacity_kwh"),
    ("interval-negative", [*BATTERY, "--option", "battery.interval_s=-1"], "option battery.interval_s"),
    ("event-duration-tiny", [*BATTERY, "--option", "market.price.event_mean_duration_s=1e-300"], "event_mean_duration_s"),
    ("soc-range-reversed", [*BATTERY, "--option", "market.initial_soc_low=0.95"], "initial_soc_low 0.95 is above"),
    ("sensor-seed-negative", [*KICKS, "--option", "sensor.seed=-1"], "option sensor.seed: -1"),
    ("sensor-noise-huge", [*KICKS, "--option", "sensor.noise_std=1e300"], "option sensor.noise_std"),
    ("sensor-per-state-count", [*KICKS, "--option", "sensor.noise_std=0.1,0.1"], "for a plant of 4 states"),
    ("latency-negative", [*KICKS, "--option", "latency.intervals=-1"], "option latency.intervals"),
    ("latency-label-control-chars", [*KICKS, "--option", "latency.platform=a\x1b[2Jb"], "option latency.platform"),
    ("unit-is-no-option", [*BATTERY, "--option", "market.price.unit=x"], "'market.price.unit' is not an option"),
    # work an option would make huge
    ("horizon-huge", [*KICKS, "--option", "horizon=100000"], "option horizon: 100000 is not a whole number in 1..100"),
    ("substeps-huge", [*KICKS, "--option", "rk4_substeps=100000000"], "option rk4_substeps"),
    ("steps-huge", [*BATTERY, "--option", "battery.episode_steps=1000000000"], "option battery.episode_steps"),
    (
        "kick-rate-huge",
        [
            "testset",
            "--task",
            "cart_pendulum/kicks",
            "--episodes",
            "1",
            "--seed",
            "1",
            "--out",
            "t.npz",
            "--option",
            "disturbances.kicks_per_s=1e9",
        ],
        "option disturbances.kicks_per_s",
    ),
    # policy specs: bounded before they are read
    (
        "spec-nested-too-deep",
        ["evaluate", "--task", "cart_pendulum/kicks_late", "--policy", "shield:3:" * 9 + "always"],
        "wrapped more than 8 deep",
    ),
    ("spec-too-long", ["evaluate", "--task", "cart_pendulum/kicks_late", "--policy", DEEP], "more than the 4096"),
]


@pytest.mark.parametrize("argv, names", [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_a_hostile_option_or_spec_is_one_line_and_touches_nothing(argv, names, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "dont_write_bytecode", True)
    refused_in_one_line(argv, names, tmp_path, capsys)


def test_the_files_a_spec_reads_are_found_at_every_depth_the_parser_takes_and_a_spec_past_its_bounds_is_refused():
    """The search for the files a spec reads (so that no output lands on them) looks at every stretch of a wrapping
    kind's argument: it is bounded as the parser is, and it still finds a base's file at the deepest wrapping."""
    from etmpc.common.errors import EtmpcError
    from etmpc.evaluation.inputs import policy_files
    from etmpc.policies.specs import MAX_NESTING, MAX_SPEC_PARTS

    from tests.end_to_end.test_hostile import CART_POLICY

    deepest = "shield:3:" * MAX_NESTING + f"rl:{CART_POLICY}"
    assert policy_files(deepest) == [CART_POLICY]
    assert policy_files(f"rollout:shield:3:rl:{CART_POLICY}:4:20") == [CART_POLICY]
    with pytest.raises(EtmpcError, match=f"more than the {MAX_SPEC_PARTS} a spec may hold"):
        policy_files("shield:" * MAX_SPEC_PARTS + "always")
    with pytest.raises(EtmpcError, match="more than the 4096"):
        policy_files(DEEP)
