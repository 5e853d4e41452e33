"""scripts/dpi_headroom.py: development episodes of their own, paired gains, and DPI continued on-policy
with its own labeller and fit."""

import importlib.util
import json
import subprocess
import sys
from pathlib import Path

import numpy as np

from etmpc.evaluation.evaluate import scores
from etmpc.learning.config import VALIDATION_ENTROPY
from etmpc.loop import run_episode
from etmpc.policies import parse_policy
from etmpc.systems import make_system

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "scripts" / "dpi_headroom.py"


def _script():
    spec = importlib.util.spec_from_file_location("dpi_headroom", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _played(task: str, spec: str, entropy: int, index: int) -> float:
    """The episode drawn and played here, step by step, without the script's jobs."""
    system = make_system(task)
    episode = system.draw_episode(np.random.default_rng(np.random.SeedSequence(entropy, spawn_key=(index, 0))))
    policy = parse_policy(spec, system.error_weights, system.name)
    return scores(system, run_episode(system, system.make_env(), policy, None, episode))[0]


def test_score_plays_its_own_stream_of_episodes(tmp_path):
    out = tmp_path / "score.json"
    done = subprocess.run([sys.executable, str(SCRIPT), "score", "battery", "always", "every:2", "--episodes", "2",
                           "--workers", "1", "--out", str(out)], capture_output=True, text=True, cwd=tmp_path, timeout=300)
    assert done.returncode == 0, done.stderr
    rows = json.loads(out.read_text())["rows"]
    development = _script().DEVELOPMENT_ENTROPY
    for spec in ("always", "every:2"):
        assert rows[spec]["objectives"] == [_played("battery", spec, development, i) for i in range(2)]
    assert rows["always"]["objectives"] != [_played("battery", "always", VALIDATION_ENTROPY, i) for i in range(2)]
    gain = (np.array(rows["every:2"]["objectives"]) - rows["always"]["objectives"]) / np.mean(rows["always"]["objectives"]) * 100
    assert np.isclose(rows["every:2"]["gain_percent"], gain.mean()) and rows["always"]["gain_percent"] == 0.0


def test_refine_is_dpis_labeller_and_fit_on_the_policys_own_episodes(tmp_path):
    from etmpc.learning import dpi
    from etmpc.policies.learned import LogisticPolicy

    start = ROOT / "policies" / "battery" / "learned.json"
    out = tmp_path / "refine.json"
    done = subprocess.run([sys.executable, str(SCRIPT), "refine", "battery", f"rl:{start}", "--futures", "1", "--labels", "3",
                           "--label-episodes", "1", "--iterations", "1", "--episodes", "1", "--workers", "1", "--out", str(out)],
                          capture_output=True, text=True, cwd=tmp_path, timeout=300)
    assert done.returncode == 0, done.stderr
    found = json.loads(out.read_text())
    template = json.loads(start.read_text())
    settings = dpi.Settings(futures=1, horizon=20, states_per_episode=3)
    labels = dpi.label_episode("battery", template, settings, template, _script().REFINE_SEED, 0)
    theta = dpi.fit(np.array([row[0] for row in labels]), np.array([row[1] - row[2] for row in labels]), settings.ridge,
                    np.asarray(template["theta"]))
    assert found["iterations"][0]["labels"] == len(labels) == 3
    assert np.allclose(found["policy"]["theta"], theta, rtol=0, atol=1e-9)
    refined = LogisticPolicy.from_json(found["policy"])  # a policy file rl: reads, with the start's normalisation
    assert refined.greedy and refined.normalisation.to_json() == template["normalisation"]
