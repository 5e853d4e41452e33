"""The whole trade-off curve: control objective against computations, over prices of a computation.

``etmpc sweep TASK`` answers the classic question of event-triggered control: *at an equal number of
computations, does a state-dependent trigger beat a periodic one, and by how much?* On the same
test-set episodes it plays

* every periodic schedule ``every:T``, T = 1 … N (``every:1`` is ``always``, ``every:N`` is
  ``never``): the **periodic front**;
* a grid of event triggers ``threshold:X`` spanning the same range of computation rates;

once (their decisions do not depend on the price: only their objective does, and it is recomputed
for every price from the control objective and the computations of each episode), and, for every
price ``p``,

* the rollout policy ``rollout:BEST:K:H`` over the best periodic schedule at ``p``, which optimises
  the objective at ``p`` (see :mod:`etmpc.policies.rollout`);
* the oracle ``oracle:BEST``: an upper bound on what any trigger could gain at ``p``, not a policy;
* a learned policy trained at ``p`` with the default learner (DPI on the ``error`` features, see
  :mod:`etmpc.learning.dpi`), chosen among its seeds on training-distribution episodes, never the test set;
* a self-triggering policy ``self:PATH`` trained at ``p`` (see :mod:`etmpc.policies.selftrigger`): at each
  solve it announces how long the plan will be kept.

Comparisons are paired per episode. *At an equal rate*: the periodic front (the schedules no other
schedule beats in both rate and control objective) is interpolated per episode between the two
of its schedules whose mean rates bracket the policy's, with the weights that make
the front's mean rate the policy's, so the difference of control objectives is a difference at the
same mean number of computations (and so at the same mean price paid). Against the *nearest
periodic schedule*: the objective at ``p``, computations included.

Outputs (all written atomically; a directory is resumable and never written into by another run):
``settings.json``, ``fixed.json``, ``price_<i>.json``, ``learned_<i>.json`` and ``self_<i>.json``
(evaluations), ``train_<i>/`` (the training run at price ``i``), ``self_policy_<i>.json`` (the
self-trigger trained at price ``i``), ``pareto.json``, ``pareto.png`` and ``SWEEP.md``.
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from etmpc.common.errors import EtmpcError
from etmpc.common.outputs import refuse_foreign, write_json, write_text
from etmpc.learning.selftrigger import SelfSettings
from etmpc.systems import check_price, make_system

# Prices of a computation, in the objective's unit. The cart pendulum: a log grid around the paper's
# 5e-5 (where 100 computations cost 1.3 % of the objective) up to where `never` wins. The battery:
# prices added to the energy its computer already draws from the battery (eta_c, in the control
# objective), from the paper's 0 up to where `never` wins.
DEFAULT_PRICES = {
    "cart_pendulum": (5e-6, 1.6e-5, 5e-5, 1.6e-4, 5e-4, 1.6e-3),
    "battery": (0.0, 3e-4, 1e-3, 3e-3, 1e-2),
}
# Event-trigger levels that span the periodic schedules' rates (from ~every step to ~never). The
# battery's prediction error is mostly the computer's own draw (2.8e-5 of charge per interval), so
# its grid is dense there.
THRESHOLDS = {
    "cart_pendulum": (0.05, 0.08, 0.13, 0.2, 0.3, 0.45, 0.7, 1.0, 1.5),
    "battery": (1e-5, 2.6e-5, 2.75e-5, 2.9e-5, 1e-4, 1e-3, 3e-3, 1e-2, 3e-2, 0.1),
}
MAX_PRICES = 50


@dataclass(frozen=True)
class LearnerSettings:
    """The default learner at each price, smaller than ``reproduce``'s: DPI, whose first policy
    rolls out over the best of ``bases`` (wide enough for every price) on training episodes."""

    seeds: tuple[int, ...] = (0, 1)
    episodes: int = 40  # training episodes per seed: 2 DPI iterations of 20
    eval_every: int = 20
    eval_episodes: int = 1  # the learning curve's test-set episodes (reported, never used to choose)
    labels: int = 15  # decisions labelled per training episode
    futures: int = 2
    horizon: int = 10
    validation_episodes: int = 20  # training-distribution episodes that choose among the seeds
    bases: tuple[str, ...] = ("always", "every:2", "every:3", "every:5", "every:8", "every:12", "every:20")
    selection_episodes: int = 20

    def config(self, domain: str, price: float):
        from etmpc.learning import dpi
        from etmpc.learning.train import TrainConfig

        return TrainConfig(domain, self.seeds, self.episodes, self.eval_every, self.eval_episodes, algorithm="dpi",
                           dpi=dpi.Settings(self.futures, self.horizon, self.labels, bases=self.bases,
                                            selection_episodes=self.selection_episodes),
                           validation_episodes=self.validation_episodes, recompute_price=price)


QUICK_LEARNER = LearnerSettings(seeds=(0,), episodes=4, eval_every=2, labels=5, futures=2, horizon=10, validation_episodes=3,
                                selection_episodes=2)


QUICK_SELF = SelfSettings(selection_episodes=2, episodes=3, solves_per_episode=3, validation_episodes=2)


@dataclass(frozen=True)
class SweepSettings:
    prices: tuple[float, ...]
    episodes: int  # the first test-set episodes, for every policy
    thresholds: tuple[float, ...]
    futures: int = 4  # K of the rollout policy
    horizon: int = 20  # H of the rollout policy
    quick: bool = False
    learner: LearnerSettings | None = LearnerSettings()  # None: no learned policies
    self_trigger: SelfSettings | None = SelfSettings()  # None: no self-triggering policies

    @classmethod
    def default(cls, domain: str, prices=None, episodes: int | None = None, quick: bool = False) -> SweepSettings:
        prices = DEFAULT_PRICES[domain] if prices is None else tuple(prices)
        if not 1 <= len(prices) <= MAX_PRICES:
            raise EtmpcError(f"give 1 to {MAX_PRICES} prices, got {len(prices)}")
        prices = tuple(check_price(p) for p in prices)
        if len(set(prices)) != len(prices):
            raise EtmpcError(f"a price is given twice: {', '.join(f'{p:g}' for p in prices)}")
        if quick:
            return cls(prices, episodes or 3, THRESHOLDS[domain][::2], futures=2, horizon=10, quick=True,
                       learner=QUICK_LEARNER, self_trigger=QUICK_SELF)
        return cls(prices, episodes or 20, THRESHOLDS[domain])

    def to_json(self) -> dict:
        return _lists(asdict(self))


def _lists(value):
    """``value`` as JSON reads it back: tuples as lists, at any depth."""
    if isinstance(value, dict):
        return {k: _lists(v) for k, v in value.items()}
    return [_lists(v) for v in value] if isinstance(value, (tuple, list)) else value


def _ours(name: str) -> bool:
    return name in ("settings.json", "fixed.json", "pareto.json", "pareto.png", "SWEEP.md") or (
        name.startswith(("price_", "learned_", "self_")) and name.endswith(".json")) or name.startswith("train_")


def check_directory(out: Path, domain: str, settings: SweepSettings) -> bool:
    """Raise unless ``out`` can hold this sweep: new, empty, or the same sweep (then True: it
    continues). Writes nothing, so every system's directory is checked before any work."""
    path = out / "settings.json"
    if not path.exists():
        refuse_foreign(out, lambda name: False, "sweep")
        return False
    try:
        stored = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise EtmpcError(f"{path} is unreadable ({exc}); move it away to start afresh") from None
    if stored != _settings_json(domain, settings):
        shown = stored.get("settings") if isinstance(stored, dict) else stored
        raise EtmpcError(f"{out} holds a sweep with other settings ({shown}); use another --out")
    refuse_foreign(out, _ours, "sweep")
    return True


