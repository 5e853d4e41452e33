"""``etmpc figure``: the paper's figures, played from the stored test set or read from evaluations, and
written as PNGs (the drawing is :mod:`etmpc.views.figures`'s).

* :func:`forecasts`: Figure 1, the battery's true production and price over a test-set episode with the
  forecasts each MPC solve was given, under one or more policies;
* :func:`trajectory`: one test-set episode of any task under a policy, played exactly as ``etmpc evaluate``
  plays it (repeat 0 of the seed): every state with every plan's prediction, the recompute steps, the
  applied and planned inputs with their bounds, and the episode's exogenous signals;
* :func:`bars`: Figure 3, the mean objective per policy from ``etmpc evaluate --json`` documents of one
  task (error bars: std over repeats; a training run's seeds as one learned bar).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from etmpc.common.errors import EtmpcError
from etmpc.common.sense import cost_or_profit
from etmpc.evaluation import testsets
from etmpc.evaluation.evaluate import scores
from etmpc.evaluation.results import Evaluation
from etmpc.evaluation.inputs import check_shipped
from etmpc.evaluation.workers import context, play_test_episode
from etmpc.loop import run_episode
from etmpc.policies import parse_policy
from etmpc.systems import make_system, system_key
from etmpc.systems import spec as spec_of
from etmpc.views import figures

RESULTS = Path("results")
FORECASTS_TASK = "battery"  # the one task with forecasts to draw
FORECASTS_POLICIES = ("every:20",)
FORECASTS_OUT = RESULTS / "figure1_battery_forecasts.png"


def _policy(system, spec: str):
    """``spec`` parsed for ``system``'s task as ``etmpc evaluate`` parses it (a shipped policy file checked)."""
    check_shipped(spec)
    return parse_policy(spec, system)


def forecasts(out: str | Path, policies=FORECASTS_POLICIES, episode: int = 0, seed: int = 0) -> Path:
    """Figure 1: battery test-set ``episode`` under each of ``policies`` (specs), a stochastic policy drawing
    from ``numpy.random.default_rng(seed)``, written to ``out``."""
    system = make_system(FORECASTS_TASK)
    stored = testsets.load(testsets.default_path(system.domain, system.task), system.domain, system.task)
    played = system.episode_from_arrays(stored.episode_arrays(episode))  # an index out of range raises here
    parsed = [(spec, _policy(system, spec)) for spec in policies]
    env = system.make_env()
    runs = [(spec, run_episode(system, env, policy, np.random.default_rng(seed), played)) for spec, policy in parsed]
    fig = figures.forecast_figure(played, runs, system.config.battery.interval_s, system.terminal_price)
    return figures.save_png_atomically(fig, out, dpi=120)


def slug(spec: str) -> str:
    """A file-name part for a policy spec: every:3 -> every-3, rl:runs/c/seed0/last.json -> rl-runs-c-seed0-last."""
    return re.sub(r"[^A-Za-z0-9.]+", "-", spec.removesuffix(".json")).strip("-.") or "policy"


def trajectory_path(task: str, spec: str, episode: int) -> Path:
    """Where :func:`trajectory` writes by default: ``results/trajectory_<task>_<policy>_ep<I>.png``."""
    return RESULTS / f"trajectory_{spec_of(task).slug}_{slug(spec)}_ep{episode}.png"


@dataclass(frozen=True)
class Drawn:
    """What :func:`trajectory` played and wrote."""

    path: Path
    objective: float
    control_objective: float
    recomputes: int
    solver_failures: int


def trajectory(out: str | Path, task, spec: str, episode: int = 0, seed: int = 0) -> Drawn:
    """Test-set ``episode`` of ``task`` (a name, or a :class:`~etmpc.systems.SystemKey` with its options) under
    policy ``spec``, played as ``etmpc evaluate`` plays it (repeat 0 of ``seed``), drawn to ``out``."""
    testsets.check_options_act(system_key(task), takes_test_set=False)  # an option the stored episodes cannot feel
    system = context(task)[0]
    played = play_test_episode(task, _policy(system, spec), seed, 0, episode)  # as evaluate plays it
    traj = played.trajectory
    objective, control = scores(system, traj)
    what = cost_or_profit(system.objective_sense)
    title = (
        f"{system_key(task)} test-set episode {episode}, policy {spec}: {what} {objective:.5g} "
        f"({control:.5g} without their price), {traj.recomputes} recomputes"
    )
    path = figures.write_trajectory_png(out, system, traj, title, system.signals(played.episode))
    return Drawn(path, objective, control, traj.recomputes, traj.solver_failures)


def load_evaluation(path: str | Path) -> dict:
    """An ``etmpc evaluate --json`` document, read and checked as :meth:`Evaluation.load` does (every run and
    summary of its fields' types; one that is not raises :class:`EtmpcError` in one line), as its JSON."""
    path = Path(path)
    if not path.exists():
        raise EtmpcError(f"{path} not found")
    if path.is_dir():
        raise EtmpcError(f"{path} is a directory, not a file")
    return Evaluation.load(path).to_json(cpu=True)


def bars_path(evaluations: list[dict], sources: list[str] | None = None) -> Path:
    """Where :func:`bars` writes by default: ``results/figure3_<task>.png``; the documents are checked first
    (one task, one test set, the same episodes)."""
    figures.policy_bars(evaluations, sources=sources)  # raises on documents that cannot be drawn together
    doc = evaluations[0]
    try:
        name = spec_of(f"{doc['domain']}/{doc['task']}").slug
    except EtmpcError:  # a task this installation does not have: its documents still draw
        name = f"{doc['domain']}-{doc['task']}"
    return RESULTS / f"figure3_{name}.png"


def bars(out: str | Path, evaluations: list[dict], group_learned: bool = True, sources: list[str] | None = None) -> Path:
    """Figure 3 of ``evaluations`` (``etmpc evaluate --json`` documents of one task), written to ``out``."""
    return figures.write_policy_bars_png(out, evaluations, group_learned=group_learned, sources=sources)
