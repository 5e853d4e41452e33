"""A MuJoCo plant from its MJCF file in ``models/``, under a plant setting: ``mismatched`` (the file as it
is, unlike the MPC's predictor on purpose) or ``matched`` (edited to agree with the predictor, which a
test then checks: it pins down the sign conventions)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from dm_control import mjcf

from etmpc.common.errors import UnknownNameError
from etmpc.common.resources import model_path

PLANTS = ("mismatched", "matched")


def load_plant(
    file: str | Path, plant: str, matched: Callable[[mjcf.RootElement], None], timestep_s: float | None = None
) -> mjcf.RootElement:
    """The MJCF ``file`` (a name in etmpc's ``models/``, or a path: a plugin's own), edited by
    ``matched(root)`` under the ``matched`` setting; ``timestep_s`` replaces the physics step."""
    if plant not in PLANTS:
        raise UnknownNameError(f"unknown plant setting {plant!r}; valid: {', '.join(PLANTS)}")
    root = mjcf.from_path(str(file if isinstance(file, Path) else model_path(file)))
    if plant == "matched":
        matched(root)
    if timestep_s is not None:
        root.option.timestep = timestep_s
    return root
