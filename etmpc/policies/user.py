"""Policies of your own: a policy object handed to :func:`etmpc.evaluate`, or ``py:MODULE:NAME`` on the
command line (a class or factory, importable from where you run etmpc).

A policy is anything with ``spec`` (its name, a string), ``stochastic`` (a bool: does ``decide`` draw
from the generator it is given?) and ``decide(s, rng) -> bool`` (True: recompute now), deciding from an
:class:`etmpc.loop.AugmentedState`. Optional: ``observes = False`` when ``decide`` never reads
``s.observation``, and ``simulates = True`` for a policy that needs the loop's whole state
(``s.context``). :func:`checked` wraps one so that whatever goes wrong inside it is one line that names
it: a ``decide`` that raises anything (``SystemExit`` and ``KeyboardInterrupt`` included: only a real
Ctrl-C stops the command) or answers what its task does not take (a bool, 0 or 1; 0, 1 or 2 with compute levels).

A policy cannot change the run it is scored on: what it is shown is read-only (see
:class:`etmpc.loop.AugmentedState`), and a policy that simulates (``simulates = True``) is handed a
context whose environment is a twin of the loop's, set to the same state at each decision, never the
loop's own.

Policies run in worker processes: they must pickle, so define their class in a module (or in a script
under ``if __name__ == "__main__":``), not inside a function.
"""

from __future__ import annotations

import importlib
import os
import sys
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from etmpc.common.errors import EtmpcError
from etmpc.common.interrupts import described, failed, genuine, users_code
from etmpc.control.timing import ANSWERS, Iterations, level_of
from etmpc.loop import AugmentedState, Decision, DecisionContext, Policy


def check_policy(policy: Any, where: str) -> None:
    """Raise :class:`EtmpcError` unless ``policy`` has the members a policy needs."""
    with users_code(f"{where}: reading its members"):
        _check_members(policy, where)


def _check_members(policy: Any, where: str) -> None:
    problems = []
    spec = getattr(policy, "spec", None)
    if not isinstance(spec, str) or not spec or any(ord(c) < 32 or ord(c) == 127 for c in spec):
        problems.append("a non-empty str `spec` on one line")
    if not isinstance(getattr(policy, "stochastic", None), (bool, np.bool_)):
        problems.append("a bool `stochastic`")
    if not callable(getattr(policy, "decide", None)):
        problems.append("a method `decide(s, rng) -> bool`")
    if problems:
        raise EtmpcError(f"{where} is not a policy: it needs {', '.join(problems)} ({type(policy).__name__} has not)")


