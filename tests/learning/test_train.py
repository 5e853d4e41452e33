"""Training: identical results for any worker count, bit-exact resume after kill -9, policy files."""

import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from tests.conftest import REPO
from etmpc.cli import main
from etmpc.common.errors import EtmpcError
from etmpc.learning.gpomdp import Settings
from etmpc.policies.learned import INITIAL_KEEP_LOGIT, LogisticPolicy, Normalisation, load_policy, sigmoid
from etmpc.policies import AugmentedState, parse_policy
from etmpc.learning.train import TrainConfig, once_each, train
from etmpc.views.curves import write_curve_png

ROOT = REPO
TINY = dict(seeds=(0, 1), episodes=4, eval_every=2, eval_episodes=3, normalisation_episodes=2, validation_episodes=2)


def files(out):
    return {p.relative_to(out).as_posix(): p.read_bytes() for p in sorted(out.rglob("*")) if p.is_file()}


def test_results_do_not_depend_on_the_number_of_workers(tmp_path):
    config = TrainConfig("battery", **TINY)
    train(config, tmp_path / "one", workers=1, progress=False, curve_png=write_curve_png)
    train(config, tmp_path / "two", workers=2, progress=False, curve_png=write_curve_png)
    assert files(tmp_path / "one") == files(tmp_path / "two") and "curve.png" in files(tmp_path / "one")
    curve = json.loads((tmp_path / "one" / "curve.json").read_text())
    assert [p["episodes"] for p in curve["points"]] == [0, 2, 4] and curve["objective_sense"] == "max"


def test_the_run_draws_with_what_it_is_given(tmp_path):
    """Learning draws nothing itself: the curve is drawn by the ``curve_png`` it is given, from the summary
    in curve.json, into curve.png's place; recording episodes with no recorder is refused before any work."""
    drawn = []
    out = tmp_path / "run"
    train(TrainConfig("battery", **TINY), out, workers=1, progress=False, curve_png=lambda *args: drawn.append(args))
    assert drawn[-1] == (out / "curve.png", json.loads((out / "curve.json").read_text()), 2)
    assert not (out / "curve.png").exists()
    with pytest.raises(EtmpcError, match="^record episodes: nothing to write them with: pass recorder="):
        train(TrainConfig("battery", **TINY), tmp_path / "rec", workers=1, progress=False, record_episodes=1)
    assert not (tmp_path / "rec").exists()


def test_curve_points_are_what_evaluate_reports(tmp_path):
    """The learning curve's last point for a seed equals `etmpc evaluate --policy rl:last.json --seed 0`."""
    from etmpc.evaluation.evaluate import evaluate

    state = train(TrainConfig("battery", **TINY), tmp_path, workers=1, progress=False)
    result = evaluate("battery", [f"rl:{tmp_path / 'seed1' / 'last.json'}"], episodes=3, workers=1, progress=False)
    row = [r for r in state.curve if r["seed"] == 1 and r["episodes"] == 4][0]
    assert result.summaries[0].objective_mean == pytest.approx(row["objective"], rel=1e-12)


def test_the_first_point_is_the_initial_policy_played_once_for_every_seed(tmp_path):
    """Every seed starts from the same policy, whose episodes once_each plays once: the first point,
    the same for each seed, is what `etmpc evaluate` reports for that policy."""
    from etmpc.evaluation.evaluate import evaluate

    state = train(TrainConfig("battery", **TINY), tmp_path / "run", workers=1, progress=False)
    (tmp_path / "initial.json").write_text(json.dumps(state.policy))
    result = evaluate("battery", [f"rl:{tmp_path / 'initial.json'}"], episodes=3, workers=1, progress=False)
    first = [r["objective"] for r in state.curve if r["episodes"] == 0]
    assert len(first) == 2 and first[0] == first[1]
    assert result.summaries[0].objective_mean == pytest.approx(first[0], rel=1e-12)


def test_once_each_plays_each_distinct_job_once_and_answers_every_job_in_order():
    class Serial:
        def __init__(self):
            self.seen = []

        def map(self, fn, jobs, on_result=None):
            self.seen += jobs
            results = [fn(job) for job in jobs]
            for job in jobs:
                on_result(job)
            return results

    backend, ticks = Serial(), []
    jobs = [("evaluate", (policy, episode)) for policy in ("a", "b", "a") for episode in (0, 1)]
    results = once_each(backend, lambda job: f"{job[1][0]}{job[1][1]}", jobs, ticks.append)
    assert results == ["a0", "a1", "b0", "b1", "a0", "a1"]
    assert backend.seen == jobs[:4] and ticks == jobs  # the repeats too, after the played ones


