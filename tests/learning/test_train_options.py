"""Training under a task's options (``etmpc train --option``): the workers play the task with them (the curve's
points are what ``etmpc evaluate`` gives with the same options, and differ from the task's without them), the
policy file and the checkpoint say which, and a run is resumed only with the options it was started with."""

import json

import pytest

from etmpc.cli import main
from etmpc.common.errors import EtmpcError
from etmpc.evaluation.evaluate import evaluate
from etmpc.learning.train import TrainConfig, train
from etmpc.systems import system_key

TASK = "cart_pendulum/kicks"
CALM = (("disturbances.kick_scale", "0"),)  # no kicks at all: an easier world than the task's
TINY = dict(seeds=(0,), episodes=2, eval_every=2, eval_episodes=2, normalisation_episodes=2, validation_episodes=2)


def last_point(state, seed=0):
    return [r for r in state.curve if r["seed"] == seed and r["episodes"] == TINY["episodes"]][0]["objective"]


def test_a_run_trains_and_evaluates_with_the_options_and_says_so(tmp_path):
    calm = train(TrainConfig(TASK, **TINY, algorithm="gpomdp", options=CALM), tmp_path / "calm", workers=1, progress=False)
    plain = train(TrainConfig(TASK, **TINY, algorithm="gpomdp"), tmp_path / "plain", workers=1, progress=False)
    policy = f"rl:{tmp_path / 'calm' / 'seed0' / 'last.json'}"
    with_options = evaluate(system_key(TASK, None, CALM), [policy], episodes=2, workers=1, progress=False)
    assert with_options.summaries[0].objective_mean == pytest.approx(last_point(calm), rel=1e-12)
    assert last_point(calm) < last_point(plain)  # without kicks the same learner's episodes cost less
    hyper = json.loads((tmp_path / "calm" / "seed0" / "last.json").read_text())["hyperparameters"]
    assert hyper["options"] == {"disturbances.kick_scale": "0.0"}
    assert "options" not in json.loads((tmp_path / "plain" / "seed0" / "last.json").read_text())["hyperparameters"]
    checkpoint = json.loads((tmp_path / "calm" / "checkpoint.json").read_text())
    assert TrainConfig.from_json(checkpoint["config"]).options == (("disturbances.kick_scale", "0.0"),)


def test_a_run_resumes_only_with_its_options(tmp_path, capsys):
    out = tmp_path / "run"
    argv = ["train", "--task", TASK, "--algorithm", "gpomdp", "--seeds", "0", "--episodes", "2", "--eval-every", "2"]
    argv += ["--eval-episodes", "2", "--out", str(out)]
    assert main([*argv, "--option", "disturbances.kick_scale=0"]) == 0
    assert "--option disturbances.kick_scale=0.0" in capsys.readouterr().out  # how to evaluate it, as trained
    assert main([*argv, "--resume"]) == 2
    err = capsys.readouterr().err
    assert "holds a gpomdp run on cart_pendulum/kicks --option disturbances.kick_scale=0.0, not cart_pendulum/kicks;" in err


def test_a_bad_option_is_refused_before_any_work(tmp_path):
    with pytest.raises(EtmpcError, match="unknown option 'disturbances.kick_scal'"):
        TrainConfig(TASK, options=(("disturbances.kick_scal", "0"),))
