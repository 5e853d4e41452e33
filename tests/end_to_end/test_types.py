"""The type checker holds the package's contracts: mypy, with the settings of pyproject.toml's ``[tool.mypy]``
(default strictness, the bodies of unannotated functions checked too, unused ``type: ignore``s and redundant
casts reported), finds no error in ``etmpc/``. docs/architecture.md ("The type checker") says why mypy."""

import subprocess
import sys

import pytest

from tests.conftest import REPO


@pytest.mark.slow  # mypy over all of etmpc/: some 20 to 70 s, most of it in numpy's and CasADi's stubs
def test_mypy_finds_no_error_in_the_package():
    result = subprocess.run(
        [sys.executable, "-m", "mypy", "--config-file", str(REPO / "pyproject.toml")], cwd=REPO, capture_output=True, text=True
    )
    errors = [line for line in result.stdout.splitlines() if ": error:" in line]
    assert result.returncode == 0 and not errors, (
        f"mypy found {len(errors)} errors (python -m mypy, in the repository):\n"
        + "\n".join(errors[:200])
        + result.stderr[-2000:]
    )
