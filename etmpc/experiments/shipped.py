"""Whether the learners a reproduce run trained are the policies shipped in ``policies/<task>/``, and, where
they are not, how the shipped file's recipe differs from the run's: the report's answer to "does this
command regenerate the shipped policies?", read from the files, never typed.

A run's DPI is trained with the run's settings (its seeds, episodes, schedules); the shipped one with the
recipe its file records (``scripts/learners.py`` in a checkout, over more seeds on some tasks), so on a task
whose recipe departs from the run's the two files differ, and the comparison names where. PPO is trained
from the task's ``ppo.yml`` by both.
"""

from __future__ import annotations

import json
from pathlib import Path

from etmpc.common.resources import data_root
from etmpc.systems import folder_name

# (learner, the run's file in DIR/policies/<task>/ and the shipped one's name, the file holding its recipe, its key)
FILES = (("DPI", "learned.json", "learned.json", "hyperparameters"), ("PPO", "ppo.zip", "ppo.json", "settings"))
# Recorded beside the recipe, not part of it: what the chosen policy scored on its validation episodes.
_OUTCOMES = {"validation_objective"}


def compare(task: str, made: Path) -> dict:
    """``{learner: {"verdict": "same" | "differs" | "not shipped", "recipe": {key: [shipped, run's]}}}`` for each
    learner the run wrote into ``made`` (``DIR/policies/<task>/``); ``recipe`` holds the recipe's entries in
    which the shipped file departs from the run's (empty: the same recipe, other bits)."""
    found = {}
    for learner, file, recipe_file, key in FILES:
        if not (made / file).is_file():
            continue
        shipped = data_root() / "policies" / folder_name(task) / file
        if not shipped.is_file():
            found[learner] = {"verdict": "not shipped"}
        elif shipped.read_bytes() == (made / file).read_bytes():
            found[learner] = {"verdict": "same"}
        else:
            theirs, ours = (_recipe(p.parent / recipe_file, key) for p in (shipped, made / file))
            departs = {k: [theirs.get(k), ours.get(k)] for k in sorted(set(theirs) | set(ours)) if theirs.get(k) != ours.get(k)}
            found[learner] = {"verdict": "differs", "recipe": departs}
    return found


def _recipe(path: Path, key: str) -> dict:
    try:
        recipe = json.loads(path.read_text()).get(key, {})
    except (OSError, ValueError, AttributeError):
        return {}
    return {k: v for k, v in recipe.items() if k not in _OUTCOMES} if isinstance(recipe, dict) else {}


def section(systems: dict) -> list[str]:
    """The report's table: per task and learner, this run's policy against the shipped one."""
    rows = [(task, learner, c) for task, r in systems.items() for learner, c in r.get("shipped", {}).items()]
    if not rows:
        return []
    lines = [
        "## This run's policies and the shipped ones",
        "",
        "Each learner's policy this run wrote (`policies/<task>/` here) against the one etmpc ships for the task. "
        "Where they differ, the recipe entries in which the shipped file departs from this run's (shipped → this "
        "run); none listed: the same recipe, other bits (another CPU's kernels, or another version of etmpc).",
        "",
        "| task | learner | this run's policy |",
        "|---|---|---|",
    ]
    for task, learner, c in rows:
        if c["verdict"] == "differs":
            departs = "; ".join(f"`{k}` {_value(a)} → {_value(b)}" for k, (a, b) in c["recipe"].items())
            verdict = f"differs: {departs}" if departs else "differs in its bits, same recipe"
        else:
            verdict = {"same": "the shipped file, byte for byte", "not shipped": "none shipped"}[c["verdict"]]
        lines.append(f"| {task} | {learner} | {verdict} |")
    return lines + [""]


def _value(v) -> str:
    if isinstance(v, list) and len(v) > 4:
        return f"[{', '.join(map(str, v[:2]))}, … {len(v)} items]"
    return "(not recorded)" if v is None else str(v)
