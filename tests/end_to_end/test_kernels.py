"""Evaluations are the same, byte for byte, whatever BLAS kernel, numpy loops and libm variant the CPU
selects (scripts/kernel_check.py forces each setting this CPU can run through the libraries' own switches),
but for the differences the script names as expected (the MPCs that call libm, on a CPU without FMA: not
played under that setting here, as they could fail nothing)."""

import importlib.util

import pytest

from tests.conftest import REPO

SCRIPT = REPO / "scripts" / "kernel_check.py"


def _script():
    spec = importlib.util.spec_from_file_location("kernel_check", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_every_policy_kind_evaluates_to_the_same_bytes_under_every_kernel_setting():
    check = _script()
    if len(check.settings()) < 2:
        pytest.skip("not an x86-64 machine: no other kernel setting to force")
    found = check.compare(episodes=2, expected=False)
    assert len(found) >= 2
    for name, values in found.items():  # each setting played every system but those expected to differ under it
        assert set(values) == {d for d in found["default"] if (d, name) not in check.EXPECTED}, name
    assert check.unexpected(found) == {}
