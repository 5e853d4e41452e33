"""``etmpc train``: training of the logistic recomputation policy over several seeds.

Two learners (``--algorithm``): ``gpomdp``, the paper's policy gradient (:mod:`etmpc.learning.gpomdp`), and
``dpi``, direct policy iteration with rollout-labelled classification (:mod:`etmpc.learning.dpi`); and two
feature sets (``--features``, :mod:`etmpc.policies.learned`): ``error`` (the default) and ``paper``.

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
* the choice of the run's policy (``selected.json``): every seed's final policy on
  ``validation_episodes`` training-distribution episodes from ``VALIDATION_ENTROPY`` (never the
  test set), the best one.

Outputs in ``DIR``: ``checkpoint.json``, ``curve.json`` and ``curve.png`` (mean and standard
deviation over seeds, the paper's Figure 2), ``seed<S>/last.json`` and ``seed<S>/best.json`` (the
best point of the test-set curve: a look back, not a model choice), ``selected.json`` (the final
policy of the seed that did best on the validation episodes: the run's answer); with
``--record N``, ``recordings/eval_<episodes>.rrd``: the first N test-set episodes of every seed's
evaluation, as Rerun recordings (see ``etmpc.views.recording``).
"""

from __future__ import annotations

import json
import sys
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np

from etmpc.common.errors import EtmpcError
from etmpc.common.outputs import refuse_foreign
from etmpc.evaluation.workers import context, make_backend
from etmpc.learning import dpi
from etmpc.learning.checkpoint import RunState, curve_summary, load_checkpoint, ours, policy_at, save
from etmpc.learning.config import ALGORITHMS, SELECTION_ENTROPY, VALIDATION_ENTROPY, TrainConfig, parse_seeds
from etmpc.learning.gpomdp import Learner
from etmpc.learning.jobs import _call, _learner_to_json, mean_scores
from etmpc.policies.learned import Normalisation, LogisticPolicy
from etmpc.systems import make_system
from etmpc.views.recording import Recorder

__all__ = ["ALGORITHMS", "TrainConfig", "curve_summary", "format_summary", "load_checkpoint", "parse_seeds", "train"]


def _evaluate_phase(state: RunState, backend, progress, testset: tuple[int, str], out: Path, record_episodes: int) -> None:
    """Evaluate every seed's policy; with ``record_episodes``, also write the first that many test-set
    episodes of each seed into ``out/recordings/eval_<episodes>.rrd``."""
    config, done = state.config, state.done
    testset_n, sha256 = testset

    def identity(seed: int, e: int) -> dict | None:
        if e >= record_episodes:
            return None
        return {"policy": f"seed{seed}/episodes{done:05d}", "training_seed": seed, "training_episodes": done}

    jobs = [("evaluate", (config.system, sha256, policy_at(state, state.learners[str(s)]["theta"]), r, e, identity(s, e)))
            for s in config.seeds for r in range(config.eval_repeats) for e in range(testset_n)]
    results = once_each(backend, _call, jobs, progress)
    records = [c[3] for c in results if c[3] is not None]
    if records:
        with Recorder(out / "recordings" / f"eval_{done:05d}.rrd") as recorder:
            for record in records:
                recorder.log_episode(record)
    per_seed = config.eval_repeats * testset_n
    sense = state.objective_sense
    for i, seed in enumerate(config.seeds):
        chunk = results[i * per_seed:(i + 1) * per_seed]
        row = {"episodes": done, "seed": seed, "objective": float(np.mean([c[0] for c in chunk])),
               "control": float(np.mean([c[1] for c in chunk])), "recomputes": float(np.mean([c[2] for c in chunk]))}
        state.curve.append(row)
        best = state.best.get(str(seed))
        better = best is None or (row["objective"] > best["objective"] if sense == "max" else row["objective"] < best["objective"])
        if better:
            state.best[str(seed)] = {"episodes": done, "objective": row["objective"], "theta": state.learners[str(seed)]["theta"]}


