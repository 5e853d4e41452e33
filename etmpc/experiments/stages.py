"""The stages of ``etmpc reproduce`` that train a learner, weigh its cost, or draw a figure, each made once
into a run's folder (a complete file from an earlier invocation is reused): split from
:mod:`etmpc.experiments.reproduce`, which plays them in order."""

from __future__ import annotations

import importlib.util
import shutil
import sys
import time
from dataclasses import replace
from pathlib import Path

from etmpc.common.documents import loads
from etmpc.common.errors import EtmpcError
from etmpc.common.outputs import write_text
from etmpc.evaluation.evaluate import evaluate
from etmpc.evaluation.workers import play_test_episode
from etmpc.evaluation.references import stored
from etmpc.experiments import efficiency
from etmpc.experiments.clock import StageClock
from etmpc.learning import hyperparams
from etmpc.learning.ppo import PpoSettings, train_ppo
from etmpc.learning.base import BUILT_IN, learners
from etmpc.learning.runner import cost_path, run, timed
from etmpc.learning.train import train
from etmpc.policies import parse_policy
from etmpc.policies.learned import write_json_atomically
from etmpc.systems import folder_name
from etmpc.views import figures
from etmpc.views.curves import write_curve_png
from etmpc.views.recording import Recorder


def evaluated_once(path: Path, timed: int | None = None, **kwargs) -> dict:
    """An evaluation's JSON, made once: a complete file from an earlier invocation is reused. With
    ``timed`` (the number of workers), its wall time and that number are kept in the file."""
    if path.exists():
        return loads(path.read_text())
    started = time.perf_counter()
    data = evaluate(**kwargs).to_json()
    if timed is not None:
        data["cost"] = {"wall_seconds": time.perf_counter() - started, "workers": timed}
    write_json_atomically(path, data)
    return data


def run_root(folder: Path, task: str) -> Path:
    """The run directory that task ``task``'s folder (``DIR/DOMAIN/TASK``, :func:`etmpc.systems.folder_name`) is in."""
    return folder.parents[len(Path(folder_name(task)).parts) - 1]


def trained(config, out: Path, run_options: dict, progress: bool) -> None:
    """``config`` (a :class:`~etmpc.learning.config.TrainConfig`) trained into ``out`` on the run's ``workers``,
    ``backend`` and ``address``, continuing from the checkpoint an interrupted invocation left there; its
    learning curve drawn as ``curve.png``."""
    workers, backend, address = run_options["workers"], run_options["backend"], run_options["address"]
    resume = (out / "checkpoint.json").exists()
    train(config, out, workers, resume=resume, backend=backend, address=address, progress=progress, curve_png=write_curve_png)


def _stored_best(system) -> str:
    """The task's best periodic schedule, as its stored references name it (``every:1`` if there are none)."""
    try:
        best = stored(system.name).best
    except EtmpcError:
        best = "every:1"
    return "always" if best == "every:1" else best  # the same schedule, as reproduce's fixed policies name it


def _ppo(
    folder: Path, domain: str, settings, run: dict, common: dict, clock: StageClock
) -> tuple[dict | None, dict | None, dict | None]:
    """PPO on the trigger environment (``train_ppo/``, redone whole if it was interrupted) with the task's
    hyperparameters, every checkpoint evaluated on the test set (``learned_ppo_checkpoints.json``, its
    learning curve), and its chosen network copied to ``DIR/policies/`` with its test-set rows
    (``learned_ppo.json``: the checkpoint it was chosen from was just played, so it is not played again);
    ``(None, None, None)`` without the 'rl' extra."""
    if settings.ppo_timesteps == 0 or importlib.util.find_spec("stable_baselines3") is None:
        _say(f"{domain}: PPO skipped" + ("" if settings.ppo_timesteps == 0 else " (pip install 'etmpc[rl]' to run it)"))
        return None, None, None
    ppo_dir = folder / "train_ppo"
    chosen = hyperparams.shipped(domain, PpoSettings(validation_episodes=settings.validation_episodes))
    if settings.ppo_timesteps is not None:
        chosen = replace(chosen, timesteps=settings.ppo_timesteps)
    with clock.stage("PPO training", ppo_dir / "training.json"):
        if not (ppo_dir / "training.json").exists():
            _say(f"{domain}: PPO (Stable-Baselines3), {chosen.timesteps} environment steps")
            if ppo_dir.exists():
                shutil.rmtree(ppo_dir)  # an interrupted run starts again
            with timed(ppo_dir, run["workers"]):
                train_ppo(domain, ppo_dir, chosen, run["workers"], say=_say, progress=common["progress"])
    training = loads((ppo_dir / "training.json").read_text())
    shipped = run_root(folder, domain) / "policies" / folder_name(domain)
    if not (shipped / "ppo.zip").exists():
        shipped.mkdir(parents=True, exist_ok=True)
        source = hyperparams.shipped_path(domain)
        if settings.ppo_timesteps is None and source.is_file():  # the file it trained with, as it is
            shutil.copyfile(source, shipped / "ppo.yml")
        else:
            write_text(shipped / "ppo.yml", hyperparams.dump(chosen, domain, "the hyperparameters this run's PPO used"))
        shutil.copyfile(ppo_dir / "selected.json", shipped / "ppo.json")
        shutil.copyfile(ppo_dir / "selected.zip", shipped / "ppo.zip")
    with clock.stage("PPO evaluation", folder / "learned_ppo.json", folder / "learned_ppo_checkpoints.json"):
        curve = evaluated_once(
            folder / "learned_ppo_checkpoints.json",
            policies=[f"sb3:{ppo_dir / c['file']}" for c in training["checkpoints"]],
            **common,
        )
        selected, picked = ppo_dir / "selected.zip", ppo_dir / training["selected"]
        if not (folder / "learned_ppo.json").exists() and selected.read_bytes() == picked.read_bytes():
            # the chosen network is one of the checkpoints just scored: its rows, under its own name
            write_json_atomically(folder / "learned_ppo.json", _renamed(curve, f"sb3:{picked}", f"sb3:{selected}"))
        ppo = evaluated_once(folder / "learned_ppo.json", policies=[f"sb3:{selected}"], **common)
    return training, ppo, curve


