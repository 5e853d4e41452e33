"""A reproduce run's policies against the shipped ones: the same file is said to be the same, the same parameters
in another record are told apart from other parameters, and other parameters name the recipe entries they depart
in, read from the two files."""

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


def test_the_same_parameters_recorded_otherwise_are_said_so_with_the_entries_recorded_otherwise(tmp_path):
    dpi = json.loads((SHIPPED / "learned.json").read_text())
    dpi["domain"] = "cart_pendulum"  # as a file of an older etmpc names the task
    dpi["hyperparameters"].update(episodes_per_seed=60, validation_objective=0.0)  # an entry it did not record; an outcome
    (tmp_path / "learned.json").write_text(json.dumps(dpi))
    assert compare(TASK, tmp_path) == {"DPI": {"verdict": "same parameters", "record": ["domain", "episodes_per_seed"]}}
    table = section({TASK: {"shipped": compare(TASK, tmp_path)}})
    assert f"| {TASK} | DPI | the shipped parameters; the files record otherwise: `domain`, `episodes_per_seed` |" in table


def test_other_parameters_name_where_the_recipe_departs_among_the_entries_both_files_record(tmp_path):
    dpi = json.loads((SHIPPED / "learned.json").read_text())
    seed, recorded = dpi["hyperparameters"]["seed"], set(dpi["hyperparameters"])
    dpi["theta"][0] += 1.0
    dpi["hyperparameters"].update(seed=seed + 1, episodes=7, validation_objective=0.0, not_recorded_there=1)
    assert "not_recorded_there" not in recorded
    (tmp_path / "learned.json").write_text(json.dumps(dpi))
    shutil.copyfile(SHIPPED / "ppo.json", tmp_path / "ppo.json")
    (tmp_path / "ppo.zip").write_bytes((SHIPPED / "ppo.zip").read_bytes() + b"\0")  # other bits, the same recipe

    found = compare(TASK, tmp_path)
    assert found["DPI"] == {"verdict": "differs", "recipe": {"episodes": [60, 7], "seed": [seed, seed + 1]}}
    assert found["PPO"] == {"verdict": "differs", "recipe": {}}
    table = section({TASK: {"shipped": found}})
    assert f"| {TASK} | DPI | other parameters: `episodes` 60 → 7; `seed` {seed} → {seed + 1} |" in table
    assert f"| {TASK} | PPO | other parameters, the same recipe |" in table


def test_a_task_with_nothing_shipped_says_so_and_a_run_without_the_comparison_has_no_table(tmp_path, monkeypatch):
    shutil.copyfile(SHIPPED / "learned.json", tmp_path / "learned.json")
    monkeypatch.setattr("etmpc.experiments.shipped.data_root", lambda: tmp_path / "an installation without policies")
    assert compare(TASK, tmp_path) == {"DPI": {"verdict": "not shipped"}}
    assert section({TASK: {}}) == []  # a run made before the comparison existed
