"""Every field of a score card checked for its type and shape before ``etmpc verify`` reads it.

A card is somebody's file, read as evidence: a field of another type (a list where an object goes, text
where a number goes, a row's per-episode list shorter than its episodes, an unknown word) must be one
line naming the file and the field (:class:`~etmpc.common.checks.BadValue`, an :class:`EtmpcError`),
never a Python error in the middle of the checks, nor a value read by its truth and so passed over. What
the fields must *equal* is :mod:`etmpc.evaluation.verify`'s to check; here only what they are.
"""

from __future__ import annotations

import math

from etmpc.common.checks import DOUBLE_MAX, BadValue
from etmpc.common.provenance import LIBM_WORDS
from etmpc.evaluation.card import TaskScore

# A row's lists with a value per episode, each in the order of episode_scores (None: a row of an older etmpc).
PER_EPISODE = ("episode_scores", "episode_objectives", "episode_recomputes", "episode_solver_failures", "episode_failures")
# The references of a task scored with options, as etmpc.evaluation.scorecard.score keeps them in the card.
CARRIED: tuple[str, ...] = ("options", "best_objectives", "oracle_objectives", "objective_sense", "best_periodic", "oracle")
CARRIED += ("test_set_sha256", "episodes", "recompute_price", "gap")
AGGREGATE_NUMBERS = ("iqm", "probability_of_improvement")  # each with its 95 % CI, a pair: number or null


def _shown(value) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _refuse(where: str, field: str, wanted: str, value) -> BadValue:
    return BadValue(f"{where}: {field} must be {wanted}, got {_shown(value)}")


def _number(value, null: bool = False) -> bool:
    """A finite number (not a bool), or null where strict JSON writes a number not known."""
    if value is None:
        return null
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _count(value) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and value >= 1


def _text(value) -> bool:
    return isinstance(value, str) and bool(value)


def _text_object(value) -> bool:
    return isinstance(value, dict) and all(isinstance(v, str) for v in value.values())


def _numbers(value, length: int, null: bool = False) -> bool:
    return isinstance(value, list) and len(value) == length and all(_number(v, null) for v in value)


def check_card(card: dict, where: str) -> None:
    """Raise :class:`BadValue` (one line: ``where``, the field, what it must be) for the first field of ``card``
    (a JSON object of format ``etmpc-scorecard``) that is not of its type: its tasks, their versions and
    references, its rows and aggregates (each row's own fields: :func:`check_row`), its machine and software."""
    _no_giant_integers(card, where)
    tasks = card.get("tasks")
    if not (isinstance(tasks, list) and tasks and all(_text(t) for t in tasks)):
        raise _refuse(where, "tasks", "a non-empty list of task names (made by an older etmpc?)", tasks)
    if len(set(tasks)) != len(tasks):
        raise BadValue(f"{where}: tasks holds {next(t for t in tasks if tasks.count(t) > 1)} twice")
    versions = card.get("task_versions")
    if not (isinstance(versions, dict) and sorted(versions) == sorted(tasks)):
        raise _refuse(where, "task_versions", "an object of a version per task of the card", versions)
    for task, version in versions.items():
        if isinstance(version, bool) or not isinstance(version, int):
            raise _refuse(where, f"task_versions.{task}", "a whole number", version)
    shown = card.get("references")
    if not (isinstance(shown, dict) and sorted(shown) == sorted(tasks)):
        raise _refuse(where, "references", "an object of the references of each task of the card", shown)
    for task in tasks:
        _references(shown[task], f"references.{task}", where)
    rows = card.get("rows")
    if not (isinstance(rows, list) and rows and all(isinstance(r, dict) for r in rows)):
        raise _refuse(where, "rows", "a non-empty list of rows (objects)", rows)
    aggregates = card.get("aggregates")
    if not (isinstance(aggregates, list) and all(isinstance(a, dict) for a in aggregates)):
        raise _refuse(where, "aggregates", "a list of objects", aggregates)
    for index, aggregate in enumerate(aggregates):
        _aggregate(aggregate, f"aggregates[{index}]", where)
    _machine(card, where)
    if "software" in card and not _text_object(card["software"]):
        raise _refuse(where, "software", "an object of versions (text)", card["software"])


# What each field of a task's references must be: a check, and what it says.
_FIELDS = {
    "episodes": (_count, "a count of episodes (a whole number >= 1)"),
    "test_set_sha256": (_text, "the test set's sha256 (text)"),
    "best_periodic": (_text, "a schedule's spec (text)"),
    "oracle": (_text, "the oracle's spec (text)"),
    "objective_sense": (lambda v: v in ("min", "max"), "min or max"),
    "gap": (_number, "a finite number"),
    "recompute_price": (_number, "a finite number"),
    "options": (lambda v: _text_object(v) and bool(v), "a non-empty object of the options' values (text)"),
}
STORED_NEEDS = ("episodes", "test_set_sha256")  # of stored references, read before the rows; the rest compared as stated


