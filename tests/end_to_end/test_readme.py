"""The README is a short user's guide whose every claim is checked: its length, the two quick-start
commands, its links, the trigger it shows (the example file's, line for line), and the Python it needs.
Its one table of numbers, the leaderboard's, is checked by tests/experiments/test_leaderboard.py."""

import ast
import re
import tomllib

from tests.conftest import REPO

README = (REPO / "README.md").read_text()


def _blocks(language: str) -> list[str]:
    return re.findall(rf"```{language}\n(.*?)```", README, flags=re.S)


def test_it_is_short_and_its_quick_start_is_the_two_make_commands():
    assert len(README.splitlines()) <= 250
    quick = README.split("## Quick start", 1)[1]
    assert [line.split("#")[0].strip() for line in _blocks("sh")[1].splitlines()] == ["make reproduce", "make test"]
    assert "```sh\nmake reproduce" in quick
    makefile = (REPO / "Makefile").read_text()
    assert "\nreproduce: setup" in makefile and "\ntest: setup" in makefile


def test_every_link_and_picture_it_shows_exists():
    targets = re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", README) + re.findall(r'<img src="([^"]+)"', README)
    assert len(targets) > 10
    assert [t for t in targets if not t.startswith("http") and not (REPO / t).is_file()] == []


def test_the_trigger_it_shows_is_the_example_files_line_for_line():
    (shown,) = [block for block in _blocks("python") if "class DriftOrAge" in block]
    example = ast.parse((REPO / "examples" / "my_trigger.py").read_text())
    (cls,) = [node for node in example.body if isinstance(node, ast.ClassDef) and node.name == "DriftOrAge"]
    cls.body = [node for node in cls.body if not (isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant))]
    (readme_cls,) = [node for node in ast.parse(shown).body if isinstance(node, ast.ClassDef)]
    assert ast.dump(readme_cls) == ast.dump(cls)  # the same fields, defaults and decide (the docstring aside)


def test_the_python_it_names_is_the_packages():
    requires = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["requires-python"]
    assert requires == ">=3.11" and "Python ≥ 3.11" in README
