"""The systems the benchmark knows, by domain name."""

from __future__ import annotations

import importlib

from etmpc.errors import UnknownNameError

# Domain name -> "module:class" of its control-loop adapter (see etmpc.loop.System).
_SYSTEMS = {
    "cart_pendulum": "etmpc.cart_pendulum.system:CartPendulumSystem",
    "battery": "etmpc.battery.system:BatterySystem",
}


def names() -> tuple[str, ...]:
    return tuple(_SYSTEMS)


def check_name(domain: str) -> None:
    """Raise :class:`UnknownNameError`, listing the valid names, unless ``domain`` is known."""
    if domain not in _SYSTEMS:
        raise UnknownNameError(f"unknown task {domain!r}; valid: {', '.join(_SYSTEMS)}")


def make_system(domain: str):
    check_name(domain)
    module, cls = _SYSTEMS[domain].split(":")
    return getattr(importlib.import_module(module), cls)()
