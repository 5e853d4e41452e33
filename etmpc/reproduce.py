"""``etmpc reproduce``: the paper's experiments on both systems, one command, with a report.

Per system, in ``DIR/<domain>/``:

1. ``baselines.json``: the fixed policies (``always``, ``never``, ``every:T`` for every T that
   matters, thresholds) on the test set;
2. ``train/``: the learned policy over the seeds with the paper's protocol (``etmpc train``);
3. ``learned.json``: each seed's final policy (``last.json``) evaluated ``repeats`` times;
4. figures: ``figure1_forecasts.png`` (battery), ``train/curve.png`` (Figure 2),
   ``figure3.png``, ``trajectory.png`` (the best fixed policy's first episode);
5. ``episodes.rrd``: a Rerun recording of representative episodes (the best fixed policy and
   the first seed's learned policy); ``episode.mp4``: a rendered video (cart pendulum).

Then ``DIR/results.json`` (everything the report says, machine-readable) and ``DIR/REPORT.md``,
which is written from ``results.json`` alone. Every stage writes its files atomically and is
skipped when they are there, so running the command again after an interruption continues; the
settings are kept in ``DIR/settings.json`` and a second run with other settings is refused.
"""

from __future__ import annotations

import json
import os
import platform
import sys
import time
from dataclasses import asdict, dataclass
from importlib import metadata
from pathlib import Path

import numpy as np

from etmpc.errors import EtmpcError
from etmpc.evaluate import evaluate
from etmpc.learned import write_json_atomically
from etmpc.systems import make_system
from etmpc.train import TrainConfig, curve_summary, load_checkpoint, train

DOMAINS = ("cart_pendulum", "battery")
BASELINES = {
    "cart_pendulum": ["always", "never"] + [f"every:{t}" for t in (2, 3, 4, 5, 7, 10, 15)]
    + [f"threshold:{x}" for x in (0.1, 0.2, 0.3, 0.5)],
    "battery": ["always", "never"] + [f"every:{t}" for t in (2, 3, 4, 5, 7, 10, 15)]
    + [f"threshold:{x}" for x in (0.005, 0.01, 0.02, 0.05)],
}
# The paper's headline figures (SPEC.md), to set the results against.
PAPER = {"cart_pendulum": {"margin_percent": 5.0}, "battery": {"margin_percent": 7.0}}


@dataclass(frozen=True)
class Settings:
    """How big the run is. ``full`` is the paper's protocol; ``quick`` the same steps, smaller."""

    seeds: tuple[int, ...] = (0, 1, 2, 3, 4)
    episodes: int = 1500  # training episodes per seed
    eval_every: int = 150
    eval_episodes: int | None = None  # test-set episodes per evaluation during training (None: all)
    test_episodes: int | None = None  # test-set episodes for the baselines and the final evaluation
    repeats: int = 5  # passes over the test set for the learned policy
    record_episodes: int = 3  # representative episodes per policy in the recording
    video_size: tuple[int, int] = (640, 480)

    def to_json(self) -> dict:
        data = asdict(self)
        data["seeds"], data["video_size"] = list(self.seeds), list(self.video_size)
        return data


FULL = Settings()
QUICK = Settings(episodes=30, eval_every=15, eval_episodes=10, test_episodes=20, repeats=2, record_episodes=2,
                 video_size=(320, 240))


def reproduce(out: Path, settings: Settings = FULL, workers: int = 1, backend: str = "local",
              address: str | None = None, domains=DOMAINS, progress: bool = True) -> dict:
    """Run (or continue) every stage into ``out``; returns ``results.json``'s content."""
    out = Path(out)
    started = time.perf_counter()
    _check_settings(out, settings, domains)
    run = dict(workers=workers, backend=backend, address=address)
    systems = {}
    for domain in domains:
        systems[domain] = _system(out / domain, domain, settings, run, progress)
    results = {
        "format": "etmpc-reproduce", "version": 1, "settings": settings.to_json(), "systems": systems,
        "software": software_versions(), "machine": machine(),
        "wall_seconds_this_invocation": time.perf_counter() - started,
    }
    write_json_atomically(out / "results.json", results)
    _write_text(out / "REPORT.md", report(results))
    return results


def _check_settings(out: Path, settings: Settings, domains) -> None:
    path = out / "settings.json"
    wanted = {"settings": settings.to_json(), "domains": list(domains)}
    if path.exists():
        try:
            stored = json.loads(path.read_text())
        except (OSError, ValueError) as exc:
            raise EtmpcError(f"{path} is unreadable ({exc}); move it away to start afresh") from None
        if stored != wanted:
            raise EtmpcError(f"{out} holds a run with other settings ({stored['settings']}); use another --out")
    else:
        out.mkdir(parents=True, exist_ok=True)
        write_json_atomically(path, wanted)


