"""The package's shape: floors that import only downwards (import-linter's contracts in pyproject.toml),
no import circle at all, rooms of one job (no module over 350 lines), packages that say what they hold,
and tests that mirror the package."""

import importlib
import pkgutil
import re
import subprocess
import sys
from pathlib import Path

import grimp

import etmpc

from tests.conftest import REPO

PACKAGE = REPO / "etmpc"
TESTS = REPO / "tests"


def test_the_import_contracts_hold():
    """Floors (cli > experiments > views > learning > envs > evaluation > policies > loop | suite > systems >
    control > common: pyproject.toml's [tool.importlinter]), evaluation and learning apart from views, no
    cycles among siblings at any depth, the spec registry above the policies, domains apart."""
    lint = Path(sys.executable).with_name("lint-imports")
    result = subprocess.run([str(lint), "--config", str(REPO / "pyproject.toml")], cwd=REPO, capture_output=True, text=True)
    assert result.returncode == 0, result.stdout[-3000:]
    assert "BROKEN" not in result.stdout and result.stdout.count("KEPT") >= 5


def test_the_domains_contract_names_every_domain_of_etmpc():
    """The independence contract lists every built-in domain (it once left the quadrotor out)."""
    import tomllib

    from etmpc.systems.registry import BUILT_IN

    contracts = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["importlinter"]["contracts"]
    (domains,) = [c for c in contracts if c["name"] == "Domains know nothing of each other"]
    assert sorted(domains["modules"]) == sorted(BUILT_IN.values())


def _strongly_connected(graph: grimp.ImportGraph) -> list[set[str]]:
    """Tarjan's components of the module graph, function-level imports included."""
    modules = sorted(graph.modules)
    edges = {m: sorted(graph.find_modules_directly_imported_by(m)) for m in modules}
    index, low, stack, on_stack, components = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in edges[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = set()
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.add(w)
                if w == v:
                    break
            components.append(component)

    sys.setrecursionlimit(max(sys.getrecursionlimit(), 10 * len(modules)))
    for m in modules:
        if m not in index:
            visit(m)
    return components


def test_no_module_is_on_an_import_circle():
    graph = grimp.build_graph("etmpc")
    assert len(graph.modules) > 40
    circles = [sorted(c) for c in _strongly_connected(graph) if len(c) > 1]
    assert circles == []


MOST_LINES = 350  # a module's; one past it holds more than one job
MOST_LINES_CLI = 250  # a command's module
SPLIT = "split it by what it does (a collaborator, a module of its own), never by compressing lines"


def test_rooms_of_one_job():
    sizes = {p.relative_to(REPO).as_posix(): len(p.read_text().splitlines()) for p in PACKAGE.rglob("*.py")}
    over = {name: n for name, n in sizes.items() if n > MOST_LINES}
    assert over == {}, f"over {MOST_LINES} lines: {over}; {SPLIT}"
    over_cli = {name: n for name, n in sizes.items() if name.startswith("etmpc/cli/") and n > MOST_LINES_CLI}
    assert over_cli == {}, f"a command over {MOST_LINES_CLI} lines: {over_cli}; {SPLIT}"


def _floor_rows() -> dict[str, str]:
    """docs/architecture.md's table of floors: each ``etmpc/<floor>/`` row's text, by floor."""
    rows = {}
    for line in (REPO / "docs" / "architecture.md").read_text().splitlines():
        found = re.match(r"\| `etmpc/(\w+)/` \| (.*) \|$", line)
        if found:
            rows[found.group(1)] = found.group(2)
    return rows


def test_the_architecture_page_names_every_module():
    """The page is checked against the code: a row for every floor, and each floor's row names every module
    of that floor (as `name.py`, at any depth) and no module that does not exist."""
    rows = _floor_rows()
    floors = sorted(p.name for p in PACKAGE.iterdir() if (p / "__init__.py").is_file() and p.name != "_data")
    assert sorted(rows) == floors
    for floor, text in rows.items():
        files = {p.name for p in (PACKAGE / floor).rglob("*.py") if p.name not in ("__init__.py", "__main__.py")}
        named = set(re.findall(r"`(?:[\w/]*/)?(\w+\.py)`", text))
        assert sorted(files - named) == [], f"docs/architecture.md's row for etmpc/{floor}/ does not name these"
        assert sorted(named - files) == [], f"docs/architecture.md's row for etmpc/{floor}/ names modules that are gone"


def test_every_package_says_what_it_holds_and_what_it_may_import():
    for info in pkgutil.walk_packages(etmpc.__path__, "etmpc."):
        if not info.ispkg or info.name.startswith("etmpc._data"):
            continue
        doc = importlib.import_module(info.name).__doc__ or ""
        assert len(doc.split()) >= 15, info.name
        top = info.name.split(".")[1]
        if info.name.count(".") == 1 and top not in ("cli",):  # the floors
            assert "may import" in doc, info.name


def test_the_tests_mirror_the_package():
    """Every test file sits in a folder named for what it tests: a floor (tests/evaluation/ for
    etmpc/evaluation/), a built-in domain (tests/tasks/battery/), or tests/end_to_end/ for what checks
    the whole product; none is left flat in tests/ but conftest.py. Each folder is a package, so that two
    files in different folders may share a name."""
    from etmpc.systems.registry import BUILT_IN

    floors = {info.name for info in pkgutil.iter_modules(etmpc.__path__) if info.ispkg and not info.name.startswith("_")}
    assert {"common", "systems", "evaluation", "cli"} <= floors
    allowed = {*floors, "end_to_end", "tasks", *(f"tasks/{domain}" for domain in BUILT_IN)}
    folders = {
        p.relative_to(TESTS).as_posix()
        for p in TESTS.rglob("*")
        if p.is_dir() and "__pycache__" not in p.parts and not p.name.startswith(".")
    }
    assert folders - allowed == set()
    assert [f for f in sorted(folders | {"."}) if not (TESTS / f / "__init__.py").is_file()] == []
    flat = {p.name for p in TESTS.glob("*.py")} - {"__init__.py", "conftest.py"}
    assert flat == set()
    assert [p.name for p in (TESTS / "tasks").glob("*.py") if p.name != "__init__.py"] == []  # a task's tests in its domain
    assert len(list(TESTS.rglob("test_*.py"))) > 50


# What the formatter and the linter read: the package, its tests and scripts, the example plugin, the docs' hooks.
SOURCES = ["etmpc", "tests", "scripts", "examples", "docs/hooks.py"]


def _ruff(*args: str) -> subprocess.CompletedProcess:
    ruff = Path(sys.executable).with_name("ruff")
    command = [str(ruff)] if ruff.exists() else [sys.executable, "-m", "ruff"]
    return subprocess.run([*command, *args, *SOURCES], cwd=REPO, capture_output=True, text=True, timeout=300)


def test_the_code_is_formatted_and_holds_lines_to_130_characters():
    """``ruff format`` (pyproject.toml's [tool.ruff]): one style; ``ruff format`` rewrites a file that is not."""
    done = _ruff("format", "--check")
    assert done.returncode == 0, done.stdout + done.stderr


def test_the_linter_finds_nothing():
    """Undefined names, unused imports, syntax errors and lines over 130 characters ([tool.ruff.lint])."""
    done = _ruff("check")
    assert done.returncode == 0, done.stdout + done.stderr
