"""``etmpc reproduce``: the paper's experiments on both systems, one command, with a report.

Per system, in ``DIR/<domain>/``:

1. ``baselines.json``: the fixed policies (``always``, ``never``, ``every:T`` for every T that
   matters, thresholds) on the test set;
2. ``train/``: the learned policy over the seeds with the paper's protocol (``etmpc train``: GPOMDP
   on the paper's features);
3. ``learned.json``: each seed's final policy (``last.json``) evaluated ``repeats`` times;
3b. ``train_dpi/``: the default learner (DPI on the ``error`` features) over its seeds; the seed
   chosen on validation episodes (``selected.json``) is copied to ``DIR/policies/<domain>/learned.json``
   (the project ships the full run's copy in ``policies/``) and evaluated on the test set
   (``learned_default.json``);
3c. ``headroom.json``: the rollout policy over the best fixed one and the ``oracle:`` upper bound on
   the first ``rollout_episodes`` test-set episodes (rollouts are expensive);
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

from etmpc.learning.dpi import Settings as DpiSettings
from etmpc.common.errors import EtmpcError
from etmpc.evaluation.evaluate import evaluate
from etmpc.policies.learned import write_json_atomically
from etmpc.common.outputs import refuse_foreign, write_text
from etmpc.systems import make_system
from etmpc.learning.train import TrainConfig, curve_summary, load_checkpoint, train

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
    # The default learner (DPI on the error features) and the headroom meters.
    dpi_seeds: tuple[int, ...] = (0, 1, 2)
    dpi_episodes: int = 60  # training episodes per seed: 3 iterations of 20
    dpi_eval_every: int = 20
    dpi_labels: int = 25  # decisions labelled per training episode
    dpi_futures: int = 4
    dpi_horizon: int = 20
    validation_episodes: int = 50  # training-distribution episodes that choose the shipped seed
    rollout_episodes: int = 30  # first test-set episodes for rollout:BEST and oracle:BEST
    rollout_futures: int = 4  # K: 8 doubles its cost (2 K H simulated steps per decision)
    rollout_horizon: int | None = 20  # None: to the episode's end
    smoke: bool = False  # a smoke run: its report gives no verdicts

    def to_json(self) -> dict:
        data = asdict(self)
        data["seeds"], data["video_size"], data["dpi_seeds"] = list(self.seeds), list(self.video_size), list(self.dpi_seeds)
        return data


FULL = Settings()
QUICK = Settings(episodes=30, eval_every=15, eval_episodes=10, test_episodes=20, repeats=2, record_episodes=2,
                 video_size=(320, 240), dpi_seeds=(0, 1), dpi_episodes=4, dpi_eval_every=2, dpi_labels=5, dpi_futures=2,
                 dpi_horizon=10, validation_episodes=5, rollout_episodes=3, rollout_futures=2, rollout_horizon=10, smoke=True)


def reproduce(out: Path, settings: Settings = FULL, workers: int = 1, backend: str = "local",
              address: str | None = None, domains=DOMAINS, progress: bool = True, sweep: bool = False) -> dict:
    """Run (or continue) every stage into ``out``; returns ``results.json``'s content. With
    ``sweep``, also the price sweep of each system (``out/sweep/<task>``, see
    :mod:`etmpc.experiments.sweep`) and its equal-rate answer in the report."""
    from etmpc.experiments import sweep as sweeps

    out = Path(out)
    started = time.perf_counter()
    sweep_settings = {d: sweeps.SweepSettings.default(d, quick=settings.smoke) for d in domains} if sweep else {}
    for domain, chosen in sweep_settings.items():  # checked before any work
        sweeps.check_directory(out / "sweep" / domain, domain, chosen)
    _check_settings(out, settings, domains)
    run = dict(workers=workers, backend=backend, address=address)
    systems = {}
    for domain in domains:
        systems[domain] = _system(out / domain, domain, settings, run, progress)
    paretos = {}
    for domain, chosen in sweep_settings.items():
        paretos[domain] = sweeps.sweep(domain, out / "sweep" / domain, chosen, workers, backend, address, progress, say=_say)
    results = {
        "format": "etmpc-reproduce", "version": 1, "settings": settings.to_json(), "systems": systems,
        "software": software_versions(), "machine": machine(),
        "wall_seconds_this_invocation": time.perf_counter() - started,
    }
    if paretos:
        results["sweep"] = paretos
    write_json_atomically(out / "results.json", results)
    write_text(out / "REPORT.md", report(results))
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
        refuse_foreign(out, lambda name: False, "reproduce run")  # a new run starts in a new or empty directory
        out.mkdir(parents=True, exist_ok=True)
        write_json_atomically(path, wanted)


def evaluated_once(path: Path, timed: int | None = None, **kwargs) -> dict:
    """An evaluation's JSON, made once: a complete file from an earlier invocation is reused. With
    ``timed`` (the number of workers), its wall time and that number are kept in the file."""
    if path.exists():
        return json.loads(path.read_text())
    started = time.perf_counter()
    data = evaluate(**kwargs).to_json()
    if timed is not None:
        data["cost"] = {"wall_seconds": time.perf_counter() - started, "workers": timed}
    write_json_atomically(path, data)
    return data


def _system(folder: Path, domain: str, settings: Settings, run: dict, progress: bool) -> dict:
    from etmpc.views import figures

    system = make_system(domain)
    folder.mkdir(parents=True, exist_ok=True)
    common = dict(domain=domain, episodes=settings.test_episodes, workers=run["workers"], backend=run["backend"],
                  address=run["address"], progress=progress)
    _say(f"{domain}: fixed policies")
    baselines = evaluated_once(folder / "baselines.json", policies=BASELINES[domain], **common)

    _say(f"{domain}: training {len(settings.seeds)} seeds x {settings.episodes} episodes")
    config = TrainConfig(domain, settings.seeds, settings.episodes, settings.eval_every, settings.eval_episodes)
    train_dir = folder / "train"
    train(config, train_dir, run["workers"], resume=(train_dir / "checkpoint.json").exists(), backend=run["backend"],
          address=run["address"], progress=progress)
    state = load_checkpoint(train_dir / "checkpoint.json")

    _say(f"{domain}: the learned policies, {settings.repeats} passes")
    learned_specs = [f"rl:{train_dir / f'seed{s}' / 'last.json'}" for s in settings.seeds]
    learned = evaluated_once(folder / "learned.json", policies=learned_specs, repeats=settings.repeats, **common)

    _say(f"{domain}: the default learner (DPI), {len(settings.dpi_seeds)} seeds x {settings.dpi_episodes} episodes")
    dpi_config = TrainConfig(domain, settings.dpi_seeds, settings.dpi_episodes, settings.dpi_eval_every, settings.eval_episodes,
                             features="error", algorithm="dpi", validation_episodes=settings.validation_episodes,
                             dpi=DpiSettings(futures=settings.dpi_futures, horizon=settings.dpi_horizon,
                                             states_per_episode=settings.dpi_labels))
    dpi_dir = folder / "train_dpi"
    train(dpi_config, dpi_dir, run["workers"], resume=(dpi_dir / "checkpoint.json").exists(), backend=run["backend"],
          address=run["address"], progress=progress)
    shipped = folder.parent / "policies" / domain / "learned.json"
    if not shipped.exists():
        write_json_atomically(shipped, json.loads((dpi_dir / "selected.json").read_text()))
    default = evaluated_once(folder / "learned_default.json", policies=[f"rl:{shipped}"], **common)

    summary = summarise_system(system, baselines, learned, curve_summary(state))
    best = summary["best_fixed"]["policy"]

    _say(f"{domain}: headroom, rollout and oracle over {best} on {settings.rollout_episodes} episodes")
    rollout_spec = f"rollout:{best}:{settings.rollout_futures}" + (f":{settings.rollout_horizon}" if settings.rollout_horizon else "")
    subset = dict(common, episodes=settings.rollout_episodes)
    rollout = evaluated_once(folder / "headroom_rollout.json", timed=run["workers"], policies=[rollout_spec], **subset)
    oracle = evaluated_once(folder / "headroom_oracle.json", timed=run["workers"], policies=[f"oracle:{best}"], **subset)
    summary["default_learner"] = summarise_default(system, baselines, default, load_checkpoint(dpi_dir / "checkpoint.json"))
    summary["headroom"] = summarise_headroom(system, best, baselines, learned, default, rollout, oracle)

    _say(f"{domain}: figures, recording, video")
    if not (folder / "figure3.png").exists():
        figures.write_policy_bars_png(folder / "figure3.png", [baselines, learned])
    if not (folder / "episodes.rrd").exists():
        evaluate(domain, [best, learned_specs[0], f"rl:{shipped}"], episodes=settings.record_episodes, workers=run["workers"],
                 progress=False, record=folder / "episodes.rrd")
    files = {"baselines": "baselines.json", "learned": "learned.json", "curve": "train/curve.png",
             "figure3": "figure3.png", "recording": "episodes.rrd", "trajectory": "trajectory.png",
             "default_learner": "learned_default.json", "curve_dpi": "train_dpi/curve.png",
             "headroom_rollout": "headroom_rollout.json", "headroom_oracle": "headroom_oracle.json"}
    _trajectory_png(folder / "trajectory.png", system, best)
    if domain == "battery":
        _forecasts_png(folder / "figure1_forecasts.png", system)
        files["figure1"] = "figure1_forecasts.png"
    if domain == "cart_pendulum" and not (folder / "episode.mp4").exists():
        from etmpc.evaluation.render import render_rollout

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


def per_episode(evaluation: dict, policies=None) -> dict[int, float]:
    """Episode -> the mean objective of ``policies`` (default: every policy in the file) over their
    finite runs (seeds and passes together)."""
    values: dict[int, list[float]] = {}
    for r in evaluation["runs"]:
        if r["finite"] and (policies is None or r["policy"] in policies):
            values.setdefault(r["episode"], []).append(r["objective"])
    return {e: float(np.mean(v)) for e, v in values.items()}


def paired(a: dict[int, float], b: dict[int, float], sense: str, episodes=None) -> dict:
    """``a`` against ``b`` on their common episodes (or ``episodes``): the mean difference ``a - b``
    with its 95 % CI, and the same as a percentage of ``|mean b|``, signed so that > 0 is better."""
    common = sorted(set(a) & set(b) if episodes is None else set(episodes) & set(a) & set(b))
    diff = np.array([a[e] - b[e] for e in common])
    sign = 1.0 if sense == "max" else -1.0
    scale = abs(float(np.mean([b[e] for e in common]))) if common else float("nan")
    ci = float(1.96 * diff.std(ddof=1) / np.sqrt(len(diff))) if len(diff) > 1 else float("nan")
    mean = float(diff.mean()) if len(diff) else float("nan")
    return {"episodes": len(common), "objective_mean": float(np.mean([a[e] for e in common])) if common else float("nan"),
            "reference_mean": float(np.mean([b[e] for e in common])) if common else float("nan"),
            "mean_difference": mean, "ci95": ci, "gain_percent": 100.0 * sign * mean / scale,
            "gain_percent_ci95": 100.0 * ci / scale, "better_episodes": int((sign * diff > 0).sum())}


def summarise_default(system, baselines: dict, default: dict, state) -> dict:
    """The default learner's shipped policy on the test set, against the best fixed policy."""
    sense = system.objective_sense
    fixed = baselines["policies"]
    best = (max if sense == "max" else min)(fixed, key=lambda spec: fixed[spec]["objective_mean"])
    (spec, row), = default["policies"].items()
    hyper = json.loads(Path(spec[3:]).read_text())["hyperparameters"]
    return {"policy": spec, "seed": hyper["seed"], "validation_objective": hyper["validation_objective"],
            "validation": state.validation, "base": state.base, **_row(row),
            "paired": paired(per_episode(default), per_episode(baselines, {best}), sense),
            "curve": curve_summary(state)["points"]}