def test_training_moves_theta_and_keeps_the_gradient_step(tmp_path):
    state = train(TrainConfig("battery", **TINY), tmp_path, workers=1, progress=False)
    initial = np.array(state.policy["theta"])
    assert initial[-1] == INITIAL_KEEP_LOGIT and np.all(initial[:-1] == 0)
    for seed in ("0", "1"):
        assert state.learners[seed]["episodes"] == 4
        assert not np.array_equal(state.learners[seed]["theta"], initial)
    assert len(state.training) == 8


CMD = [
    sys.executable,
    "-m",
    "etmpc.cli",
    "train",
    "--task",
    "cart_pendulum",
    "--seeds",
    "0-1",
    "--episodes",
    "12",
    "--eval-every",
    "3",
    "--eval-episodes",
    "2",
    "--workers",
    "1",
    "--algorithm",
    "gpomdp",
    "--validation-episodes",
    "3",
]


@pytest.mark.slow
def test_kill_9_then_resume_ends_bit_for_bit_like_an_uninterrupted_run(tmp_path):
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    subprocess.run(CMD + ["--out", str(tmp_path / "whole")], check=True, capture_output=True, env=env)

    killed = tmp_path / "killed"
    proc = subprocess.Popen(CMD + ["--out", str(killed)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)
    checkpoint, deadline = killed / "checkpoint.json", time.monotonic() + 120
    while time.monotonic() < deadline:  # wait for the second checkpoint, then kill mid-phase
        if checkpoint.exists() and json.loads(checkpoint.read_text())["learners"]["0"]["episodes"] >= 3:
            break
        time.sleep(0.02)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    done = json.loads(checkpoint.read_text())["learners"]["0"]["episodes"]
    assert 3 <= done < 12, "the run should have been killed part of the way through"

    resumed = subprocess.run(CMD + ["--out", str(killed), "--resume"], capture_output=True, text=True, env=env)
    assert resumed.returncode == 0, resumed.stderr
    assert files(tmp_path / "whole") == files(killed)


def test_an_existing_run_is_never_overwritten(tmp_path, capsys):
    train(TrainConfig("battery", **TINY), tmp_path, workers=1, progress=False)
    before = files(tmp_path)
    assert (
        main(["train", "--task", "battery", "--seeds", "0-1", "--episodes", "4", "--out", str(tmp_path), "--algorithm", "gpomdp"])
        == 2
    )
    assert "--resume" in capsys.readouterr().err
    assert (
        main(
            [
                "train",
                "--task",
                "battery",
                "--seeds",
                "0-2",
                "--episodes",
                "4",
                "--out",
                str(tmp_path),
                "--resume",
                "--algorithm",
                "gpomdp",
            ]
        )
        == 2
    )
    assert "different settings" in capsys.readouterr().err
    (tmp_path / "checkpoint.json").write_text('{"format": "etmpc-train-checkpoint", "version": 1, "config": {')
    corrupt = files(tmp_path)
    assert (
        main(
            [
                "train",
                "--task",
                "battery",
                "--seeds",
                "0-1",
                "--episodes",
                "4",
                "--eval-every",
                "2",
                "--out",
                str(tmp_path),
                "--resume",
            ]
        )
        == 2
    )
    assert "corrupt" in capsys.readouterr().err
    assert files(tmp_path) == corrupt
    assert {k: v for k, v in before.items() if k != "checkpoint.json"} == {
        k: v for k, v in corrupt.items() if k != "checkpoint.json"
    }


@pytest.mark.parametrize(
    "argv, message",
    [
        (["train", "--task", "battery", "--seeds", "3-1", "--out", "x"], "--seeds"),
        (["train", "--task", "battery", "--seeds", "a", "--out", "x"], "--seeds"),
        (["train", "--task", "pendulum", "--out", "x"], "unknown task"),
        (["train", "--task", "battery", "--baseline", "median", "--out", "x"], "invalid choice"),
        (["train", "--task", "battery", "--algorithm", "gpomdp", "--learning-rate", "-1", "--out", "x"], "learning rate"),
        (
            ["train", "--task", "battery", "--learning-rate", "0.1", "--out", "x"],
            "--learning-rate is a setting of gpomdp only, not of dpi",
        ),
        (["train", "--task", "battery", "--address", "ray://h:10001", "--out", "x"], "--backend ray"),
        (["train", "--task", "battery", "--backend", "ray", "--address", "nonsense", "--out", "x"], "bad --address"),
        (["train", "--task", "battery", "--backend", "ray", "--address", "127.0.0.1:1", "--out", "x"], "cannot reach"),
    ],
)
def test_bad_train_input_is_one_line_and_exit_2(capsys, tmp_path, argv, message):
    argv = [a if a != "x" else str(tmp_path / "run") for a in argv]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err
    assert not (tmp_path / "run").exists()


def make_policy(domain="battery", nx=1):
    rng = np.random.default_rng(0)
    normalisation = Normalisation.fit(rng.normal(size=(50, 2 * nx + 1)))
    return LogisticPolicy.initial(normalisation, domain, {"discount": 0.975})


def test_policy_file_round_trips_exactly_and_starts_by_recomputing(tmp_path):
    policy = make_policy()
    policy.theta[:3] = [0.1, 1 / 3, -2e-17]
    policy.save(tmp_path / "p.json")
    loaded = load_policy(tmp_path / "p.json", "battery", nx=1)
    np.testing.assert_array_equal(loaded.theta, policy.theta)
    np.testing.assert_array_equal(loaded.normalisation.std_sq, policy.normalisation.std_sq)
    s = AugmentedState(np.array([0.5]), np.array([0.4]), 3, np.array([0.45]))
    assert loaded.keep_probability(s) == policy.keep_probability(s)
    fresh = make_policy()
    assert fresh.keep_probability(s) == pytest.approx(sigmoid(INITIAL_KEEP_LOGIT)) and sigmoid(INITIAL_KEEP_LOGIT) < 0.05


@pytest.mark.parametrize(
    "content, message",
    [
        ("{", "cannot be read"),
        ('{"format": "something-else"}', "not an etmpc logistic policy"),
        ("WRONG_SIZE", "features"),
        ("WRONG_TASK", "trained on 'battery'"),
    ],
)
def test_bad_policy_files_are_one_line_errors(tmp_path, capsys, content, message):
    path = tmp_path / "p.json"
    if content == "WRONG_SIZE":
        make_policy("cart_pendulum", nx=1).save(path)
    elif content == "WRONG_TASK":
        make_policy("battery", nx=4).save(path)
    else:
        path.write_text(content)
    assert main(["evaluate", "--task", "cart_pendulum", "--policy", f"rl:{path}", "--episodes", "1", "--workers", "1"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err


def test_rl_spec_needs_a_path():
    from etmpc.common.errors import EtmpcError

    with pytest.raises(EtmpcError, match="rl:PATH"):
        parse_policy("rl:", "cart_pendulum")
    assert Settings().discount == 0.975 and Settings().learning_rate == 0.05


def test_training_benchmark_script_measures_both_ends(tmp_path):
    """`scripts/bench.py training`: the policy that mostly keeps its plan recomputes less and runs
    faster than the initial one, every worker's memory is measured, and the projection is the
    protocol's episode counts over the measured rates."""
    out = tmp_path / "bench.json"
    done = subprocess.run(
        [
            sys.executable,
            str(ROOT / "scripts" / "bench.py"),
            "training",
            "battery",
            "--episodes",
            "3",
            "--workers",
            "1",
            "--json",
            str(out),
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr
    data = json.loads(out.read_text())
    start, keeper = data["rates"]["start (initial policy)"], data["rates"]["mostly keeps (bias +3)"]
    assert start["recomputes"] > 80 > 30 > keeper["recomputes"]
    assert keeper["train"] > start["train"]
    assert len(data["peak_rss_mib"]) == 1 and 50 < data["peak_rss_mib"][0] < 1024
    expected = 5 * 1500 / start["train"] + 5 * 11 * 100 / start["evaluate"]
    assert data["protocol_projection_seconds"]["start (initial policy)"] == pytest.approx(expected)
