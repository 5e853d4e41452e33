"""One id per task, the same string (or its mechanical Gymnasium form) on every surface: the registry, the
command line, the Gymnasium registry, dm-control's suite, the folders under tasks/ and policies/, the stored
references, the score cards and the leaderboard. The older names still work, with one deprecation line."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import pytest

from etmpc import suite
from etmpc.cli import main
from etmpc.systems import TaskNameDeprecation, domains, spec, specs

REPO = Path(__file__).resolve().parents[2]
IDS = [s.id for s in specs()]


def test_each_spec_derives_every_name_from_its_domain_and_task():
    for s in specs():
        assert s.id == f"{s.domain}/{s.task}" and s.folder == s.id and s.slug == s.id.replace("/", "-")
        assert s.gym_id == f"etmpc/{s.slug}-v{s.version}"
        assert spec(s.id) is not None and spec(s.id).id == s.id
        assert s.default == (s.task == domains()[s.domain].TASKS[0])
        if s.default:  # the domain alone names its first task
            assert spec(s.domain) == s


@pytest.mark.parametrize("task", IDS)
def test_the_system_the_suite_and_gymnasium_know_the_task_by_its_id(task):
    import gymnasium

    import etmpc  # noqa: F401  (registers the environments)

    s = spec(task)
    assert s.system_class.name == task  # a System names itself by the id
    assert (s.domain, s.task) in suite.ALL_TASKS  # dm-control's suite: the id's two parts
    registered = gymnasium.spec(s.gym_id)
    assert spec(registered.kwargs["task"]).id == task


def test_the_command_line_lists_the_ids(capsys):
    with pytest.raises(SystemExit):
        main(["evaluate", "--help"])
    help_text = " ".join(capsys.readouterr().out.split())
    for task in IDS:
        assert task in help_text


def test_the_folders_of_the_stored_data_are_the_ids():
    for root, required in (("tasks", ("testset.npz", "testset.npz.sha256", "references.json")), ("policies", ())):
        folders = {p.parent.relative_to(REPO / root).as_posix() for p in (REPO / root).glob("*/*/*")}
        assert folders <= set(IDS), f"{root}/ has folders that are no task's: {sorted(folders - set(IDS))}"
        for task in IDS if root == "tasks" else folders:
            for name in required:
                assert (REPO / root / task / name).is_file(), f"{root}/{task}/{name}"
    assert not [p for p in (REPO / "tasks").glob("*/*") if p.is_file()], "a flat file beside the task folders"


def test_stored_references_cards_and_the_leaderboard_name_tasks_by_id():
    for task in IDS:
        assert json.loads((REPO / "tasks" / task / "references.json").read_text())["task"] == task
    card = json.loads((REPO / "docs" / "results" / "quadrotor.json").read_text())
    assert {row["task"] for row in card["rows"]} == {"quadrotor/waypoints"} and card["tasks"] == ["quadrotor/waypoints"]
    board = json.loads((REPO / "docs" / "leaderboard.json").read_text())
    named = {row["task"] for entry in board["entries"] for row in entry["rows"]}
    assert named == set(IDS)
    kept = {
        p.relative_to(REPO / "results" / "leaderboard").as_posix() for p in (REPO / "results" / "leaderboard").glob("*/*/*.json")
    }
    assert {k.split("/", 1)[1].removesuffix(".json").removesuffix(".choice") for k in kept} == set(IDS)


def test_an_older_name_works_with_one_deprecation_warning():
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert spec("cart_pendulum-kicks").id == "cart_pendulum/kicks"
    assert [w.category for w in caught] == [TaskNameDeprecation]
    assert "say 'cart_pendulum/kicks'" in str(caught[0].message)


def test_the_older_positional_task_is_taken_with_one_deprecation_line(capsys):
    assert main(["testset", "--task", "battery", "battery", "--seed", "1", "--out", "x.npz"]) == 2
    assert "give the task once" in capsys.readouterr().err
    assert main(["discriminate"]) == 2  # no task at all: the one-line error says what to add
    assert capsys.readouterr().err == "etmpc: error: etmpc discriminate needs --task TASK\n"


def test_the_older_positional_form_plays_the_same_as_the_new(tmp_path, capsys):
    new, old = tmp_path / "new.npz", tmp_path / "old.npz"
    assert main(["testset", "--task", "battery", "--seed", "3", "--episodes", "2", "--out", str(new)]) == 0
    capsys.readouterr()
    assert main(["testset", "battery", "--seed", "3", "--episodes", "2", "--out", str(old)]) == 0
    err = capsys.readouterr().err.splitlines()
    assert err == ["etmpc: warning: 'etmpc testset battery' is deprecated: say 'etmpc testset --task battery'"]
    assert new.read_bytes() == old.read_bytes()
