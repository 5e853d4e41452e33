"""Are evaluations the same, byte for byte, whatever numerical kernels the CPU selects?

Plays the same policies on the first test-set episodes of every task of the suite once per *kernel
setting* and compares the evaluation JSONs byte for byte. A setting is what
another x86-64 machine would run with the same packages, forced on this one through the libraries' own
switches:

* ``OPENBLAS_CORETYPE``: OpenBLAS's kernels (``Prescott``: SSE3, no FMA; ``Haswell``: AVX2 + FMA;
  ``SkylakeX``: AVX-512);
* ``NPY_DISABLE_CPU_FEATURES``: numpy's own vectorised loops (its dispatch targets above the baseline);
* ``GLIBC_TUNABLES=glibc.cpu.hwcaps=...``: which variant of libm's exp, sin, cos, log glibc picks.

Only settings this CPU can run are tried. One kind of difference is known, and reported, not failed
(:data:`EXPECTED`): libm without FMA, on the kicks tasks (the noisy one too), the reacher's and the quadrotors'. Their MPCs'
generated C calls ``sin`` and ``cos`` (the quadrotor's also ``tan``, ``exp``, ``log``, ``log1p``) hundreds
of times per linearisation (the balance task's too, but its episodes here come out the same; the
battery's MPC calls none), and glibc's FMA variants (picked on every x86-64 CPU with FMA: Intel since Haswell,
AMD since Piledriver) round about one argument in 1,500 differently from its SSE2 ones. Machines with FMA
replay the evaluations byte for byte; one without does not (docs/using.md gives the sizes measured).

Usage::

    python scripts/kernel_check.py [--episodes 4]
    python scripts/kernel_check.py --ppo

prints one line per setting and exits 1 if any evaluation differs from the default one, other than
an expected difference. A setting's
run is this script with ``--digest``: it prints the sha256 of each system's evaluation JSON.

``--ppo`` asks the same of PPO training (the ``rl`` extra): a short run on the balance task, once with the
CPU's own PyTorch kernels and once with ``kernels=portable`` (:mod:`etmpc.learning.kernels`), under each
setting above plus MKL's and ATen's own switches (``MKL_ENABLE_INSTRUCTIONS``, ``ATEN_CPU_CAPABILITY``); it
compares the trained networks' bytes, and exits 1 if the portable ones differ.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import platform
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
NO_FMA = "no FMA: OpenBLAS Prescott, numpy baseline, libm without AVX2/FMA"
# (system, setting) pairs that differ by a known cause (the module's docstring): reported, not failed
OTHER_TASKS = ("cart_pendulum/kicks", "cart_pendulum/kicks_late", "cart_pendulum/kicks_levels", "reacher", "reacher/jumps_late")
# The noisy variants: a schedule and the shipped DPI, and on kicks_noisy the rollout meter, which starts its
# futures from states drawn from the filter's belief and compares close returns (under NumPy's filter on BLAS it
# decided otherwise under other kernels; the filter is CasADi's, run as C, since kicks_noisy v1 and
# waypoints_noisy v1). The quadrotor's meter (rollout:every:7:2:3) also replays the same on every setting, but
# costs 13 s per setting: add it here for a run by hand.
NOISY = {"cart_pendulum/kicks_noisy": ("every:4", "rollout:every:4:2:5"), "quadrotor/waypoints_noisy": ("every:7",)}
EXPECTED = {(task, NO_FMA) for task in ("quadrotor", *OTHER_TASKS, *NOISY)}  # their MPCs call libm from generated C


def cpu_flags() -> set[str]:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("flags"):
                return set(line.split(":", 1)[1].split())
    except OSError:
        pass
    return set()


def numpy_dispatch() -> list[str]:
    """numpy's dispatch targets (above its baseline), as ``NPY_DISABLE_CPU_FEATURES`` names them."""
    try:
        from numpy._core._multiarray_umath import __cpu_dispatch__
    except ImportError:  # numpy < 2
        from numpy.core._multiarray_umath import __cpu_dispatch__
    return list(__cpu_dispatch__)


