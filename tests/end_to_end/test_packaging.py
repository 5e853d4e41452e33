"""The release artifacts (`make dist`): the sdist holds the sources, the data and the licence files, and
the wheel built from it holds every module of etmpc/ and the data; both carry the Apache-2.0 licence
and pass `twine check`; installed into a clean virtual environment, every command works from outside
the checkout. CITATION.cff is valid and says what the package and the README say."""

import json
import os
import shutil
import subprocess
import sys
import tarfile
import tomllib
import zipfile
from email.parser import Parser
from pathlib import Path

import pytest

from tests.conftest import REPO

COMMANDS = ("evaluate", "score", "train", "train-self", "reproduce", "sweep", "render", "replay", "bench")
# The caches too: other tests (running beside this one) write into them while the tree is copied.
_LEFT_OUT = shutil.ignore_patterns(
    ".git",
    ".venv",
    "build",
    "dist",
    "results",
    "*.egg-info",
    "__pycache__",
    ".pytest_cache",
    ".grimp_cache",
    ".import_linter_cache",
    ".ruff_cache",
)


PROJECT = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]
LICENCE_FILES = ("LICENSE", "NOTICE")


@pytest.fixture(scope="module")
def dist(tmp_path_factory) -> Path:
    """dist/ as `make dist` makes it: the sdist, then the wheel built from the unpacked sdist (so the
    sdist is complete), from a copy of the tree (building in the checkout would leave files there)."""
    tmp = tmp_path_factory.mktemp("dist")
    source = tmp / "source"
    shutil.copytree(REPO, source, ignore=_LEFT_OUT)
    built = subprocess.run(
        [sys.executable, "-m", "build", "--outdir", str(tmp / "dist"), str(source)], capture_output=True, text=True
    )
    assert built.returncode == 0, built.stdout[-3000:] + built.stderr[-3000:]
    return tmp / "dist"


@pytest.fixture(scope="module")
def wheel(dist) -> Path:
    (built,) = dist.glob("etmpc-*.whl")
    return built


@pytest.fixture(scope="module")
def sdist(dist) -> Path:
    (built,) = dist.glob("etmpc-*.tar.gz")
    return built


def test_the_wheel_holds_every_module_and_the_data_and_nothing_else(wheel):
    names = set(zipfile.ZipFile(wheel).namelist())
    modules = {p.relative_to(REPO).as_posix() for p in (REPO / "etmpc").rglob("*.py")}
    assert modules and modules <= names, sorted(modules - names)
    data = {f"etmpc/_data/models/{p.name}" for p in (REPO / "models").glob("*.xml")}
    data |= {f"etmpc/_data/tasks/{p.relative_to(REPO / 'tasks').as_posix()}" for p in (REPO / "tasks").glob("*/*/testset.npz*")}
    data |= {
        f"etmpc/_data/tasks/{p.relative_to(REPO / 'tasks').as_posix()}" for p in (REPO / "tasks").glob("*/*/references.json")
    }
    data |= {
        f"etmpc/_data/policies/{p.relative_to(REPO / 'policies').as_posix()}"
        for recipe in ("ppo.yml", "dpi.yml")
        for p in (REPO / "policies").glob(f"*/*/{recipe}")
    }
    assert len(data) > 12 and data <= names, sorted(data - names)
    recipes = ("/ppo.yml", "/dpi.yml")
    assert not {n for n in names if n.startswith("etmpc/_data/policies/") and not n.endswith(recipes)}  # no policy ships in it
    top_level = {name.split("/")[0] for name in names}
    assert top_level == {"etmpc", f"{wheel.name.split('-')[0]}-{wheel.name.split('-')[1]}.dist-info"}