def _settings_json(domain: str, settings: SweepSettings) -> dict:
    return {"format": "etmpc-sweep", "domain": domain, "settings": settings.to_json()}


def _start(out: Path, domain: str, settings: SweepSettings) -> None:
    """A new run in a new or empty directory, or the same run continued; never another's files."""
    if not check_directory(out, domain, settings):
        out.mkdir(parents=True, exist_ok=True)
        write_json(out / "settings.json", _settings_json(domain, settings))


def _stage(path: Path, **kwargs) -> dict:
    """An evaluation made once (a complete file from an earlier invocation is reused), with its
    wall time and number of workers."""
    from etmpc.evaluation.evaluate import evaluate

    if path.exists():
        return json.loads(path.read_text())
    started = time.perf_counter()
    data = evaluate(**kwargs).to_json()
    data["cost"] = {"wall_seconds": time.perf_counter() - started, "workers": kwargs.get("workers")}
    write_json(path, data)
    return data


def sweep(domain: str, out: Path, settings: SweepSettings, workers: int = 1, backend: str = "local",
          address: str | None = None, progress: bool = True, say=lambda line: None) -> dict:
    """Run (or continue) the sweep of ``domain`` into ``out``; returns ``pareto.json``'s content."""
    out = Path(out)
    system = make_system(domain)
    _start(out, domain, settings)
    started = time.perf_counter()
    run = dict(domain=domain, episodes=settings.episodes, workers=workers, backend=backend, address=address,
               progress=progress)
    periodic = [f"every:{t}" for t in range(1, system.horizon + 1)]
    events = [f"threshold:{x:g}" for x in settings.thresholds]
    say(f"{domain}: {len(periodic)} periodic schedules and {len(events)} event triggers")
    fixed = _stage(out / "fixed.json", policies=periodic + events, **run)
    priced = []
    for i, price in enumerate(settings.prices):
        best = best_periodic(fixed, periodic, price, system.objective_sense)
        say(f"{domain}: price {price:g}: rollout and oracle over {best}")
        specs = [f"rollout:{best}:{settings.futures}:{settings.horizon}", f"oracle:{best}"]
        evaluation = _stage(out / f"price_{i}.json", policies=specs, recompute_price=price, **run)
        if settings.learner is not None:
            evaluation = _merge(evaluation, _learned(out, i, domain, price, settings.learner, run))
        if settings.self_trigger is not None:
            evaluation = _merge(evaluation, _self(out, i, domain, price, settings.self_trigger, run, say))
        priced.append(evaluation)
    pareto = build_pareto(domain, system.objective_sense, settings, fixed, periodic, events, priced)
    pareto["wall_seconds_this_invocation"] = time.perf_counter() - started
    pareto["cpu_seconds_of_evaluations"] = sum(
        e["cost"]["wall_seconds"] * (e["cost"]["workers"] or 1) for e in [fixed, *priced])
    write_json(out / "pareto.json", pareto)
    from etmpc.views.figures import save_png_atomically

    save_png_atomically(draw_pareto(pareto), out / "pareto.png")
    write_text(out / "SWEEP.md", "\n".join(report_section(pareto)) + "\n")
    return pareto