def settings() -> dict[str, dict[str, str]]:
    """Kernel settings this CPU can run: name -> environment."""
    if platform.machine().lower() not in ("x86_64", "amd64"):
        return {"default": {}}
    flags = cpu_flags()
    dispatch = numpy_dispatch()
    wide = [t for t in dispatch if t.startswith(("X86_V4", "AVX512"))]
    chosen = {"default": {}}
    chosen["SSE: OpenBLAS Prescott, numpy baseline loops"] = {
        "OPENBLAS_CORETYPE": "Prescott",
        "NPY_DISABLE_CPU_FEATURES": " ".join(dispatch),
    }
    if {"avx2", "fma"} <= flags:
        chosen["AVX2 machine: OpenBLAS Haswell, numpy and libm without AVX-512"] = {
            "OPENBLAS_CORETYPE": "Haswell",
            "NPY_DISABLE_CPU_FEATURES": " ".join(wide),
            "GLIBC_TUNABLES": "glibc.cpu.hwcaps=-AVX512F,-AVX512DQ,-AVX512BW,-AVX512VL,-AVX512CD",
        }
        chosen[NO_FMA] = {
            "OPENBLAS_CORETYPE": "Prescott",
            "NPY_DISABLE_CPU_FEATURES": " ".join(dispatch),
            "GLIBC_TUNABLES": "glibc.cpu.hwcaps=-AVX2,-FMA,-AVX512F,-AVX",
        }
    if {"avx512f", "avx512dq", "avx512bw", "avx512vl", "avx512cd"} <= flags:
        chosen["AVX-512 machine: OpenBLAS SkylakeX"] = {"OPENBLAS_CORETYPE": "SkylakeX"}
    return chosen


def ppo_settings() -> dict[str, dict[str, str]]:
    """:func:`settings`, with PyTorch's own switches as that machine would take them (MKL's widest
    instructions, ATen's vector width)."""
    chosen = settings()
    widths = {
        "SSE": ("SSE4_2", "default"),
        "no FMA": ("SSE4_2", "default"),
        "AVX2": ("AVX2", "avx2"),
        "AVX-512": ("AVX512", "avx512"),
    }
    for name, env in chosen.items():
        for prefix, (mkl, aten) in widths.items():
            if name.startswith(prefix):
                env.update(MKL_ENABLE_INSTRUCTIONS=mkl, ATEN_CPU_CAPABILITY=aten)
    return chosen


def ppo_digest(kernels: str) -> str:
    """The sha256 of a short PPO run's network, trained in this process with PyTorch's ``kernels``."""
    from etmpc.learning.ppo import train_ppo
    from etmpc.learning.ppo_settings import PpoSettings

    settings = PpoSettings(timesteps=1024, n_steps=256, batch_size=128, checkpoints=1, validation_episodes=2, kernels=kernels)
    with tempfile.TemporaryDirectory() as tmp:
        train_ppo("cart_pendulum/balance", Path(tmp) / "run", settings)
        return hashlib.sha256((Path(tmp) / "run" / "selected.zip").read_bytes()).hexdigest()


def compare_ppo() -> dict[str, dict[str, str]]:
    """Each setting's :func:`ppo_digest` per kernel setting, each in a fresh interpreter (PyTorch reads its switches
    when it loads)."""
    found: dict[str, dict[str, str]] = {}
    for name, env in ppo_settings().items():
        for kernels in ("native", "portable"):
            result = subprocess.run(
                [sys.executable, __file__, "--ppo-digest", kernels],
                env={**os.environ, **env},
                capture_output=True,
                text=True,
                check=True,
            )
            found.setdefault(name, {})[kernels] = result.stdout.strip().splitlines()[-1]
    return found


SELF_TRIGGER_FEATURES = {"cart_pendulum": 4 + 4 + 4 + 1 + 1, "battery": 1 + 1 + 1 + 1 + 1 + 4}


def _self_trigger(path: Path, domain: str) -> str:
    """A self-trigger whose announcements depend on the plan (random but fixed parameters)."""
    import numpy as np

    from etmpc.common.outputs import write_json
    from etmpc.policies.selftrigger import CANDIDATES, SelfTrigger

    p = SELF_TRIGGER_FEATURES[domain]
    theta = np.random.default_rng(5).normal(size=(len(CANDIDATES), 1 + p))
    write_json(path, SelfTrigger(str(path), domain, CANDIDATES, theta, np.zeros(p), np.ones(p)).to_json())
    return f"self:{path}"


