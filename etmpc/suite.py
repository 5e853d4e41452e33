"""dm-control style suite: ``etmpc.suite.load(domain, task)`` returns a ready environment.

>>> env = load("cart_pendulum", "balance", task_kwargs={"random": 0})
"""

from __future__ import annotations

import importlib
from types import ModuleType

from etmpc.errors import UnknownNameError

# Domain name -> module holding a ``SUITE`` of task factories (as in dm_control.suite).
_DOMAINS = {"cart_pendulum": "etmpc.cart_pendulum.env", "battery": "etmpc.battery.env"}


def domains() -> tuple[str, ...]:
    return tuple(_DOMAINS)


def _domain(name: str) -> ModuleType:
    if name not in _DOMAINS:
        raise UnknownNameError(f"unknown domain {name!r}; valid: {', '.join(_DOMAINS)}")
    return importlib.import_module(_DOMAINS[name])


def tasks(domain_name: str) -> tuple[str, ...]:
    return tuple(_domain(domain_name).SUITE)


def load(domain_name: str, task_name: str, task_kwargs: dict | None = None, environment_kwargs: dict | None = None):
    """Build ``domain_name/task_name``. ``task_kwargs`` go to the task factory (``random``, ...)."""
    suite = _domain(domain_name).SUITE
    if task_name not in suite:
        raise UnknownNameError(f"unknown task {task_name!r} for domain {domain_name!r}; valid: {', '.join(suite)}")
    kwargs = dict(task_kwargs or {})
    if environment_kwargs is not None:
        kwargs["environment_kwargs"] = environment_kwargs
    return suite[task_name](**kwargs)
