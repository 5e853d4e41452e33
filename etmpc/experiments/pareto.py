"""The numbers of the trade-off curve: the periodic front, equal-rate comparisons and ``pareto.json``.

Comparisons are paired per episode. *At an equal rate*: the periodic front (the schedules no other
schedule beats in both rate and control objective) is interpolated per episode between the two of its
schedules whose mean rates bracket the policy's, with the weights that make the front's mean rate the
policy's. Against the *nearest periodic schedule*: the objective at the price, recomputes included.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from etmpc.loop import computation_cost
from etmpc.evaluation import metrics
from etmpc.policies.specs import find, kind_of


def episode_table(evaluation: dict) -> dict[str, dict[int, tuple[float, float]]]:
    """policy -> episode -> (control objective, recomputes), over finite runs (repeats averaged)."""
    values: dict[str, dict[int, list[tuple[float, float]]]] = {}
    for r in evaluation["runs"]:
        if r["finite"]:
            values.setdefault(r["policy"], {}).setdefault(r["episode"], []).append((r["control_objective"], r["recomputes"]))
    return {spec: {e: tuple(np.mean(v, axis=0)) for e, v in by.items()} for spec, by in values.items()}


def objective(control: float, computations: float, price: float, sense: str) -> float:
    """The objective at ``price``: the control objective and the price of the recomputes, which counts
    against it whatever its sense (added to a cost, taken from a profit)."""
    return control - metrics.oriented(computation_cost(computations, price), sense)


def _priced(cell: tuple[float, float], price: float, sense: str) -> float:
    """:func:`objective` of an :func:`episode_table` cell, (control objective, recomputes), at ``price``."""
    control, computations = cell
    return objective(control, computations, price, sense)


def best_periodic(fixed: dict, periodic: list[str], price: float, sense: str) -> str:
    """The periodic schedule with the best mean objective at ``price`` on the evaluated episodes."""
    table = episode_table(fixed)
    means = {spec: np.mean([objective(c, n, price, sense) for c, n in table[spec].values()]) for spec in periodic}
    return metrics.best(means, sense, key=lambda spec: (means[spec], spec))


def _ci(diff: np.ndarray) -> float | None:
    """The half-width of the paired 95 % normal interval; ``None`` (JSON null) for one episode."""
    return metrics.mean_ci95(diff) if len(diff) > 1 else None


def _percent(value: float | None, scale: float) -> float | None:
    return None if value is None else 100.0 * value / scale


def front(table: dict, periodic: list[str], episodes: list[int], sense: str) -> list[str]:
    """The periodic schedules no other beats on ``episodes``: none has a lower-or-equal mean rate and
    a better-or-equal mean control objective (one of them strictly), ordered by rate. Comparing with
    this front, never with a dominated schedule, keeps the comparison fair to the periodic side."""
    points = {
        p: (np.mean([table[p][e][1] for e in episodes]), metrics.oriented(np.mean([table[p][e][0] for e in episodes]), sense))
        for p in periodic
    }
    efficient = [
        p
        for p, (rate, value) in points.items()
        if not any(r <= rate and v >= value and (r, v) != (rate, value) for r, v in points.values())
    ]
    return sorted(efficient, key=lambda p: (points[p][0], p))


def versus_front(table: dict, periodic: list[str], spec: str, sense: str) -> dict | None:
    """``spec``'s control objective against the periodic front at its mean rate, paired per episode.

    The front (:func:`front`) at rate ``r`` is ``w c(T1) + (1 - w) c(T2)`` per episode, where ``T1``,
    ``T2`` are its schedules whose mean rates bracket ``r`` on the same episodes and ``w`` makes the
    mean rate ``r``. ``None`` when ``r`` is outside the front's range. Gains > 0 are better.
    """
    episodes = sorted(table[spec])
    if not episodes or any(e not in table[p] for p in periodic for e in episodes):
        return None
    rate = float(np.mean([table[spec][e][1] for e in episodes]))
    ordered = front(table, periodic, episodes, sense)
    rates = np.array([np.mean([table[p][e][1] for e in episodes]) for p in ordered])
    if not rates[0] - 1e-9 <= rate <= rates[-1] + 1e-9:
        return None
    if len(ordered) == 1:
        lo = hi = 0
    else:
        hi = int(np.clip(np.searchsorted(rates, rate), 1, len(rates) - 1))
        lo = hi - 1
    w = 0.0 if rates[hi] == rates[lo] else (rate - rates[lo]) / (rates[hi] - rates[lo])  # weight of the faster one
    front_values = np.array([(1 - w) * table[ordered[lo]][e][0] + w * table[ordered[hi]][e][0] for e in episodes])
    mine = np.array([table[spec][e][0] for e in episodes])
    gain = metrics.oriented(mine - front_values, sense)
    scale = abs(float(front_values.mean()))
    ci = _ci(gain)
    return {
        "episodes": len(episodes),
        "computations": rate,
        "between": [ordered[lo], ordered[hi]],
        "weight": float(w),
        "front_control_objective": float(front_values.mean()),
        "control_objective": float(mine.mean()),
        "gain": float(gain.mean()),
        "gain_ci95": ci,
        "gain_percent": 100.0 * float(gain.mean()) / scale,
        "gain_percent_ci95": _percent(ci, scale),
        "better_episodes": int((gain > 0).sum()),
    }


def versus_nearest(table: dict, periodic: list[str], spec: str, price: float, sense: str) -> dict:
    """``spec``'s objective at ``price`` against the periodic schedule with the nearest mean rate."""
    episodes = sorted(table[spec])
    rate = np.mean([table[spec][e][1] for e in episodes])
    nearest = min(periodic, key=lambda p: (abs(np.mean([table[p][e][1] for e in episodes]) - rate), p))
    mine = np.array([_priced(table[spec][e], price, sense) for e in episodes])
    theirs = np.array([_priced(table[nearest][e], price, sense) for e in episodes])
    gain = metrics.oriented(mine - theirs, sense)
    scale, ci = abs(float(theirs.mean())), _ci(gain)
    return {
        "policy": nearest,
        "objective": float(theirs.mean()),
        "gain": float(gain.mean()),
        "gain_ci95": ci,
        "gain_percent": 100.0 * float(gain.mean()) / scale,
        "gain_percent_ci95": _percent(ci, scale),
    }


