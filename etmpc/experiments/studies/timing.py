"""Time in the loop: how the ranking of triggers changes when a solve takes time, and what the learners
trained on it gain (writes ``docs/results/timing.json`` and the generated page ``docs/results/timing.md``).

Each task with time in the loop plays the episodes of the task it adds time to (the same stored test
set), so every comparison below is paired episode by episode, with 95 % CIs (normal, on the paired
differences). The periodic schedules and the oracle come from each task's stored references; the event
triggers and the shipped learned policies are played here on all 100 stored episodes. Nothing here
chooses anything: the triggers are the references', the reproduce table's thresholds and the shipped
policies, chosen on training-distribution episodes.

    etmpc study timing [--workers 2] [--out docs/results]
    etmpc study timing --page-only            # the page again from timing.json
"""

from __future__ import annotations

import argparse
import itertools

import numpy as np

from etmpc.common.resources import data_root
from etmpc.evaluation.compare import paired
from etmpc.evaluation.evaluate import evaluate
from etmpc.evaluation.references import stored
from etmpc.experiments.studies import runner
from etmpc.systems import folder_name, make_system

REPO = data_root()  # the checkout: its policies/ hold the shipped learners
PAIRS = (
    ("cart_pendulum/kicks", "cart_pendulum/kicks_late"),
    ("reacher", "reacher/jumps_late"),
    ("cart_pendulum/kicks", "cart_pendulum/kicks_levels"),
)
PERIODS = range(1, 7)  # every:T (and iterate:T) shown; the references hold them all, the best among them


def shipped(task: str) -> dict[str, str]:
    """The learned policies shipped for ``task``: name -> spec (DPI's rl:, PPO's sb3:)."""
    folder = REPO / "policies" / folder_name(task)
    found = {}
    if (folder / "learned.json").is_file():
        found["DPI"] = f"rl:{(folder / 'learned.json').relative_to(REPO)}"
    if (folder / "ppo.zip").is_file():
        found["PPO"] = f"sb3:{(folder / 'ppo.zip').relative_to(REPO)}"
    return found


_PLAYED: dict[tuple[str, str], list[float]] = {}  # (task, spec) -> objectives: each played once per run


def objectives(task: str, specs: list[str], workers: int) -> dict[str, list[float]]:
    """Each spec's objective per stored test-set episode (in episode order), and the references' schedules
    and oracle."""
    refs = stored(task)
    table = {spec: list(values) for spec, values in refs.periodic.items()}
    table["oracle"] = list(refs.oracle)
    played = [s for s in specs if s not in table and (task, s) not in _PLAYED]
    if played:
        result = evaluate(task, played, workers=workers, progress=False)
        for spec in played:
            runs = sorted((r for r in result.runs if r.policy == spec), key=lambda r: r.episode)
            _PLAYED[task, spec] = [r.objective for r in runs]
    return table | {s: _PLAYED[task, s] for s in specs if (task, s) in _PLAYED}


def versus(table: dict, a: str, b: str, sense: str) -> dict:
    """``a`` against ``b``, paired (``gain_percent`` > 0: ``a`` is better)."""
    return paired(dict(enumerate(table[a])), dict(enumerate(table[b])), sense)


def triggers(task: str) -> list[str]:
    system = make_system(task)
    fixed = [f"every:{t}" for t in PERIODS] + ([f"iterate:{t}" for t in PERIODS] if system.compute_levels else [])
    return fixed + [f"threshold:{x:g}" for x in system.benchmark.report_thresholds]


def study_pair(base: str, variant: str, workers: int, say) -> dict:
    system = make_system(variant)
    sense = system.objective_sense
    base_policies = shipped(base)
    own_policies = shipped(variant)
    common = triggers(base) + list(base_policies.values())
    say(f"{base}: {len(common)} triggers")
    at_zero = objectives(base, common, workers)
    late_specs = triggers(variant) + list(base_policies.values()) + list(own_policies.values())
    say(f"{variant}: {len(late_specs)} triggers")
    late = objectives(variant, late_specs, workers)
    refs_zero = stored(base)
    refs_late = stored(variant)
    names = {spec: f"{name} of {base}" for name, spec in base_policies.items()}
    names |= {spec: f"{name} trained on {variant}" for name, spec in own_policies.items()}

    def row(table, spec, best):
        return {"spec": spec, "name": names.get(spec, spec), "objective_mean": float(np.mean(table[spec]))} | {
            "versus_best_periodic": versus(table, spec, best, sense)
        }

    rows_zero = [row(at_zero, s, refs_zero.best) for s in common + ["oracle"]]
    rows_late = [row(late, s, refs_late.best) for s in late_specs + ["oracle"]]
    # Pairs of triggers played on both whose order changes: A - B at latency 0 against A - B with time in the loop.
    changes = []
    for a, b in itertools.combinations(common, 2):
        zero = versus(at_zero, a, b, sense)
        timed = versus(late, a, b, sense)
        if np.sign(zero["mean_difference"]) != np.sign(timed["mean_difference"]) and zero["mean_difference"] != 0:
            significant = abs(zero["mean_difference"]) > zero["ci95"] and abs(timed["mean_difference"]) > timed["ci95"]
            changes.append(
                {"a": names.get(a, a), "b": names.get(b, b), "at_zero": zero, "timed": timed, "significant": significant}
            )
    changes.sort(key=lambda c: (not c["significant"], -min(abs(c["at_zero"]["gain_percent"]), abs(c["timed"]["gain_percent"]))))
    learned = {}
    for name, spec in own_policies.items():
        entry = {"versus_best_periodic": versus(late, spec, refs_late.best, sense)}
        if name in base_policies:  # the same learner trained at latency 0, played with time in the loop
            entry["versus_trained_at_zero"] = versus(late, spec, base_policies[name], sense)
        learned[name] = entry
    found = {
        "base": base,
        "variant": variant,
        "latency": system.latency.describe(),
        "compute_levels": system.compute_levels,
        "best_periodic": {"base": refs_zero.best, "variant": refs_late.best},
        "oracle_versus_best_periodic": {
            "base": versus(at_zero, "oracle", refs_zero.best, sense),
            "variant": versus(late, "oracle", refs_late.best, sense),
        },
        "at_zero": rows_zero,
        "timed": rows_late,
        "order_changes": changes,
        "learned": learned,
    }
    if system.compute_levels:  # the best policy that may take one SQP iteration against the best that may not
        may_iterate = [s for s in late_specs if s.startswith("iterate:")] + [own_policies[n] for n in own_policies]
        solve_only = [s for s in late_specs if not s.startswith("iterate:") and s not in own_policies.values()]
        pick = lambda specs: min(specs, key=lambda s: np.mean(late[s]) * (1 if sense == "min" else -1))  # noqa: E731
        best_it = pick(may_iterate)
        best_solve = pick(solve_only)
        found["levels"] = {
            "best_that_may_iterate": names.get(best_it, best_it),
            "best_keep_or_solve": names.get(best_solve, best_solve),
            "versus": versus(late, best_it, best_solve, sense),
        }
    return found