def _learned(out: Path, i: int, domain: str, price: float, learner: LearnerSettings, run: dict) -> dict:
    """The default learner trained at ``price`` (``train_<i>/``, resumable), its chosen policy
    evaluated on the sweep's episodes at that price (``learned_<i>.json``)."""
    from etmpc.learning.train import train

    path, train_dir = out / f"learned_{i}.json", out / f"train_{i}"
    if path.exists():
        return json.loads(path.read_text())
    train(learner.config(domain, price), train_dir, run["workers"], resume=(train_dir / "checkpoint.json").exists(),
          backend=run["backend"], address=run["address"], progress=run["progress"])
    return _stage(path, policies=[f"rl:{train_dir / 'selected.json'}"], recompute_price=price, **run)


def _self(out: Path, i: int, domain: str, price: float, settings: SelfSettings, run: dict, say) -> dict:
    """The self-trigger trained at ``price`` (``self_policy_<i>.json``, kept once written), evaluated
    on the sweep's episodes at that price (``self_<i>.json``)."""
    from etmpc.learning.selftrigger import train_self
    from etmpc.systems import system_key

    path, policy = out / f"self_{i}.json", out / f"self_policy_{i}.json"
    if path.exists():
        return json.loads(path.read_text())
    if not policy.exists():
        train_self(system_key(domain, price), policy, settings, run["workers"], run["backend"], run["address"], say=say)
    return _stage(path, policies=[f"self:{policy}"], recompute_price=price, **run)


