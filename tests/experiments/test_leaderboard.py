"""The generated leaderboard: its references score 0 and 100, every row says what it cost, an interrupted
run continues without playing again, and the README's table is the page's, generated from its JSON."""

from __future__ import annotations

import json

import pytest

from etmpc.experiments import leaderboard_rows
from etmpc.experiments.leaderboard import BEGIN, END, build, headline, table_in
from etmpc.systems import names as suite_tasks

from tests.conftest import REPO


@pytest.fixture(scope="module")
def board(tmp_path_factory):
    out = tmp_path_factory.mktemp("board")
    readme = out / "README.md"
    readme.write_text(f"# etmpc\n\n{BEGIN}\n(the table goes here)\n{END}\n\nthe rest\n")
    data = build(out / "docs", out / "work", ["battery"], episodes=2, workers=1, readme=readme)
    return out, data


def test_the_references_score_0_and_100_and_every_row_says_what_it_cost(board):
    _, data = board
    rows = {e["name"]: e["rows"][0] for e in data["entries"]}
    learners = leaderboard_rows.shipped_learners()
    shipped = {name for name, file, _, _ in learners if leaderboard_rows.shipped_policy("battery", file)}
    assert "DPI (shipped)" in shipped
    assert set(rows) == {"always", "best periodic", "best threshold", "rollout meter", "oracle"} | shipped
    assert rows["best periodic"]["score"] == 0.0 and rows["oracle"]["score"] == 100.0
    assert all(r["error"] is None and r["cpu_ms"]["total"] > 0 for r in rows.values())
    assert rows["rollout meter"]["cpu_ms"]["decide"] > rows["best periodic"]["cpu_ms"]["decide"]  # its net cost shows
    assert data["generated"]["commit"] and data["generated"]["software"]["etmpc"]


def test_the_page_and_the_readme_hold_the_table_made_from_the_json(board):
    out, data = board
    table = headline(json.loads((out / "docs" / "leaderboard.json").read_text()))
    assert table == headline(data)
    assert table_in((out / "docs" / "leaderboard.md").read_text()) == table
    text = (out / "README.md").read_text()
    assert table_in(text) == table and text.endswith("the rest\n")
    assert (out / "docs" / "leaderboard_profile.png").read_bytes()[:4] == b"\x89PNG"


def test_an_interrupted_run_continues_without_playing_a_finished_row_again(board, monkeypatch):
    out, data = board

    def no_play(*args, **kwargs):
        raise AssertionError("played again")

    monkeypatch.setattr(leaderboard_rows, "play_and_score", no_play)
    monkeypatch.setattr(leaderboard_rows, "best_threshold", no_play)  # its choice is kept too
    again = build(out / "again", out / "work", ["battery"], episodes=2, workers=1)
    assert headline(again) == headline(data)


@pytest.mark.parametrize("kind", ["oracle", "rollout meter"])
def test_the_costliest_rows_come_from_references_that_kept_their_runs_and_are_the_played_ones(kind, monkeypatch, tmp_path):
    """References that kept the oracle's or the rollout meter's evaluation give its row without playing it again,
    the same row as playing it gives (that the stored evaluations are what playing gives:
    tests/evaluation/test_scorecard.py)."""
    from dataclasses import replace

    from etmpc.evaluation.evaluate import evaluate
    from etmpc.evaluation.references import rollout_meter_spec, stored
    from etmpc.systems import make_system

    refs = replace(stored("cart_pendulum").head(2), oracle_evaluation=None, rollout_evaluation=None)
    spec = refs.oracle_spec if kind == "oracle" else rollout_meter_spec(make_system("cart_pendulum"), refs.best)
    played = evaluate("cart_pendulum", [spec], episodes=2, workers=1, progress=False)
    expected = leaderboard_rows.play_and_score("cart_pendulum", refs, spec, workers=1, progress=False)

    def no_play(*args, **kwargs):
        raise AssertionError("played again")

    monkeypatch.setattr(leaderboard_rows, "play_and_score", no_play)
    entry = leaderboard_rows.Entry(kind, "bound", {"cart_pendulum": spec})
    field = "oracle_evaluation" if kind == "oracle" else "rollout_evaluation"
    kept = replace(refs, **{field: played.to_json(cpu=True)})
    row, _ = leaderboard_rows._row(entry, "cart_pendulum", kept, tmp_path, 2, 1, lambda line: None)
    assert row.episode_scores == expected.episode_scores and (kind != "oracle" or row.score == 100.0)
    assert (row.objective_mean, row.recomputes_mean, row.solver_failures, row.failures_mean) == (
        expected.objective_mean,
        expected.recomputes_mean,
        expected.solver_failures,
        expected.failures_mean,
    )
    assert getattr(kept.head(1), field) is None  # a part of the test set: its row is played
    other = replace(entry, specs={"cart_pendulum": spec.replace(refs.best, "every:2")})
    with pytest.raises(AssertionError, match="played again"):  # a row of another spec is not taken from them
        leaderboard_rows._row(other, "cart_pendulum", kept, tmp_path / "other", 2, 1, lambda line: None)


