"""A reproduce run's policies against the shipped ones: the same file is said to be the same, and a file that
differs names the recipe entries it departs in, read from the two files."""

import json
import shutil

from etmpc.experiments.shipped import compare, section

from tests.conftest import REPO

TASK = "cart_pendulum/kicks_late"
SHIPPED = REPO / "policies" / "cart_pendulum" / "kicks_late"


def test_a_copy_of_the_shipped_files_is_the_same_and_a_missing_learner_is_not_compared(tmp_path):
    shutil.copyfile(SHIPPED / "learned.json", tmp_path / "learned.json")
    assert compare(TASK, tmp_path) == {"DPI": {"verdict": "same"}}  # no ppo.zip written: PPO did not run
    assert "| cart_pendulum/kicks_late | DPI | the shipped file, byte for byte |" in section(
        {TASK: {"shipped": compare(TASK, tmp_path)}}
    )


def test_a_policy_trained_otherwise_names_where_its_recipe_departs_and_only_there(tmp_path):
    dpi = json.loads((SHIPPED / "learned.json").read_text())
    seed = dpi["hyperparameters"]["seed"]
    dpi["hyperparameters"].update(seed=seed + 1, episodes=7, validation_objective=0.0)  # the last: an outcome
    (tmp_path / "learned.json").write_text(json.dumps(dpi))
    ppo = json.loads((SHIPPED / "ppo.json").read_text())
    (tmp_path / "ppo.json").write_text(json.dumps(ppo))
    (tmp_path / "ppo.zip").write_bytes((SHIPPED / "ppo.zip").read_bytes() + b"\0")  # other bits, the same recipe

    found = compare(TASK, tmp_path)
    assert found["DPI"] == {"verdict": "differs", "recipe": {"episodes": [60, 7], "seed": [seed, seed + 1]}}
    assert found["PPO"] == {"verdict": "differs", "recipe": {}}
    table = section({TASK: {"shipped": found}})
    assert f"| {TASK} | DPI | differs: `episodes` 60 → 7; `seed` {seed} → {seed + 1} |" in table
    assert f"| {TASK} | PPO | differs in its bits, same recipe |" in table


def test_a_task_with_nothing_shipped_says_so_and_a_run_without_the_comparison_has_no_table(tmp_path, monkeypatch):
    shutil.copyfile(SHIPPED / "learned.json", tmp_path / "learned.json")
    monkeypatch.setattr("etmpc.experiments.shipped.data_root", lambda: tmp_path / "an installation without policies")
    assert compare(TASK, tmp_path) == {"DPI": {"verdict": "not shipped"}}
    assert section({TASK: {}}) == []  # a run made before the comparison existed
