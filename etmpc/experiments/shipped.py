"""Whether the learners a reproduce run trained are the policies shipped in ``policies/<task>/``, and, where
they are not, how the shipped file's recipe differs from the run's: the report's answer to "does this
command regenerate the shipped policies?", read from the files, never typed.

Three answers, per learner: the same file, byte for byte; the same parameters in a file that records them
otherwise (a shipped file written by an older etmpc names the task by its domain, or records fewer of its
recipe's entries); or other parameters, with the recipe entries, recorded by both files, in which the shipped
one departs from the run's. A run's DPI is trained with the run's settings (its seeds, episodes,
schedules); the shipped one with the recipe its file records (``etmpc study learners`` in a checkout, over
more seeds on some tasks). PPO is trained from the task's ``ppo.yml`` by both.
"""

from __future__ import annotations

import json
from pathlib import Path

from etmpc.common.resources import data_root
from etmpc.systems import folder_name

# (learner, the policy file, the file recording its recipe, the recipe's key there)
FILES = (("DPI", "learned.json", "learned.json", "hyperparameters"), ("PPO", "ppo.zip", "ppo.json", "settings"))
# Recorded beside the recipe, not part of it: what the chosen policy scored on its validation episodes.
_OUTCOMES = {"validation_objective"}
# A JSON policy's record, not its parameters: the recipe, and the task it names (an older file: its domain).
_RECORD = ("hyperparameters", "domain")


def compare(task: str, made: Path) -> dict:
    """For each learner the run wrote into ``made`` (``DIR/policies/<task>/``): ``{"verdict": "same"}`` (byte for
    byte), ``{"verdict": "same parameters", "record": [entries recorded otherwise]}``, ``{"verdict": "differs",
    "recipe": {entry: [shipped, run's]}}`` (the entries both files record, where they depart; empty: the same
    recipe, other bits) or ``{"verdict": "not shipped"}``."""
    found: dict[str, dict[str, object]] = {}
    for learner, file, recipe_file, key in FILES:
        ours = made / file
        if not ours.is_file():
            continue
        theirs = data_root() / "policies" / folder_name(task) / file
        if not theirs.is_file():
            found[learner] = {"verdict": "not shipped"}
        elif theirs.read_bytes() == ours.read_bytes():
            found[learner] = {"verdict": "same"}
        elif (record := _record_only(theirs, ours)) is not None:
            found[learner] = {"verdict": "same parameters", "record": record}
        else:
            a, b = (_recipe(p.parent / recipe_file, key) for p in (theirs, ours))
            found[learner] = {
                "verdict": "differs",
                "recipe": {k: [a[k], b[k]] for k in sorted(a.keys() & b.keys()) if a[k] != b[k]},
            }
    return found


def _load(path: Path):
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return None


def _hyperparameters(policy: dict) -> dict:
    """A JSON policy's recorded recipe (none: empty)."""
    recipe = policy.get("hyperparameters")
    return recipe if isinstance(recipe, dict) else {}


def _record_only(theirs: Path, ours: Path) -> list[str] | None:
    """The entries in which two JSON policies' records differ, if their parameters are the same; else None."""
    a, b = _load(theirs), _load(ours)
    if not (isinstance(a, dict) and isinstance(b, dict)):
        return None
    if {k: v for k, v in a.items() if k not in _RECORD} != {k: v for k, v in b.items() if k not in _RECORD}:
        return None
    recipes = [_hyperparameters(a), _hyperparameters(b)]
    differ = {k for k in recipes[0].keys() | recipes[1].keys() if recipes[0].get(k) != recipes[1].get(k)}
    return sorted(differ - _OUTCOMES | ({"domain"} if a.get("domain") != b.get("domain") else set()))


def _recipe(path: Path, key: str) -> dict:
    recipe = (_load(path) or {}).get(key, {})
    return {k: v for k, v in recipe.items() if k not in _OUTCOMES} if isinstance(recipe, dict) else {}


def section(systems: dict) -> list[str]:
    """The report's table: per task and learner, this run's policy against the shipped one."""
    rows = [(task, learner, c) for task, r in systems.items() for learner, c in r.get("shipped", {}).items()]
    if not rows:
        return []
    lines = [
        "## This run's policies and the shipped ones",
        "",
        "Each learner's policy this run wrote (`policies/<task>/` here) against the one etmpc ships for the task: the "
        "same file; the same parameters in a file that records them otherwise (a shipped file written by an older "
        "etmpc); or other parameters, with the recipe entries, recorded by both files, in which the shipped one "
        "departs (shipped → this run). None listed: the same recipe, other bits (another CPU's kernels, or another "
        "version of etmpc).",
        "",
        "| task | learner | this run's policy |",
        "|---|---|---|",
    ]
    for task, learner, c in rows:
        if c["verdict"] == "differs":
            departs = "; ".join(f"`{k}` {_value(a)} → {_value(b)}" for k, (a, b) in c["recipe"].items())
            verdict = f"other parameters: {departs}" if departs else "other parameters, the same recipe"
        elif c["verdict"] == "same parameters":
            verdict = "the shipped parameters; the files record otherwise: " + ", ".join(f"`{k}`" for k in c["record"])
        else:
            verdict = {"same": "the shipped file, byte for byte", "not shipped": "none shipped"}[c["verdict"]]
        lines.append(f"| {task} | {learner} | {verdict} |")
    return lines + [""]


def _value(v) -> str:
    if isinstance(v, list) and len(v) > 4:
        return f"[{', '.join(map(str, v[:2]))}, … {len(v)} items]"
    return str(v)
