"""The tasks of the benchmark, and the registry that finds them by name.

One folder per domain (``cart_pendulum/``, ``battery/``), registered by one line in :data:`DOMAINS`.
A domain's package names its ``TASKS`` (the default first) and exports ``SUITE``, its dm-control task
factories (as a ``dm_control.suite`` domain does), and ``SYSTEMS``, task name -> the
:class:`~etmpc.systems.base.System` class the control loop plays; those two load MuJoCo and
dm-control when first asked, so that naming the tasks loads neither. :mod:`etmpc.systems.base` says what a system provides, feature by
feature; ``docs/adding-a-task.md`` says in which order to write one.

A system is built from its *key*: ``DOMAIN`` (its default task) or ``DOMAIN/TASK``, followed by
``@PRICE`` for another price of a computation (:func:`system_key`). Jobs carry the key, so every
worker builds the same system, and a sweep over prices needs nothing else.

This package may import ``etmpc.common`` and ``etmpc.control``.
"""

from __future__ import annotations

import importlib
import math
from dataclasses import replace
from types import ModuleType

from etmpc.common.errors import EtmpcError, UnknownNameError

# Domain name -> its package. A new domain is a folder beside these and one line here.
DOMAINS = {
    "cart_pendulum": "etmpc.systems.cart_pendulum",
    "battery": "etmpc.systems.battery",
    "reacher": "etmpc.systems.reacher",
}


def domain(name: str) -> ModuleType:
    """The package of domain ``name`` (raises :class:`UnknownNameError`, listing the valid names)."""
    if name not in DOMAINS:
        raise UnknownNameError(f"unknown domain {name!r}; valid: {', '.join(DOMAINS)}")
    return importlib.import_module(DOMAINS[name])


def names() -> tuple[str, ...]:
    """The task names the command line takes: ``DOMAIN`` for a domain's default task, ``DOMAIN/TASK``
    for the others."""
    found = []
    for name in DOMAINS:
        tasks = list(domain(name).TASKS)
        found += [name] + [f"{name}/{task}" for task in tasks[1:]]
    return tuple(found)


def _parse(name: str) -> tuple[str, str]:
    """``(domain, task)`` of a task name (``DOMAIN`` or ``DOMAIN/TASK``)."""
    domain_name, _, task = name.partition("/")
    if domain_name not in DOMAINS:
        raise UnknownNameError(f"unknown task {name!r}; valid: {', '.join(names())}")
    tasks = list(domain(domain_name).TASKS)
    if task and task not in tasks:
        raise UnknownNameError(f"unknown task {name!r}; valid: {', '.join(names())}")
    return domain_name, task or tasks[0]


def check_name(name: str) -> None:
    """Raise :class:`UnknownNameError`, listing the valid names, unless ``name`` is a known task."""
    _parse(name)


def canonical(name: str) -> str:
    """``DOMAIN`` for a domain's default task (however it was named), else ``DOMAIN/TASK``."""
    domain_name, task = _parse(name)
    return domain_name if task == domain(domain_name).TASKS[0] else f"{domain_name}/{task}"


def distinct(names_given) -> list[str]:
    """The tasks named, canonical, each once: a task named twice (even as ``battery`` and
    ``battery/trading``) is refused, naming it; an unknown name is refused, listing the valid ones."""
    tasks: list[str] = []
    for name in names_given:
        task = canonical(name)
        if task in tasks:
            raise EtmpcError(f"task {task} is given twice")
        tasks.append(task)
    return tasks


def folder_name(name: str) -> str:
    """A task's name as one folder: ``DOMAIN`` for a domain's default task, else ``DOMAIN-TASK``."""
    return canonical(name).replace("/", "-")


def check_price(price: float) -> float:
    """A price of a computation: a finite number >= 0 (in the objective's unit)."""
    price = float(price)
    if not (math.isfinite(price) and price >= 0.0):
        raise EtmpcError(f"the price of a computation must be a finite number >= 0, got {price}")
    return price


def system_key(name: str, recompute_price: float | None = None) -> str:
    """The key of task ``name`` (see the module's docstring), ``@PRICE`` when the price of a
    computation is not the system's default."""
    key = canonical(name)
    return key if recompute_price is None else f"{key}@{check_price(recompute_price)!r}"


def system_class(name: str) -> type:
    """The :class:`~etmpc.systems.base.System` class of task ``name`` (``DOMAIN`` or ``DOMAIN/TASK``)."""
    domain_name, task = _parse(name)
    return domain(domain_name).SYSTEMS[task]


def make_system(key: str):
    """The system of ``key`` (a task name, optionally ``@PRICE``: see :func:`system_key`)."""
    name, priced, price = key.partition("@")
    domain_name, task = _parse(name)
    cls = domain(domain_name).SYSTEMS[task]
    config = cls.Config()
    if priced:
        config = replace(config, recompute_price=check_price(price))
    return cls(config)