def summarise_headroom(system, best: str, baselines: dict, learned: dict, default: dict, rollout: dict, oracle: dict) -> dict:
    """Every contender and the oracle bound against the best fixed policy, paired on the episodes the
    rollout policy played. Rows, in order: the oracle (an upper bound, not a policy), the rollout
    policy, the default learner, the paper's learner, the best fixed policy."""
    sense = system.objective_sense
    reference = per_episode(baselines, {best})
    episodes = sorted(per_episode(rollout))
    rows = {}
    for name, evaluation in (("oracle", oracle), ("rollout", rollout), ("learned_default", default), ("learned_paper", learned),
                             ("best_fixed", None)):
        evaluation = evaluation or {"policies": {best: None}, "runs": [r for r in baselines["runs"] if r["policy"] == best]}
        runs = [r for r in evaluation["runs"] if r["episode"] in episodes and r["finite"]]
        rows[name] = dict(paired(per_episode(evaluation), reference, sense, episodes), policies=list(evaluation["policies"]),
                          recomputes_mean=float(np.mean([r["recomputes"] for r in runs])) if runs else float("nan"))
    cost = rollout.get("cost", {})
    steps = sum(r["steps"] for r in rollout["runs"])
    return {"reference": best, "episodes": len(episodes), "rows": rows, "rollout_cost": cost,
            # CPU seconds per step of the rollout policy (its decision and the step itself; the solve is a small part).
            "rollout_seconds_per_step": cost["wall_seconds"] * cost["workers"] / steps if cost and steps else None}