def _references(ref, field: str, where: str) -> None:
    """A task's references: the stored ones named (``stored``: their file), or those of a task scored with
    options (``stored`` null, ``options`` given), which the card carries episode by episode."""
    if not isinstance(ref, dict):
        raise _refuse(where, field, "an object", ref)
    stored = ref.get("stored")
    if stored is not None and not _text(stored):
        raise _refuse(where, f"{field}.stored", "the stored references' file (text) or null", stored)
    if "options" in ref and stored is not None:
        raise BadValue(f"{where}: {field} names stored references and options: references with options are never stored")
    needed = CARRIED if "options" in ref else STORED_NEEDS
    for key, (ok, wanted) in _FIELDS.items():
        if (key in needed or key in ref) and not ok(ref.get(key)):
            raise _refuse(where, f"{field}.{key}", wanted, ref.get(key))
    for key in ("best_objectives", "oracle_objectives"):
        if key in needed and not _numbers(ref.get(key), ref["episodes"]):
            raise _refuse(where, f"{field}.{key}", f"a list of {ref['episodes']} finite numbers (one per episode)", ref.get(key))


def _aggregate(aggregate: dict, field: str, where: str) -> None:
    if not _text(aggregate.get("policy")):
        raise _refuse(where, f"{field}.policy", "a policy's spec (text)", aggregate.get("policy"))
    tasks = aggregate.get("tasks")
    if isinstance(tasks, bool) or not isinstance(tasks, int) or tasks < 0:
        raise _refuse(where, f"{field}.tasks", "a count of tasks (a whole number >= 0)", tasks)
    for key in AGGREGATE_NUMBERS:
        if key not in aggregate or not _number(aggregate[key], null=True):
            raise _refuse(where, f"{field}.{key}", "a finite number or null", aggregate.get(key))
        if not _numbers(aggregate.get(f"{key}_ci95"), 2, null=True):
            raise _refuse(where, f"{field}.{key}_ci95", "a pair of finite numbers or nulls", aggregate.get(f"{key}_ci95"))


def _machine(card: dict, where: str) -> None:
    """The scorer's machine: absent (an older etmpc), or an object whose ``libm`` (absent, or one of
    :data:`~etmpc.common.provenance.LIBM_WORDS`) says how its C library rounded."""
    if "machine" not in card:
        return
    machine = card["machine"]
    if not isinstance(machine, dict):
        raise _refuse(where, "machine", "an object", machine)
    for key in ("processor", "system"):
        if key in machine and not isinstance(machine[key], str):
            raise _refuse(where, f"machine.{key}", "text", machine[key])
    if "libm" in machine and not (isinstance(machine["libm"], str) and machine["libm"] in LIBM_WORDS):
        raise _refuse(where, "machine.libm", f"one of {', '.join(LIBM_WORDS)}", machine["libm"])


def check_row(row: TaskScore, index: int, where: str) -> None:
    """Each of a row's per-episode lists (read from the card, each of its type: :meth:`TaskScore.from_json`)
    holds a value for each of the row's episodes; ``episode_scores`` may be empty where an episode ended
    non-finite (such a row has no score: ``etmpc score`` writes it so)."""
    for name in PER_EPISODE:
        values = getattr(row, name)
        if values is None or len(values) == row.episodes or (name == "episode_scores" and not values and row.nonfinite_episodes):
            continue
        raise BadValue(
            f"{where}: rows[{index}] ({row.policy} on {row.task}): {name} holds {len(values)} values for its "
            f"{row.episodes!r} episodes"
        )


def _no_giant_integers(card: dict, where: str) -> None:
    """No whole number beyond a double's range anywhere in ``card`` (JSON has them; every number here is
    read as a double, where such a one is an ``OverflowError``). Walked without recursion: a card nested as
    deep as the JSON reader goes is still one line."""
    stack = [(card, "")]
    while stack:
        value, at = stack.pop()
        if isinstance(value, dict):
            stack += [(v, f"{at}.{k}" if at else str(k)) for k, v in value.items()]
        elif isinstance(value, list):
            stack += [(v, f"{at}[{i}]") for i, v in enumerate(value)]
        elif isinstance(value, int) and not isinstance(value, bool) and abs(value) > DOUBLE_MAX:
            raise BadValue(f"{where}: {at} is a whole number beyond a double's range")
