"""Every number the README and the docs quote by hand is under a marker naming the results file it comes
from, and agrees with it (scripts/doc_numbers.py; `python scripts/doc_numbers.py --write` rewrites them)."""

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
    assert {n.source for n in found} <= {
        str(p.relative_to(REPO))
        for p in [
            REPO / "docs" / "leaderboard.json",
            *REPO.glob("docs/results/*.json"),  # cards and pages made by etmpc's commands (etmpc score --json, ...)
            *REPO.glob("tasks/*/*_references.json"),
            *REPO.glob("policies/*/*.json"),
        ]
    }


def test_no_page_calls_the_100_point_reference_a_bound_that_knows_the_future():
    for page in doc_numbers.pages():
        text = page.read_text()
        assert not re.search(r"bound that knows|oracle that knows", text), page


def test_score_help_names_the_leaderboards_rows(capsys):
    from etmpc.cli import main
    from etmpc.experiments import leaderboard

    with pytest.raises(SystemExit):
        main(["score", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert all(name in text for name in leaderboard.row_names()) and "GPOMDP (shipped)" in text and "PPO (shipped)" in text


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
