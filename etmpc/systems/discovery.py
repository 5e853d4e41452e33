"""The domains of tasks: etmpc's own (:data:`BUILT_IN`) and those of other installed packages (the ``etmpc.tasks``
entry points), found by name, and where a domain keeps its stored data. What a domain's package names is
:mod:`etmpc.systems.registry`'s docstring; the tasks inside the domains are the registry's.

A plugin that fails to import (whatever its code raises, ``SystemExit`` too; only a real Ctrl-C or SIGTERM stops
the command), or does not name its tasks, gives one one-line warning naming it; every other task still works.
"""

from __future__ import annotations

import importlib
import warnings
from functools import cache
from importlib.metadata import entry_points
from pathlib import Path
from types import ModuleType

from etmpc.common import interrupts
from etmpc.common.errors import EtmpcError, UnknownNameError
from etmpc.common.resources import tasks_dir

# Domain name -> its package: a new domain of etmpc's own is a folder beside these and one line here.
BUILT_IN = {
    "cart_pendulum": "etmpc.systems.cart_pendulum",
    "battery": "etmpc.systems.battery",
    "reacher": "etmpc.systems.reacher",
    "quadrotor": "etmpc.systems.quadrotor",
}
ENTRY_POINTS = "etmpc.tasks"


def lazy(module: str, systems: dict[str, str], suite: str):
    """A domain package's module ``__getattr__``: ``SYSTEMS`` (task -> ``"module:Class"``) and ``SUITE``
    (``"module:NAME"``) imported when first asked, so that naming the tasks loads neither MuJoCo nor
    dm-control (they pick their OpenGL backend on import)."""

    def load(target: str):
        name, _, attribute = target.partition(":")
        return getattr(importlib.import_module(name), attribute)

    def __getattr__(name: str):
        if name == "SYSTEMS":  # task -> the System class the loop plays
            return {task: load(target) for task, target in systems.items()}
        if name == "SUITE":  # the dm-control task factories, as a dm_control.suite domain has them
            return load(suite)
        raise AttributeError(f"module {module!r} has no attribute {name!r}")

    return __getattr__


def _problem(package: ModuleType) -> str | None:
    """What is wrong with a domain's package, or None."""
    tasks = getattr(package, "TASKS", None)
    if not (isinstance(tasks, tuple) and tasks and all(isinstance(t, str) and t and "/" not in t for t in tasks)):
        return "its TASKS is not a non-empty tuple of task names"
    seeds = getattr(package, "TEST_SET_SEEDS", None)
    if not (isinstance(seeds, dict) and set(seeds) <= set(tasks)):
        return "its TEST_SET_SEEDS is not a dict of its tasks' seeds"
    return None


@cache
def domains() -> dict[str, ModuleType]:
    """Every domain's package by name: etmpc's own, then the installed plugins' (``etmpc.tasks``)."""
    found = {name: importlib.import_module(package) for name, package in BUILT_IN.items()}
    with interrupts.watching():  # a Ctrl-C is told apart from a KeyboardInterrupt a plugin raises
        for point in sorted(entry_points(group=ENTRY_POINTS), key=lambda p: p.name):
            where = f"task plugin {point.name!r} ({point.value})"
            problem: str | None
            if point.name in found or not point.name.isidentifier():
                problem = "names a domain etmpc already has" if point.name in found else "is not a valid domain name"
            else:
                try:  # the plugin's code: whatever it raises (SystemExit too) leaves the other tasks working
                    package = point.load()
                    problem = _problem(package)
                except BaseException as exc:
                    if not isinstance(exc, EtmpcError) and interrupts.genuine(exc):  # a real Ctrl-C or SIGTERM
                        raise
                    problem = f"failed to import ({interrupts.described(exc)})"
                else:
                    if problem is None:
                        found[point.name] = package
                        continue
            warnings.warn(f"etmpc: {where} {problem}; its tasks are left out", RuntimeWarning, stacklevel=2)
    return found


def domain(name: str) -> ModuleType:
    """The package of domain ``name`` (raises :class:`UnknownNameError`, listing the valid names)."""
    packages = domains()
    if name not in packages:
        raise UnknownNameError(f"unknown domain {name!r}; valid: {', '.join(packages)}")
    return packages[name]


def data_dir(domain_name: str) -> Path:
    """The folder of a domain's stored test sets and references."""
    data = getattr(domain(domain_name), "DATA", None)
    return Path(data) if data is not None else tasks_dir() / domain_name