def _renamed(evaluation: dict, policy: str, name: str) -> dict:
    """``evaluation`` (an :class:`~etmpc.evaluation.results.Evaluation`'s JSON) of ``policy`` alone, named ``name``."""
    summary = evaluation["policies"][policy]
    return dict(
        # its wall time and per-run CPU list (if any) were every checkpoint's: neither is this policy's alone
        {k: v for k, v in evaluation.items() if k not in ("cost", "cpu_seconds")},
        policies={name: dict(summary, policy=name)},
        runs=[dict(r, policy=name) for r in evaluation["runs"] if r["policy"] == policy],
    )


def _other_learners(folder: Path, domain: str, settings, run_options: dict, common: dict, clock: StageClock) -> dict:
    """Every registered learner that is not built in (:data:`etmpc.learning.base.LEARNERS`), trained with
    its settings (its ``quick_settings()`` in a smoke run) into ``train_<name>/`` by the runner, its policy
    evaluated on the test set (``learned_<name>.json``): ``{name: (evaluation JSON, spec)}``."""
    found = {}
    for name, cls in learners().items():
        if name in BUILT_IN:
            continue
        chosen = cls.quick_settings() if settings.smoke and hasattr(cls, "quick_settings") else cls.Settings()
        stage = folder / f"train_{name}"
        _say(f"{domain}: the learner {name}")
        with clock.stage(f"learner {name}", folder / f"learned_{name}.json"):
            with timed(stage, run_options["workers"]):
                trained = run(
                    cls(chosen),
                    domain,
                    stage,
                    None,
                    run_options["workers"],
                    resume=True,
                    backend=run_options["backend"],
                    address=run_options["address"],
                    progress=common["progress"],
                    say=_say,
                    recorder=Recorder,
                    curve_png=write_curve_png,
                )
            found[name] = (evaluated_once(folder / f"learned_{name}.json", policies=[trained.policy], **common), trained.policy)
    return found


def _cost(folder: Path) -> dict | None:
    path = cost_path(folder)
    return loads(path.read_text()) if path.exists() else None


def _efficiency(folder: Path, system, baselines: dict, best: str, state, ppo_run: dict | None, ppo_curve: dict | None) -> dict:
    """Each learner's curve of test-set gain against the steps one run (one seed) simulated."""
    sense, steps = system.objective_sense, system.episode_steps
    curves = {
        "dpi": efficiency.dpi_points(
            loads((folder / "train_dpi" / "checkpoint.json").read_text()),
            loads((folder / "train_dpi" / "curve.json").read_text()),
            baselines,
            best,
            sense,
            steps,
        )
    }
    if state is not None:
        curves["gpomdp"] = efficiency.gpomdp_points(
            loads((folder / "train" / "checkpoint.json").read_text()),
            loads((folder / "train" / "curve.json").read_text()),
            baselines,
            best,
            sense,
            steps,
        )
    if ppo_run is not None:
        assert ppo_curve is not None  # PPO's run and its checkpoints' curve come together (stages._ppo)
        curves["ppo"] = efficiency.ppo_points(ppo_run, ppo_curve, baselines, best, sense)
    return curves


def _trajectory_png(path: Path, system, spec: str) -> None:
    if path.exists():
        return
    played = play_test_episode(system.name, parse_policy(spec, system), 0, 0, 0)
    figures.write_trajectory_png(
        path,
        system,
        played.trajectory,
        title=f"{system.name}: test-set episode 0 under {spec}",
        signals=system.signals(played.episode),
    )


def _forecasts_png(path: Path, system) -> None:
    if path.exists():
        return
    runs = [(spec, play_test_episode(system.name, parse_policy(spec, system), 0, 0, 0)) for spec in ("every:20", "every:5")]
    fig = figures.forecast_figure(
        runs[0][1].episode, [(spec, played.trajectory) for spec, played in runs], system.control_interval_s, system.terminal_price
    )
    figures.save_png_atomically(fig, path, dpi=110)


def _say(line: str) -> None:
    print(line, file=sys.stderr, flush=True)
