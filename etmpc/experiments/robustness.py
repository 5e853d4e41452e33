"""``etmpc robustness``: triggers scored across a range of one of a task's options (a sensor's noise, the gusts'
strength), on the task's stored test set: the same episodes at every value, so the curve is paired along the
option and across the triggers.

At each value of the option, every policy is played on the test set (:func:`etmpc.evaluate` with the task's key
at that value), and the curve gives its mean objective with a 95 % CI over the episodes, its failures per
episode, and, against a baseline policy (``against``: a fixed schedule, say), its improvement in percent of
the baseline's mean objective, paired episode by episode, with a 95 % CI. Writes ``robustness.json``,
``robustness.png`` (one panel per measure) and ``ROBUSTNESS.md`` into the output folder (:data:`FILES`): a new
or empty one, or one that holds only an earlier curve's files (:func:`check_out`, before any work).

Every value's system is built, and every policy parsed on it, before the first episode is played
(:func:`robustness`): a value that only fails when its system is made (a solver's block longer than the
horizon, weights that give no LQR gain) is refused in one line, with nothing played.
"""

from __future__ import annotations

import math
import platform
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from etmpc.common.errors import EtmpcError
from etmpc.common.outputs import refuse_foreign, write_json, write_text
from etmpc.common.provenance import commit_and_date
from etmpc.common.sense import oriented
from etmpc.evaluation import metrics
from etmpc.evaluation.evaluate import evaluate, parse_policies
from etmpc.evaluation.inputs import check_run_outputs, run_inputs
from etmpc.evaluation.testsets import check_options_act
from etmpc.systems import system_class, system_key
from etmpc.systems.options import canonical, described, settable, shown, split

FORMAT = "etmpc-robustness"
FILES = ("robustness.json", "robustness.png", "ROBUSTNESS.md")  # what a curve writes into its folder


def check_out(out: Path, policies: Sequence[str], option: str = "--out") -> None:
    """Raise, before any work, unless ``out`` can take a curve of ``policies``: a directory (new, empty, or
    holding only an earlier curve's :data:`FILES`, which are replaced), none of whose files is one the
    policies read, nor a FIFO or a device."""
    check_run_outputs({}, {option: out}, run_inputs(policies), writes={option: FILES})
    refuse_foreign(Path(out), lambda name: name in FILES, "robustness curve", option)


def _made(key, option: str, text: str):
    """``key``'s system, built now: a value that fails only when the system is made is one line naming it."""
    try:
        return key.make()
    except EtmpcError as exc:
        raise EtmpcError(f"--vary {option}={text}: {exc}") from None
    except (ArithmeticError, ValueError) as exc:  # a singular LQR weight, a block longer than the horizon
        raise EtmpcError(f"--vary {option}={text}: the task cannot be built with it ({exc}): choose another value") from None


def _costs(runs: list[dict], spec: str, sense: str) -> np.ndarray:
    """``spec``'s objective per episode, as costs (lower is better), in episode order."""
    mine = sorted((r["episode"], r["objective"]) for r in runs if r["policy"] == spec)
    return -oriented(np.array([float("nan") if v is None else v for _, v in mine]), sense)


