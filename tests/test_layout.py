"""The package's shape: floors that import only downwards (import-linter's contracts in pyproject.toml),
no import circle at all, rooms of one job (no module over 400 lines), and packages that say what they hold."""

import importlib
import pkgutil
import subprocess
import sys
from pathlib import Path

import grimp

import etmpc

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "etmpc"


def test_the_import_contracts_hold():
    """Floors (cli > experiments > learning > envs > evaluation > views > policies > loop | suite > systems >
    control > common: pyproject.toml's [tool.importlinter]), no cycles among siblings at any depth, the spec
    registry above the policies, domains apart."""
    lint = Path(sys.executable).with_name("lint-imports")
    result = subprocess.run([str(lint), "--config", str(ROOT / "pyproject.toml")], cwd=ROOT, capture_output=True, text=True)
    assert result.returncode == 0, result.stdout[-3000:]
    assert "BROKEN" not in result.stdout and result.stdout.count("KEPT") >= 4


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


def test_rooms_of_one_job():
    sizes = {p.relative_to(ROOT).as_posix(): len(p.read_text().splitlines()) for p in PACKAGE.rglob("*.py")}
    assert {name: n for name, n in sizes.items() if n > 400} == {}
    assert {name: n for name, n in sizes.items() if name.startswith("etmpc/cli/") and n > 250} == {}


def test_every_package_says_what_it_holds_and_what_it_may_import():
    for info in pkgutil.walk_packages(etmpc.__path__, "etmpc."):
        if not info.ispkg or info.name.startswith("etmpc._data"):
            continue
        doc = importlib.import_module(info.name).__doc__ or ""
        assert len(doc.split()) >= 15, info.name
        top = info.name.split(".")[1]
        if info.name.count(".") == 1 and top not in ("cli",):  # the floors
            assert "may import" in doc, info.name
