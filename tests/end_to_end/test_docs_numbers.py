"""Every number the README and the docs quote by hand is under a marker naming the results file or the module of
etmpc it comes from, and agrees with it (scripts/doc_numbers.py; `python scripts/doc_numbers.py --write` rewrites them)."""

from __future__ import annotations

import importlib.util
import json
import re
import sys

import pytest

from tests.conftest import REPO

_spec = importlib.util.spec_from_file_location("doc_numbers", REPO / "scripts" / "doc_numbers.py")
doc_numbers = importlib.util.module_from_spec(_spec)
sys.modules["doc_numbers"] = doc_numbers  # its dataclass looks its module up
_spec.loader.exec_module(doc_numbers)


def test_every_marked_number_in_the_readme_and_the_docs_is_its_sources():
    problems = doc_numbers.check(doc_numbers.pages())
    assert problems == [], "\n" + "\n".join(problems) + "\n(python scripts/doc_numbers.py --write rewrites them)"


def test_the_docs_quote_numbers_from_the_results_files():
    found = [n for page in doc_numbers.pages() for n in doc_numbers.numbers(page)]
    assert len(found) > 20
    files = {n.source for n in found if not n.python}
    assert files <= {
        str(p.relative_to(REPO))
        for p in [
            REPO / "docs" / "leaderboard.json",
            *REPO.glob("docs/results/*.json"),  # cards and pages made by etmpc's commands (etmpc score --json, ...)
            *REPO.glob("tasks/*/*/references.json"),
            *REPO.glob("policies/*/*.json"),
        ]
    }
    # and the code's own numbers from its modules (a task's Config, its task module's constants)
    assert all(n.source == "etmpc" or n.source.startswith("etmpc.") for n in found if n.python)


def test_no_page_calls_the_100_point_reference_a_bound_that_knows_the_future():
    for page in doc_numbers.pages():
        text = page.read_text()
        assert not re.search(r"bound that knows|oracle that knows", text), page


