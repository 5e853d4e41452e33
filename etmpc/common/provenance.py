"""What made a generated file: the checkout's commit, whether it had uncommitted changes, and the date;
and which rounding of the C library's elementary functions this machine has (:func:`libm_rounding`)."""

from __future__ import annotations

import datetime
import math
import subprocess

from etmpc.common.resources import data_root


def commit_and_date() -> dict:
    """``{"commit", "uncommitted_changes", "date"}`` of the checkout etmpc runs from (the repository's
    ``git``; an installed copy says it is not a checkout)."""

    def git(*args: str) -> str | None:
        try:
            done = subprocess.run(["git", *args], cwd=data_root(), capture_output=True, text=True, timeout=10)
        except (OSError, subprocess.SubprocessError):
            return None
        return done.stdout.strip() if done.returncode == 0 else None

    commit = git("rev-parse", "--short", "HEAD")
    dirty = bool(git("status", "--porcelain", "--untracked-files=no")) if commit else None
    return {
        "commit": commit or "(not a git checkout)",
        "uncommitted_changes": dirty,
        "date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
    }


# Three arguments whose sine glibc's FMA and SSE2 variants round differently (found among 10^6 uniform
# arguments in [-4, 4], glibc 2.36): (x, sin x with FMA, sin x without), as float.hex writes them.
_SINE_PROBES = (
    ("0x1.9621cd950e400p-2", "0x1.8b91620766e00p-2", "0x1.8b91620766e01p-2"),
    ("0x1.41dd7a7ec3f20p+1", "0x1.2c688d4c2d16dp-1", "0x1.2c688d4c2d16ep-1"),
    ("-0x1.30f3afc48044cp+0", "-0x1.db8e70413c12fp-1", "-0x1.db8e70413c12ep-1"),
)
LIBM_WORDS = {
    "fma": "glibc's FMA variants (an x86-64 CPU with fused multiply-add)",
    "sse2": "glibc's SSE2 variants (an x86-64 CPU without fused multiply-add)",
    "other": "neither of glibc's x86-64 variants (another C library or CPU)",
}


def libm_rounding() -> str:
    """Which variant of the C library's ``sin`` (and with it ``cos``, ``exp``, ``log``) this process calls,
    as MuJoCo and the MPCs' compiled code call it: ``"fma"`` or ``"sse2"`` (glibc picks one by the CPU), or
    ``"other"``. The kicks tasks', the reacher's and the quadrotor's numbers replay bit for bit only between
    machines of the same answer (``docs/using.md``)."""
    found = tuple(math.sin(float.fromhex(x)).hex() for x, _, _ in _SINE_PROBES)
    if found == tuple(fma for _, fma, _ in _SINE_PROBES):
        return "fma"
    return "sse2" if found == tuple(sse2 for _, _, sse2 in _SINE_PROBES) else "other"
