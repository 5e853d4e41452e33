"""PyTorch's numerical kernels in a PPO training process: the machine's own, or the same on every x86-64 host.

A PPO run's weights come from PyTorch's matrix products (Intel MKL's ``sgemm`` in the PyPI wheels) and its
elementwise kernels (ATen's, dispatched by the CPU's vector width). Both pick their code path by the CPU, so
the same training on two x86-64 machines can give weights that differ in their last bits, and grow apart
over a long run. A setting ``kernels`` says which paths a training process takes:

* ``native`` (the default, and how the shipped networks were trained): the CPU's own;
* ``portable``: MKL's conditional bit-wise reproducibility at its compatible (SSE2) path
  (``MKL_CBWR=COMPATIBLE``) and ATen's non-vectorised kernels (``ATEN_CPU_CAPABILITY=default``), the same
  on every x86-64 CPU. Both are read by the libraries when PyTorch loads, so :func:`pin` sets them before it
  is imported, and refuses once it has been imported with another path. ``scripts/kernel_check.py --ppo``
  trains the same run under the kernel settings this CPU can force and compares the networks' bytes.

The environments' own arithmetic (MuJoCo, numpy, the compiled MPC) is kernel-independent already: the
evaluations are (``scripts/kernel_check.py``).
"""

from __future__ import annotations

import os
import sys

from etmpc.common.errors import EtmpcError

KERNELS = ("native", "portable")
#: What ``portable`` sets, for MKL and for ATen, read when PyTorch loads.
PORTABLE = {"MKL_CBWR": "COMPATIBLE", "ATEN_CPU_CAPABILITY": "default"}


def pin(kernels: str) -> None:
    """Make this process's PyTorch take ``kernels``' paths: for ``portable``, set :data:`PORTABLE` before PyTorch
    is imported; a process that imported it already must have been started with them."""
    if kernels not in KERNELS:
        raise EtmpcError(f"kernels must be one of {', '.join(KERNELS)}, got {kernels!r}")
    if kernels == "native":
        return
    if "torch" not in sys.modules:
        os.environ.update(PORTABLE)
        return
    unset = {name: value for name, value in PORTABLE.items() if os.environ.get(name) != value}
    if unset or in_effect()["cpu_capability"] != "DEFAULT":
        shown = " ".join(f"{name}={value}" for name, value in PORTABLE.items())
        raise EtmpcError(
            f"kernels=portable must be chosen before PyTorch is loaded, and this process has loaded it: "
            f"train in a fresh process, or start this one with {shown}"
        )


def in_effect() -> dict:
    """The paths this process's PyTorch takes, as a run's ``training.json`` records them."""
    import torch

    return {"cpu_capability": torch.backends.cpu.get_cpu_capability(), "MKL_CBWR": os.environ.get("MKL_CBWR")}
