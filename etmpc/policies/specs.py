"""The registry of policy kinds, and the parser it makes: a spec is ``KIND`` or ``KIND:ARG``.

Each kind is a :class:`Kind`: its name (the text before the spec's first colon), its syntax and a
line of help, whether it is clairvoyant (an oracle: it knows each episode's future), and a builder
that turns the argument into a policy. :data:`BUILT_IN` holds etmpc's own; other installed packages
add theirs through the ``etmpc.policies`` entry point group (``name = "module:KIND"``, the name being
the kind's), read once when first asked. A plugin that fails to load (whatever its code raises,
``SystemExit`` too), names a built-in kind, or is not a :class:`Kind` gives one one-line warning naming it;
every other kind still works. A plugin kind's builder that raises anything but an :class:`EtmpcError` is
one error line naming the plugin. Only a real Ctrl-C or SIGTERM goes through (:mod:`etmpc.common.interrupts`).

The registry is the only reader of a spec's text: the CLI's help (:func:`syntax`), the error's list
of valid kinds, and what a results file's spec was (:func:`kind_of`) all come from it.

The parser sits above the policies it builds: it imports each kind, none of them imports it.
"""

from __future__ import annotations

import warnings
from dataclasses import replace
from functools import cache
from importlib.metadata import entry_points

import numpy as np
from numpy.typing import ArrayLike

from etmpc.common import interrupts
from etmpc.common.errors import EtmpcError, UnknownNameError
from etmpc.loop import Policy
from etmpc.policies.builders import Context, Kind, every, file_kind, iterate, learned, no_argument, number, threshold
from etmpc.policies.fixed import Always, Never
from etmpc.policies.rollout import parse_rollout
from etmpc.policies.sb3 import load_sb3
from etmpc.policies.selftrigger import load_self
from etmpc.policies.shield import Shield
from etmpc.policies.user import load_user
from etmpc.systems import SystemKey, make_system
from etmpc.systems.capabilities import ShieldRule

ENTRY_POINTS = "etmpc.policies"
#: The longest spec, the most ``:``-separated parts and the deepest wrapping a spec may hold: a path is at most 4096
#: characters on Linux, no built-in spec has more than a dozen parts, and no built-in kind wraps another more than
#: twice (``oracle:shield:BASE``); a spec past these is refused before it is read.
MAX_SPEC_CHARS, MAX_SPEC_PARTS, MAX_NESTING = 4096, 64, 8
RULE = "AGE[:MARGIN[:DEVIATION]]"  # how a shield's own rule is written (ShieldRule.text)


def _simulates(spec: str) -> bool:
    kind = find(spec)
    if kind is not None and kind.build is _shield:  # a shield simulates what its base does
        return _simulates(_shielded(spec.partition(":")[2])[1])
    return kind is not None and kind.simulates


def _shield(arg: str, spec: str, context: Context) -> Policy:
    """``shield:BASE`` (the task's rule) or ``shield:AGE[:MARGIN[:DEVIATION]]:BASE``: numbers first, then the base's
    spec."""
    numbers, base = _shielded(arg)
    if not base:
        raise EtmpcError(f"bad policy {spec!r}: give the policy to shield, shield:BASE or shield:{RULE}:BASE")
    if (kind := find(base)) is not None and kind.clairvoyant:
        raise EtmpcError(f"bad policy {spec!r}: {base} is an oracle, a reference and not a policy: shield a policy")
    if numbers:
        age = number(numbers[0], int, spec)
        try:
            rule = ShieldRule(age, *(number(text, float, spec) for text in numbers[1:]))
        except EtmpcError as exc:
            raise EtmpcError(f"bad policy {spec!r}: {exc}") from None
    elif context.shield is None:
        raise EtmpcError(f"bad policy {spec!r}: task {context.task} declares no shield rule: write shield:{RULE}:BASE")
    else:
        rule = context.shield
    if rule.margin is not None and context.safety_margin is None:
        raise EtmpcError(
            f"bad policy {spec!r}: task {context.task} has no safety margin: shield it by age alone, shield:AGE:BASE"
        )
    weights = np.asarray(context.error_weights, dtype=float)
    return Shield(context.parse(base), rule.max_age, rule.margin, context.safety_margin, context.levels, rule.deviation, weights)


def _shielded(arg: str) -> tuple[list[str], str]:
    """A shield's argument as its numbers (at most three, first) and its base's spec."""
    parts = arg.split(":")
    numbers: list[str] = []
    while parts and len(numbers) < 3 and _numeric(parts[0]):
        numbers.append(parts.pop(0))
    return numbers, ":".join(parts)