def once_each(backend, fn, jobs: list, progress) -> list:
    """``backend.map(fn, jobs, progress)``, with each distinct job played once: an evaluation's
    result is a function of its arguments alone, and every seed starts from the same policy, so the
    first evaluation would otherwise play each episode once per seed."""
    keys = [json.dumps(job, sort_keys=True, default=str) for job in jobs]
    distinct, repeats = {}, []
    for key, job in zip(keys, jobs):
        if key in distinct:
            repeats.append(job)
        else:
            distinct[key] = job
    played = dict(zip(distinct, backend.map(fn, list(distinct.values()), progress)))
    if progress is not None:
        for job in repeats:  # counted on the progress bar as played
            progress(job)
    return [played[key] for key in keys]


def _eval_episodes(config: TrainConfig) -> tuple[int, str]:
    """How many test-set episodes each evaluation plays, and the test set's digest (loads and checks
    the test set)."""
    _, _, testset = context(config.domain)
    n = testset.episodes if config.eval_episodes is None else config.eval_episodes
    if not 1 <= n <= testset.episodes:
        raise EtmpcError(f"eval episodes must be in 1..{testset.episodes}, got {n}")
    return n, testset.sha256


def train(config: TrainConfig, out: Path, workers: int = 1, resume: bool = False, backend: str = "local",
          address: str | None = None, progress: bool = True, record_episodes: int = 0) -> RunState:
    """Train ``config`` into ``out`` (see the module docstring). With ``record_episodes``, each
    evaluation also writes that many test-set episodes per seed into a Rerun recording,
    ``out/recordings/eval_<episodes>.rrd`` (not part of the config: it changes no result)."""
    out = Path(out)
    if record_episodes < 0:
        raise EtmpcError(f"record episodes must be >= 0, got {record_episodes}")
    checkpoint = out / "checkpoint.json"
    refuse_foreign(out, ours, "training run")
    if checkpoint.exists():
        if not resume:
            raise EtmpcError(f"{out} already holds a training run; pass --resume to continue it, or choose another --out")
        state = load_checkpoint(checkpoint)
        if state.config != config:
            raise EtmpcError(f"{checkpoint} was made with different settings ({_difference(state.config, config)}); "
                             "resume with the same ones, or choose another --out")
    else:
        state = None
    testset = _eval_episodes(config)  # fails on a bad test set or size before any work
    testset_n = testset[0]
    total = len(config.seeds) * (config.episodes + len(config.milestones) * config.eval_repeats * testset_n
                                 + config.validation_episodes)
    started = time.perf_counter()
    with make_backend(backend, workers, address) as pool, _Progress(total, f"train {config.domain}", progress) as bar:
        tick = lambda job: bar.update(job[1][5] - job[1][4] if job[0] == "train" else 1 if job[0] != "score" else 0)  # noqa: E731
        if state is None:
            states = pool.map(_call, [("normalisation", (config.system, i, config.features)) for i in range(config.normalisation_episodes)])
            normalisation = Normalisation.fit(np.concatenate(states))
            hyper = {"algorithm": config.algorithm, "features": config.features,
                     "normalisation_episodes": config.normalisation_episodes}
            if config.recompute_price is not None:  # trained for another price than the system's own
                hyper["recompute_price"] = config.recompute_price
            if config.algorithm == "gpomdp":
                hyper.update(discount=config.gpomdp.discount, learning_rate=config.gpomdp.learning_rate, baseline=config.gpomdp.baseline)
            else:
                hyper.update(asdict(config.dpi), bases=list(config.dpi.bases))
            initial = LogisticPolicy.initial(normalisation, config.domain, hyper, config.features, greedy=config.algorithm == "dpi")
            if config.algorithm == "gpomdp":
                learner = _learner_to_json(Learner.start(initial.theta, config.gpomdp, context(config.system)[0].episode_steps))
                base = None
            else:
                learner = {"theta": initial.theta.tolist(), "episodes": 0, "iterations": 0, "data": []}
                base = dpi.choose_base(config.dpi, make_system(config.system).objective_sense,
                                       lambda bases, n: mean_scores(pool, config.system, bases, SELECTION_ENTROPY, n))
            # One learner per seed, sharing nothing (a DPI learner's labels grow in place).
            state = RunState(config, initial.to_json(), {str(s): json.loads(json.dumps(learner)) for s in config.seeds}, base=base)
            _evaluate_phase(state, pool, tick, testset, out, record_episodes)
            save(out, state)
            resumed_from = 0
        else:
            bar.update(len(config.seeds) * (state.done + sum(1 for m in config.milestones if m <= state.done) * config.eval_repeats * testset_n))
            resumed_from = bar.n
        for start, stop in zip(config.milestones, config.milestones[1:]):
            if stop <= state.done:
                continue
            if config.algorithm == "gpomdp":
                jobs = [("train", (config.system, state.policy, state.learners[str(s)], s, start, stop)) for s in config.seeds]
                for seed, (learner, stats) in zip(config.seeds, pool.map(_call, jobs, tick)):
                    state.learners[str(seed)] = learner
                    state.training += [dict(s, seed=seed) for s in stats]
            else:
                dpi.iteration(state, pool, tick, start, stop)
            _evaluate_phase(state, pool, tick, testset, out, record_episodes)
            summary = save(out, state)
            _report(state, summary["points"][-1], started, bar, resumed_from)
        if not state.validation:
            policies = [policy_at(state, state.learners[str(s)]["theta"]) for s in config.seeds]
            means = mean_scores(pool, config.system, policies, VALIDATION_ENTROPY, config.validation_episodes,
                                 lambda job: bar.update(1))
            state.validation = {str(s): mean for s, mean in zip(config.seeds, means)}
            save(out, state)
    return state


