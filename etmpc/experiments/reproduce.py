"""``etmpc reproduce``: the paper's experiments on every task, one command, with a report.

Per task, in ``DIR/<domain>/<task>/`` (its folder, :func:`etmpc.systems.folder_name`):

1. ``baselines.json``: the fixed policies (``always``, ``never``, ``every:T`` for every T that
   matters, thresholds) on the test set;
2. ``train/``: the learned policy over the seeds with the paper's protocol (``etmpc train``: GPOMDP
   on the paper's features, ``[x_i, x_k, i - k]``);
3. ``learned.json``: each seed's final policy (``last.json``) evaluated ``repeats`` times;
3b. ``train_dpi/``: the default learner (DPI on the ``error`` features) over its seeds; the seed
   chosen on validation episodes (``selected.json``) is copied to ``DIR/policies/<domain>/learned.json``
   and evaluated on the test set (``learned_default.json``); whether it and PPO's network are the files
   shipped in ``policies/`` is in the report (:mod:`etmpc.experiments.shipped`);
3c. ``headroom.json``: the rollout policy over the best fixed one and the ``oracle:`` reference on
   the first ``rollout_episodes`` test-set episodes (rollouts are expensive);
3d. ``train_ppo/``: PPO from Stable-Baselines3 on the trigger environment (with the 'rl' extra), with
   the task's hyperparameters (``policies/<task>/ppo.yml``); its chosen network is copied with them to
   ``DIR/policies/<domain>/ppo.zip`` (``.json``, ``.yml``) and evaluated on the test set
   (``learned_ppo.json``), every checkpoint too, for its learning curve (``learned_ppo_checkpoints.json``);
3e. ``efficiency.png``: every learner's test-set gain against the environment steps it simulated
   (:mod:`etmpc.experiments.efficiency`); each training stage's wall time is in ``<stage>_cost.json``;
4. figures: ``figure1_forecasts.png`` (battery), ``train/curve.png`` (Figure 2),
   ``figure3.png``, ``trajectory.png`` (the best fixed policy's first episode);
5. ``episodes.rrd``: a Rerun recording of representative episodes (the best fixed policy and
   the first seed's learned policy); ``episode.mp4``: a rendered video (cart pendulum).

Each stage's wall time is kept in ``DIR/<domain>/<task>/stage_seconds.json`` as it finishes
(:mod:`etmpc.experiments.clock`): the report's table of where the time went.

Then ``DIR/results.json`` (everything the report says, machine-readable) and ``DIR/REPORT.md``,
which is written from ``results.json`` alone. Every stage writes its files atomically and is
skipped when they are there, so running the command again after an interruption continues; the
settings are kept in ``DIR/settings.json`` and a second run with other settings is refused.
"""

from __future__ import annotations

import time
from pathlib import Path

from etmpc.common.documents import loads
from etmpc.common.errors import EtmpcError
from etmpc.common.outputs import check_outputs, refuse_foreign, what_differs, write_text
from etmpc.common.progress import stage
from etmpc.common.provenance import commit_and_date
from etmpc.evaluation.evaluate import evaluate
from etmpc.views.render import render_rollout
from etmpc.evaluation.backends import shared_pools
from etmpc.experiments import shipped as shipped_policies
from etmpc.experiments import sweep as sweeps
from etmpc.experiments.clock import StageClock
from etmpc.experiments.report import PAPER, machine, report, software_versions
from etmpc.experiments.reproduce_settings import FULL, QUICK, Settings  # noqa: F401 (reproduce's API)
from etmpc.experiments.summary import (
    summarise_default,
    summarise_headroom,
    summarise_learners,
    summarise_scorecard,
    summarise_system,
)
from etmpc.learning.dpi_recipe import recipe
from etmpc.learning.runner import cost_path, timed  # noqa: F401 (cost_path: reproduce's API)
from etmpc.learning.train import TrainConfig, curve_summary, load_checkpoint
from etmpc.policies.learned import write_json_atomically
from etmpc.systems import distinct, folder_name, make_system, names, same_task
from etmpc.systems.capabilities import Experiments, Scene, offers, require
from etmpc.views import figures
from etmpc.views.curves import write_efficiency_png
from etmpc.views.recording import Recorder
from etmpc.experiments.stages import (  # noqa: F401 (evaluated_once: reproduce's API)
    _cost,
    _efficiency,
    _forecasts_png,
    _other_learners,
    _ppo,
    _say,
    _stored_best,
    _trajectory_png,
    evaluated_once,
    run_root,
    trained,
)


def reproduce(
    out: Path,
    settings: Settings = FULL,
    workers: int = 1,
    backend: str = "local",
    address: str | None = None,
    domains=None,
    progress: bool = True,
    sweep: bool = False,
) -> dict:
    """Run (or continue) every stage into ``out``; returns ``results.json``'s content. With
    ``sweep``, also the price sweep of each task (``out/sweep/<task>``, see
    :mod:`etmpc.experiments.sweep`) and its equal-rate answer in the report."""
    with shared_pools():  # one pool of workers for every stage
        return _reproduce(Path(out), settings, workers, backend, address, domains, progress, sweep)