def _row(s: dict) -> dict:
    keys = ("objective_mean", "objective_std", "control_objective_mean", "recomputes_mean", "solver_failures")
    return {k: s[k] for k in keys}


def _trajectory_png(path: Path, system, spec: str) -> None:
    if path.exists():
        return
    from etmpc.views import figures
    from etmpc.policies import parse_policy
    from etmpc.evaluation.workers import play_test_episode

    played = play_test_episode(system.domain, parse_policy(spec, system.error_weights, system.domain), 0, 0, 0)
    figures.write_trajectory_png(path, system, played.trajectory, title=f"{system.domain}: test-set episode 0 under {spec}",
                                 signals=system.signals(played.episode))


def _forecasts_png(path: Path, system) -> None:
    if path.exists():
        return
    from etmpc.views import figures
    from etmpc.policies import parse_policy
    from etmpc.evaluation.workers import play_test_episode

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
    ]
    if s.get("smoke"):
        lines += ["**This is a smoke run (`--quick`): every size is far too small for a conclusion. It checks that "
                  "every stage runs; it gives no verdicts.**", ""]
    lines += [
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
        ] + headroom_section(r, s.get("smoke", False)) + [
            f"Files: {', '.join(f'`{v}`' for v in r['files'].values())}.",
            "",
        ]
    if results.get("sweep"):
        from etmpc.experiments.sweep import report_section

        lines += ["# Beyond the paper: the trade-off curve", ""]
        for domain, pareto in results["sweep"].items():
            lines += report_section(pareto) + ["", f"![trade-off](sweep/{domain}/pareto.png)", ""]
    lines += ["## Against the paper", ""]
    lines += (["No verdicts in a smoke run."] if s.get("smoke") else against_the_paper(results)) + [""]
    lines += ["## Software and machine", "", "| package | version |", "|---|---|"]
    lines += [f"| {k} | {v} |" for k, v in results["software"].items()]
    m = results["machine"]
    lines += ["", f"Machine: {m['cpu']}, {m['cores']} cores, {m['memory_gib']} GiB, {m['platform']}.", ""]
    return "\n".join(lines)