def digests(episodes: int, skip: tuple[str, ...] = ()) -> dict[str, str]:
    """The sha256 of each system's evaluation JSON (but the ``skip``'s), played in this process."""
    from etmpc.evaluation.evaluate import evaluate
    from etmpc.systems import folder_name

    policies = {
        "cart_pendulum": [
            "always",
            "every:3",
            "threshold:0.3",
            f"rl:{ROOT / 'policies/cart_pendulum/balance/learned.json'}",
            "rollout:every:3:2:5",
        ],
        "battery": ["every:3", "threshold:0.01", f"rl:{ROOT / 'policies/battery/trading/learned.json'}", "rollout:always:2:5"],
        "quadrotor": ["every:7", "threshold:0.5", f"rl:{ROOT / 'policies/quadrotor/waypoints/learned.json'}"],
        # the other tasks: their kicks, jumps, latency and compute levels, with a schedule and the shipped DPI
        **{task: ["every:3", f"rl:{ROOT / 'policies' / folder_name(task) / 'learned.json'}"] for task in OTHER_TASKS},
        **{
            task: [first, f"rl:{ROOT / 'policies' / folder_name(task) / 'learned.json'}", *rest]
            for task, (first, *rest) in NOISY.items()
        },
    }
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        for domain, specs in [(d, specs) for d, specs in policies.items() if d not in skip]:
            if domain in SELF_TRIGGER_FEATURES:
                specs = specs + [_self_trigger(Path(tmp) / f"self_{domain}.json", domain)]
            text = json.dumps(evaluate(domain, specs, episodes=episodes, workers=1, progress=False).to_json())
            out[domain] = hashlib.sha256(text.replace(tmp, "TMP").encode()).hexdigest()  # the file's name is no result
    return out


def compare(episodes: int = 4, expected: bool = True) -> dict[str, dict[str, str]]:
    """Each setting's digests, computed in a fresh interpreter under that setting's environment; without
    ``expected``, not those of the systems :data:`EXPECTED` to differ under it (they could fail nothing)."""
    found = {}
    for name, env in settings().items():
        skip = [] if expected else [f"--skip={task}" for task, setting in sorted(EXPECTED) if setting == name]
        result = subprocess.run(
            [sys.executable, __file__, "--digest", "--episodes", str(episodes), *skip],
            env={**os.environ, **env},
            capture_output=True,
            text=True,
            check=True,
        )
        found[name] = json.loads(result.stdout.strip().splitlines()[-1])
    return found


def unexpected(found: dict[str, dict[str, str]]) -> dict[str, list[str]]:
    """Setting -> the systems whose evaluations differ from the default setting's, other than :data:`EXPECTED`."""
    reference = found["default"]
    return {
        name: differing
        for name, values in found.items()
        if (differing := [d for d, v in values.items() if v != reference[d] and (d, name) not in EXPECTED])
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--episodes", type=int, default=4, help="first N test-set episodes per system (default 4)")
    parser.add_argument("--digest", action="store_true", help="print this process's digests as JSON (one setting)")
    parser.add_argument("--skip", action="append", default=[], metavar="SYSTEM", help="with --digest: not this system")
    parser.add_argument("--ppo", action="store_true", help="compare PPO training's networks instead (the rl extra)")
    parser.add_argument("--ppo-digest", choices=("native", "portable"), help="print one PPO run's digest (one setting)")
    args = parser.parse_args()
    if args.digest:
        print(json.dumps(digests(args.episodes, tuple(args.skip))))
        return 0
    if args.ppo_digest:
        print(ppo_digest(args.ppo_digest))
        return 0
    if args.ppo:
        found = compare_ppo()
        for name, values in found.items():
            print(f"{name}: " + ", ".join(f"{k} {v[:12]}" for k, v in values.items()))
        portable = {values["portable"] for values in found.values()}
        native = {values["native"] for values in found.values()}
        print(f"portable: {len(portable)} network(s) over {len(found)} settings; native: {len(native)}")
        return 0 if len(portable) == 1 else 1
    found = compare(args.episodes)
    reference, failed = found["default"], unexpected(found)
    for name, values in found.items():
        verdict = "DIFFERS" if name in failed else "same" if values == reference else "expected"
        print(f"{verdict:8s} {name}: " + ", ".join(f"{d} {v[:12]}" for d, v in values.items()))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