def _evaluated(path: Path, **kwargs) -> dict:
    """An evaluation's JSON, made once: a complete file from an earlier invocation is reused."""
    if path.exists():
        return json.loads(path.read_text())
    data = evaluate(**kwargs).to_json()
    write_json_atomically(path, data)
    return data


def _system(folder: Path, domain: str, settings: Settings, run: dict, progress: bool) -> dict:
    from etmpc import figures

    system = make_system(domain)
    folder.mkdir(parents=True, exist_ok=True)
    common = dict(domain=domain, episodes=settings.test_episodes, workers=run["workers"], backend=run["backend"],
                  address=run["address"], progress=progress)
    _say(f"{domain}: fixed policies")
    baselines = _evaluated(folder / "baselines.json", policies=BASELINES[domain], **common)

    _say(f"{domain}: training {len(settings.seeds)} seeds x {settings.episodes} episodes")
    config = TrainConfig(domain, settings.seeds, settings.episodes, settings.eval_every, settings.eval_episodes)
    train_dir = folder / "train"
    train(config, train_dir, run["workers"], resume=(train_dir / "checkpoint.json").exists(), backend=run["backend"],
          address=run["address"], progress=progress)
    state = load_checkpoint(train_dir / "checkpoint.json")

    _say(f"{domain}: the learned policies, {settings.repeats} passes")
    learned_specs = [f"rl:{train_dir / f'seed{s}' / 'last.json'}" for s in settings.seeds]
    learned = _evaluated(folder / "learned.json", policies=learned_specs, repeats=settings.repeats, **common)

    summary = summarise_system(system, baselines, learned, curve_summary(state))
    best = summary["best_fixed"]["policy"]

    _say(f"{domain}: figures, recording, video")
    if not (folder / "figure3.png").exists():
        figures.write_policy_bars_png(folder / "figure3.png", [baselines, learned])
    if not (folder / "episodes.rrd").exists():
        evaluate(domain, [best, learned_specs[0]], episodes=settings.record_episodes, workers=run["workers"],
                 progress=False, record=folder / "episodes.rrd")
    files = {"baselines": "baselines.json", "learned": "learned.json", "curve": "train/curve.png",
             "figure3": "figure3.png", "recording": "episodes.rrd", "trajectory": "trajectory.png"}
    _trajectory_png(folder / "trajectory.png", system, best)
    if domain == "battery":
        _forecasts_png(folder / "figure1_forecasts.png", system)
        files["figure1"] = "figure1_forecasts.png"
    if domain == "cart_pendulum" and not (folder / "episode.mp4").exists():
        from etmpc.render import render_rollout

        render_rollout(domain, best, 0, folder / "episode.mp4", width=settings.video_size[0], height=settings.video_size[1])
    if domain == "cart_pendulum":
        files["video"] = "episode.mp4"
    summary["files"] = {k: f"{domain}/{v}" for k, v in files.items()}
    return summary


def summarise_system(system, baselines: dict, learned: dict, curve: dict) -> dict:
    """The numbers of the report for one system, from the evaluation JSONs and the learning curve."""
    sense = system.objective_sense
    better = (lambda a, b: a > b) if sense == "max" else (lambda a, b: a < b)
    fixed = baselines["policies"]
    best = None
    for spec, s in fixed.items():
        if best is None or better(s["objective_mean"], fixed[best]["objective_mean"]):
            best = spec
    per_seed = [s["objective_mean"] for s in learned["policies"].values()]
    # As evaluate does: a run that ended on a non-finite state is counted, never averaged in.
    learned_runs = [r for r in learned["runs"] if r["finite"]]
    # Paired over test-set episodes: the learned policy's mean over seeds and passes against the
    # best fixed policy on the same episode.
    by_episode: dict[int, list[float]] = {}
    for r in learned_runs:
        by_episode.setdefault(r["episode"], []).append(r["objective"])
    fixed_by_episode = {r["episode"]: r["objective"] for r in baselines["runs"] if r["policy"] == best and r["finite"]}
    episodes = sorted(set(by_episode) & set(fixed_by_episode))
    diff = np.array([np.mean(by_episode[e]) - fixed_by_episode[e] for e in episodes])
    gain = diff if sense == "max" else -diff  # > 0: the learned policy is better
    learned_mean = float(np.mean([r["objective"] for r in learned_runs]))
    best_value = fixed[best]["objective_mean"]
    margin_percent = 100.0 * (learned_mean - best_value) / abs(best_value) * (1 if sense == "max" else -1)
    points = curve["points"]
    values = [p["objective_mean"] for p in points]
    best_point = points[int(np.argmax(values) if sense == "max" else np.argmin(values))]
    return {
        "domain": system.domain,
        "objective_sense": sense,
        "episodes": baselines["policies"][best]["episodes"],
        "fixed": {spec: _row(s) for spec, s in fixed.items()},
        "best_fixed": dict(_row(fixed[best]), policy=best),
        "learned": {
            "objective_mean": learned_mean,
            "objective_std_seeds": float(np.std(per_seed, ddof=1)) if len(per_seed) > 1 else 0.0,
            "control_objective_mean": float(np.mean([r["control_objective"] for r in learned_runs])),
            "recomputes_mean": float(np.mean([r["recomputes"] for r in learned_runs])),
            "solver_failures": int(sum(r["solver_failures"] for r in learned["runs"])),
            "nonfinite_episodes": len(learned["runs"]) - len(learned_runs),
            "per_seed": per_seed,
            "repeats": next(iter(learned["policies"].values()))["repeats"],
        },
        "paired": {
            "mean_difference": float(diff.mean()),
            "ci95": float(1.96 * diff.std(ddof=1) / np.sqrt(len(diff))) if len(diff) > 1 else float("nan"),
            "learned_better_episodes": int((gain > 0).sum()),
            "episodes": len(diff),
        },
        "margin_percent": margin_percent,
        "curve": {"start": points[0], "best": best_point, "final": points[-1], "points": points},
    }