def build_pareto(
    domain: str, sense: str, settings, fixed: dict, periodic: list[str], events: list[str], priced: list[dict]
) -> dict:
    """``pareto.json``: a point per (policy, price) and, per price, the equal-rate answer."""
    fixed_table = episode_table(fixed)
    on_front = front(fixed_table, periodic, sorted(fixed_table[periodic[0]]), sense)
    points: list[dict] = []
    answers: list[dict] = []
    for price, evaluation in zip(settings.prices, priced, strict=True):
        table = {**episode_table(evaluation), **fixed_table}
        kinds = {**{p: "periodic" for p in periodic}, **{p: "event" for p in events}}
        for spec in evaluation["policies"]:  # the priced policies: rollout, rl, self and the oracle
            family = kind_of(spec).family
            kinds[spec] = family if family in ("oracle", "learned", "self") else "rollout"
        rows = {}
        for spec, kind in kinds.items():
            by = table.get(spec, {})
            if not by:
                continue
            cells = list(by.values())
            rows[spec] = {
                "policy": spec,
                "kind": kind,
                "price": price,
                "clairvoyant": kind == "oracle",
                "episodes": len(cells),
                "computations": float(np.mean([n for _, n in cells])),
                "control_objective": float(np.mean([c for c, _ in cells])),
                "objective": float(np.mean([objective(c, n, price, sense) for c, n in cells])),
                "versus_nearest_periodic": None if kind == "periodic" else versus_nearest(table, periodic, spec, price, sense),
                "versus_periodic_front": None if kind == "periodic" else versus_front(table, periodic, spec, sense),
            }
            if kind == "periodic":
                rows[spec]["on_front"] = spec in on_front
        points += rows.values()
        answers.append(_answer(price, rows, best_periodic(fixed, periodic, price, sense)))
    return {
        "format": "etmpc-pareto",
        "version": 1,
        "domain": domain,
        "objective_sense": sense,
        "settings": settings.to_json(),
        "test_set": fixed["test_set"],
        "episodes": settings.episodes,
        "points": points,
        "answers": answers,
    }