def _merge(a: dict, b: dict) -> dict:
    """Two evaluations of the same episodes as one (their policies and runs side by side)."""
    return {**a, "policies": {**a["policies"], **b["policies"]}, "runs": a["runs"] + b["runs"],
            "cost": {"wall_seconds": a["cost"]["wall_seconds"] + b["cost"]["wall_seconds"], "workers": a["cost"]["workers"]}}


# -- the numbers ------------------------------------------------------------------------------------
def episode_table(evaluation: dict) -> dict[str, dict[int, tuple[float, float]]]:
    """policy -> episode -> (control objective, computations), over finite runs (repeats averaged)."""
    values: dict[str, dict[int, list[tuple[float, float]]]] = {}
    for r in evaluation["runs"]:
        if r["finite"]:
            values.setdefault(r["policy"], {}).setdefault(r["episode"], []).append((r["control_objective"], r["recomputes"]))
    return {spec: {e: tuple(np.mean(v, axis=0)) for e, v in by.items()} for spec, by in values.items()}


def objective(control: float, computations: float, price: float, sense: str) -> float:
    """The objective at ``price``: the control objective and the price of the computations, sense-aware."""
    return control + price * computations if sense == "min" else control - price * computations


def best_periodic(fixed: dict, periodic: list[str], price: float, sense: str) -> str:
    """The periodic schedule with the best mean objective at ``price`` on the evaluated episodes."""
    table = episode_table(fixed)
    means = {spec: np.mean([objective(c, n, price, sense) for c, n in table[spec].values()]) for spec in periodic}
    return (max if sense == "max" else min)(means, key=lambda spec: (means[spec], spec))


def _ci(diff: np.ndarray) -> float | None:
    """The half-width of the paired 95 % normal interval; ``None`` (JSON null) for one episode."""
    return float(1.96 * diff.std(ddof=1) / math.sqrt(len(diff))) if len(diff) > 1 else None


def _percent(value: float | None, scale: float) -> float | None:
    return None if value is None else 100.0 * value / scale


def front(table: dict, periodic: list[str], episodes: list[int], sense: str) -> list[str]:
    """The periodic schedules no other beats on ``episodes``: none has a lower-or-equal mean rate and
    a better-or-equal mean control objective (one of them strictly), ordered by rate. Comparing with
    this front, never with a dominated schedule, keeps the comparison fair to the periodic side."""
    sign = 1.0 if sense == "max" else -1.0
    points = {p: (np.mean([table[p][e][1] for e in episodes]), sign * np.mean([table[p][e][0] for e in episodes]))
              for p in periodic}
    efficient = [p for p, (rate, value) in points.items()
                 if not any(r <= rate and v >= value and (r, v) != (rate, value) for r, v in points.values())]
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
    sign = 1.0 if sense == "max" else -1.0
    gain = sign * (mine - front_values)
    scale = abs(float(front_values.mean()))
    ci = _ci(gain)
    return {"episodes": len(episodes), "computations": rate, "between": [ordered[lo], ordered[hi]], "weight": float(w),
            "front_control_objective": float(front_values.mean()), "control_objective": float(mine.mean()),
            "gain": float(gain.mean()), "gain_ci95": ci, "gain_percent": 100.0 * float(gain.mean()) / scale,
            "gain_percent_ci95": _percent(ci, scale), "better_episodes": int((gain > 0).sum())}


