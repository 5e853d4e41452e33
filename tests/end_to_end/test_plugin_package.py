"""The example plugin (examples/etmpc_slider: a MuJoCo task and a trigger kind in a package of its own),
installed into a fresh virtual environment: every entry into etmpc sees the task and the kind, with no
change to etmpc, and uninstalling the package takes them away.

The fresh environment sees this one's packages (etmpc among them) through a ``.pth`` file, so that
nothing is downloaded; the plugin itself is built and installed there, from a copy of its folder."""

import os
import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest

from tests.conftest import REPO

EXAMPLE = REPO / "examples" / "etmpc_slider"


@pytest.fixture(scope="module")
def venv(tmp_path_factory):
    """A virtual environment without the plugin, and ``run(*argv)`` / ``pip(*argv)`` in it."""
    where = tmp_path_factory.mktemp("plugin")
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(where / "venv")], check=True)
    python = where / "venv" / "bin" / "python"
    purelib = subprocess.run(
        [str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
        check=True,
        capture_output=True,
        text=True,
    ).stdout.strip()
    parent = sysconfig.get_paths()["purelib"]  # this environment's: etmpc and its dependencies
    Path(purelib, "_parent.pth").write_text(f"import site; site.addsitedir({parent!r})\n")
    shutil.copytree(EXAMPLE, where / "source", ignore=shutil.ignore_patterns("__pycache__", "*.egg-info", "build"))
    env = dict(os.environ, MUJOCO_GL=os.environ.get("MUJOCO_GL", "egl"), PYTHONWARNINGS="default")
    env.pop("PYTHONPATH", None)

    def run(*argv: str) -> subprocess.CompletedProcess:
        return subprocess.run([str(python), *argv], capture_output=True, text=True, cwd=where, env=env, timeout=600)

    def pip(*argv: str) -> None:
        subprocess.run(
            [sys.executable, "-m", "pip", "--python", str(python), "--no-input", "-q", *argv],
            check=True,
            cwd=where,
            env=env,
            timeout=600,
        )

    return run, pip, where / "source"


SEES = """
import warnings
warnings.simplefilter("error")  # a plugin that failed to load would warn
import gymnasium
import etmpc
from etmpc import suite
from etmpc.policies.specs import kinds
from etmpc.systems import names
print("tasks", *names())
print("kinds", *kinds())
if "slider/track" in names():
    env = suite.load("slider", "track", task_kwargs={"random": 0})
    print("suite", env.reset().observation["reference_m"].shape, env.action_spec().shape)
    gym = gymnasium.make("etmpc/slider-track-v0")
    gym.reset(seed=0)
    print("gym", gym.step(1)[0].shape)
"""


def test_an_installed_plugin_adds_its_task_and_kind_everywhere_and_uninstalling_removes_them(venv):
    run, pip, source = venv
    before = run("-c", SEES)
    assert before.returncode == 0, before.stderr
    assert before.stdout.splitlines() == [
        "tasks cart_pendulum/balance cart_pendulum/kicks cart_pendulum/kicks_late cart_pendulum/kicks_levels "
        "cart_pendulum/kicks_noisy battery/trading reacher/jumps reacher/jumps_late quadrotor/waypoints "
        "quadrotor/waypoints_noisy",
        "kinds always never every iterate threshold rl self py sb3 shield rollout oracle",
    ]

    pip("install", "--no-deps", "--no-build-isolation", str(source))
    after = run("-c", SEES)
    assert after.returncode == 0, after.stderr
    assert after.stdout.splitlines() == [
        "tasks cart_pendulum/balance cart_pendulum/kicks cart_pendulum/kicks_late cart_pendulum/kicks_levels "
        "cart_pendulum/kicks_noisy battery/trading reacher/jumps reacher/jumps_late quadrotor/waypoints "
        "quadrotor/waypoints_noisy slider/track",
        "kinds always never every iterate threshold rl self py sb3 shield rollout oracle driftage",
        "suite () (1,)",
        "gym (12,)",
    ]

    evaluated = run(
        "-m",
        "etmpc.cli",
        "evaluate",
        "--task",
        "slider",
        "--policy",
        "every:3",
        "--policy",
        "driftage:0.05:4",
        "--episodes",
        "3",
        "--workers",
        "1",
    )
    assert evaluated.returncode == 0, evaluated.stderr
    assert "slider/track: objective (lower is better)" in evaluated.stdout and "driftage:0.05:4" in evaluated.stdout
    scored = run(
        "-m", "etmpc.cli", "score", "--policy", "driftage:0.05:4", "--task", "slider", "--episodes", "3", "--workers", "1"
    )
    assert scored.returncode == 0, scored.stderr
    assert "references: slider/track: every:3 and oracle:every:3" in scored.stdout  # the plugin's stored references
    own = run("-m", "pytest", "-q", "-p", "no:cacheprovider", str(source / "tests"))  # the plugin's tests, installed
    assert own.returncode == 0, own.stdout[-2000:]
    helped = run("-m", "etmpc.cli", "evaluate", "--help")
    assert "slider" in helped.stdout and "driftage:X:T" in " ".join(helped.stdout.split())

    pip("uninstall", "-y", "etmpc-slider")
    gone = run("-c", SEES)
    assert gone.returncode == 0 and gone.stdout == before.stdout, gone.stderr
    refused = run("-m", "etmpc.cli", "evaluate", "--task", "slider", "--policy", "every:3", "--episodes", "1")
    assert refused.returncode == 2
    assert refused.stderr.strip() == (
        "etmpc: error: unknown task 'slider'; valid: cart_pendulum/balance, cart_pendulum/kicks, cart_pendulum/kicks_late, "
        "cart_pendulum/kicks_levels, cart_pendulum/kicks_noisy, battery/trading, reacher/jumps, reacher/jumps_late, "
        "quadrotor/waypoints, quadrotor/waypoints_noisy"
    )