@dataclass(eq=False)
class Checked:
    """``policy`` with its answers checked: an exception in ``decide``, or an answer that is no answer on the
    task (:func:`~etmpc.control.timing.level_of`: a bool, 0 or 1; with compute ``levels`` 0, 1, 2 or an
    ``Iterations(k)`` too), is an :class:`EtmpcError` naming the policy and the answer. Its ``spec`` is
    ``name``: the policy's own spec, or the ``py:MODULE:NAME`` it was loaded by. ``levels``: whether the task
    it plays has compute levels (None: not known here; 0, 1, 2 and ``Iterations(k)`` pass, and the loop
    refuses a level its task has not)."""

    policy: Any
    name: str
    _twin: Any = field(default=None, repr=False)  # (system, environment) a simulating policy plays in
    levels: bool | None = None

    def __post_init__(self):  # read once: a property of the user's that changes cannot change the run
        self.stochastic = bool(self._member("stochastic", None))
        self.observes = bool(self._member("observes", True))
        self.simulates = bool(self._member("simulates", False))

    def _member(self, name: str, default):
        with users_code(f"policy {self.name}: reading {name}"):
            return getattr(self.policy, name) if default is None else getattr(self.policy, name, default)

    @property
    def spec(self) -> str:
        return self.name

    def __getstate__(self):  # the twin environment stays in its process
        return {k: v for k, v in self.__dict__.items() if k != "_twin"} | {"_twin": None}

    def _sandboxed(self, context: DecisionContext) -> DecisionContext:
        """``context`` with a twin of its environment, set to the loop's state: a simulating policy may
        step and change it, and the loop's own plant and episode stay as they were."""
        if self._twin is None or self._twin[0] is not context.system:
            self._twin = (context.system, context.system.make_env())
        twin = self._twin[1]
        twin.physics.restore(context.env.physics.snapshot())
        twin.task.resume(context.env.task.episode, context.step)
        return replace(context, env=twin)

    def decide(self, s: AugmentedState, rng: np.random.Generator | None) -> Decision:
        if s.context is not None:
            s = replace(s, context=self._sandboxed(s.context))
        try:
            answer = self.policy.decide(s, rng)
        except BaseException as exc:  # the user's code: anything it raises becomes one line naming it
            if genuine(exc):
                raise
            raise failed(f"policy {self.name}: decide", exc) from None
        if answer is True or answer is False:  # the common answer, at once: this is asked at every decision
            return answer
        if level_of(answer, self.levels is not False) is None:
            raise EtmpcError(
                f"policy {self.name}: decide must return a bool (True: recompute), {_EXPECTED[self.levels]}; "
                f"it returned {type(answer).__name__} {answer!r}"
            )
        if isinstance(answer, Iterations):
            return answer
        return bool(answer) if isinstance(answer, np.bool_) else int(answer)


_EXPECTED = {
    False: "or 0 or 1 (keep, a full solve) on a task without compute levels",
    True: f"or a compute level ({ANSWERS[True]})",
    None: "or on a task with compute levels 0, 1, Iterations(k) or 2 (keep, one SQP iteration, at most k, a full solve)",
}


def checked(policy: Any, name: str | None = None, levels: bool | None = None) -> Policy:
    """``policy`` (a policy object) checked on entry and at every decision; ``levels``: whether the task it
    will play has compute levels (None: not known; the loop then checks what the task takes)."""
    if isinstance(policy, Checked):
        return policy if levels is None or policy.levels == levels else replace(policy, levels=levels, _twin=None)
    if name is None:
        with users_code(f"policy {type(policy).__name__}: reading spec"):
            name = str(getattr(policy, "spec", type(policy).__name__))
    check_policy(policy, f"policy {' '.join(name.splitlines())}")
    return Checked(policy, name, levels=levels)


_MISSING = object()


def load_user(spec: str, levels: bool | None = None) -> Policy:
    """``py:MODULE:NAME``: ``NAME`` from ``MODULE`` (importable from the working directory or
    ``sys.path``), called with no arguments if it is a class or a factory, checked (its answers as a task
    with compute ``levels``, or without, takes them)."""
    target = spec[len("py:") :]
    module_name, _, name = target.rpartition(":")
    if not module_name or not name:
        raise EtmpcError(f"bad policy {spec!r}: use py:MODULE:NAME (a class or factory of a policy)")
    if os.getcwd() not in sys.path:  # as `python -m` does: your modules beside you are importable
        sys.path.insert(0, os.getcwd())
    try:
        module = importlib.import_module(module_name)
    except BaseException as exc:  # SystemExit on import included: one line, never the end of the command
        if genuine(exc):
            raise
        raise EtmpcError(f"policy {spec}: cannot import {module_name} ({described(exc)})") from None
    with users_code(f"policy {spec}: {module_name}.{name}"):  # a module-level __getattr__ of the user's may raise
        factory = getattr(module, name, _MISSING)
    if factory is _MISSING:
        raise EtmpcError(f"policy {spec}: {module_name} has no {name}")
    with users_code(f"policy {spec}: {name}()"):
        if isinstance(factory, type) or (callable(factory) and not callable(getattr(factory, "decide", None))):
            policy = factory()  # a class or a function that makes the policy
        else:
            policy = factory
    return checked(policy, spec, levels)
