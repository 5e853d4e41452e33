"""The test-set learning curve of a GPOMDP or DPI run (:mod:`etmpc.learning.phased`): at each milestone
every seed's policy is scored on the stored test set (:func:`evaluation_jobs`, each distinct episode played
once: :func:`once_each`), and each seed's mean becomes a point of the curve and, if better, its best point
(:func:`add_points`). A look back at the run, never what chooses its policy (validation episodes do)."""

from __future__ import annotations

import json

import numpy as np

from etmpc.common.sense import oriented
from etmpc.learning.checkpoint import RunState, policy_of


def evaluation_jobs(state: RunState, testset_episodes: int, sha256: str, record_episodes: int) -> list:
    """The ``"evaluate"`` jobs of one evaluation (:func:`etmpc.learning.jobs.evaluate_theta`): every seed's policy
    on the first ``testset_episodes`` test-set episodes (the set of digest ``sha256``), ``eval_repeats`` times, seed
    by seed; the first ``record_episodes`` episodes of each seed also return what a recording keeps of them."""
    config, done = state.config, state.done

    def identity(seed: int, e: int) -> dict | None:
        if e >= record_episodes:
            return None
        return {"policy": f"seed{seed}/episodes{done:05d}", "training_seed": seed, "training_episodes": done}

    return [
        ("evaluate", (config.system, sha256, policy_of(state, state.learners[str(s)]), r, e, identity(s, e)))
        for s in config.seeds
        for r in range(config.eval_repeats)
        for e in range(testset_episodes)
    ]


def add_points(state: RunState, results: list, per_seed: int) -> None:
    """Each seed's mean over its ``per_seed`` results (:func:`evaluation_jobs`' order) as a point of the curve at
    the run's episodes so far, and as the seed's best point where it is better (sense-aware) than the one kept."""
    done, sense = state.done, state.objective_sense
    for i, seed in enumerate(state.config.seeds):
        chunk = results[i * per_seed : (i + 1) * per_seed]
        row = {
            "episodes": done,
            "seed": seed,
            "objective": float(np.mean([c[0] for c in chunk])),
            "control": float(np.mean([c[1] for c in chunk])),
            "recomputes": float(np.mean([c[2] for c in chunk])),
        }
        state.curve.append(row)
        best = state.best.get(str(seed))
        better = best is None or oriented(row["objective"], sense) > oriented(best["objective"], sense)
        if better:
            learner = state.learners[str(seed)]
            state.best[str(seed)] = {"episodes": done, "objective": row["objective"], "theta": learner["theta"]}
            if "theta_level" in learner:  # compute levels
                state.best[str(seed)]["theta_level"] = learner["theta_level"]


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
