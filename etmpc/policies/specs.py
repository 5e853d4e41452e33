"""Policies from their command-line specs: ``always``, ``never``, ``every:T`` (T >= 1), ``threshold:X``
(X >= 0), ``rl:PATH`` (a learned policy saved by ``etmpc train``), ``self:PATH`` (a self-triggering
policy saved by ``etmpc train-self``), ``py:MODULE:NAME`` (a trigger of your own, see
:mod:`etmpc.policies.user`), ``sb3:PATH`` (a network trained on the trigger environment), ``rollout:BASE[:K[:H]]`` and the upper bound ``oracle:BASE``.

The parser sits above the policies it builds: it imports each kind, none of them imports it.
"""

from __future__ import annotations

import math

import numpy as np

from etmpc.common.errors import EtmpcError, UnknownNameError
from etmpc.policies.fixed import Always, Every, Never
from etmpc.policies.learned import load_policy
from etmpc.policies.rollout import parse_rollout
from etmpc.policies.sb3 import load_sb3
from etmpc.policies.selftrigger import load_self
from etmpc.policies.threshold import Threshold
from etmpc.policies.user import load_user
from etmpc.loop import Policy


# The kinds of policy a spec names (the text before its first colon).
KINDS = ("always", "never", "every", "threshold", "rl", "self", "py", "sb3", "rollout", "oracle")


def names_a_kind(spec: str) -> bool:
    """True if ``spec`` is written as a built-in policy's spec (``every:3``, ``oracle:...``; ``py:`` is
    the users' own kind and not counted): a policy object of someone's must not take such a name, or the
    results would show its numbers under that policy's."""
    kind = spec.partition(":")[0]
    return kind in KINDS and kind != "py"


def _number(text: str, kind: type, spec: str):
    try:
        if text != text.strip():  # int(" 3") is 3, but "every: 3" is not how a spec is written
            raise ValueError(text)
        value = kind(text)
    except ValueError:
        raise EtmpcError(f"bad policy {spec!r}: {text!r} is not a{'n integer' if kind is int else ' number'}") from None
    return value


def parse_policy(spec: str, error_weights: np.ndarray, domain: str | None = None, steps: int = 100) -> Policy:
    """Build a policy from its command-line spec; bad specs raise :class:`EtmpcError`.

    ``rl:PATH`` is checked against ``domain`` and the state size ``len(error_weights)``; ``steps``
    (the episode length) bounds a rollout's look-ahead.
    """
    if any(ord(c) < 32 or ord(c) == 127 for c in spec):  # a line break would split every table and message
        raise EtmpcError(f"bad policy {spec!r}: it holds a control character (a line break?)")
    name, _, arg = spec.partition(":")
    if name in ("rollout", "oracle"):
        return parse_rollout(spec, lambda base: parse_policy(base, error_weights, domain, steps), steps)
    if name in ("always", "never"):
        if arg:
            raise EtmpcError(f"bad policy {spec!r}: {name!r} takes no argument")
        return Always() if name == "always" else Never()
    if name == "every":
        period = _number(arg, int, spec)
        if period < 1:
            raise EtmpcError(f"bad policy {spec!r}: the period must be a whole number of steps >= 1")
        return Every(period)
    if name == "threshold":
        level = _number(arg, float, spec)
        if not (math.isfinite(level) and level >= 0):
            raise EtmpcError(f"bad policy {spec!r}: the threshold must be a finite number >= 0")
        return Threshold(level, np.asarray(error_weights, dtype=float))
    if name == "self":
        if not arg:
            raise EtmpcError(f"bad policy {spec!r}: give the policy file, self:PATH")
        return load_self(arg, domain)
    if name == "py":
        return load_user(spec)
    if name == "sb3":
        if not arg:
            raise EtmpcError(f"bad policy {spec!r}: give the model file, sb3:PATH")
        return load_sb3(arg, domain)
    if name == "rl":
        if not arg:
            raise EtmpcError(f"bad policy {spec!r}: give the policy file, rl:PATH")
        return load_policy(arg, domain, nx=len(error_weights))
    raise UnknownNameError(f"unknown policy {spec!r}; valid: always, never, every:T, threshold:X, rl:PATH, self:PATH, "
                           "py:MODULE:NAME, sb3:PATH, rollout:BASE[:K[:H]], oracle:BASE")