class _Progress:
    """A tqdm bar (on a terminal) with its own count, so the ETA line works when the bar is off."""

    def __init__(self, total: int, desc: str, enabled: bool):
        from tqdm import tqdm

        self.n, self.total = 0, total
        self._bar = tqdm(total=total, unit="ep", desc=desc, disable=None if enabled else True)
        self._quiet = not enabled

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self._bar.close()

    def update(self, n: int) -> None:
        self.n += n
        self._bar.update(n)

    def write(self, line: str) -> None:
        if not self._quiet:
            self._bar.write(line, file=sys.stderr)


def _report(state: RunState, point: dict, started: float, bar, resumed_from: int) -> None:
    """One line per phase on stderr, for logs where the progress bar is off."""
    elapsed = time.perf_counter() - started
    done_here, left = bar.n - resumed_from, bar.total - bar.n
    eta = elapsed * left / done_here if done_here > 0 else float("nan")
    bar.write(f"{state.config.domain}: {state.done}/{state.config.episodes} episodes per seed, test objective "
              f"{point['objective_mean']:.5f} ± {point['objective_std']:.5f}, {point['recomputes_mean']:.1f} recomputes; "
              f"elapsed {elapsed:.0f} s, ETA {eta:.0f} s")


def _difference(a: TrainConfig, b: TrainConfig) -> str:
    da, db = a.to_json(), b.to_json()
    return ", ".join(f"{k}: {da[k]} vs {db[k]}" for k in da if da[k] != db[k])


def format_summary(state: RunState) -> str:
    summary = curve_summary(state)
    lines = [f"{state.config.domain}: objective ({'higher' if summary['objective_sense'] == 'max' else 'lower'} is better) on the test set",
             f"{'episodes':>9}{'mean':>12}{'std':>10}{'recomputes':>12}"]
    lines += [f"{p['episodes']:>9}{p['objective_mean']:>12.5f}{p['objective_std']:>10.5f}{p['recomputes_mean']:>12.2f}" for p in summary["points"]]
    return "\n".join(lines)