def test_the_best_threshold_is_chosen_once_and_chosen_again_when_its_task_changes(board, monkeypatch, tmp_path):
    import shutil

    from etmpc.common.errors import EtmpcError

    out, data = board
    work = tmp_path / "work"
    shutil.copytree(out / "work", work)
    path = work / "best-threshold" / "battery" / "trading.choice.json"
    chosen = data["entries"][2]["specs"]["battery/trading"]
    assert json.loads(path.read_text())["chosen"] == chosen
    monkeypatch.setattr(leaderboard_rows, "best_threshold", lambda *a: pytest.fail("chosen again"))
    assert leaderboard_rows.kept_threshold("battery", work, 1, lambda line: None) == chosen
    calls = []
    monkeypatch.setattr(leaderboard_rows, "best_threshold", lambda task, workers, say: calls.append(task) or "threshold:0.01")
    monkeypatch.setattr(leaderboard_rows, "task_version", lambda task: 99)  # the task changed: its choice does not stand
    assert leaderboard_rows.kept_threshold("battery", work, 1, lambda line: None) == "threshold:0.01" and calls == ["battery"]
    edited = json.loads(path.read_text())
    edited["chosen"] = "threshold:0.02"  # by hand: refused, never used
    path.write_text(json.dumps(edited))
    with pytest.raises(EtmpcError, match="kept leaderboard row"):
        leaderboard_rows.kept_threshold("battery", work, 1, lambda line: None)


def test_the_readmes_headline_table_is_the_generated_leaderboards():
    generated = json.loads((REPO / "docs" / "leaderboard.json").read_text())
    table = headline(generated)
    assert table_in((REPO / "README.md").read_text()) == table
    assert table_in((REPO / "docs" / "leaderboard.md").read_text()) == table
    names = [e["name"] for e in generated["entries"]]
    assert generated["episodes"] == 100 and generated["tasks"] == list(suite_tasks()) and "DPI (shipped)" in names


def test_a_row_is_played_again_when_the_policy_file_behind_its_spec_changed(tmp_path, monkeypatch):
    # A shipped policy retrained in place keeps its path, so its spec; its finished row must not stand.
    policy = tmp_path / "policies" / "cart_pendulum" / "learned.json"
    policy.parent.mkdir(parents=True)
    policy.write_bytes((REPO / "policies" / "cart_pendulum" / "balance" / "learned.json").read_bytes())
    entry = leaderboard_rows.Entry("DPI (shipped)", "learned", {"cart_pendulum": f"rl:{policy}"})
    from etmpc.evaluation.references import stored

    refs = stored("cart_pendulum")
    played = []
    real = leaderboard_rows.play_and_score
    monkeypatch.setattr(leaderboard_rows, "play_and_score", lambda *a, **k: played.append(a[2]) or real(*a, **k))
    first, _ = leaderboard_rows._row(entry, "cart_pendulum", refs, tmp_path / "work", 1, 1, lambda line: None)
    again, _ = leaderboard_rows._row(entry, "cart_pendulum", refs, tmp_path / "work", 1, 1, lambda line: None)
    assert len(played) == 1 and again == first  # unchanged: kept
    data = json.loads(policy.read_text())
    data["theta"] = [0.0] * (len(data["theta"]) - 1) + [5.0]  # keeps every plan it may
    policy.write_text(json.dumps(data))
    changed, _ = leaderboard_rows._row(entry, "cart_pendulum", refs, tmp_path / "work", 1, 1, lambda line: None)
    assert len(played) == 2 and changed.episode_scores != first.episode_scores


