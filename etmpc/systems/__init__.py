"""The systems the benchmark knows, by domain name.

A system is built from its *key*: the domain name, or ``DOMAIN@PRICE`` for the same system with
another price of a computation (:func:`system_key`). Jobs carry the key, so every worker builds the
same system, and a sweep over prices needs nothing else.
"""

from __future__ import annotations

import importlib
import math
from dataclasses import replace

from etmpc.common.errors import EtmpcError, UnknownNameError

# Domain name -> "module:class" of its control-loop adapter (see etmpc.loop.System); the module
# also holds the system's ``Config``.
_SYSTEMS = {
    "cart_pendulum": "etmpc.systems.cart_pendulum.system:CartPendulumSystem",
    "battery": "etmpc.systems.battery.system:BatterySystem",
}


def names() -> tuple[str, ...]:
    return tuple(_SYSTEMS)


def check_name(domain: str) -> None:
    """Raise :class:`UnknownNameError`, listing the valid names, unless ``domain`` is known."""
    if domain not in _SYSTEMS:
        raise UnknownNameError(f"unknown task {domain!r}; valid: {', '.join(_SYSTEMS)}")


def check_price(price: float) -> float:
    """A price of a computation: a finite number >= 0 (in the objective's unit)."""
    price = float(price)
    if not (math.isfinite(price) and price >= 0.0):
        raise EtmpcError(f"the price of a computation must be a finite number >= 0, got {price}")
    return price


def system_key(domain: str, recompute_price: float | None = None) -> str:
    """``domain``, or ``domain@PRICE`` when the price of a computation is not the system's default."""
    check_name(domain)
    return domain if recompute_price is None else f"{domain}@{check_price(recompute_price)!r}"


def make_system(key: str):
    """The system of ``key`` (a domain name, or ``domain@PRICE``: see :func:`system_key`)."""
    domain, priced, price = key.partition("@")
    check_name(domain)
    module, cls = _SYSTEMS[domain].split(":")
    module = importlib.import_module(module)
    config = module.Config()
    if priced:
        config = replace(config, recompute_price=check_price(price))
    return getattr(module, cls)(config)