def versus_nearest(table: dict, periodic: list[str], spec: str, price: float, sense: str) -> dict:
    """``spec``'s objective at ``price`` against the periodic schedule with the nearest mean rate."""
    episodes = sorted(table[spec])
    rate = np.mean([table[spec][e][1] for e in episodes])
    nearest = min(periodic, key=lambda p: (abs(np.mean([table[p][e][1] for e in episodes]) - rate), p))
    mine = np.array([objective(*table[spec][e], price, sense) for e in episodes])
    theirs = np.array([objective(*table[nearest][e], price, sense) for e in episodes])
    gain = (1.0 if sense == "max" else -1.0) * (mine - theirs)
    scale, ci = abs(float(theirs.mean())), _ci(gain)
    return {"policy": nearest, "objective": float(theirs.mean()), "gain": float(gain.mean()), "gain_ci95": ci,
            "gain_percent": 100.0 * float(gain.mean()) / scale, "gain_percent_ci95": _percent(ci, scale)}


def build_pareto(domain: str, sense: str, settings: SweepSettings, fixed: dict, periodic: list[str], events: list[str],
                 priced: list[dict]) -> dict:
    """``pareto.json``: a point per (policy, price) and, per price, the equal-rate answer."""
    fixed_table = episode_table(fixed)
    on_front = front(fixed_table, periodic, sorted(fixed_table[periodic[0]]), sense)
    points, answers = [], []
    for price, evaluation in zip(settings.prices, priced, strict=True):
        table = {**episode_table(evaluation), **fixed_table}
        kinds = {**{p: "periodic" for p in periodic}, **{p: "event" for p in events}}
        for spec in evaluation["policies"]:
            kinds[spec] = ("oracle" if spec.startswith("oracle:") else "learned" if spec.startswith("rl:")
                           else "self" if spec.startswith("self:") else "rollout")
        rows = {}
        for spec, kind in kinds.items():
            by = table.get(spec, {})
            if not by:
                continue
            cells = list(by.values())
            rows[spec] = {
                "policy": spec, "kind": kind, "price": price, "upper_bound": kind == "oracle", "episodes": len(cells),
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
    return {"format": "etmpc-pareto", "version": 1, "domain": domain, "objective_sense": sense,
            "settings": settings.to_json(), "test_set": fixed["test_set"], "episodes": settings.episodes,
            "points": points, "answers": answers}


def _answer(price: float, rows: dict, best: str) -> dict:
    """At ``price``: the gain over the periodic front at equal rates of the rollout, learned and
    self-triggering policies, of the best event trigger, and of the oracle (the bound)."""
    def best_of(kind):
        candidates = [r for r in rows.values() if r["kind"] == kind and r["versus_periodic_front"] is not None]
        if not candidates:
            return None
        row = max(candidates, key=lambda r: r["versus_periodic_front"]["gain"])
        return {"policy": row["policy"], **row["versus_periodic_front"]}
    return {"price": price, "best_periodic": best, "rollout": best_of("rollout"), "learned": best_of("learned"),
            "self": best_of("self"), "best_event": best_of("event"), "oracle": best_of("oracle")}


# -- the figure and the report ------------------------------------------------------------------------
def draw_pareto(pareto: dict):
    """Control objective against computations per episode: every periodic schedule as a grey dot and
    the periodic front (the schedules no other beats) as a line, the event triggers as a dashed line
    of points; at each price, coloured by price, the rollout (diamond), learned (square) and
    self-triggering (triangle) policies as filled points and the oracle bound as a hollow circle."""
    import matplotlib.pyplot as plt

    points, sense = pareto["points"], pareto["objective_sense"]
    prices = pareto["settings"]["prices"]
    first = [p for p in points if p["price"] == prices[0]]
    fig, ax = plt.subplots(figsize=(8, 5.2), layout="constrained")
    periodic = [p for p in first if p["kind"] == "periodic"]
    ax.plot([p["computations"] for p in periodic], [p["control_objective"] for p in periodic], "o", color="0.55",
            markersize=4, label="periodic every:T", gid="periodic-points")
    for kind, style, label in (("periodic", dict(color="black", marker="o", linestyle="-"), "the periodic front"),
                               ("event", dict(color="tab:blue", marker="x", linestyle="--"), "event trigger threshold:X")):
        rows = sorted((p for p in first if p["kind"] == kind and p.get("on_front", True)), key=lambda p: p["computations"])
        ax.plot([p["computations"] for p in rows], [p["control_objective"] for p in rows], label=label, gid=kind, **style)
    colours = plt.get_cmap("viridis")(np.linspace(0.0, 0.9, len(prices)))
    for colour, price in zip(colours, prices, strict=True):
        for kind, marker, face, name in (("rollout", "D", colour, "rollout"), ("learned", "s", colour, "learned (DPI)"),
                                         ("self", "^", colour, "self-trigger"), ("oracle", "o", "none", "oracle bound")):
            rows = [p for p in points if p["price"] == price and p["kind"] == kind]
            if not rows:
                continue
            label = f"{name}, price {price:g}"
            ax.scatter([p["computations"] for p in rows], [p["control_objective"] for p in rows], marker=marker, s=60,
                       facecolors=face, edgecolors=colour, linewidths=1.5, label=label, gid=f"{kind}@{price!r}", zorder=3)
    ax.set_xlabel("computations per episode")
    ax.set_ylabel(f"control objective ({'lower' if sense == 'min' else 'higher'} is better)")
    ax.set_title(f"{pareto['domain']}: the trade-off, {pareto['episodes']} test-set episodes (oracle: an upper bound)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, ncols=2, loc="best")
    return fig


def short_name(spec: str) -> str:
    """A policy's name for tables and legends: a learned policy by its run folder and file, a
    self-trigger by its file."""
    if spec.startswith("rl:"):
        path = Path(spec[3:])
        return f"rl:{path.parent.name}/{path.name}"
    if spec.startswith("self:"):
        return f"self:{Path(spec[5:]).name}"
    return spec


def _pct(row: dict | None) -> str:
    if row is None:
        return "outside the periodic range"
    ci = "(one episode: no CI)" if row["gain_percent_ci95"] is None else f"± {row['gain_percent_ci95']:.2f} %"
    return f"`{short_name(row['policy'])}` {row['computations']:.1f} computations: {row['gain_percent']:+.2f} % {ci}"


def report_section(pareto: dict) -> list[str]:
    """A Markdown section: at equal rates, each state-dependent policy against the periodic front."""
    sense = "lower" if pareto["objective_sense"] == "min" else "higher"
    lines = [f"## {pareto['domain']}: state-dependent against periodic at equal computation rates", "",
             f"First {pareto['episodes']} test-set episodes, paired per episode; the periodic front interpolated at "
             f"each policy's mean rate; gains in control objective ({sense} is better), > 0 = better than the front, "
             "95 % CI. The oracle is an upper bound, not a policy. The best event trigger is the best of "
             f"{len(pareto['settings']['thresholds'])} levels, so its gain is biased upwards (a maximum over noisy "
             "estimates).", "",
             "| price | best periodic | rollout | learned (DPI, trained at the price) | self-trigger (trained at the price) "
             "| best event trigger | oracle bound |",
             "|---|---|---|---|---|---|---|"]
    for a in pareto["answers"]:
        learned = "not trained" if pareto["settings"].get("learner") is None else _pct(a["learned"])
        own = "not trained" if pareto["settings"].get("self_trigger") is None else _pct(a.get("self"))
        lines.append(f"| {a['price']:g} | `{a['best_periodic']}` | {_pct(a['rollout'])} | {learned} | {own} | "
                     f"{_pct(a['best_event'])} | {_pct(a['oracle'])} |")
    return lines
