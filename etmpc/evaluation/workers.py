"""Where episodes run and how they are seeded: the per-process context (the system, its environment and
the test set, built once per process), a test-set episode played (:func:`play_test_episode`), the policies'
draws (:func:`policy_rng`) and how many workers a run gets (:func:`workers_for`).

Every random draw is seeded by the job itself, so results never depend on where they ran. The worker
processes themselves and the backends that spread jobs over them are :mod:`etmpc.evaluation.backends`'.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any

import numpy as np

from etmpc.evaluation import testsets as ts_mod
from etmpc.common.errors import EtmpcError
from etmpc.common import progress
from etmpc.evaluation.mainscript import missing_main_script
from etmpc.loop import Trajectory, run_episode
from etmpc.loop.records import EpisodeRecord
from etmpc.systems import SystemKey, make_system

_CONTEXTS: dict = {}


def context(domain: str | SystemKey, testset_path: str | None = None, sha256: str | None = None):
    """``(system, env, testset)`` for ``domain``, built once per process (the stored test set by
    default). ``sha256``, the digest the driver verified, keys the cache, so a test-set file that
    changed in between is loaded afresh."""
    key = (domain, testset_path, sha256)
    if key not in _CONTEXTS:
        system = make_system(domain)
        path = testset_path or ts_mod.default_path(system.domain, system.task)
        testset = ts_mod.load(path, system.domain, system.task)
        if sha256 is not None and testset.sha256 != sha256:
            raise EtmpcError(
                f"test set {path} on this worker has sha256 {testset.sha256[:12]}…, the run uses "
                f"{sha256[:12]}…: install the same etmpc on every worker"
            )
        env = system.make_env()
        testset.check_playable(system, env.task)
        # The MPC is made when first asked for, and with it its compiled code (built, or loaded from the cache):
        # made here, so that no episode's measured solve time holds the one-off build.
        getattr(system, "mpc", None)
        _CONTEXTS[key] = (system, env, testset)
    return _CONTEXTS[key]


@dataclass(frozen=True, eq=False)
class Played:
    """One test-set episode played (see :func:`play_test_episode`)."""

    system: Any
    env: Any
    trajectory: Trajectory
    episode: Any  # the stored episode, as the system's task replays it
    index: int
    repeat: int
    seed: int
    test_set_sha256: str

    def record(self, policy: str, announce=None, **extra) -> EpisodeRecord:
        """What a recording keeps of this episode, under the policy's name (``extra``: more identity;
        ``announce``: a self-trigger's, to record what it announced at each solve)."""
        failures = None if self.system.failures is None else self.system.failures(self.trajectory, self.episode)
        identity = {
            "policy": policy,
            "episode": self.index,
            "repeat": self.repeat,
            "seed": self.seed,
            "test_set_sha256": self.test_set_sha256,
            # what evaluate's table counts beside the objective, so that etmpc replay shows the same columns
            "solver_failures": int(self.trajectory.solver_failures),
            **({} if failures is None else {"failures": float(failures), "failure_name": self.system.failure_name}),
            **extra,
        }
        return EpisodeRecord.from_trajectory(self.system, self.trajectory, identity, self.episode, announce)


def play_test_episode(
    domain: str | SystemKey,
    policy,
    seed: int,
    repeat: int,
    episode: int,
    testset_path: str | None = None,
    sha256: str | None = None,
) -> Played:
    """Test-set ``episode`` under ``policy`` with the policy's draws of pass ``repeat`` of ``seed``: how
    ``evaluate``, the evaluations during ``train``, ``render`` and the figures all play an episode."""
    system, env, testset = context(domain, testset_path, sha256)
    stored = system.episode_from_arrays(testset.episode_arrays(episode))  # a bad index raises TestSetError
    named = f"episode {episode}" + (f" of {policy.spec}" if isinstance(getattr(policy, "spec", None), str) else "")
    with progress.episode(named + (f", repeat {repeat}" if repeat else "")):  # what a long episode's lines name
        traj = run_episode(system, env, policy, policy_rng(seed, repeat, episode), stored)
    return Played(system, env, traj, stored, episode, repeat, seed, testset.sha256)


def policy_rng(seed: int, repeat: int, episode: int) -> np.random.Generator:
    """A stochastic policy's draws on test-set ``episode`` in pass ``repeat``: the same for every
    policy (common random numbers), and for ``evaluate`` and the evaluations during ``train``."""
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(repeat, episode)))


def default_workers() -> int:
    return max(1, len(os.sched_getaffinity(0)))


# Fewer jobs than this run in this process when the number of workers is not given. A spawned worker
# starts in 2-5 s (imports, the compiled MPC, the test set) and a job (an episode) takes 20-250 ms
# depending on the task, so below a few dozen jobs starting workers costs more than it saves. Measured
# on 2 cores, cart_pendulum, every:3, warm cache, evaluate's own time: 3 episodes 0.2 s with one worker
# against 5.6 s with two; 10: 0.4 s against 5.2 s; 30: 0.6 s against 4.8 s (see workers_for).
SERIAL_JOBS = 32


def workers_for(jobs: int) -> int:
    """The number of workers when none is given: one (this process) for fewer than ``SERIAL_JOBS``
    jobs, where spawning workers costs more than it saves, or where no worker can start (a main script
    read from stdin); else one per core. The results are the same either way (gathered in job order,
    every draw seeded by its job); and a small run from a script without ``if __name__ == "__main__":``
    then just works, as no worker re-runs the script."""
    return 1 if jobs < SERIAL_JOBS or missing_main_script() else default_workers()