def _numeric(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _rollout(arg: str, spec: str, context: Context) -> Policy:
    return parse_rollout(spec, context.parse, context.steps, simulating=_simulates)


BUILT_IN: tuple[Kind, ...] = (
    Kind("always", "always", "recompute at every step (standard MPC)", no_argument(Always), family="periodic"),
    Kind("never", "never", "keep each plan to its end", no_argument(Never), family="periodic"),
    Kind("every", "every:T", "recompute when the plan is T steps old", every, family="periodic"),
    Kind(
        "iterate",
        "iterate:T[:K]",
        "one SQP iteration (or up to K) when the plan is T steps old (a task with compute levels)",
        iterate,
        family="periodic",
    ),
    Kind(
        "threshold",
        "threshold:X[:iterate][:reading]",
        "recompute when the weighted prediction error exceeds X (:iterate: one SQP iteration, with compute levels; "
        ":reading: the error on the sensor's readings)",
        threshold,
        family="event",
    ),
    Kind("rl", "rl:PATH", "a learned policy (etmpc train)", file_kind(learned, "policy"), family="learned", path=True),
    Kind(
        "self",
        "self:PATH",
        "a self-triggering policy (etmpc train --algorithm self)",
        file_kind(lambda path, c: load_self(path, c.task), "policy"),
        family="self",
        path=True,
    ),
    Kind(
        "py",
        "py:MODULE:NAME",
        "your own policy (a class or factory)",
        lambda arg, spec, c: load_user(spec, c.levels),
        family="users",
    ),
    Kind(
        "sb3",
        "sb3:PATH",
        "a network trained on the Gymnasium environment (etmpc train --algorithm ppo)",
        file_kind(lambda path, c: load_sb3(path, c.task), "model"),
        family="learned",
        path=True,
    ),
    Kind(
        "shield",
        f"shield:[{RULE}:]BASE",
        "BASE, but compute when the plan is AGE steps old, the safety margin is below MARGIN or the state is more than "
        "DEVIATION off the plan (default: the task's rule)",
        _shield,
        family="shielded",
        wraps=True,
    ),
    Kind(
        "rollout",
        "rollout:BASE[:K[:H]]",
        "simulate both answers over K sampled futures, H steps ahead",
        _rollout,
        family="rollout",
        simulates=True,
    ),
    Kind(
        "oracle",
        "oracle:BASE",
        "the same with the episode's own future: the oracle, a reference and not a policy",
        _rollout,
        clairvoyant=True,
        family="oracle",
        simulates=True,
    ),
)


def _warn(what: str) -> None:
    """One warning, of one line (the command line prints it as ``etmpc: warning: ...``)."""
    warnings.warn(f"etmpc: {' '.join(what.split())}; left out", RuntimeWarning, stacklevel=3)


@cache
def kinds() -> dict[str, Kind]:
    """Every kind by name: the built-in ones, then the installed plugins' (``etmpc.policies``)."""
    found = {kind.name: kind for kind in BUILT_IN}
    with interrupts.watching():  # a Ctrl-C is told apart from a KeyboardInterrupt a plugin raises
        for point in sorted(entry_points(group=ENTRY_POINTS), key=lambda p: p.name):
            where = f"policy kind plugin {point.name!r} ({point.value})"
            try:  # the plugin's code: whatever it raises (SystemExit too) leaves the other kinds working
                kind = point.load()
            except BaseException as exc:
                if not isinstance(exc, EtmpcError) and interrupts.genuine(exc):  # a real Ctrl-C or SIGTERM
                    raise
                _warn(f"{where} failed to load ({interrupts.described(exc)})")
                continue
            if not isinstance(kind, Kind):
                _warn(f"{where} is not an etmpc.policies.specs.Kind")
            elif kind.name != point.name or ":" in kind.name or not kind.name:
                _warn(f"{where} names its kind {kind.name!r}, not {point.name!r}")
            elif kind.name in found:
                _warn(f"{where} names a kind etmpc already has")
            else:
                found[kind.name] = kind
    return found


def syntax() -> str:
    """Every kind's syntax, for help texts: ``always | never | every:T | ...``."""
    return " | ".join(kind.syntax for kind in kinds().values())


def find(spec: str) -> Kind | None:
    """The kind ``spec`` is written as, or None."""
    return kinds().get(spec.partition(":")[0])


def kind_of(spec: str) -> Kind:
    """The kind of ``spec`` (a spec of a results file, say); an unknown one raises :class:`UnknownNameError`."""
    kind = find(spec)
    if kind is None:
        raise UnknownNameError(f"unknown policy {spec!r}; valid: {syntax()}")
    return kind


def names_a_kind(spec: str) -> bool:
    """True if ``spec`` is written as a registered kind's spec other than the users' own ``py:``
    (``every:3``, ``oracle:...``): a policy object of someone's must not take such a name, or the results
    would show its numbers under that policy's."""
    kind = find(spec)
    return kind is not None and kind.family != "users"


def parse_policy(spec: str, system, *legacy) -> Policy:
    """Build the policy ``spec`` for ``system`` (the built task it will play, or its name: its ``error_weights``,
    the diagonal of W, its ``name``, which ``rl:`` files made for one task are checked against, and
    its ``episode_steps``, which bound a rollout's look-ahead). A bad spec raises :class:`EtmpcError`,
    an unknown kind :class:`UnknownNameError` listing the valid ones.

    The older form ``parse_policy(spec, error_weights, task=None, steps=100)`` still works in this
    release, with a ``DeprecationWarning``.
    """
    if isinstance(system, (str, SystemKey)):
        system = make_system(system)
    if isinstance(system, np.ndarray) or legacy:
        warnings.warn(
            "parse_policy(spec, error_weights, task, steps) is deprecated: pass the system, parse_policy(spec, system)",
            DeprecationWarning,
            stacklevel=2,
        )
        return _parse(spec, _legacy_context(system, *legacy))
    # a stand-in for a system (a test's) may give only error_weights, name and episode_steps: the rest of
    # what is read here (System's members) defaults as on a task that offers none
    levels = bool(getattr(system, "compute_levels", False))
    variant_of = getattr(system, "variant_of", None)
    shield = getattr(system, "shield", None)
    margin = getattr(system, "safety_margin", None)
    return _parse(
        spec, Context(system.error_weights, system.name, system.episode_steps, _unset, levels, variant_of, shield, margin)
    )


def _legacy_context(error_weights: ArrayLike, task: str | None = None, steps: int = 100) -> Context:
    """The context of the older form, ``parse_policy(spec, error_weights, task=None, steps=100)``."""
    return Context(np.asarray(error_weights), task, steps, _unset)


def _unset(spec: str) -> Policy:
    """A context's ``parse`` before :func:`_parse` sets its own (no builder sees a context without it)."""
    raise AssertionError(f"no parser for {spec!r}: the context was not made by _parse")


def _short(spec: str) -> str:
    return repr(spec) if len(spec) <= 60 else f"{spec[:57]!r}..."


def check_size(spec: str) -> None:
    """Refuse, in one line, a spec longer than :data:`MAX_SPEC_CHARS`, of more than :data:`MAX_SPEC_PARTS` parts or
    holding a control character: what a reader of specs (the parser, :func:`etmpc.evaluation.inputs.policy_files`)
    checks before it looks inside."""
    if not isinstance(spec, str):
        raise EtmpcError(f"a policy spec is text, got {type(spec).__name__}")
    if len(spec) > MAX_SPEC_CHARS:
        raise EtmpcError(f"bad policy {_short(spec)}: {len(spec)} characters, more than the {MAX_SPEC_CHARS} a spec may hold")
    if (parts := spec.count(":") + 1) > MAX_SPEC_PARTS:
        raise EtmpcError(f"bad policy {_short(spec)}: {parts} parts, more than the {MAX_SPEC_PARTS} a spec may hold")
    if any(ord(c) < 32 or ord(c) == 127 for c in spec):  # a line break would split every table and message
        raise EtmpcError(f"bad policy {spec!r}: it holds a control character (a line break?)")


def _parse(spec: str, context: Context, depth: int = 0, whole: str | None = None) -> Policy:
    """``spec``, a policy wrapped ``depth`` deep in the spec ``whole`` (the one a user wrote)."""
    check_size(spec)
    whole = spec if whole is None else whole
    if depth > MAX_NESTING:
        raise EtmpcError(f"bad policy {_short(whole)}: policies wrapped more than {MAX_NESTING} deep (shield:, rollout:)")
    context = replace(context, parse=lambda base: _parse(base, context, depth + 1, whole))
    kind = kind_of(spec)
    if any(kind is own for own in BUILT_IN):
        return kind.build(spec.partition(":")[2], spec, context)
    with interrupts.watching():  # a plugin's builder: all it raises but an EtmpcError, a Ctrl-C or SIGTERM is one line
        try:
            return kind.build(spec.partition(":")[2], spec, context)
        except BaseException as exc:
            if interrupts.genuine(exc):
                raise
            origin = next((point.value for point in entry_points(group=ENTRY_POINTS) if point.name == kind.name), "?")
            raise EtmpcError(
                f"bad policy {spec!r}: the {kind.name!r} plugin ({origin}) failed: {interrupts.described(exc)}"
            ) from None