def _reproduce(
    out: Path, settings: Settings, workers: int, backend: str, address: str | None, domains, progress: bool, sweep: bool
) -> dict:
    domains = list(names()) if domains is None else distinct(domains)  # every task, by its id (DOMAIN/TASK)
    started = time.perf_counter()
    sweep_settings = {d: sweeps.SweepSettings.default(d, quick=settings.smoke) for d in domains} if sweep else {}
    for domain, chosen in sweep_settings.items():  # checked before any work
        sweeps.check_directory(out / "sweep" / folder_name(domain), domain, chosen)
    _check_settings(out, settings, domains)
    run = dict(workers=workers, backend=backend, address=address)
    systems = {}
    for i, domain in enumerate(domains, 1):
        with stage(f"{domain} ({i}/{len(domains)})"):  # named in the progress lines, with each stage's name
            systems[domain] = _system(out / folder_name(domain), domain, settings, run, progress)
    paretos = {}
    for domain, chosen in sweep_settings.items():
        paretos[domain] = sweeps.sweep(
            domain, out / "sweep" / folder_name(domain), chosen, workers, backend, address, progress, say=_say
        )
    results = {
        "format": "etmpc-reproduce",
        "version": 1,
        "settings": settings.to_json(),
        "systems": systems,
        "software": software_versions(),
        "machine": machine(),
        "provenance": commit_and_date(),
        "wall_seconds_this_invocation": time.perf_counter() - started,
    }
    if paretos:
        results["sweep"] = paretos
    write_json_atomically(out / "results.json", results)
    write_text(out / "REPORT.md", report(results))
    return results


def _check_settings(out: Path, settings: Settings, domains) -> None:
    """Start a new run in a new or empty ``out``, or continue the one there with the same settings; its
    files, every one the run's (a FIFO or a device among them would hang it when read back), are checked first."""
    check_outputs({}, {"--out": out}, writes={"--out": lambda name: True})
    path = out / "settings.json"
    wanted = {"settings": settings.to_json(), "domains": list(domains)}
    if path.exists():
        try:
            stored = loads(path.read_text())
        except (OSError, ValueError) as exc:
            raise EtmpcError(f"{path} is unreadable ({exc}); move it away to start afresh") from None
        if stored != wanted:
            raise EtmpcError(f"{out} holds a run with other settings ({what_differs(stored, wanted)}); use another --out")
    else:
        refuse_foreign(out, lambda name: False, "reproduce run")  # a new run starts in a new or empty directory
        out.mkdir(parents=True, exist_ok=True)
        write_json_atomically(path, wanted)