def _row(s: dict) -> dict:
    keys = ("objective_mean", "objective_std", "control_objective_mean", "recomputes_mean", "solver_failures")
    return {k: s[k] for k in keys}


def _trajectory_png(path: Path, system, spec: str) -> None:
    if path.exists():
        return
    from etmpc import figures
    from etmpc.policies import parse_policy
    from etmpc.workers import play_test_episode

    played = play_test_episode(system.domain, parse_policy(spec, system.error_weights, system.domain), 0, 0, 0)
    figures.write_trajectory_png(path, system, played.trajectory, title=f"{system.domain}: test-set episode 0 under {spec}",
                                 signals=system.signals(played.episode))


def _forecasts_png(path: Path, system) -> None:
    if path.exists():
        return
    from etmpc import figures
    from etmpc.policies import parse_policy
    from etmpc.workers import play_test_episode

    runs = [(spec, play_test_episode(system.domain, parse_policy(spec, system.error_weights), 0, 0, 0)) for spec in ("every:20", "every:5")]
    fig = figures.forecast_figure(runs[0][1].episode, [(spec, played.trajectory) for spec, played in runs],
                                  system.control_interval_s, system.terminal_price)
    figures.save_png_atomically(fig, path, dpi=110)


def software_versions() -> dict:
    names = ("numpy", "scipy", "mujoco", "dm-control", "casadi", "control", "rerun-sdk", "ray", "matplotlib", "av")
    versions = {"python": platform.python_version()}
    for name in names:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = None
    versions["etmpc"] = metadata.version("etmpc")
    return versions


def machine() -> dict:
    cpu = platform.processor() or ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    try:
        memory = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 2**30
    except (ValueError, OSError):
        memory = float("nan")
    return {"platform": platform.platform(), "cpu": cpu, "cores": len(os.sched_getaffinity(0)), "memory_gib": round(memory, 1)}


# -- the report ------------------------------------------------------------------------------------
def _f(x: float) -> str:
    return f"{x:.5f}"