def robustness(
    task: str,
    option: str,
    values: Sequence[str],
    policies: Sequence[str],
    against: str | None = None,
    episodes: int | None = None,
    workers: int | None = None,
    fixed: Sequence[tuple[str, str]] = (),
    progress: bool = True,
    say: Callable[[str], None] = lambda line: None,
) -> dict:
    """Score ``policies`` on ``task`` at each of ``values`` of ``option`` (with the ``fixed`` options too); see
    the module's docstring. Every value is checked, its system built and every policy parsed on it, before any
    episode is played."""
    if not values:
        raise EtmpcError("give at least one value of the option to vary")
    if against is not None and against not in policies:
        raise EtmpcError(f"--against {against} is not one of the policies given")
    if option in dict(fixed):
        raise EtmpcError(f"option {option} is both varied and fixed")
    keys = [system_key(task, None, (*fixed, (option, value))) for value in values]  # each value checked here
    check_options_act(keys[0], takes_test_set=False)  # an option that only acts when episodes are drawn: the curve would be flat
    texts = [dict(key.options)[option] for key in keys]
    if len(set(texts)) != len(texts):
        raise EtmpcError(f"a value of {option} is given twice: {', '.join(texts)}")
    systems = [_made(key, option, text) for key, text in zip(keys, texts)]  # every value's system, before any episode
    for system, text in zip(systems, texts):  # and every policy on each
        try:
            parse_policies(system, list(policies))
        except EtmpcError as exc:
            raise EtmpcError(f"--vary {option}={text}: {exc}") from None
    started = time.perf_counter()
    system = systems[0]
    sense = system.objective_sense
    levels = []
    for key, text in zip(keys, texts):
        say(f"{task}: {option}={text}")
        evaluation = evaluate(key, list(policies), episodes, workers=workers, progress=progress).to_json()
        runs = evaluation["runs"]
        found: dict[str, dict] = {}  # each policy's entry at this value
        base = _costs(runs, against, sense) if against is not None else None
        for spec in policies:
            costs = _costs(runs, spec, sense)
            summary = evaluation["policies"][spec]
            entry = {
                "objective": float(summary["objective_mean"]),
                "objective_ci95": float(metrics.mean_ci95(-costs if sense == "max" else costs)),
                "recomputes": float(summary["recomputes_mean"]),
                "failures": summary.get("failures_mean"),
                "failures_ci95": summary.get("failures_ci95"),
            }
            if base is not None:
                scale = abs(float(np.mean(base)))
                gain = 100.0 * (base - costs) / scale if scale > 0 else np.full(costs.shape, math.nan)
                entry["improvement_pct"] = float(np.mean(gain))
                entry["improvement_ci95"] = float(metrics.mean_ci95(gain))
            found[spec] = entry
        episodes_played = len({r["episode"] for r in runs})
        levels.append(
            {"value": text, "policies": found, "test_set_sha256": evaluation["test_set"]["sha256"], "episodes": episodes_played}
        )
    return commit_and_date() | {
        "format": FORMAT,
        "task": system.name,
        "option": option,
        "default": canonical(settable(system_class(task).Config())[option]),
        "unit": described(system_class(task).Config())[option][0].unit,  # the option's, for the figure's axis
        "fixed": dict(keys[0].options) | {option: None},
        "objective_sense": sense,
        "against": against,
        "policies": list(policies),
        "levels": levels,
        "machine": f"{platform.machine()}, {platform.system()}",
        "seconds": time.perf_counter() - started,
    }


def markdown(document: dict) -> str:
    """The curve as a table: one row per value, one column per policy."""
    fixed = {k: v for k, v in document["fixed"].items() if v is not None}
    better = "higher" if document["objective_sense"] == "max" else "lower"
    lines = [
        f"## `{document['task']}` against `{document['option']}`",
        "",
        f"Default `{document['default'] or '()'}`"
        + (f"; fixed: `{shown(tuple(fixed.items()))}`" if fixed else "")
        + f". {document['levels'][0]['episodes']} stored test-set episodes at every value (the same ones: paired). "
        f"Objective ({better} is better) ± 95 % CI; failures per episode"
        + (
            f"; improvement over `{document['against']}` in % of its mean objective, paired per episode, ± 95 % CI."
            if document["against"]
            else "."
        ),
        "",
        "| " + document["option"] + " | " + " | ".join(f"`{p}`" for p in document["policies"]) + " |",
        "|---|" + "---|" * len(document["policies"]),
    ]
    for level in document["levels"]:
        cells = []
        for spec in document["policies"]:
            e = level["policies"][spec]
            cell = f"{e['objective']:.4g} ± {e['objective_ci95']:.2g}"
            if e.get("failures") is not None:
                cell += f"; {e['failures']:.2f} fail"
            if document["against"] and spec != document["against"]:
                cell += f"; {e['improvement_pct']:+.1f} ± {e['improvement_ci95']:.1f} %"
            cells.append(cell)
        lines.append(f"| {level['value']} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def parse_vary(text: str) -> tuple[str, list[str]]:
    """``NAME=V1;V2;...`` as ``(NAME, [V1, V2, ...])`` (values separated by ``;``, since a value may be a list)."""
    name, values = split(text)
    found = [v.strip() for v in values.split(";") if v.strip()]
    if not found:
        raise EtmpcError(f"--vary {text}: give NAME=V1;V2;... (values separated by ';')")
    return name, found


def write(document: dict, out: Path, table: bool = True) -> list[Path]:
    """``robustness.json``, ``robustness.png`` and (with ``table``) ``ROBUSTNESS.md`` into ``out``."""
    from etmpc.views.robustness import write_robustness_png

    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "robustness.json", document)
    written = [out / "robustness.json", write_robustness_png(document, out / "robustness.png")]
    if table:
        written.append(write_text(out / "ROBUSTNESS.md", markdown(document)))
    return written
