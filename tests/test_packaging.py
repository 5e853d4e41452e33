"""The built wheel holds every module of etmpc/ and the data, and installed into a clean virtual
environment, every command works from outside the checkout."""

import json
import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
COMMANDS = ("evaluate", "score", "train", "train-self", "reproduce", "sweep", "render", "replay", "bench")
_LEFT_OUT = shutil.ignore_patterns(".git", ".venv", "build", "dist", "results", "*.egg-info", "__pycache__", ".pytest_cache")


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    """The wheel built from a copy of the tree (building in the checkout would leave build/ there)."""
    tmp = tmp_path_factory.mktemp("wheel")
    source = tmp / "source"
    shutil.copytree(ROOT, source, ignore=_LEFT_OUT)
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--quiet", "-w", str(tmp), str(source)],
                   check=True, capture_output=True)
    (built,) = tmp.glob("etmpc-*.whl")
    return built


def test_the_wheel_holds_every_module_and_the_data_and_nothing_else(wheel):
    names = set(zipfile.ZipFile(wheel).namelist())
    modules = {p.relative_to(ROOT).as_posix() for p in (ROOT / "etmpc").rglob("*.py")}
    assert modules and modules <= names, sorted(modules - names)
    data = {f"etmpc/_data/models/{p.name}" for p in (ROOT / "models").glob("*.xml")}
    data |= {f"etmpc/_data/tasks/{p.relative_to(ROOT / 'tasks').as_posix()}" for p in (ROOT / "tasks").glob("*/*_testset.npz*")}
    data |= {f"etmpc/_data/tasks/{p.relative_to(ROOT / 'tasks').as_posix()}" for p in (ROOT / "tasks").glob("*/*_references.json")}
    data |= {f"etmpc/_data/policies/{p.relative_to(ROOT / 'policies').as_posix()}" for p in (ROOT / "policies").glob("*/ppo.yml")}
    assert len(data) > 12 and data <= names, sorted(data - names)
    assert not {n for n in names if n.startswith("etmpc/_data/policies/") and not n.endswith("/ppo.yml")}  # no policy ships in it
    top_level = {name.split("/")[0] for name in names}
    assert top_level == {"etmpc", f"{wheel.name.split('-')[0]}-{wheel.name.split('-')[1]}.dist-info"}


def test_the_installed_commands_work_outside_the_checkout(wheel, tmp_path):
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
    subprocess.run([venv / "bin" / "python", "-m", "pip", "install", "--quiet", str(wheel)], check=True,
                   capture_output=True)
    outside = tmp_path / "elsewhere"
    outside.mkdir()
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    etmpc = str(venv / "bin" / "etmpc")

    def run(*argv):
        return subprocess.run([etmpc, *argv], cwd=outside, env=env, capture_output=True, text=True, timeout=600)

    where = subprocess.run([venv / "bin" / "python", "-c", "import etmpc; print(etmpc.__file__)"], cwd=outside, env=env,
                           capture_output=True, text=True, check=True).stdout.strip()
    assert Path(where).is_relative_to(venv), where  # the installed package, not the checkout
    assert run("--version").stdout.startswith("etmpc ")
    for command in COMMANDS:
        result = run(command, "--help")
        assert result.returncode == 0 and "usage: etmpc " + command in result.stdout, (command, result.stderr)

    shipped = ROOT / "policies" / "cart_pendulum" / "learned.json"
    result = run("evaluate", "cart_pendulum", "--policy", f"rl:{shipped}", "--policy", "every:3", "--episodes", "3",
                 "--workers", "2", "--json", "installed.json")
    assert result.returncode == 0, result.stderr
    from etmpc.evaluation.evaluate import evaluate  # the same evaluation from the checkout: the same numbers

    here = evaluate("cart_pendulum", [f"rl:{shipped}", "every:3"], episodes=3, workers=1, progress=False).to_json()
    installed = json.loads((outside / "installed.json").read_text())
    assert installed["runs"] == here["runs"] and installed["test_set"]["sha256"] == here["test_set"]["sha256"]

    result = run("score", "every:3", "--task", "battery", "--workers", "2")  # the stored references are installed
    best = json.loads((ROOT / "tasks" / "battery" / "trading_references.json").read_text())["best"]
    assert result.returncode == 0 and f"references: battery: {best} and oracle:{best}" in result.stdout, result.stderr

    result = run("sweep", "cart_pendulum", "--quick", "--prices", "5e-5", "--out", "sweep", "--workers", "2")
    assert result.returncode == 0, result.stderr
    for name in ("pareto.json", "pareto.png", "SWEEP.md"):
        assert (outside / "sweep" / "cart_pendulum" / name).is_file()