def report(results: dict) -> str:
    """``REPORT.md`` from ``results.json``'s content alone."""
    s = results["settings"]
    lines = [
        "# etmpc: the paper's experiments, reproduced",
        "",
        f"Settings: {len(s['seeds'])} seeds x {s['episodes']} training episodes, evaluated every {s['eval_every']}"
        f" on {s['eval_episodes'] or 'all'} test-set episodes; fixed policies and the final learned policies on "
        f"{s['test_episodes'] or 'all'} test-set episodes, the learned ones {s['repeats']} times.",
        "",
    ]
    for domain, r in results["systems"].items():
        sense = "higher" if r["objective_sense"] == "max" else "lower"
        unit = "profit, EUR" if r["objective_sense"] == "max" else "cost"
        lines += [f"## {domain}", "", f"Objective: {unit}, {sense} is better, mean over {r['episodes']} test-set episodes.", "",
                  "| policy | objective | ± std over episodes | control | recomputes | solver failures |",
                  "|---|---|---|---|---|---|"]
        for spec, row in r["fixed"].items():
            mark = " **(best fixed)**" if spec == r["best_fixed"]["policy"] else ""
            lines.append(f"| `{spec}`{mark} | {_f(row['objective_mean'])} | {_f(row['objective_std'])} | "
                         f"{_f(row['control_objective_mean'])} | {row['recomputes_mean']:.2f} | {row['solver_failures']} |")
        le = r["learned"]
        lines.append(f"| learned ({len(le['per_seed'])} seeds x {le['repeats']} passes) | {_f(le['objective_mean'])} | "
                     f"± {_f(le['objective_std_seeds'])} over seeds | {_f(le['control_objective_mean'])} | "
                     f"{le['recomputes_mean']:.2f} | {le['solver_failures']} |")
        p = r["paired"]
        c = r["curve"]
        lines += [
            "",
            f"**Learned minus best fixed (`{r['best_fixed']['policy']}`)**, paired over test-set episodes: "
            f"{p['mean_difference']:+.5f} ± {p['ci95']:.5f} (95 % CI); the learned policy is better in "
            f"{p['learned_better_episodes']}/{p['episodes']} episodes; margin {r['margin_percent']:+.2f} % "
            f"(positive: the learned policy is better).",
            "",
            f"**Learning curve** (test-set objective, mean ± std over seeds): start {_f(c['start']['objective_mean'])} "
            f"({c['start']['recomputes_mean']:.1f} recomputes), best {_f(c['best']['objective_mean'])} at "
            f"{c['best']['episodes']} episodes, final {_f(c['final']['objective_mean'])} ± {_f(c['final']['objective_std'])} "
            f"({c['final']['recomputes_mean']:.1f} recomputes).",
            "",
            f"![learning curve]({r['files']['curve']}) ![Figure 3]({r['files']['figure3']})",
            "",
            f"Files: {', '.join(f'`{v}`' for v in r['files'].values())}.",
            "",
        ]
    lines += ["## Against the paper", ""] + against_the_paper(results) + [""]
    lines += ["## Software and machine", "", "| package | version |", "|---|---|"]
    lines += [f"| {k} | {v} |" for k, v in results["software"].items()]
    m = results["machine"]
    lines += ["", f"Machine: {m['cpu']}, {m['cores']} cores, {m['memory_gib']} GiB, {m['platform']}.", ""]
    return "\n".join(lines)


def against_the_paper(results: dict) -> list[str]:
    """Each headline claim of SPEC.md, and whether it holds here, with the numbers."""
    out = []
    systems = results["systems"]
    for domain, r in systems.items():
        paper = PAPER[domain]["margin_percent"]
        holds = r["margin_percent"] > 0 and r["paired"]["mean_difference"] != 0 and \
            r["paired"]["ci95"] < abs(r["paired"]["mean_difference"])
        out.append(f"- *The learned policy is the best on {domain}, about {paper:g} % better than the second best.* "
                   f"{'Holds' if holds else 'Does not hold'} here: learned {_f(r['learned']['objective_mean'])} against "
                   f"the best fixed `{r['best_fixed']['policy']}` {_f(r['best_fixed']['objective_mean'])}, a margin of "
                   f"{r['margin_percent']:+.2f} % (paired difference {r['paired']['mean_difference']:+.5f} ± "
                   f"{r['paired']['ci95']:.5f}).")
    if "cart_pendulum" in systems:
        r = systems["cart_pendulum"]
        always = r["fixed"]["always"]
        le = r["learned"]
        cheap = {spec: row for spec, row in r["fixed"].items() if row["recomputes_mean"] <= 25.0
                 and row["control_objective_mean"] <= always["control_objective_mean"] * 1.01}
        holds = le["recomputes_mean"] < 25.0 and le["control_objective_mean"] <= always["control_objective_mean"] * 1.01
        out.append(
            "- *On the cart pendulum the learned policy reaches virtually the control performance of standard MPC "
            "(`always`) with less than a quarter of its computations.* "
            f"{'Holds' if holds else 'Does not hold'} for the learned policy: control {_f(le['control_objective_mean'])} "
            f"with {le['recomputes_mean']:.1f} computations, against `always` {_f(always['control_objective_mean'])} with "
            f"100. Fixed policies that do (control within 1 % of `always`, at most 25 computations): "
            + (", ".join(f"`{s}` ({_f(v['control_objective_mean'])}, {v['recomputes_mean']:.0f})" for s, v in cheap.items())
               or "none") + ".")
    if "battery" in systems:
        r = systems["battery"]
        best = r["best_fixed"]
        always = r["fixed"]["always"]
        out.append(
            "- *On the battery the saving comes from keeping larger parts of one plan, not from the computation's "
            f"energy.* Here the best policy is `{best['policy']}` ({_f(best['objective_mean'])}, "
            f"{best['recomputes_mean']:.0f} computations); `always` earns {_f(always['objective_mean'])} and `never` "
            f"{_f(r['fixed']['never']['objective_mean'])}. "
            + ("Keeping plans does not pay on this benchmark's forecast model: a new plan trades at the true current "
               "price, a kept one at a forecast." if best["policy"] == "always" else
               "Keeping plans pays here."))
    return out


def _say(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


def _write_text(path: Path, text: str) -> None:
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(text)
    tmp.replace(path)

