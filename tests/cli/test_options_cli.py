"""Options on the command line: --option on the commands that take it (one-line errors elsewhere), a card scored
with options that verifies (its references replayed too), and the robustness curve, against evaluate's own numbers."""

import json

import numpy as np
import pytest

from etmpc.cli import main
from etmpc.evaluation.evaluate import evaluate
from etmpc.experiments.robustness import robustness
from etmpc.systems import system_key

KICKS = "cart_pendulum/kicks"
NOISE = ["--option", "sensor.noise_std=0.01,0,0.01,0", "--option", "sensor.measured=1,0,1,0"]


@pytest.mark.parametrize(
    "argv, message",
    [
        (["evaluate", "--task", KICKS, "--policy", "every:3", "--option", "sensor.nois=1"], "unknown option 'sensor.nois'"),
        (["evaluate", "--task", KICKS, "--policy", "every:3", "--option", "horizon"], "NAME=VALUE"),
        (["evaluate", "--task", KICKS, "--policy", "every:3", "--option", "horizon=x"], "not a whole number"),
        (["evaluate", "--task", "battery", "--policy", "every:3", "--option", "sensor.noise_std=1"], "unknown option"),
        (["reproduce", "--task", KICKS, "--option", "horizon=10"], "etmpc reproduce does not take --option yet"),
        (["score", "--task", KICKS, "--leaderboard", "--option", "horizon=10"], "no --option with them"),
        (["robustness", "--task", KICKS, "--vary", "horizon", "--policy", "every:3", "--out", "x"], "NAME=VALUE"),
        (
            ["robustness", "--task", KICKS, "--vary", "sensor.dropout=0.1;0.10", "--policy", "every:3", "--out", "x"],
            "given twice",
        ),
        (
            [
                "robustness",
                "--task",
                KICKS,
                "--vary",
                "horizon=10",
                "--option",
                "horizon=12",
                "--policy",
                "every:3",
                "--out",
                "x",
            ],
            "both varied and fixed",
        ),
        (
            ["robustness", "--task", KICKS, "--vary", "horizon=10", "--policy", "every:3", "--against", "every:2", "--out", "x"],
            "--against every:2 is not one of the policies",
        ),
    ],
)
def test_bad_options_are_one_line_and_exit_2(capsys, argv, message):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("etmpc: error:") and message in err, err


def test_a_card_scored_with_options_carries_them_and_verifies_its_references_too(tmp_path, capsys):
    card = tmp_path / "card.json"
    argv = ["score", "--policy", "every:3", "--task", KICKS, "--episodes", "1", "--workers", "1", "--json", str(card), *NOISE]
    assert main(argv) == 0
    data = json.loads(card.read_text())
    refs = data["references"][KICKS]
    assert refs["stored"] is None
    assert refs["options"] == {"sensor.measured": "true,false,true,false", "sensor.noise_std": "0.01,0.0,0.01,0.0"}
    assert len(refs["best_objectives"]) == len(refs["oracle_objectives"]) == 1
    assert "with --option sensor.measured=true,false,true,false" in capsys.readouterr().out
    # the row's objectives are evaluate's under the same options, not the task's without them
    key = system_key(KICKS, None, dict(refs["options"]))
    played = evaluate(key, ["every:3"], 1, workers=1, progress=False).to_json()["runs"]
    assert data["rows"][0]["episode_objectives"] == [r["objective"] for r in played]
    exact = evaluate(KICKS, ["every:3"], 1, workers=1, progress=False).to_json()["runs"]
    assert data["rows"][0]["episode_objectives"] != [r["objective"] for r in exact]
    assert main(["verify", str(card), "--sample", "0", "--workers", "1"]) == 0
    tampered = tmp_path / "tampered.json"
    refs["oracle_objectives"][0] += 1e-6
    tampered.write_text(json.dumps(data))
    assert main(["verify", str(tampered), "--sample", "0", "--workers", "1"]) == 2
    out = capsys.readouterr().out
    assert "references' oracle:" in out and "episode 0: objective" in out


def test_the_robustness_curve_is_evaluate_at_each_value_paired_against_the_baseline(tmp_path):
    values = ["0.5", "2"]
    document = robustness(KICKS, "disturbances.kick_scale", values, ["every:3", "threshold:0.2"], "every:3", 3, 1, progress=False)
    assert [level["value"] for level in document["levels"]] == ["0.5", "2.0"]
    for level, value in zip(document["levels"], values):
        runs = evaluate(system_key(KICKS, None, {"disturbances.kick_scale": value}), ["every:3", "threshold:0.2"], 3, workers=1)
        cost = {s: np.array([r.objective for r in runs.runs if r.policy == s]) for s in ("every:3", "threshold:0.2")}
        entry = level["policies"]["threshold:0.2"]
        assert entry["objective"] == pytest.approx(cost["threshold:0.2"].mean(), rel=1e-12)
        gain = 100 * (cost["every:3"] - cost["threshold:0.2"]) / cost["every:3"].mean()
        assert entry["improvement_pct"] == pytest.approx(gain.mean(), rel=1e-9)
        assert level["policies"]["every:3"]["improvement_pct"] == 0.0
    # stronger kicks cost the fixed schedule more, on the same episodes
    assert document["levels"][1]["policies"]["every:3"]["objective"] > document["levels"][0]["policies"]["every:3"]["objective"]


def test_figure_trajectory_plays_the_episode_with_the_options(tmp_path, capsys):
    out = tmp_path / "noisy.png"
    assert main(["figure", "trajectory", "--task", KICKS, "--policy", "every:3", "--out", str(out), *NOISE]) == 0
    shown = capsys.readouterr().out
    key = system_key(KICKS, None, {"sensor.noise_std": "0.01,0,0.01,0", "sensor.measured": "1,0,1,0"})
    noisy = evaluate(key, ["every:3"], 1, workers=1, progress=False).to_json()["runs"][0]["objective"]
    exact = evaluate(KICKS, ["every:3"], 1, workers=1, progress=False).to_json()["runs"][0]["objective"]
    assert f"objective {noisy:.5f}" in shown and f"{noisy:.5f}" != f"{exact:.5f}" and out.stat().st_size > 0


def test_discriminate_plays_both_stages_with_the_options(monkeypatch):
    from etmpc.experiments import discriminate

    keys = []

    class Stop(Exception):
        pass

    def evaluate(key, *args, **kwargs):
        keys.append(key)
        raise Stop

    monkeypatch.setattr(discriminate, "evaluate", evaluate)
    with pytest.raises(Stop):
        discriminate.discriminate(KICKS, 0.2, 1, 1, options={"disturbances.kick_scale": "2"})
    assert keys == [system_key(KICKS, None, {"disturbances.kick_scale": "2"})]
    assert main(["discriminate", "--task", KICKS, "--option", "disturbances.kick_scal=2"]) == 2


def test_bench_times_the_task_with_its_options(capsys):
    from etmpc.evaluation.bench import format_bench, run_bench

    figures = run_bench(system_key("battery", None, {"horizon": "12"}), episodes=1, references=False)
    assert figures["options"] == {"horizon": "12"} and figures["mpc_solve"]["samples"] > 0
    assert format_bench(figures).splitlines()[0].startswith("battery/trading --option horizon=12: 1 test-set episode per policy")
