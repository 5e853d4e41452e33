"""Fixtures for every folder of tests/ (which mirrors the package: tests/<floor>/, tests/tasks/<domain>/,
tests/end_to_end/), and ``REPO``, the checkout's root, for tests that read its files."""

import os
import re
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

import pytest  # noqa: E402

from etmpc.evaluation import testsets as testset  # noqa: E402
from etmpc.loop import ClosedLoop  # noqa: E402
from etmpc.systems.battery.system import BatterySystem  # noqa: E402
from etmpc.systems.cart_pendulum.system import CartPendulumSystem  # noqa: E402

# The checkout's root: the nearest folder above this file that holds pyproject.toml (wherever a test
# file sits under tests/, ``from tests.conftest import REPO`` finds the same folder).
REPO = next(p for p in Path(__file__).resolve().parents if (p / "pyproject.toml").is_file())


@pytest.fixture(scope="session")
def cart_system():
    return CartPendulumSystem()


@pytest.fixture(scope="session")
def cart_testset(cart_system):
    return testset.load(testset.default_path("cart_pendulum", "balance"), "cart_pendulum", "balance")


@pytest.fixture(scope="session")
def battery_system():
    return BatterySystem()


@pytest.fixture(scope="session")
def battery_testset(battery_system):
    return testset.load(testset.default_path("battery", "trading"), "battery", "trading")


@pytest.fixture
def features_while_kept():
    """``(features, last state)``: a task's exogenous features at each of ``steps`` decisions while
    the plan made at step 0 of ``episode`` is kept (the first at step 1)."""

    def play(system, episode, steps: int = 4):
        loop = ClosedLoop(system, system.make_env()).reset(episode)
        loop.step(True)  # the plan, made at step 0
        seen = []
        for _ in range(steps):
            s = loop.augmented_state()
            seen.append(system.exogenous_features(s))
            loop.step(False)
        return seen, s

    return play


# -- two workers (pytest-xdist: -n 2 --dist loadgroup, in pyproject.toml) ---------------------------------
# A file runs whole, its tests in turn in one worker, when it has a module-scoped fixture (made once, not
# once per worker; tests/experiments/test_reproduce.py's tests also continue one another's run) or an
# xdist_group mark (tests/end_to_end/test_ray.py: `ray stop --force` stops every Ray instance of the user).
# Any other test is a unit of work of its own.
_RUNS_WHOLE = re.compile(r"""scope\s*=\s*["']module["']|\bxdist_group\b""")
# The longest units (measured with two workers on 2 cores: about 135, 65, 50, 50, 25 and 10 s), started
# first so that no worker is left with one of them at the end. Only the order: a file missing here is fine.
_FIRST = (
    "tests/experiments/test_reproduce.py",
    "tests/end_to_end/test_packaging.py",
    "tests/end_to_end/test_ray.py",
    "tests/end_to_end/test_kernels.py",
    "tests/experiments/test_leaderboard.py",
    "tests/end_to_end/test_plugin_package.py",
)


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config, log):
    """--dist loadgroup, its groups read here, from the test files: xdist's own reading of xdist_group
    marks does nothing on pytest 9.2 (it rewrites a test's id where pytest no longer reads it,
    pytest-xdist issue #1386), and it cannot see which tests share a module-scoped fixture."""
    if config.getvalue("dist") != "loadgroup":
        return None
    from xdist.scheduler import LoadScopeScheduling

    tests = Path(__file__).resolve().parent
    whole = {p.relative_to(config.rootpath).as_posix() for p in tests.rglob("test_*.py") if _RUNS_WHOLE.search(p.read_text())}

    class Scheduling(LoadScopeScheduling):
        """A unit of work is a whole file or one test (a scope of LoadScopeScheduling); the longest first."""

        def _split_scope(self, nodeid: str) -> str:
            path = nodeid.split("::", 1)[0]
            return path if path in whole else nodeid

        def _assign_work_unit(self, node) -> None:
            if not getattr(self, "_ordered", False):  # the queue is complete when the first unit is sent
                self._ordered = True
                for first in reversed(_FIRST):
                    for scope in [s for s in self.workqueue if s.split("::", 1)[0] == first]:
                        self.workqueue.move_to_end(scope, last=False)
            super()._assign_work_unit(node)

    return Scheduling(config, log)


# The build that takes longest (about 30 s of the 70 s that all the builds take on 2 cores), started first.
_BUILT_FIRST = ("reacher/jumps",)


def _build(name: str) -> None:
    from etmpc.systems import make_system

    make_system(name).mpc  # with it, on a task that counts SQP iterations, the one-iteration code


def pytest_sessionstart(session):
    """Before the workers start, every task's compiled MPC is built into the cache (or found there, in
    about 3 s), in as many processes as there are workers: so on a machine whose cache is empty no test's
    output shows the one line a build says, whichever worker comes to a task first (each would otherwise
    wait on the lock, silent, or build)."""
    config = session.config
    workers = getattr(config.option, "numprocesses", None)
    if hasattr(config, "workerinput") or not workers:
        return  # a worker, or a serial run: the first test to need a task builds it, as before
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    from etmpc.systems import names

    tasks = sorted(names(), key=lambda name: name not in _BUILT_FIRST)
    with ProcessPoolExecutor(int(workers), mp_context=multiprocessing.get_context("spawn")) as pool:
        list(pool.map(_build, tasks))