def test_a_verified_card_joins_as_a_row_and_a_forged_one_is_refused_before_any_row(board, monkeypatch, tmp_path):
    from etmpc.cli import main
    from etmpc.common.errors import EtmpcError

    out, data = board
    card = tmp_path / "card.json"
    assert (
        main(["score", "--policy", "every:2", "--task", "battery", "--episodes", "2", "--workers", "1", "--json", str(card)]) == 0
    )
    monkeypatch.setattr(leaderboard_rows, "play_and_score", lambda *a, **k: pytest.fail("a row was played"))
    monkeypatch.setattr(leaderboard_rows, "best_threshold", lambda task, workers, say: data["entries"][2]["specs"][task])
    joined = build(tmp_path / "docs", out / "work", ["battery"], episodes=2, workers=1, cards=[card])
    entry = next(e for e in joined["entries"] if e["name"] == "every:2 (submitted)")
    assert entry["kind"] == "submitted" and entry["specs"] == {"battery/trading": "every:2"}
    assert entry["rows"][0]["episode_scores"] == json.loads(card.read_text())["rows"][0]["episode_scores"]
    forged = json.loads(card.read_text())
    forged["rows"][0]["score"] += 10.0
    (tmp_path / "forged.json").write_text(json.dumps(forged))
    with pytest.raises(EtmpcError, match="does not verify"):
        build(tmp_path / "docs", out / "work", ["battery"], episodes=2, workers=1, cards=[tmp_path / "forged.json"])


def _failures_cell(page_text: str, name: str) -> str:
    """The failures cell of entry ``name``'s row in the page's first per-task table."""
    line = next(line for line in page_text.split("## Per task")[1].splitlines() if line.startswith(f"| {name} | "))
    return line.split(" | ")[4]


def test_a_row_timed_on_the_wall_clock_is_played_again(board, tmp_path):
    from etmpc.common.documents import SEAL, sealed

    out, _ = board
    (kept,) = (out / "work" / "always").glob("*/*.json")
    current = json.loads(kept.read_text())
    assert current["key"]["cpu_clock"] == "thread_time" and leaderboard_rows._kept(kept, current["key"]) is not None
    wall = {k: v for k, v in current.items() if k != SEAL}
    wall["key"] = {k: v for k, v in current["key"].items() if k != "cpu_clock"}  # as an etmpc that timed the wall kept it
    (tmp_path / "wall.json").write_text(json.dumps(sealed(wall)))
    assert leaderboard_rows._kept(tmp_path / "wall.json", current["key"]) is None


