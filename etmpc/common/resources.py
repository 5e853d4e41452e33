"""Where the model files and stored test sets live.

In a source checkout (and an editable install) they are the repository's ``models/`` and
``tasks/`` folders; a built wheel carries the same folders as package data in ``etmpc/_data``.
"""

from __future__ import annotations

from pathlib import Path

_PACKAGE = Path(__file__).resolve().parents[1]  # etmpc/


def data_root() -> Path:
    installed = _PACKAGE / "_data"
    return installed if installed.is_dir() else _PACKAGE.parent


def model_path(name: str) -> Path:
    """Path of an MJCF file in ``models/``."""
    return data_root() / "models" / name


def tasks_dir() -> Path:
    """The folder of stored test sets (``tasks/``)."""
    return data_root() / "tasks"
