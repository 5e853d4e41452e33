"""``etmpc train``: training of the logistic recomputation policy over several seeds.

Two learners (``--algorithm``): ``gpomdp``, the paper's policy gradient (:mod:`etmpc.learning.gpomdp`), and
``dpi``, direct policy iteration with rollout-labelled classification (:mod:`etmpc.learning.dpi`); and three
feature sets (``--features``, :mod:`etmpc.policies.features`): ``error`` (the default), ``paper`` and ``levels``. On a
task with compute levels (keep, one SQP iteration or a full solve: ``cart_pendulum/kicks_levels``) DPI trains
the two-stage policy (keep or compute, then a full solve or one iteration; see :mod:`etmpc.learning.dpi`) and
GPOMDP, whose gradient is the keep-or-solve policy's, refuses the task.

The run advances in *phases* of ``eval_every`` training episodes. In each phase every seed trains
its block of episodes (seeds run in parallel), then every seed's policy is evaluated on the test
set (its episodes run in parallel), then a checkpoint is written atomically. A killed run resumed
with ``--resume`` restarts from the last checkpoint and ends bit for bit where an uninterrupted run
would, because every random draw is keyed by ``(seed, episode)`` and never by history:

* training episode ``e`` of seed ``s``: the environment's episode from ``SeedSequence(TRAIN_ENTROPY,
  spawn_key=(s, e, 0))``, the policy's draws from ``spawn_key=(s, e, 1)``;
* evaluation: the stored test set, and the policy's draws from ``SeedSequence(0, spawn_key=(repeat,
  episode))``, exactly as ``etmpc evaluate --seed 0`` draws them, so ``etmpc evaluate --policy
  rl:DIR/seed0/best.json`` reproduces a point of the curve;
* the feature normalisation: measured once per run on ``normalisation_episodes`` episodes under a
  policy that recomputes with probability 1/2 (so plan ages vary), from ``NORMALISATION_ENTROPY``;
* DPI: training episode ``e`` of seed ``s`` and its rollouts from ``SeedSequence(DPI_ENTROPY,
  spawn_key=(s, e, k))``; its iteration-0 schedule is chosen on episodes from ``SELECTION_ENTROPY``;
* the choice of the run's policy (``selected.json``): every seed's final policy (DPI: every
  iteration's policy of every seed) on ``validation_episodes`` training-distribution episodes from
  ``VALIDATION_ENTROPY`` (never the test set), the best one; ``seed<S>/selected.json`` is the best of
  seed ``S``'s own.

Outputs in ``DIR``: ``checkpoint.json``, ``curve.json`` and ``curve.png`` (mean and standard
deviation over seeds, the paper's Figure 2), ``seed<S>/last.json`` and ``seed<S>/best.json`` (the
best point of the test-set curve: a look back, not a model choice), ``seed<S>/selected.json`` (the seed's
best on the validation episodes), ``selected.json`` (the best of all on the validation episodes: the
run's answer); with
``--record N``, ``recordings/eval_<episodes>.rrd``: the first N test-set episodes of every seed's
evaluation, as Rerun recordings. The caller gives what draws the curve and writes the recordings
(``etmpc train`` gives ``etmpc.views.curves.write_curve_png`` and ``etmpc.views.recording.Recorder``).
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable

from etmpc.common.sense import higher_or_lower
from etmpc.learning.checkpoint import RunState, curve_summary, load_checkpoint
from etmpc.learning.config import ALGORITHMS, TrainConfig, parse_seeds
from etmpc.learning.curve import once_each
from etmpc.learning.phased import _Phased
from etmpc.learning.runner import run
from etmpc.loop.records import EpisodeSink

__all__ = ["ALGORITHMS", "TrainConfig", "curve_summary", "format_summary", "load_checkpoint", "once_each", "parse_seeds", "train"]


def train(
    config: TrainConfig,
    out: Path,
    workers: int = 1,
    resume: bool = False,
    backend: str = "local",
    address: str | None = None,
    progress: bool = True,
    record_episodes: int = 0,
    recorder: Callable[[Path], EpisodeSink] | None = None,
    curve_png: Callable[[Path, dict, int], None] | None = None,
) -> RunState:
    """Train ``config`` into ``out`` (see the module docstring). With ``record_episodes``, each
    evaluation also writes that many test-set episodes per seed into a Rerun recording,
    ``out/recordings/eval_<episodes>.rrd``, opened by ``recorder`` (not part of the config: it changes no
    result). With ``curve_png``, the learning curve is drawn into ``out/curve.png`` at each checkpoint.

    The learner of ``config.algorithm`` (:mod:`etmpc.learning.phased`) driven by
    :func:`etmpc.learning.runner.run`; returns its state."""
    learner = _Phased.from_config(config, record_episodes)
    run(
        learner,
        config.system,
        out,
        config.seeds,
        workers,
        resume,
        backend,
        address,
        progress,
        recorder=recorder,
        curve_png=curve_png,
    )
    assert learner.run_state is not None  # the runner set it up or resumed it
    return learner.run_state


def format_summary(state: RunState) -> str:
    summary = curve_summary(state)
    lines = [
        f"{state.config.domain}: objective ({higher_or_lower(summary['objective_sense'])} is better) on the test set",
        f"{'episodes':>9}{'mean':>12}{'std':>10}{'recomputes':>12}",
    ]
    lines += [
        f"{p['episodes']:>9}{p['objective_mean']:>12.5f}{p['objective_std']:>10.5f}{p['recomputes_mean']:>12.2f}"
        for p in summary["points"]
    ]
    return "\n".join(lines)