def test_score_help_names_the_leaderboards_rows(capsys):
    from etmpc.cli import main
    from etmpc.experiments import leaderboard_rows

    with pytest.raises(SystemExit):
        main(["score", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert all(name in text for name in leaderboard_rows.row_names()) and "GPOMDP (shipped)" in text and "PPO (shipped)" in text


# -- the checker itself, on a small fake page --------------------------------------------------------
@pytest.fixture
def fake(tmp_path):
    (tmp_path / "r.json").write_text(
        json.dumps(
            {
                "entries": [
                    {
                        "name": "DPI (shipped)",
                        "rows": [{"task": "battery", "score": 32.0616, "objective": 0.89278, "share": 0.77}],
                    },
                    {"name": "best periodic", "rows": [{"task": "battery", "score": 0.0, "objective": 0.80173}]},
                ]
            }
        )
    )
    dpi = "r.json entries[name=DPI (shipped)].rows[task=battery]"
    page = tmp_path / "page.md"
    page.write_text(
        "# A page\n\n"
        f"DPI scores <!-- number: {dpi}.score | .1f -->32.1<!-- /number --> on the battery,\n"
        f"a gain of <!-- number: {dpi}.objective | +.2% | vs=entries[name=best periodic].rows[task=battery].objective -->"
        f"+11.36 %<!-- /number --> (wrongly: <!-- number: r.json entries[1].rows[0].objective | .5f -->0.80173"
        f"<!-- /number -->), better in <!-- number: {dpi}.share | .0f | scale=100 -->77<!-- /number --> episodes.\n"
    )
    return tmp_path, page


def test_the_checker_passes_a_page_that_agrees(fake):
    root, page = fake
    assert doc_numbers.check([page], root) == []
    assert [n.line for n in doc_numbers.numbers(page)] == [3, 4, 4, 4]


def test_the_checker_fails_on_an_edited_number_naming_page_line_key_and_both_values(fake):
    root, page = fake
    page.write_text(page.read_text().replace("-->32.1<", "-->33.1<").replace("-->+11.36 %<", "-->+11.08 %<"))
    problems = doc_numbers.check([page], root)
    assert len(problems) == 2
    assert f"{page}:3" in problems[0] and "rows[task=battery].score" in problems[0]
    assert "'32.1'" in problems[0] and "'33.1'" in problems[0]
    assert f"{page}:4" in problems[1] and "'+11.36 %'" in problems[1] and "'+11.08 %'" in problems[1]


def test_the_checker_fails_on_a_key_its_source_does_not_have(fake):
    root, page = fake
    page.write_text(page.read_text().replace("[task=battery].score", "[task=reacher].score"))
    (problem,) = doc_numbers.check([page], root)
    assert "cannot be read" in problem and "0 items with task='reacher'" in problem


def test_a_ratio_to_another_key_is_the_value_over_its_size(fake):
    root, page = fake
    rows = "entries[name=best periodic].rows[task=battery]", "entries[name=DPI (shipped)].rows[task=battery]"
    gap = f"r.json {rows[0]}.objective | .2% | per={rows[1]}.objective"
    page.write_text(f"<!-- number: {gap} -->89.80 %<!-- /number -->\n")  # 0.80173 / 0.89278, by hand
    assert doc_numbers.check([page], root) == []
    page.write_text(f"<!-- number: {gap} -->89.81 %<!-- /number -->\n")
    assert len(doc_numbers.check([page], root)) == 1


def test_write_rewrites_every_marked_number_from_its_source(fake):
    root, page = fake
    right = page.read_text()
    page.write_text(right.replace("-->32.1<", "-->9<").replace("-->77<", "-->70<"))
    assert doc_numbers.write([page], root) == [page]
    assert page.read_text() == right
    assert doc_numbers.write([page], root) == []


# -- a number the code holds: MODULE:ATTRIBUTE ------------------------------------------------------
def test_a_module_source_reads_a_dataclass_fields_default_its_property_an_item_and_a_constant(tmp_path):
    from etmpc.systems.battery.parameters import Battery
    from etmpc.systems.cart_pendulum import kicks_system
    from etmpc.systems.quadrotor import TEST_SET_SEEDS as seeds
    from etmpc.systems.quadrotor import system, task

    config = system.Config()
    quad = "etmpc.systems.quadrotor.system:Config"
    page = tmp_path / "page.md"
    page.write_text(
        f"angles <!-- number: {quad}.angle_weight | g -->{config.angle_weight:g}<!-- /number -->,\n"
        f"rates in Q <!-- number: {quad}.feedback_state_weights[9] | g -->{config.feedback_state_weights[9]:g}<!-- /number -->"
        f" (of <!-- number: {quad}.feedback_state_weights[-1] | g -->{config.feedback_state_weights[-1]:g}<!-- /number -->),"
        f" at most <!-- number: {quad}.solver.max_iterations | d -->{config.solver.max_iterations:d}<!-- /number --> QPs,\n"
        f"step <!-- number: {quad}.solver.step_tolerance | .1% -->{config.solver.step_tolerance * 100:.1f} %<!-- /number -->,"
        f" terminal <!-- number: {quad}.terminal_angle_weight | .2f | per=Config.angle_weight -->"
        f"{config.terminal_angle_weight / config.angle_weight:.2f}<!-- /number --> of it, over"
        f" <!-- number: {quad}.horizon | g | times=QuadrotorSystem.control_interval_s -->"
        f"{config.horizon * system.QuadrotorSystem.control_interval_s:g}<!-- /number --> s;\n"
        # a constant of a task module, an item of a numpy array
        f"z from <!-- number: etmpc.systems.quadrotor.task:BOX_LOW[2] | g -->{task.BOX_LOW[2]:g}<!-- /number --> m;\n"
        # a field whose default is a default_factory's; a dict's item
        f"kicks: <!-- number: etmpc.systems.cart_pendulum.kicks_system:Config.solver.max_iterations | d -->"
        f"{kicks_system.Config().solver.max_iterations:d}<!-- /number --> iterations, seed"
        f" <!-- number: etmpc.systems.quadrotor:TEST_SET_SEEDS[waypoints] | d -->{seeds['waypoints']}<!-- /number -->\n"
        # a dataclass's property, off its class: the default instance's
        f"<!-- number: etmpc.systems.battery.parameters:Battery.trade_limit_kw | g -->"
        f"{Battery().trade_limit_kw:g}<!-- /number --> kW\n"
    )
    assert doc_numbers.check([page], tmp_path) == []
    found = doc_numbers.numbers(page)
    assert [n.line for n in found] == [1, 2, 2, 2, 3, 3, 3, 4, 5, 5, 6] and all(n.python for n in found)
    assert found[0].source == "etmpc.systems.quadrotor.system" and found[0].key == "Config.angle_weight"


def test_a_marker_in_a_tables_row_separates_its_options_by_an_escaped_bar(tmp_path):
    from etmpc.systems.quadrotor.system import Config

    page = tmp_path / "page.md"
    row = "| quadrotor | <!-- number: etmpc.systems.quadrotor.system:Config.recompute_price \\| .2f -->{:.2f}<!-- /number --> |\n"
    page.write_text("| task | price |\n|---|---|\n" + row.format(Config.recompute_price))
    (number,) = doc_numbers.numbers(page)
    assert number.options == {"fmt": ".2f"} and doc_numbers.check([page], tmp_path) == []
    page.write_text("| task | price |\n|---|---|\n" + row.format(Config.recompute_price + 1))
    assert doc_numbers.write([page], tmp_path) == [page]
    assert page.read_text().endswith(row.format(Config.recompute_price))


def test_the_checker_names_a_module_sources_number_that_disagrees_with_the_code(tmp_path):
    from etmpc.systems.quadrotor.system import Config

    page = tmp_path / "page.md"
    right = f"<!-- number: etmpc.systems.quadrotor.system:Config.angle_weight | g -->{Config.angle_weight:g}<!-- /number -->\n"
    page.write_text("# A page\n\n" + right.replace(f"-->{Config.angle_weight:g}<", "-->0.25<"))
    (problem,) = doc_numbers.check([page], tmp_path)
    assert f"{page}:3" in problem and "etmpc.systems.quadrotor.system:Config.angle_weight" in problem
    assert f"is '{Config.angle_weight:g}'" in problem and "'0.25'" in problem
    assert doc_numbers.write([page], tmp_path) == [page] and page.read_text() == "# A page\n\n" + right


def test_a_module_source_that_does_not_hold_the_key_cannot_be_read(tmp_path):
    page = tmp_path / "page.md"
    for spec, why in [
        ("etmpc.systems.quadrotor.system:Config.no_such_weight", "no 'no_such_weight'"),
        ("etmpc.systems.quadrotor.system:Config.feedback_state_weights[12]", "index out of range"),
        ("etmpc.systems.quadrotor.system:Config.feedback_state_weights[name=x]", "indexed by a number"),
        ("etmpc.systems.quadrotor:TEST_SET_SEEDS[hover]", "no item 'hover'"),
        ("etmpc.systems.quadrotor.system:Config.__init__", "dunder"),
        ("etmpc.systems.no_such_module:Config.horizon", "No module named"),
    ]:
        page.write_text(f"<!-- number: {spec} | g -->1<!-- /number -->\n")
        (problem,) = doc_numbers.check([page], tmp_path)
        assert "cannot be read" in problem and why in problem, problem


def test_a_module_outside_etmpc_is_refused_and_never_imported(tmp_path, monkeypatch):
    (tmp_path / "evil_numbers.py").write_text("import pathlib\npathlib.Path(__file__).with_name('ran').touch()\nX = 1\n")
    (tmp_path / "etmpc_evil.py").write_text("import pathlib\npathlib.Path(__file__).with_name('ran').touch()\nX = 1\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    page = tmp_path / "page.md"
    for name in ("evil_numbers", "etmpc_evil", "os.path", "etmpc..systems", "etmpc.systems/x"):
        page.write_text(f"<!-- number: {name}:X | g -->1<!-- /number -->\n")
        (problem,) = doc_numbers.check([page], tmp_path)
        assert "must be etmpc's" in problem, problem
        with pytest.raises(ValueError, match="must be etmpc's"):
            doc_numbers.write([page], tmp_path)
        with pytest.raises(ValueError, match="not a module of etmpc"):
            doc_numbers.module(name, tmp_path)
    assert not (tmp_path / "ran").exists() and "evil_numbers" not in sys.modules and "etmpc_evil" not in sys.modules


def test_a_module_source_is_read_from_the_checked_repositorys_own_etmpc(tmp_path):
    """A worktree's check reads its own code: an etmpc imported from elsewhere cannot be read."""
    from etmpc.systems.quadrotor.system import Config

    (tmp_path / "etmpc").mkdir()
    page = tmp_path / "page.md"
    page.write_text(f"<!-- number: etmpc.systems.quadrotor.system:Config.horizon | d -->{Config.horizon}<!-- /number -->\n")
    (problem,) = doc_numbers.check([page], tmp_path)
    assert "cannot be read" in problem and f"not from {tmp_path.resolve() / 'etmpc'}" in problem
    assert doc_numbers.check([page], REPO) == []


# -- a text the registry holds: <!-- generated: MODULE:FUNCTION --> -------------------------------------
def test_the_generated_task_lists_are_the_registrys():
    """The texts the pages are generated from, against the registry and Gymnasium's own registry."""
    import gymnasium

    from etmpc.systems import catalogue, registry

    own = [spec for spec in registry.specs() if spec.domain in registry.BUILT_IN]
    rows = catalogue.gym_ids_table().splitlines()[2:]
    assert len(rows) == len(own)
    for spec, row in zip(own, rows):
        cells = [cell.strip(" `") for cell in row.strip("|").split("|")]
        assert cells[:2] == [spec.id, spec.gym_id]
        steps = gymnasium.spec(spec.gym_id).max_episode_steps  # what gym.make's TimeLimit ends the episode at
        assert cells[2].startswith(f"{steps} steps")
    assert catalogue.task_ids() == ", ".join(f"`{name}`" for name in registry.names() if name.split("/")[0] in registry.BUILT_IN)
    assert catalogue.domain_names() == ", ".join(f"`{name}`" for name in registry.BUILT_IN)


def test_a_page_that_lists_tasks_by_hand_fails_and_write_generates_it(tmp_path):
    from etmpc.systems import catalogue

    count = "<!-- generated: etmpc.systems.catalogue:task_count -->{}<!-- /generated -->"
    table = "<!-- generated: etmpc.systems.catalogue:gym_ids_table -->\n\n{}\n\n<!-- /generated -->"
    page = tmp_path / "page.md"
    right = f"The suite has {count.format(catalogue.task_count())} tasks:\n\n{table.format(catalogue.gym_ids_table())}\n"
    page.write_text(right)
    assert doc_numbers.check([page], tmp_path) == []
    stale = right.replace("-v2`", "-v0`").replace(f"-->{catalogue.task_count()}<", "-->five<")
    page.write_text(stale)
    problems = doc_numbers.check([page], tmp_path)
    assert len(problems) == 2 and f"{page}:1" in problems[0] and "'five'" in problems[0]
    assert f"{page}:3" in problems[1] and "gym_ids_table" in problems[1]
    assert doc_numbers.write([page], tmp_path) == [page] and page.read_text() == right


def test_a_generated_text_names_a_function_of_etmpc(tmp_path):
    page = tmp_path / "page.md"
    page.write_text("<!-- generated: etmpc.systems.catalogue:_WORDS -->x<!-- /generated -->\n")
    (problem,) = doc_numbers.check([page], tmp_path)
    assert "not a function" in problem
    page.write_text("<!-- generated: os:getcwd -->x<!-- /generated -->\n")
    (problem,) = doc_numbers.check([page], tmp_path)
    assert "must be etmpc's" in problem


def test_no_marker_starts_a_line_of_the_readmes_text():
    """GitHub shows the README as it is: an HTML comment that starts a line ends the paragraph it is in (the
    site drops the markers, docs/hooks.py). A generated table's markers stand on lines of their own."""
    for number, line in enumerate((REPO / "README.md").read_text().splitlines(), 1):
        if line.startswith(("<!-- number:", "<!-- generated:")):
            assert re.fullmatch(r"<!-- generated: \S+ -->", line), f"README.md:{number}: {line[:80]}"
