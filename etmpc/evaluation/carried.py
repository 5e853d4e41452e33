"""The references a score card carries itself: those of a task scored with options (``etmpc score --option``),
computed for that run on the stored test set and kept in the card episode by episode, which ``etmpc verify``
checks the card's rows against and replays in turn (:mod:`etmpc.evaluation.verify`)."""

from __future__ import annotations

from etmpc.common.errors import EtmpcError
from etmpc.evaluation.evaluate import parse_policies
from etmpc.evaluation.references import References, stored
from etmpc.systems import system_key


def carried(task: str, ref: dict, where: str) -> References:
    """The references a card scored ``task`` against with its options (computed for that run on the stored test
    set, carried in the card episode by episode): what this replay checks the card's rows against, and replays
    in turn on the sampled episodes (:func:`reference_jobs`)."""
    try:
        options = system_key(task, None, tuple(ref["options"].items())).options  # the options, checked here
        best, oracle = [float(v) for v in ref["best_objectives"]], [float(v) for v in ref["oracle_objectives"]]
        episodes, price = ref["episodes"], float(ref["recompute_price"])
        refs = References(
            task,
            ref["test_set_sha256"],
            episodes,
            price,
            ref["objective_sense"],
            {ref["best_periodic"]: best},
            ref["best_periodic"],
            oracle,
        )
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise EtmpcError(f"{where}: its references of {task} with options are incomplete ({exc})") from None
    if len(best) != episodes or len(oracle) != episodes or not isinstance(episodes, int) or episodes < 1:
        raise EtmpcError(
            f"{where}: its references of {task} carry {len(best)} and {len(oracle)} objectives for {episodes} episodes"
        )
    stored_sha = stored(task).test_set_sha256
    if refs.test_set_sha256 != stored_sha:
        raise EtmpcError(f"{where} scored {task} on another test set than the stored one: it is not a suite result")
    if dict(options) != ref["options"]:
        raise EtmpcError(f"{where}: {task}'s options {ref['options']} are not written as etmpc writes them ({dict(options)})")
    return refs


def options_of(card: dict, task: str) -> tuple:
    """The options ``card`` scored ``task`` with (none: the task as it is)."""
    return tuple(((card.get("references") or {}).get(task) or {}).get("options", {}).items())


def reference_jobs(card: dict, references: dict[str, References], episodes_of) -> list[tuple]:
    """The replays of the references a card carries (a task scored with options): its best schedule and the oracle
    over it on the episodes ``episodes_of(count, k)`` gives for the ``k``-th such task (a seeded sample), each job
    with what it must give, ``(task, spec, episode, objective)``."""
    found = []
    for position, (task, refs) in enumerate(references.items()):
        options = options_of(card, task)
        if not options:
            continue
        key = system_key(task, None, options)
        system = key.make()
        for spec, objectives in ((refs.best, refs.periodic[refs.best]), (refs.oracle_spec, refs.oracle)):
            (policy,) = parse_policies(system, [spec]).values()
            for episode in episodes_of(refs.episodes, position):
                job = (key, None, refs.test_set_sha256, spec, policy, 0, episode, 0, False)
                found.append((job, (task, spec, episode, objectives[episode])))
    return found
