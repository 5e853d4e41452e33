"""Where episodes run: the per-process context, the policies' seeding, and a pool that keeps order.

Work is a list of jobs for a module-level function; results come back in job order whatever the
number of worker processes, so results never depend on where they ran.
"""

from __future__ import annotations

import os
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context

import numpy as np

from etmpc import testset as ts_mod
from etmpc.systems import make_system

_CONTEXTS: dict = {}


def context(domain: str, testset_path: str | None = None, sha256: str | None = None):
    """``(system, env, testset)`` for ``domain``, built once per process (the stored test set by
    default). ``sha256``, the digest the driver verified, keys the cache, so a test-set file that
    changed in between is loaded afresh."""
    key = (domain, testset_path, sha256)
    if key not in _CONTEXTS:
        system = make_system(domain)
        path = testset_path or ts_mod.default_path(system.domain, system.task)
        _CONTEXTS[key] = (system, system.make_env(), ts_mod.load(path, system.domain, system.task))
    return _CONTEXTS[key]


def policy_rng(seed: int, repeat: int, episode: int) -> np.random.Generator:
    """A stochastic policy's draws on test-set ``episode`` in pass ``repeat``: the same for every
    policy (common random numbers), and for ``evaluate`` and the evaluations during ``train``."""
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(repeat, episode)))


def default_workers() -> int:
    return max(1, len(os.sched_getaffinity(0)))


class LocalBackend:
    """Jobs in this process (``workers=1``) or a pool of spawned processes, results in job order."""

    def __init__(self, workers: int):
        self.workers = workers
        self._pool = None

    def __enter__(self):
        if self.workers > 1:
            self._pool = ProcessPoolExecutor(self.workers, get_context("spawn"))
        return self

    def __exit__(self, *exc):
        if self._pool is not None:
            self._pool.shutdown(cancel_futures=True)

    def map(self, fn, jobs: list, on_result=None, chunksize: int = 1) -> list:
        results = []
        iterator = map(fn, jobs) if self._pool is None else self._pool.map(fn, jobs, chunksize=chunksize)
        for job, result in zip(jobs, iterator):
            results.append(result)
            if on_result is not None:
                on_result(job)
        return results