def _pct(row: dict) -> str:
    return f"{row['gain_percent']:+.2f} % ± {row['gain_percent_ci95']:.2f} %"


def headroom_section(r: dict, smoke: bool) -> list[str]:
    """What any trigger could gain over the best fixed policy, and what the learners reach."""
    h, d = r["headroom"], r["default_learner"]
    best = h["reference"]
    names = {"oracle": "upper bound, **not a policy**: knows the episode's future", "rollout": "rollout policy",
             "learned_default": "learned, default learner (DPI, error features)",
             "learned_paper": "learned, the paper's (GPOMDP, paper features)", "best_fixed": "best fixed"}
    lines = [f"### Headroom over `{best}`", "",
             f"Paired over test-set episodes 0–{h['episodes'] - 1} (the rollout policies are expensive); "
             "gain > 0 is better than the best fixed policy; 95 % CIs.", "",
             "| | policies | recomputes | objective | gain over best fixed | gain % |", "|---|---|---|---|---|---|"]
    for key, row in h["rows"].items():
        specs = ", ".join(f"`{p}`" for p in row["policies"]) if len(row["policies"]) <= 2 else f"{len(row['policies'])} seeds"
        sign = 1 if r["objective_sense"] == "max" else -1
        gain = ("reference", "reference") if key == "best_fixed" else \
            (f"{sign * row['mean_difference']:+.5f} ± {row['ci95']:.5f}", _pct(row))
        lines.append(f"| {names[key]} | {specs} | {row['recomputes_mean']:.1f} | {_f(row['objective_mean'])} | "
                     f"{gain[0]} | {gain[1]} |")
    if h["rollout_seconds_per_step"] is not None:
        cost = h["rollout_cost"]
        lines += ["", f"The rollout policy cost {h['rollout_seconds_per_step'] * 1e3:.0f} ms of CPU per step (its decision "
                  f"included): {cost['wall_seconds']:.0f} s for {h['episodes']} episodes on {cost['workers']} workers."]
    p = d["paired"]
    lines += ["", f"**The default learner on all {p['episodes']} test-set episodes** (`{d['policy']}`, seed {d['seed']}, "
              f"chosen on {len(d['validation'])} seeds' validation episodes, never the test set; iteration 0 rolled out "
              f"over `{d['base']}`): {_f(d['objective_mean'])} with {d['recomputes_mean']:.1f} recomputes; against "
              f"`{best}`: gain {_pct(p)}, better in {p['better_episodes']}/{p['episodes']} episodes."]
    if not smoke:
        ci_low = p["gain_percent"] - p["gain_percent_ci95"]
        lines.append(f"Its CI {'excludes' if ci_low > 0 else 'does not exclude'} 0.")
    return lines + [""]


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