def _answer(price: float, rows: dict, best: str) -> dict:
    """At ``price``: the gain over the periodic front at equal rates of the rollout, learned and
    self-triggering policies, of the best event trigger, and of the oracle (a reference)."""

    def best_of(kind):
        candidates = [r for r in rows.values() if r["kind"] == kind and r["versus_periodic_front"] is not None]
        if not candidates:
            return None
        row = max(candidates, key=lambda r: r["versus_periodic_front"]["gain"])
        return {"policy": row["policy"], **row["versus_periodic_front"]}

    return {
        "price": price,
        "best_periodic": best,
        "rollout": best_of("rollout"),
        "learned": best_of("learned"),
        "self": best_of("self"),
        "best_event": best_of("event"),
        "oracle": best_of("oracle"),
    }


def short_name(spec: str) -> str:
    """A policy's name for tables and legends: a learned policy by its run folder and file, a
    self-trigger by its file."""
    kind, path = find(spec), Path(spec.partition(":")[2])
    if kind is not None and kind.name == "rl":
        return f"rl:{path.parent.name}/{path.name}"
    if kind is not None and kind.name == "self":
        return f"self:{path.name}"
    return spec


def _pct(row: dict | None) -> str:
    if row is None:
        return "outside the periodic range"
    ci = "(one episode: no CI)" if row["gain_percent_ci95"] is None else f"± {row['gain_percent_ci95']:.2f} %"
    return f"`{short_name(row['policy'])}` {row['computations']:.1f} recomputes: {row['gain_percent']:+.2f} % {ci}"


def _with_options(pareto: dict) -> str:
    """`` with --option NAME=VALUE ...`` for a sweep made with the task's options, else nothing."""
    written = "".join(f" --option {name}={value}" for name, value in pareto["settings"].get("options") or [])
    return f" with{written}" if written else ""


def report_section(pareto: dict) -> list[str]:
    """A Markdown section: at equal rates, each state-dependent policy against the periodic front."""
    sense = metrics.higher_or_lower(pareto["objective_sense"])
    lines = [
        f"## {pareto['domain']}{_with_options(pareto)}: state-dependent against periodic at equal recompute rates",
        "",
        f"First {pareto['episodes']} test-set episodes, paired per episode; the periodic front interpolated at "
        f"each policy's mean rate; gains in control objective ({sense} is better), > 0 = better than the front, "
        "95 % CI. The oracle knows the future: a reference, not a policy. The best event trigger is the best of "
        f"{len(pareto['settings']['thresholds'])} levels, so its gain is biased upwards (a maximum over noisy "
        "estimates).",
        "",
        "| price | best periodic | rollout | learned (DPI, trained at the price) | self-trigger (trained at the price) "
        "| best event trigger | oracle |",
        "|---|---|---|---|---|---|---|",
    ]
    for a in pareto["answers"]:
        learned = "not trained" if pareto["settings"].get("learner") is None else _pct(a["learned"])
        own = "not trained" if pareto["settings"].get("self_trigger") is None else _pct(a.get("self"))
        lines.append(
            f"| {a['price']:g} | `{a['best_periodic']}` | {_pct(a['rollout'])} | {learned} | {own} | "
            f"{_pct(a['best_event'])} | {_pct(a['oracle'])} |"
        )
    return lines