def test_the_installed_commands_work_outside_the_checkout(wheel, tmp_path):
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
    # --no-compile: the modules a command imports are compiled when first imported, not every installed one (7 s)
    install = [venv / "bin" / "python", "-m", "pip", "install", "--quiet", "--no-compile", str(wheel)]
    subprocess.run(install, check=True, capture_output=True)
    outside = tmp_path / "elsewhere"
    outside.mkdir()
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    etmpc = str(venv / "bin" / "etmpc")

    def run(*argv):
        return subprocess.run([etmpc, *argv], cwd=outside, env=env, capture_output=True, text=True, timeout=600)

    where = subprocess.run(
        [venv / "bin" / "python", "-c", "import etmpc; print(etmpc.__file__)"],
        cwd=outside,
        env=env,
        capture_output=True,
        text=True,
        check=True,
    ).stdout.strip()
    assert Path(where).is_relative_to(venv), where  # the installed package, not the checkout
    assert run("--version").stdout.startswith("etmpc ")
    for command in COMMANDS:
        result = run(command, "--help")
        assert result.returncode == 0 and "usage: etmpc " + command in result.stdout, (command, result.stderr)

    shipped = REPO / "policies" / "cart_pendulum" / "balance" / "learned.json"
    result = run(
        "evaluate",
        "--task",
        "cart_pendulum",
        "--policy",
        f"rl:{shipped}",
        "--policy",
        "every:3",
        "--episodes",
        "3",
        "--workers",
        "2",
        "--json",
        "installed.json",
    )
    assert result.returncode == 0, result.stderr
    from etmpc.evaluation.evaluate import evaluate  # the same evaluation from the checkout: the same numbers

    here = evaluate("cart_pendulum", [f"rl:{shipped}", "every:3"], episodes=3, workers=1, progress=False).to_json()
    installed = json.loads((outside / "installed.json").read_text())
    assert installed["runs"] == here["runs"] and installed["test_set"]["sha256"] == here["test_set"]["sha256"]

    result = run("score", "--policy", "every:3", "--task", "battery", "--workers", "2")  # the stored references are installed
    best = json.loads((REPO / "tasks" / "battery" / "trading" / "references.json").read_text())["best"]
    assert result.returncode == 0 and f"references: battery/trading: {best} and oracle:{best}" in result.stdout, result.stderr
    result = run("score", "--policy", "every:3", "--task", "battery", "--episodes", "2", "--workers", "1")  # references computed
    assert result.returncode == 0 and "references: battery/trading: " in result.stdout, result.stderr

    # `pip show` as this pip prints it (the venv's own, from ensurepip, may be too old to print License-Expression)
    shown = subprocess.run(
        [sys.executable, "-m", "pip", "--python", str(venv / "bin" / "python"), "show", "etmpc"],
        cwd=outside,
        env=env,
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    assert "License-Expression: Apache-2.0" in shown.splitlines(), shown

    result = run("sweep", "cart_pendulum", "--quick", "--prices", "5e-5", "--out", "sweep", "--workers", "2")
    assert result.returncode == 0, result.stderr
    for name in ("pareto.json", "pareto.png", "SWEEP.md"):
        assert (outside / "sweep" / "cart_pendulum" / "balance" / name).is_file()


def test_the_wheel_carries_the_licence_in_its_metadata_and_dist_info(wheel):
    with zipfile.ZipFile(wheel) as archive:
        info = f"{PROJECT['name']}-{PROJECT['version']}.dist-info"
        metadata = Parser().parsestr(archive.read(f"{info}/METADATA").decode())
        shipped = {name: archive.read(f"{info}/licenses/{name}") for name in LICENCE_FILES}
    assert PROJECT["license"] == "Apache-2.0"
    assert metadata.get("License-Expression", metadata.get("License")) == "Apache-2.0"
    assert sorted(metadata.get_all("License-File")) == sorted(LICENCE_FILES)
    assert shipped == {name: (REPO / name).read_bytes() for name in LICENCE_FILES}
    assert b"Apache License" in shipped["LICENSE"] and b"Version 2.0, January 2004" in shipped["LICENSE"]
    assert metadata["Description-Content-Type"] == "text/markdown" and metadata.get_payload().strip()


def test_the_sdist_holds_what_the_wheel_is_built_from_and_twine_check_passes(sdist, wheel):
    top = f"{PROJECT['name']}-{PROJECT['version']}"
    with tarfile.open(sdist) as archive:
        names = {member.name.removeprefix(f"{top}/") for member in archive.getmembers() if member.isfile()}
    needed = {"pyproject.toml", "setup.py", "README.md", "CITATION.cff", *LICENCE_FILES}
    needed |= {p.relative_to(REPO).as_posix() for p in (REPO / "etmpc").rglob("*.py")}
    needed |= {p.relative_to(REPO).as_posix() for p in (REPO / "models").glob("*.xml")}
    for pattern in (
        "*/*/*.npz",
        "*/*/*.sha256",
        "*/*/references.json",
        "*/*/benchmark.json",
    ):  # the package data of pyproject.toml
        needed |= {p.relative_to(REPO).as_posix() for p in (REPO / "tasks").glob(pattern)}
    needed |= {p.relative_to(REPO).as_posix() for r in ("ppo.yml", "dpi.yml") for p in (REPO / "policies").glob(f"*/*/{r}")}
    assert not needed - names, sorted(needed - names)  # CITATION.cff: `include CITATION.cff` in MANIFEST.in
    assert not {n for n in names if n.startswith("policies/") and not n.endswith(("/ppo.yml", "/dpi.yml"))}  # no policy ships
    checked = subprocess.run(
        [sys.executable, "-m", "twine", "check", "--strict", str(sdist), str(wheel)], capture_output=True, text=True
    )
    assert checked.returncode == 0 and checked.stdout.count("PASSED") == 2, checked.stdout + checked.stderr


def test_citation_cff_is_valid_and_says_what_the_package_and_the_readme_say():
    yaml = pytest.importorskip("yaml")
    cff = yaml.safe_load((REPO / "CITATION.cff").read_text())
    assert {"cff-version", "message", "title", "authors"} <= cff.keys() and cff["cff-version"] == "1.2.0"
    assert cff["type"] == "software" and cff["authors"] == [{"name": "The etmpc authors"}]
    assert cff["version"] == PROJECT["version"] and cff["license"] == PROJECT["license"]
    assert PROJECT["authors"] == [{"name": "The etmpc authors"}]
    (paper,) = cff["references"]
    assert paper["type"] == "conference-paper" and paper["year"] == 2021
    assert [a["family-names"] for a in paper["authors"]] == ["Bøhn", "Gros", "Moe", "Johansen"]
    assert "arXiv:2011.13365" in [i["value"] for i in paper["identifiers"]]
    citing = (REPO / "README.md").read_text().split("## Citing", 1)[1].split("\n## ", 1)[0]
    assert "CITATION.cff" in citing and "@software{etmpc" in citing and "@inproceedings{bohn2021optimization" in citing
    assert f"title   = {{{cff['title']}}}" in citing and f"version = {{{cff['version']}}}" in citing
    assert f"year    = {{{str(cff['date-released'])[:4]}}}" in citing and paper["title"] in citing
