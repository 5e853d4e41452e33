"""Compiled CasADi functions: the same numbers as CasADi, a cache that is trusted only when intact."""

import subprocess
import sys

import casadi as ca
import numpy as np
import pytest

from etmpc.control import compiled


@pytest.fixture
def function():
    x, y = ca.SX.sym("x", 3), ca.SX.sym("y", 2)
    return ca.Function("etmpc_test_fn", [x, y], [ca.sin(x) * y[0], ca.sumsqr(x) + y[1]], ["x", "y"], ["a", "b"])


@pytest.fixture
def builds(monkeypatch):
    """Counts the builds (compiler runs) of etmpc.control.compiled."""
    count = [0]
    build = compiled._build

    def counting(*args, **kwargs):
        count[0] += 1
        return build(*args, **kwargs)

    monkeypatch.setattr(compiled, "_build", counting)
    return count


def test_compiled_function_matches_casadi(function, tmp_path, builds):
    fast = compiled.CompiledFunction(function, cache=tmp_path)
    x, y = np.array([0.3, -1.2, 2.0]), np.array([1.5, -0.25])
    (a, b), code = fast.call(x, y)
    assert code == 0 and builds[0] == 1
    expected_a, expected_b = (np.asarray(v).ravel() for v in function(x, y))
    np.testing.assert_allclose(a, expected_a, rtol=1e-15)
    np.testing.assert_allclose(b, expected_b, rtol=1e-15)


def test_valid_cache_is_reused_without_building(function, tmp_path, builds):
    first = compiled.CompiledFunction(function, cache=tmp_path)
    stamp = first.library.stat()
    second = compiled.CompiledFunction(function, cache=tmp_path)
    assert builds[0] == 1 and second.library == first.library
    assert second.library.stat().st_mtime_ns == stamp.st_mtime_ns
    assert sorted(p.suffix for p in tmp_path.iterdir()) == [".lock", ".sha256", ".so"]  # no build leftovers


BUILD = """
import sys, casadi as ca, numpy as np
from etmpc.control import compiled
x, y = ca.SX.sym("x", 3), ca.SX.sym("y", 2)
function = ca.Function("etmpc_test_fn", [x, y], [ca.sin(x) * y[0], ca.sumsqr(x) + y[1]], ["x", "y"], ["a", "b"])
builds = []
build = compiled._build
compiled._build = lambda *args: builds.append(1) or build(*args)
(a, b), code = compiled.CompiledFunction(function, cache=sys.argv[1]).call(np.ones(3), np.ones(2))
print(len(builds), code, a[0] == np.sin(1.0), b[0] == 4.0)
"""


@pytest.mark.parametrize("damage", ["truncate", "garbage", "no digest", "wrong digest"])
def test_damaged_cache_is_rebuilt_not_trusted(tmp_path, damage):
    """Each run in a fresh process, as the tool's next run would (a library loaded in a process
    stays mapped there; the damage is done as a disk would do it, to the file in place)."""

    def run():
        done = subprocess.run([sys.executable, "-c", BUILD, str(tmp_path)], capture_output=True, text=True, check=True)
        return done.stdout.split()

    assert run() == ["1", "0", "True", "True"]
    (library,) = tmp_path.glob("*.so")
    digest = library.with_suffix(".sha256")
    if damage == "truncate":
        library.write_bytes(library.read_bytes()[:1000])
    elif damage == "garbage":
        library.write_bytes(b"\x7fELF not really a library")
    elif damage == "no digest":
        digest.unlink()
    else:
        digest.write_text("0" * 64 + "\n")
    assert run() == ["1", "0", "True", "True"]  # rebuilt once, and right
    assert digest.read_text().strip() == compiled._digest(library)
    assert run() == ["0", "0", "True", "True"]  # and trusted from then on


def test_failed_build_leaves_nothing_and_says_why(function, tmp_path, monkeypatch):
    monkeypatch.setenv("CC", "false")  # a "compiler" that runs and fails
    with pytest.raises(compiled.CompileError, match="failed"):
        compiled.CompiledFunction(function, cache=tmp_path)
    assert [p.suffix for p in tmp_path.iterdir()] == [".lock"]


def test_without_a_compiler_the_mpc_runs_interpreted(cart_system, monkeypatch):
    from dataclasses import replace

    from etmpc.systems.cart_pendulum.system import CartPendulumSystem

    default = cart_system.mpc  # built (or loaded) before the compiler goes away
    monkeypatch.setenv("CC", "/nonexistent/cc")
    system = CartPendulumSystem(replace(cart_system.config))
    with pytest.warns(RuntimeWarning, match="virtual machine"):
        mpc = system.mpc
    assert not mpc.is_compiled
    x = np.array([0.0, 0.2, 0.3, -0.1])
    interpreted, compiled_plan = mpc.solve(x, np.zeros(1)), default.solve(x, np.zeros(1))
    assert default.is_compiled and interpreted.success
    assert abs(interpreted.cost - compiled_plan.cost) <= 1e-12 * compiled_plan.cost
