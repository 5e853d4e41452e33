"""An evaluation has one representation: the JSON ``etmpc evaluate --json`` writes is the Evaluation
itself, back and forth, and a policy's objectives come out as an array in the runs' own numbers."""

from __future__ import annotations

import json

import numpy as np
import pytest

from etmpc.common.errors import EtmpcError
from etmpc.common.outputs import strict
from etmpc.evaluation.evaluate import evaluate
from etmpc.evaluation.results import Evaluation


@pytest.fixture(scope="module")
def played():
    return evaluate("cart_pendulum", ["every:3", "threshold:0.3"], episodes=1, repeats=2, workers=1, progress=False)


def test_an_evaluation_saved_and_loaded_is_the_same_evaluation(played, tmp_path):
    path = played.save(tmp_path / "e.json", cpu=True)
    again = Evaluation.load(path)
    assert strict(again.to_json(cpu=True)) == strict(played.to_json(cpu=True)) == json.loads(path.read_text())
    assert again.runs == played.runs  # the same dataclasses, field by field


def test_a_missing_number_written_as_null_is_nan_again(played):
    data = strict(played.to_json())
    data["policies"]["every:3"]["objective_mean"] = None  # a policy whose every run failed has no mean
    assert data["policies"]["every:3"]["failures_ci95"] is None  # one episode: the failures have no CI
    summary = Evaluation.from_json(data).summaries[0]
    assert np.isnan(summary.objective_mean) and np.isnan(summary.failures_ci95) and summary.failure_name == "off balance"
    for name in ("failure_name", "failures_mean", "failures_ci95"):  # as a task that counts no failures writes it
        del data["policies"]["every:3"][name]
    summary = Evaluation.from_json(data).summaries[0]
    assert summary.failure_name is None and summary.failures_ci95 is None  # a field that may be None stays None


def test_a_policys_objectives_are_its_runs_by_repeat_and_episode(played):
    table = played.objectives("threshold:0.3")
    assert table.shape == (2, 1)
    for r in played.runs:
        if r.policy == "threshold:0.3":
            assert table[r.repeat, r.episode] == r.objective
    with pytest.raises(EtmpcError, match="no runs of 'always'"):
        played.objectives("always")


def test_a_file_that_is_not_an_evaluation_is_one_line(tmp_path):
    (tmp_path / "x.json").write_text('{"domain": "cart_pendulum"}')
    with pytest.raises(EtmpcError, match=r"x.json is not an etmpc evaluation \(missing or wrong 'policies'\)"):
        Evaluation.load(tmp_path / "x.json")
    (tmp_path / "y.json").write_text("[NaN]")
    with pytest.raises(EtmpcError, match="cannot read an evaluation"):
        Evaluation.load(tmp_path / "y.json")