def test_the_failures_column_is_mean_and_ci_and_an_older_row_or_page_without_them_still_works(board, tmp_path):
    import copy

    from etmpc.common.documents import SEAL, sealed
    from etmpc.experiments.leaderboard_page import page

    out, data = board
    always = next(e for e in data["entries"] if e["name"] == "always")["rows"][0]
    assert always["episode_failures"] == [0, 0] and always["failures_ci95"] == 0.0  # a plan every step is never cut
    assert _failures_cell(page(data), "always") == "0.00 ± 0.00 (0 ep.)" and "Failures (curtailed): per episode" in page(data)
    crashed = copy.deepcopy(data)  # one episode with many failing steps, one with none
    row = next(e for e in crashed["entries"] if e["name"] == "always")["rows"][0]
    row.update(episode_failures=[0, 7], failures_mean=3.5, failures_ci95=6.86)
    assert _failures_cell(page(crashed), "always") == "3.50 ± 6.86 (1 ep.)"
    # A row kept by an etmpc that counted no failures is played again; the row kept now is kept.
    (kept,) = (out / "work" / "always").glob("*/*.json")
    current = json.loads(kept.read_text())
    assert current["key"]["failures"] == "curtailed"
    assert leaderboard_rows._kept(kept, current["key"]) is not None
    older = {k: v for k, v in current.items() if k != SEAL}
    older["key"] = {k: v for k, v in current["key"].items() if k != "failures"}
    older["row"] = {k: v for k, v in current["row"].items() if k not in ("failures_ci95", "episode_failures")}
    (tmp_path / "older.json").write_text(json.dumps(sealed(older)))
    assert leaderboard_rows._kept(tmp_path / "older.json", current["key"]) is None
    # A page made from an older JSON (rows without the CI, references without failure names) shows the mean alone.
    data = copy.deepcopy(data)
    for entry in data["entries"]:
        entry["rows"] = [{k: v for k, v in r.items() if k not in ("failures_ci95", "episode_failures")} for r in entry["rows"]]
    for ref in data["references"].values():
        del ref["failure_name"]
    assert _failures_cell(page(data), "always") == "0.00" and "Failures (" not in page(data)
    for entry in data["entries"]:  # rows of an etmpc that counted no failures on the task
        entry["rows"] = [dict(r, failures_mean=None) for r in entry["rows"]]
    assert _failures_cell(page(data), "always") == "-"
    stored = page(json.loads((REPO / "docs" / "leaderboard.json").read_text()))  # the stored page's JSON, as it is
    assert _failures_cell(stored, "always") == "0.00 ± 0.00 (0 ep.)"  # cart_pendulum: a plan every step keeps the pole up


def test_each_shipped_learner_has_a_shielded_row_on_the_tasks_that_declare_a_shield(monkeypatch):
    from etmpc.evaluation.references import stored
    from etmpc.systems import make_system

    monkeypatch.setattr(leaderboard_rows, "kept_threshold", lambda task, work, workers, say: "threshold:1")
    tasks = ["cart_pendulum/kicks", "quadrotor/waypoints", "battery/trading"]
    board = {e.name: e for e in leaderboard_rows.entries(tasks, {t: stored(t) for t in tasks}, 1, print)}
    for name, file, prefix, _ in leaderboard_rows.shipped_learners():
        for task in tasks:
            path, rule = leaderboard_rows.shipped_policy(task, file), make_system(task).shield
            shielded = board.get(name + leaderboard_rows.SHIELDED)
            if path is None or rule is None:  # the battery counts no safety failures: no shield, no row
                assert shielded is None or task not in shielded.specs
                continue
            assert board[name].specs[task] == f"{prefix}{path}"
            assert shielded.specs[task] == f"shield:{rule.text}:{prefix}{path}" and shielded.kind == "learned"
    assert "DPI (shipped) + shield" in board and "DPI (shipped) + shield" in leaderboard_rows.row_names()


def test_no_page_file_lands_on_the_readme_it_edits_though_the_readme_may_lie_beside_them(tmp_path):
    from etmpc.common.errors import EtmpcError
    from etmpc.experiments.leaderboard import PAGE, check_files

    (tmp_path / "docs").mkdir()
    for name in ("README.md", *PAGE):
        (tmp_path / "docs" / name).write_text(f"# mine\n\n{BEGIN}\n{END}\n")
    check_files(tmp_path / "docs", tmp_path / "work", tmp_path / "docs" / "README.md")
    for name in PAGE:
        with pytest.raises(EtmpcError, match=f"would write over the --readme it edits .*{name}"):
            check_files(tmp_path / "docs", tmp_path / "work", tmp_path / "docs" / name)
