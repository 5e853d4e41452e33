"""Triggers of your own: a policy object handed to :func:`etmpc.evaluate`, or ``py:MODULE:NAME`` on the
command line (a class or factory, importable from where you run etmpc).

A policy is anything with ``spec`` (its name, a string), ``stochastic`` (a bool: does ``decide`` draw
from the generator it is given?) and ``decide(s, rng) -> bool`` (True: recompute now), deciding from an
:class:`etmpc.loop.AugmentedState`. Optional: ``observes = False`` when ``decide`` never reads
``s.observation``, and ``simulates = True`` for a policy that needs the loop's whole state
(``s.context``). :func:`checked` wraps one so that whatever goes wrong inside it is one line that names
it: a ``decide`` that raises or answers anything but a bool.

Policies run in worker processes: they must pickle, so define their class in a module (or in a script
under ``if __name__ == "__main__":``), not inside a function.
"""

from __future__ import annotations

import importlib
import os
import sys
from dataclasses import dataclass
from typing import Any

import numpy as np

from etmpc.common.errors import EtmpcError
from etmpc.loop import AugmentedState, Policy


def check_policy(policy: Any, where: str) -> None:
    """Raise :class:`EtmpcError` unless ``policy`` has the members a policy needs."""
    problems = []
    if not isinstance(getattr(policy, "spec", None), str) or not getattr(policy, "spec", ""):
        problems.append("a non-empty str `spec`")
    if not isinstance(getattr(policy, "stochastic", None), (bool, np.bool_)):
        problems.append("a bool `stochastic`")
    if not callable(getattr(policy, "decide", None)):
        problems.append("a method `decide(s, rng) -> bool`")
    if problems:
        raise EtmpcError(f"{where} is not a policy: it needs {', '.join(problems)} ({type(policy).__name__} has not)")


@dataclass(eq=False)
class Checked:
    """``policy`` with its answers checked: an exception or a non-bool answer in ``decide`` is an
    :class:`EtmpcError` naming the policy. Its ``spec`` is ``name``: the policy's own spec, or the
    ``py:MODULE:NAME`` it was loaded by."""

    policy: Any
    name: str

    @property
    def spec(self) -> str:
        return self.name

    @property
    def stochastic(self) -> bool:
        return bool(self.policy.stochastic)

    @property
    def observes(self) -> bool:
        return bool(getattr(self.policy, "observes", True))

    @property
    def simulates(self) -> bool:
        return bool(getattr(self.policy, "simulates", False))

    def decide(self, s: AugmentedState, rng: np.random.Generator) -> bool:
        try:
            answer = self.policy.decide(s, rng)
        except EtmpcError:
            raise
        except Exception as exc:  # the user's code: any error becomes one line naming it
            raise EtmpcError(f"policy {self.name}: decide raised {type(exc).__name__}: {exc}") from None
        if not isinstance(answer, (bool, np.bool_)):
            raise EtmpcError(f"policy {self.name}: decide must return a bool (True: recompute), "
                             f"it returned {type(answer).__name__} {answer!r}")
        return bool(answer)


def checked(policy: Any, name: str | None = None) -> Policy:
    """``policy`` (a policy object) checked on entry and at every decision."""
    if isinstance(policy, Checked):
        return policy
    name = name or str(getattr(policy, "spec", type(policy).__name__))
    check_policy(policy, f"policy {name}")
    return Checked(policy, name)


def load_user(spec: str) -> Policy:
    """``py:MODULE:NAME``: ``NAME`` from ``MODULE`` (importable from the working directory or
    ``sys.path``), called with no arguments if it is a class or a factory, checked."""
    target = spec[len("py:"):]
    module_name, _, name = target.rpartition(":")
    if not module_name or not name:
        raise EtmpcError(f"bad policy {spec!r}: use py:MODULE:NAME (a class or factory of a policy)")
    if os.getcwd() not in sys.path:  # as `python -m` does: your modules beside you are importable
        sys.path.insert(0, os.getcwd())
    try:
        module = importlib.import_module(module_name)
    except Exception as exc:
        raise EtmpcError(f"policy {spec}: cannot import {module_name} ({type(exc).__name__}: {exc})") from None
    try:
        factory = getattr(module, name)
    except AttributeError:
        raise EtmpcError(f"policy {spec}: {module_name} has no {name}") from None
    if callable(factory) and not callable(getattr(factory, "decide", None)) or isinstance(factory, type):
        try:
            policy = factory()
        except Exception as exc:
            raise EtmpcError(f"policy {spec}: {name}() raised {type(exc).__name__}: {exc}") from None
    else:
        policy = factory
    return checked(policy, spec)
