"""PyTorch's kernels in a PPO training process (etmpc.learning.kernels): ``portable`` makes PyTorch itself
report its non-vectorised kernels, and is refused once PyTorch was loaded with the CPU's own. Whether the
networks come out the same under every kernel setting this CPU can force is scripts/kernel_check.py --ppo's
question (about 2 min: not in the suite)."""

import json
import subprocess
import sys

import pytest

pytest.importorskip("torch")

from etmpc.common.errors import EtmpcError  # noqa: E402
from etmpc.learning import kernels  # noqa: E402
from etmpc.learning.ppo_settings import PpoSettings, SettingError, settings_json  # noqa: E402


def _fresh(code: str, **env: str) -> subprocess.CompletedProcess:
    """``code`` in a fresh interpreter, without the kernel switches of this one, plus ``env``."""
    import os

    clean = {k: v for k, v in os.environ.items() if k not in kernels.PORTABLE}
    return subprocess.run([sys.executable, "-c", code], env={**clean, **env}, capture_output=True, text=True)


def test_portable_kernels_are_what_pytorch_then_runs_and_native_leaves_the_cpus_own():
    code = "import json; from etmpc.learning.kernels import pin, in_effect; pin({!r}); print(json.dumps(in_effect()))"
    portable = json.loads(_fresh(code.format("portable")).stdout)
    assert portable == {"cpu_capability": "DEFAULT", "MKL_CBWR": "COMPATIBLE"}  # what torch says it runs
    native = json.loads(_fresh(code.format("native")).stdout)
    assert native["MKL_CBWR"] is None  # left alone; the capability is this CPU's (DEFAULT only on one without AVX2)


def test_portable_is_refused_in_one_line_once_pytorch_is_loaded_with_other_kernels():
    ran = _fresh("import torch\nfrom etmpc.learning.kernels import pin\npin('portable')")
    assert ran.returncode != 0 and "EtmpcError: kernels=portable must be chosen before PyTorch is loaded" in ran.stderr
    assert "MKL_CBWR=COMPATIBLE ATEN_CPU_CAPABILITY=default" in ran.stderr  # how to start the process instead
    started = _fresh("import torch\nfrom etmpc.learning.kernels import pin\npin('portable')", **kernels.PORTABLE)
    assert started.returncode == 0, started.stderr  # a process started with them is fine
    with pytest.raises(EtmpcError, match="kernels must be one of native, portable, got 'fast'"):
        kernels.pin("fast")


def test_the_setting_is_checked_and_kept_only_where_it_is_not_the_native_default():
    with pytest.raises(SettingError, match="kernels must be one of native, portable, got 'fast'"):
        PpoSettings(kernels="fast")
    assert "kernels" not in settings_json(PpoSettings())  # the files of runs before it read as the same settings
    assert settings_json(PpoSettings(kernels="portable"))["kernels"] == "portable"