def _system(folder: Path, domain: str, settings: Settings, run: dict, progress: bool) -> dict:
    """One task's stages into ``folder``. ``domain`` is the task's name (``DOMAIN`` or ``DOMAIN/TASK``).
    The paper's own tasks also get the paper's learner (GPOMDP, its protocol); every task gets the
    fixed policies, the default learner, the headroom, PPO, figures, a recording and, with a scene, a video."""
    system = make_system(domain)
    require(system, Experiments, "etmpc reproduce")
    folder.mkdir(parents=True, exist_ok=True)
    common = dict(
        task=domain,
        episodes=settings.test_episodes,
        workers=run["workers"],
        backend=run["backend"],
        address=run["address"],
        progress=progress,
    )
    clock = StageClock(folder)
    _say(f"{domain}: fixed policies")
    with clock.stage("fixed policies", folder / "baselines.json"):
        baselines = evaluated_once(
            folder / "baselines.json", policies=system.benchmark.baselines(system.compute_levels), **common
        )

    learned, state, learned_specs = None, None, []
    if system.name in PAPER:
        _say(f"{domain}: training {len(settings.seeds)} seeds x {settings.episodes} episodes")
        config = TrainConfig(
            domain, settings.seeds, settings.episodes, settings.eval_every, settings.eval_episodes, features="paper"
        )  # the paper's learner on the paper's features, as the report says
        train_dir = folder / "train"
        with clock.stage("GPOMDP training", cost_path(train_dir)), timed(train_dir, run["workers"]):
            trained(config, train_dir, run, progress)
        state = load_checkpoint(train_dir / "checkpoint.json")

        _say(f"{domain}: the learned policies, {settings.repeats} passes")
        learned_specs = [f"rl:{train_dir / f'seed{s}' / 'last.json'}" for s in settings.seeds]
        with clock.stage("GPOMDP evaluation", folder / "learned.json"):
            learned = evaluated_once(folder / "learned.json", policies=learned_specs, repeats=settings.repeats, **common)

    dpi_config = settings.dpi(recipe(system.name), system.benchmark.capped)  # the task's dpi.yml, at the run's sizes
    _say(f"{domain}: the default learner (DPI), {len(dpi_config.seeds)} seeds x {dpi_config.episodes} episodes")
    dpi_dir = folder / "train_dpi"
    with clock.stage("DPI training", cost_path(dpi_dir)), timed(dpi_dir, run["workers"]):
        trained(dpi_config, dpi_dir, run, progress)
    shipped = run_root(folder, system.name) / "policies" / folder_name(system.name) / "learned.json"
    if not shipped.exists():
        write_json_atomically(shipped, loads((dpi_dir / "selected.json").read_text()))
    with clock.stage("DPI evaluation", folder / "learned_default.json"):
        default = evaluated_once(folder / "learned_default.json", policies=[f"rl:{shipped}"], **common)

    summary = summarise_system(system, baselines, learned, curve_summary(state) if state is not None else None)
    best = summary["best_fixed"]["policy"]

    _say(f"{domain}: headroom, rollout and oracle over {best} on {settings.rollout_episodes} episodes")
    rollout_spec = f"rollout:{best}:{settings.rollout_futures}:{system.benchmark.capped(settings.rollout_horizon)}"
    subset = dict(common, episodes=settings.rollout_episodes)
    with clock.stage("rollout", folder / "headroom_rollout.json"):
        rollout = evaluated_once(folder / "headroom_rollout.json", timed=run["workers"], policies=[rollout_spec], **subset)
    with clock.stage("oracle", folder / "headroom_oracle.json"):
        oracle = evaluated_once(folder / "headroom_oracle.json", timed=run["workers"], policies=[f"oracle:{best}"], **subset)
    summary["default_learner"] = summarise_default(system, baselines, default, load_checkpoint(dpi_dir / "checkpoint.json"))
    summary["headroom"] = summarise_headroom(system, best, baselines, learned, default, rollout, oracle)
    ppo_run, ppo, ppo_curve = _ppo(folder, domain, settings, run, common, clock)
    costs = {name: _cost(folder / stage) for name, stage in (("gpomdp", "train"), ("dpi", "train_dpi"), ("ppo", "train_ppo"))}
    curves = _efficiency(folder, system, baselines, best, state, ppo_run, ppo_curve)
    summary["learners"] = summarise_learners(
        system, baselines, learned, default, ppo, ppo_run, settings.to_json(), dpi_config, costs, curves
    )
    summary["efficiency"] = curves
    if not (folder / "efficiency.png").exists():
        chosen = {
            name: dict(summary["learners"][name], simulated_steps=points[-1]["simulated_steps"])
            for name, points in curves.items()
            if name in summary["learners"]
        }
        write_efficiency_png(folder / "efficiency.png", system.name, best, curves, chosen)
    scored = {
        "best periodic": (baselines, _stored_best(system)),
        "best fixed": (baselines, best),
        **{f"GPOMDP seed {s}": (learned, spec) for s, spec in zip(settings.seeds, learned_specs)},
        "DPI": (default, f"rl:{shipped}"),
        "PPO": (ppo, f"sb3:{folder / 'train_ppo' / 'selected.zip'}"),
    }
    others = _other_learners(folder, domain, settings, run, common, clock)
    if others:  # learners registered beyond the built-in ones: each trained, evaluated and scored
        summary["other_learners"] = {name: {"policy": spec, "evaluation": data} for name, (data, spec) in others.items()}
        scored.update(others)
    summary["scorecard"] = summarise_scorecard(system, scored)
    summary["shipped"] = shipped_policies.compare(system.name, shipped.parent)

    _say(f"{domain}: figures, recording, video")
    files = {
        "baselines": "baselines.json",
        "learned": "learned.json",
        "curve": "train/curve.png",
        "figure3": "figure3.png",
        "recording": "episodes.rrd",
        "trajectory": "trajectory.png",
        "default_learner": "learned_default.json",
        "curve_dpi": "train_dpi/curve.png",
        "headroom_rollout": "headroom_rollout.json",
        "headroom_oracle": "headroom_oracle.json",
        "efficiency": "efficiency.png",
    }
    if learned is None:
        del files["learned"], files["curve"]
    with clock.stage("figures, recording, video", folder / "figure3.png", folder / "episodes.rrd", folder / "trajectory.png"):
        if not (folder / "figure3.png").exists():
            figures.write_policy_bars_png(folder / "figure3.png", [baselines, learned if learned is not None else default])
        if not (folder / "episodes.rrd").exists():
            evaluate(
                domain,
                [best, *learned_specs[:1], f"rl:{shipped}"],
                episodes=settings.record_episodes,
                workers=run["workers"],
                progress=False,
                record=folder / "episodes.rrd",
                recorder=Recorder,
            )
        _trajectory_png(folder / "trajectory.png", system, best)
        if same_task(system.name, "battery"):  # the paper's Figure 1: forecasts of the battery's prices and production
            _forecasts_png(folder / "figure1_forecasts.png", system)
            files["figure1"] = "figure1_forecasts.png"
        if offers(system, Scene):
            if not (folder / "episode.mp4").exists():
                width, height = settings.video_size
                render_rollout(domain, best, 0, folder / "episode.mp4", width=width, height=height, progress=progress)
            files["video"] = "episode.mp4"
    summary["files"] = {k: f"{folder_name(domain)}/{v}" for k, v in files.items()}
    summary["stage_seconds"] = clock.read()
    return summary