def _pct(d: dict) -> str:
    return f"{d['gain_percent']:+.2f} % ± {d['gain_percent_ci95']:.2f}"


def page(results: dict) -> str:
    lines = [
        "# Time in the loop: results",
        "",
        runner.generated("timing", "docs/results/timing.json"),
        "",
        f"Made at commit `{results['commit']}` ({results['date']}) on {results['machine']}, in {results['seconds']:.0f} s. "
        "Every comparison is paired on the 100 stored test-set episodes the two tasks share; ± is the 95 % CI of "
        "the paired mean difference, as a percentage of the second's mean; > 0 means better. The tasks are described "
        "on [time in the loop](../tasks/timing.md).",
        "",
    ]
    for pair in results["pairs"]:
        base = pair["base"]
        variant = pair["variant"]
        lines += [
            f"## `{variant}` against `{base}`",
            "",
            f"Latency: {pair['latency']}."
            + (" Compute levels: keep, one SQP iteration, a full solve, priced per iteration." if pair["compute_levels"] else ""),
            "",
        ]
        oracle = pair["oracle_versus_best_periodic"]
        lines += [
            f"* The oracle over the best periodic schedule: {_pct(oracle['base'])} over `{pair['best_periodic']['base']}` "
            f"at latency 0; {_pct(oracle['variant'])} over `{pair['best_periodic']['variant']}` on `{variant}`."
        ]
        for name, entry in pair["learned"].items():
            text = f"* {name} trained on `{variant}`: {_pct(entry['versus_best_periodic'])} over its best periodic schedule"
            if "versus_trained_at_zero" in entry:
                text += f"; {_pct(entry['versus_trained_at_zero'])} over the {name} trained at latency 0, played late"
            lines.append(text + ".")
        if not pair["learned"]:
            lines.append(f"* No learned policy is shipped for `{variant}` yet.")
        if "levels" in pair:
            lv = pair["levels"]
            lines.append(
                f"* The best policy that may take one SQP iteration ({lv['best_that_may_iterate']}) against the best that "
                f"keeps or solves ({lv['best_keep_or_solve']}): {_pct(lv['versus'])}."
            )
        lines += [
            "",
            "| trigger | objective at latency 0 | vs best periodic | objective on the variant | vs best periodic |",
            "|---|---|---|---|---|",
        ]
        late = {r["spec"]: r for r in pair["timed"]}
        for r in pair["at_zero"]:
            t = late.get(r["spec"])
            lines.append(
                f"| {r['name']} | {r['objective_mean']:.3f} | {_pct(r['versus_best_periodic'])} | "
                + (f"{t['objective_mean']:.3f} | {_pct(t['versus_best_periodic'])} |" if t else "– | – |")
            )
        for spec, t in late.items():
            if spec not in {r["spec"] for r in pair["at_zero"]}:
                lines.append(f"| {t['name']} | – | – | {t['objective_mean']:.3f} | {_pct(t['versus_best_periodic'])} |")
        significant = [c for c in pair["order_changes"] if c["significant"]]
        lines += [
            "",
            f"Pairs of triggers whose order changes: {len(pair['order_changes'])}, of which {len(significant)} "
            "with both CIs excluding 0.",
            "",
        ]
        if pair["order_changes"]:
            lines += ["| A | B | A vs B at latency 0 | A vs B on the variant | both CIs exclude 0 |", "|---|---|---|---|---|"]
            for c in pair["order_changes"][:8]:
                lines.append(
                    f"| {c['a']} | {c['b']} | {_pct(c['at_zero'])} | {_pct(c['timed'])} | {'yes' if c['significant'] else 'no'} |"
                )
        lines.append("")
    return "\n".join(lines)


def arguments(parser: argparse.ArgumentParser) -> None:
    runner.options(parser)


def run(args: argparse.Namespace) -> None:
    results = runner.Results(args.out, "timing")
    if args.page_only:
        results.write_page(page)
        return
    clock = runner.Stopwatch()
    say = lambda line: print(line, flush=True)  # noqa: E731
    pairs = [study_pair(base, variant, args.workers, say) for base, variant in PAIRS]
    provenance = runner.made()
    document = {
        "commit": provenance["commit"],
        "date": provenance["date"],
        "machine": runner.machine(args.workers, cpu=True),
        "seconds": clock.seconds(),
        "pairs": pairs,
    }
    results.write(document, page)
