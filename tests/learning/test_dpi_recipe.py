"""DPI's recipe as data (policies/<task>/dpi.yml, etmpc.learning.dpi_recipe): each shipped file is the run of the
policy it ships beside, as that policy's own file records it; a bad file is one line naming the file and the key;
and etmpc reproduce trains from it."""

import json
from dataclasses import replace
from pathlib import Path

import pytest

from etmpc.experiments.reproduce_settings import FULL, QUICK
from etmpc.learning import dpi_recipe
from etmpc.learning.hyperparams import HyperparameterError
from etmpc.systems import folder_name, names

SHIPPED = [task for task in names() if dpi_recipe.shipped_path(task).is_file()]


def test_every_task_that_ships_a_dpi_policy_ships_its_recipe():
    with_policy = [task for task in names() if (Path("policies") / folder_name(task) / "learned.json").is_file()]
    assert with_policy and SHIPPED == with_policy


@pytest.mark.parametrize("task", SHIPPED)
def test_each_recipe_is_the_run_its_shipped_policy_records(task):
    """The truth is the shipped learned.json's own record of the run that made it."""
    config = dpi_recipe.recipe(task)
    made = json.loads((Path("policies") / folder_name(task) / "learned.json").read_text())["hyperparameters"]
    assert config.domain == task and config.algorithm == "dpi" and made["algorithm"] == "dpi"
    assert made["seed"] in config.seeds
    # the policy is one iteration's (its episodes), of a run of the recipe's episodes where the file records them
    assert made["episodes"] <= config.episodes and made["episodes"] % config.eval_every == 0
    assert config.episodes == made.get("episodes_per_seed", config.episodes)
    for name in ("features", "normalisation_episodes", "validation_episodes"):
        assert getattr(config, name) == made[name], name
    for name in ("futures", "horizon", "states_per_episode", "ridge", "selection_episodes"):
        assert getattr(config.dpi, name) == made[name], name
    assert list(config.dpi.bases) == made["bases"] and config.dpi.failure_cost == made.get("failure_cost", 0.0)


@pytest.mark.parametrize("task", SHIPPED[:2])
def test_a_recipe_written_reads_back_to_the_same_run(task):
    config = dpi_recipe.recipe(task)
    import yaml

    assert dpi_recipe.parse(yaml.safe_load(dpi_recipe.dump(config, "a comment")), task, "here") == config


@pytest.mark.parametrize(
    "change, message",
    [
        ({"ridg": 0.01}, "unknown key 'ridg'; known: bases, episodes,"),
        ({"ridge": -1.0}, "ridge must be >= 0, got -1.0"),
        ({"features": "colours"}, "colours"),
        ({"seeds": [0, 0]}, "seeds must be distinct"),
    ],
)
def test_a_bad_recipe_is_one_line_naming_the_file(tmp_path, change, message):
    task = "cart_pendulum/kicks"
    document = dpi_recipe.to_document(dpi_recipe.recipe(task))
    (entry,) = document.values()
    entry.update(change)
    path = tmp_path / "dpi.yml"
    import yaml

    path.write_text(yaml.safe_dump(document))
    with pytest.raises(HyperparameterError, match=f"^{path}: .*") as caught:
        dpi_recipe.load(path, task)
    assert message in str(caught.value) and "\n" not in str(caught.value)


def test_a_recipe_missing_a_key_or_another_tasks_is_refused(tmp_path):
    document = dpi_recipe.to_document(dpi_recipe.recipe("cart_pendulum/kicks"))
    (entry,) = document.values()
    del entry["ridge"]
    with pytest.raises(HyperparameterError, match="ridge is missing"):
        dpi_recipe.parse(document, "cart_pendulum/kicks", "dpi.yml")
    with pytest.raises(HyperparameterError, match="no mapping for etmpc/cart_pendulum-balance"):
        dpi_recipe.parse(document, "cart_pendulum/balance", "dpi.yml")


def test_a_variant_without_its_own_recipe_takes_its_worlds_and_a_task_without_any_dpis_defaults(monkeypatch):
    real = dpi_recipe.shipped_path
    monkeypatch.setattr(dpi_recipe, "shipped_path", lambda t: Path("/nowhere") if t.endswith("_noisy") else real(t))
    variant = dpi_recipe.recipe("cart_pendulum/kicks_noisy")
    assert variant == replace(dpi_recipe.recipe("cart_pendulum/kicks"), domain="cart_pendulum/kicks_noisy")
    monkeypatch.setattr(dpi_recipe, "shipped_path", lambda t: Path("/nowhere"))
    default = dpi_recipe.recipe("cart_pendulum/kicks")
    assert (default.seeds, default.episodes, default.eval_every) == (
        dpi_recipe.DEFAULT_SEEDS,
        dpi_recipe.DEFAULT_EPISODES,
        dpi_recipe.DEFAULT_EVAL_EVERY,
    )


def test_reproduce_trains_the_recipe_at_full_size_and_its_own_sizes_when_quick():
    task = "cart_pendulum/kicks_late"
    recipe = dpi_recipe.recipe(task)
    full = FULL.dpi(recipe, lambda h: h)
    assert full == replace(recipe, eval_episodes=FULL.eval_episodes)  # the shipped run, but its learning curve's episodes
    quick = QUICK.dpi(recipe, lambda h: min(h, 7))
    assert (quick.seeds, quick.episodes, quick.eval_every) == (QUICK.dpi_seeds, QUICK.dpi_episodes, QUICK.dpi_eval_every)
    assert (quick.dpi.futures, quick.dpi.horizon, quick.dpi.states_per_episode) == (QUICK.dpi_futures, 7, QUICK.dpi_labels)
    assert quick.dpi.bases == recipe.dpi.bases and quick.features == recipe.features  # what quick does not size
