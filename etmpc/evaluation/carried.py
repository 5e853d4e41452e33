"""The references a score card carries itself: those of a task scored with options (``etmpc score --option``),
computed for that run on the stored test set and kept in the card episode by episode.

``etmpc verify`` takes none of them on the card's word: a card that names a worse schedule as the best
(with that schedule's true objectives) would raise every score of the task and still replay. So verify
rebuilds them in full from the task and its options on the card's episodes, exactly as ``etmpc score``
built them (:func:`rebuild`: every periodic schedule, then the oracle over the best), compares every
number the card carries with the rebuilt ones (:func:`differences`), and checks the rows against the
rebuilt references, never the card's (:mod:`etmpc.evaluation.verify`). The fields' types are checked
before (:mod:`etmpc.evaluation.card_checks`).
"""

from __future__ import annotations

from collections.abc import Callable

from etmpc.common.errors import EtmpcError
from etmpc.evaluation import testsets
from etmpc.evaluation.references import References, build_references
from etmpc.systems import SystemKey, system_key


def key_of(task: str, ref: dict, where: str) -> SystemKey:
    """``task`` with the options the card scored it with, each checked (an option the task does not have, or
    a value it does not take, is one line), once its test set is known to be the stored one and its episodes
    within it: all before anything is played."""
    try:
        key = system_key(task, None, tuple(ref["options"].items()))
        system = key.make()
    except EtmpcError as exc:
        raise EtmpcError(f"{where}: references.{task}.options: {exc}") from None
    test_set = testsets.load(testsets.default_path(system.domain, system.task), system.domain, system.task)
    if ref["test_set_sha256"] != test_set.sha256:
        raise EtmpcError(f"{where} scored {task} on another test set than the stored one: it is not a suite result")
    if ref["episodes"] > test_set.episodes:
        raise EtmpcError(f"{where} scored {task} on {ref['episodes']} episodes; its test set has {test_set.episodes}")
    return key


def rebuild(
    key: SystemKey, episodes: int, workers: int | None, progress: bool, say: Callable[[str], None] = lambda line: None
) -> References:
    """The references of ``key`` (a task with its options) on the first ``episodes`` of its stored test set, as
    :func:`etmpc.evaluation.scorecard.score` builds them for a card: every periodic schedule, then the oracle
    over the best (no rollout meter). It costs what scoring the task's references cost."""
    return build_references(key, None, workers, progress, say, episodes, meter=False)


def differences(task: str, ref: dict, key: SystemKey, refs: References) -> list[str]:
    """Every number the card carries about ``task``'s references that is not the rebuilt ``refs``' bit for bit,
    one line each (the best schedule, the oracle, the gap and the price: ``verify``'s own comparison)."""
    own = {
        "options": dict(key.options),  # as etmpc writes them (canonical)
        "objective_sense": refs.objective_sense,
        "test_set_sha256": refs.test_set_sha256,
        "episodes": refs.episodes,
    }
    found = [
        f"{task}: references' {name} {ref[name]!r} in the card, {value!r} rebuilt"
        for name, value in own.items()
        if ref[name] != value
    ]
    for name, spec, rebuilt in (
        ("best_objectives", ref["best_periodic"], refs.periodic[refs.best]),
        ("oracle_objectives", ref["oracle"], refs.oracle),
    ):
        found += [
            f"{task}: references' {spec} ({name}) episode {episode}: objective {stated!r} in the card, "
            f"{value!r} rebuilt ({refs.oracle_spec if name == 'oracle_objectives' else refs.best}'s)"
            for episode, (stated, value) in enumerate(zip(ref[name], rebuilt))
            if stated != value
        ]
    return found


def options_of(card: dict, task: str) -> tuple:
    """The options ``card`` scored ``task`` with (none: the task as it is)."""
    return tuple(((card.get("references") or {}).get(task) or {}).get("options", {}).items())
