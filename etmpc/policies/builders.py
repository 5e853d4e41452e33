"""A kind of policy (:class:`Kind`: its name, syntax and builder), what a builder may use (:class:`Context`), and
how each built-in kind that wraps no other reads its argument: ``always``, ``never``, ``every:T``, ``iterate:T[:K]``,
``threshold:X[:iterate][:reading]`` and the kinds that name a file (``rl:``, ``self:``, ``sb3:``). A builder is
``build(arg, spec, context)`` and raises :class:`~etmpc.common.errors.EtmpcError` with a one-line message on bad
input. The registry of kinds, its parser and the kinds that wrap another (``shield:``, ``rollout:``, ``oracle:``)
are :mod:`etmpc.policies.specs`' (which gives ``Kind`` and ``Context`` to plugins too).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from etmpc.common.documents import loads
from etmpc.common.errors import EtmpcError
from etmpc.loop import Policy
from etmpc.policies.fixed import Every, Iterate
from etmpc.policies.learned import load_policy
from etmpc.policies.threshold import Threshold
from etmpc.systems.capabilities import ShieldRule


@dataclass(frozen=True)
class Context:
    """What a kind's builder may use: the task's ``error_weights`` (the diagonal of W), its name
    (``task``, for policy files made for one task), the episode's length, and ``parse`` for a kind that
    wraps another policy (``rollout:BASE``)."""

    error_weights: np.ndarray
    task: str | None
    steps: int
    parse: Callable[[str], Policy]
    levels: bool = False  # the task's decisions are compute levels (keep, one SQP iteration, a full solve)
    variant_of: str | None = None  # the task whose world this one plays with time in the loop: its rl: files fit
    shield: ShieldRule | None = None  # the task's own shield rule (shield:BASE)
    safety_margin: Callable[[np.ndarray], float] | None = None  # the task's margin to a safety failure


@dataclass(frozen=True)
class Kind:
    """A kind of policy: ``build(arg, spec, context)`` makes one from the text after the first colon
    (``""`` when there is none), raising :class:`EtmpcError` with a one-line message on bad input."""

    name: str
    syntax: str  # how a spec of this kind is written, for the help and errors ("every:T")
    summary: str  # one line: what it does
    build: Callable[[str, str, Context], Policy]
    clairvoyant: bool = False  # True: it knows each episode's future; a reference, not a policy
    family: str = "other"  # periodic, event, learned, shielded, self, rollout, oracle, users, other: how tables group it
    path: bool = False  # its argument is a file (rl:PATH): tables shorten it
    simulates: bool = False  # it simulates the loop itself, so it may not be another such kind's base
    wraps: bool = False  # its argument holds another policy's spec (shield:AGE:BASE): what it reads, the base reads too


def number(text: str, kind: type, spec: str):
    try:
        if text != text.strip():  # int(" 3") is 3, but "every: 3" is not how a spec is written
            raise ValueError(text)
        return kind(text)
    except ValueError:
        raise EtmpcError(f"bad policy {spec!r}: {text!r} is not a{'n integer' if kind is int else ' number'}") from None


def no_argument(policy: type) -> Callable[[str, str, Context], Policy]:
    def build(arg: str, spec: str, context: Context) -> Policy:
        if arg:
            raise EtmpcError(f"bad policy {spec!r}: {spec.partition(':')[0]!r} takes no argument")
        return policy()

    return build


def every(arg: str, spec: str, context: Context) -> Policy:
    period = number(arg, int, spec)
    if period < 1:
        raise EtmpcError(f"bad policy {spec!r}: the period must be a whole number of steps >= 1")
    return Every(period)


def iterate(arg: str, spec: str, context: Context) -> Policy:
    if not context.levels:
        raise EtmpcError(
            f"bad policy {spec!r}: one SQP iteration is a compute level, and task {context.task} has none "
            "(its decisions are keep or solve)"
        )
    text, colon, rest = arg.partition(":")
    period = number(text, int, spec)
    if period < 1:
        raise EtmpcError(f"bad policy {spec!r}: the period must be a whole number of steps >= 1")
    count = number(rest, int, spec) if colon else 1
    if count < 1:
        raise EtmpcError(f"bad policy {spec!r}: the SQP iterations at a time must be a whole number >= 1")
    return Iterate(period, count)


def threshold(arg: str, spec: str, context: Context) -> Policy:
    text, *modifiers = arg.split(":")
    level = number(text, float, spec)
    if not (math.isfinite(level) and level >= 0):
        raise EtmpcError(f"bad policy {spec!r}: the threshold must be a finite number >= 0")
    reads = modifiers[-1:] == ["reading"]
    answer = ":".join(modifiers[:-1] if reads else modifiers)
    if answer not in ("", "iterate"):
        raise EtmpcError(
            f"bad policy {spec!r}: after the threshold only ':iterate' (one SQP iteration) and then ':reading' "
            "(the error on the sensor's readings) may follow"
        )
    if answer and not context.levels:
        raise EtmpcError(
            f"bad policy {spec!r}: one SQP iteration is a compute level, and task {context.task} has none "
            "(its decisions are keep or solve): write threshold:X"
        )
    return Threshold(level, np.asarray(context.error_weights, dtype=float), iterate=bool(answer), reads=reads)


def learned(path: str, context: Context) -> Policy:
    """An ``rl:`` file made for the task, or for the task a timing variant plays with time in the loop
    (the same world and features: the learner trained at latency 0, played late)."""
    task = context.task
    if context.variant_of is not None and task is not None and _trained_on(path) == context.variant_of:
        task = context.variant_of
    return load_policy(path, task, nx=len(context.error_weights))


def _trained_on(path: str) -> str | None:
    """The task a policy file says it was made for (None if it cannot say: load_policy says why)."""
    try:
        data = loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return data.get("domain") if isinstance(data, dict) else None


def file_kind(load: Callable[[str, Context], Policy], what: str) -> Callable[[str, str, Context], Policy]:
    def build(arg: str, spec: str, context: Context) -> Policy:
        if not arg:
            raise EtmpcError(f"bad policy {spec!r}: give the {what} file, {spec.partition(':')[0]}:PATH")
        return load(arg, context)

    return build
