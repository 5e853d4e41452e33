"""Evaluate recomputation policies on a stored test set, in parallel, with identical results.

Every (policy, repeat, episode) run is independent: the environment replays the stored episode and
a stochastic policy draws from its own generator, seeded by ``SeedSequence(seed, spawn_key=(repeat,
episode))`` (the same for every policy: common random numbers). Runs are spread over worker
processes and gathered back in order, so the numbers do not depend on the number of workers.
"""

from __future__ import annotations

import contextlib
import io
import os
import pickle
from pathlib import Path
from typing import Callable

from etmpc.evaluation import testsets as ts_mod
from etmpc.common import checks, interrupts
from etmpc.common.progress import Progress
from etmpc.common.errors import EtmpcError
from etmpc.common.interrupts import described, genuine
from etmpc.common.sense import oriented
from etmpc.loop import announcer, clairvoyant
from etmpc.loop.records import EpisodeRecord, EpisodeSink
from etmpc.systems import SystemKey, system_key
from etmpc.evaluation.inputs import check_run_outputs, run_inputs
from etmpc.evaluation.mainscript import refuse_in_rerun_main, unimportable_main
from etmpc.evaluation.backends import make_backend
from etmpc.evaluation.workers import play_test_episode, workers_for
from etmpc.evaluation.results import Evaluation, PolicySummary, RunResult, failures_cell, summarise  # noqa: F401 (re-exported)
from etmpc.evaluation.table import format_table  # noqa: F401 (re-exported: the README and examples import it from here)
from etmpc.evaluation.arguments import check_arguments, check_policies, parse_policies  # noqa: F401 (re-exported)


# -- worker side ---------------------------------------------------------------------------------
def scores(system, traj) -> tuple[float, float]:
    """``(objective, control objective)`` of an episode, sense-aware: a cost (min) or a profit (max)."""
    ret = traj.policy_return(system.recompute_price)
    rewards = float(traj.rewards[: traj.steps].sum())
    return oriented(ret, system.objective_sense), oriented(rewards, system.objective_sense)  # a cost: negated


def _run(job: tuple) -> tuple[RunResult, EpisodeRecord | None, dict[str, float]]:
    """One test-set episode; with ``record``, also what a recording keeps of it (else nothing extra
    is built or sent back); and the controller's CPU time in it (:meth:`Trajectory.cpu_seconds`)."""
    domain, testset_path, sha256, spec, policy, repeat, episode, seed, record = job
    played = play_test_episode(domain, policy, seed, repeat, episode, testset_path, sha256)
    traj = played.trajectory
    objective, control_objective = scores(played.system, traj)
    return (
        RunResult(
            policy=spec,
            repeat=repeat,
            episode=episode,
            objective=objective,
            control_objective=control_objective,
            recomputes=traj.recomputes,
            solver_failures=traj.solver_failures,
            steps=traj.steps,
            finite=not traj.nonfinite,
            failures=None if played.system.failures is None else played.system.failures(traj, played.episode),
        ),
        (played.record(spec, announcer(policy), clairvoyant=clairvoyant(policy)) if record else None),
        traj.cpu_seconds(),
    )


# -- driver side ---------------------------------------------------------------------------------
def run_jobs(jobs: list, workers: int, progress: bool, backend: str = "local", address: str | None = None) -> list[tuple]:
    chunk = max(1, min(8, len(jobs) // (4 * workers)))
    with Progress(len(jobs), enabled=progress) as bar, make_backend(backend, workers, address) as pool:
        return pool.map(_run, jobs, on_result=lambda job: bar.update(), chunksize=chunk)


def evaluate(
    task: str | SystemKey | None = None,
    policies: list | None = None,
    episodes: int | None = None,
    repeats: int = 1,
    workers: int | None = None,
    seed: int = 0,
    test_set: str | os.PathLike | None = None,
    progress: bool = True,
    backend: str = "local",
    address: str | None = None,
    record: str | Path | EpisodeSink | None = None,
    recompute_price: float | None = None,
    *,
    options=None,
    domain: str | SystemKey | None = None,
    testset_path: str | os.PathLike | None = None,
    recorder: Callable[[Path], EpisodeSink] | None = None,
) -> Evaluation:
    """Run every policy on the first ``episodes`` test-set episodes, ``repeats`` times each, on
    ``workers`` processes of ``backend`` (see ``etmpc.evaluation.backends.make_backend``).

    ``task``: a task's name (``DOMAIN`` or ``DOMAIN/TASK``), or a :class:`~etmpc.systems.SystemKey`
    (``domain=``, its old name, works for this release with a ``DeprecationWarning``). ``policies``: spec strings
    (``every:3``, ``rl:PATH``, ``py:MODULE:NAME``, ...) and policy objects (anything with ``spec``,
    ``stochastic`` and ``decide(s, rng)``, see :mod:`etmpc.policies.user`), side by side; each is
    named by its spec in the results, and every one meets the same episodes with the same draws.
    With ``record``, also write every episode into that Rerun recording (``.rrd``), opened by ``recorder``
    (:class:`etmpc.views.recording.Recorder`, which :func:`etmpc.evaluate` gives); or into an open one (an
    :class:`~etmpc.loop.records.EpisodeSink`: ``Recorder(connect=URL)``, ``Recorder(spawn=True)``), closed at the end.
    ``recompute_price``: the price of a recompute, if not the task's own (it enters every
    objective, and what rollouts optimise). ``options`` (the task's, NAME -> value: :mod:`etmpc.systems.options`)
    and ``test_set`` (a file; default the task's stored one): the keywords of :func:`etmpc.score` and the
    environments (``testset_path=``, the old name of ``test_set=``, works for this release, deprecated).

    Bad arguments, policies and files raise :class:`EtmpcError` with the command line's messages
    (:func:`check_arguments`), before any work; so does a policy's own failure, naming it."""
    task, price = checks.renamed("task", task, "domain", domain), recompute_price
    test_set = checks.renamed("test_set", test_set, "testset_path", testset_path, required=False)
    if options is not None and isinstance(task, (str, SystemKey)):  # a SystemKey carries its own: refused
        task, price = system_key(task, price, options), None
    with interrupts.watching():  # a policy that raises KeyboardInterrupt is its failure, not a Ctrl-C
        return _evaluate(
            task, policies, episodes, repeats, workers, seed, test_set, progress, backend, address, record, price, recorder
        )


class MainOnlyError(EtmpcError):
    """A policy whose class lives in a ``__main__`` that worker processes cannot re-create."""


class _MainReferences(pickle.Pickler):
    """A pickler that notes the classes and functions of ``__main__`` that it pickles by name."""

    def __init__(self, file):
        super().__init__(file)
        self.found: list[str] = []

    def persistent_id(self, obj):
        if isinstance(obj, type) or callable(obj) and hasattr(obj, "__qualname__"):
            if getattr(obj, "__module__", None) == "__main__":
                self.found.append(obj.__qualname__)
        return None


def check_picklable(spec: str, policy, backend: str = "local") -> None:
    """Raise :class:`EtmpcError` unless ``policy`` goes to a worker process and back: pickled, or with
    the ``ray`` backend cloudpickled (as Ray sends it). Pickle names a class by its module, so a class
    of a ``__main__`` that a spawned worker cannot re-create (``python -c``, stdin, a notebook) round-trips
    here but not there: refused too (Ray's cloudpickle sends such a class by value)."""
    dumps: Callable[[object], bytes] = pickle.dumps
    if backend == "ray":
        with contextlib.suppress(ImportError):
            from ray import cloudpickle

            dumps = cloudpickle.dumps
    try:
        if backend == "local":
            buffer = io.BytesIO()
            pickler = _MainReferences(buffer)
            pickler.dump(policy)
            data = buffer.getvalue()
        else:
            data = dumps(policy)
            pickler = None
        pickle.loads(data)
    except BaseException as exc:
        if genuine(exc):
            raise
        raise EtmpcError(
            f"policy {spec} cannot be sent to worker processes ({described(exc)}): use --workers 1 "
            "(workers=1 in Python), or make it picklable (its class at the top level of a module, "
            "no lambdas, open files or locks in it)"
        ) from None
    found = pickler.found if pickler is not None else []  # what the local pickler saw of __main__
    where = unimportable_main() if found else None
    if where is not None:
        raise MainOnlyError(
            f"policy {spec}: {found[0]} is defined in __main__ ({where}), which worker "
            "processes cannot import: define it in a module (or a script run under `if __name__ == "
            '"__main__":`), or use workers=1'
        )


def _evaluate(
    domain, policies, episodes, repeats, workers, seed, testset_path, progress, backend, address, record, price, recorder
) -> Evaluation:
    refuse_in_rerun_main()  # a worker spawned from a script without a __main__ guard, re-running it: not again
    check_arguments(domain, policies, episodes, repeats, workers, seed, testset_path, progress, backend, address, record, price)
    sink = record if isinstance(record, EpisodeSink) else None  # a recording opened by the caller (a live viewer)
    record = None if sink is not None else record
    if record is not None and recorder is None:  # the recording's writer is the caller's (etmpc.evaluate gives one)
        raise EtmpcError("record: nothing to write it with: pass recorder=etmpc.views.recording.Recorder, or call etmpc.evaluate")
    key = system_key(domain, price)  # the task and the price, checked once: every worker builds from it
    ts_mod.check_options_act(key, testset_path)  # an option the stored episodes cannot feel: refused, not ignored
    system = key.make()
    # Parsed (or checked) once here, so a bad policy fails before any work starts, then sent with each job.
    parsed = parse_policies(system, policies)
    policies = list(parsed)
    if record is not None:  # the API's check of what the command line checks before calling (no input overwritten)
        check_run_outputs({"record": record}, inputs=run_inputs(policies, testset_path))
    path = testset_path or str(ts_mod.default_path(system.domain, system.task))
    testset = ts_mod.load(path, system.domain, system.task)
    testset.check_playable(system, system.make_env().task)  # a bad episode fails here, before any work
    episodes = testset.episodes if episodes is None else episodes
    if not 1 <= episodes <= testset.episodes:
        raise ts_mod.TestSetError(f"--episodes must be in 1..{testset.episodes} for this test set, got {episodes}")
    # By default, one worker (this process) for a small run, where starting workers costs more than it saves;
    # and for a policy of a __main__ that workers cannot re-create (python -c, a notebook): it can only run here.
    chosen = workers is None
    workers = workers_for(len(policies) * repeats * episodes) if chosen else workers
    if workers > 1 or backend != "local":
        try:
            for spec, policy in parsed.items():
                check_picklable(spec, policy, backend)
        except MainOnlyError:
            if not chosen:
                raise
            workers = 1
    # Workers find the stored test set themselves (a cluster node's install may live elsewhere) and
    # check that its digest is the one verified here.
    sink = recorder(Path(record)) if record is not None else sink  # a bad path fails before any work
    jobs = [
        (key, testset_path, testset.sha256, spec, parsed[spec], r, e, seed, sink is not None)
        for spec in policies
        for r in range(repeats)
        for e in range(episodes)
    ]
    try:
        outcomes = run_jobs(jobs, workers, progress, backend, address)
        if sink is not None:
            for _, kept, _ in outcomes:
                sink.log_episode(kept)
    except BaseException:
        if sink is not None:
            sink.close(keep=False)
        raise
    if sink is not None:
        sink.close()
    runs = [result for result, _, _ in outcomes]
    summaries = [
        summarise(
            spec,
            [r for r in runs if r.policy == spec],
            system.objective_sense,
            episodes,
            repeats,
            system.failure_name,
            clairvoyant(parsed[spec]),
        )
        for spec in policies
    ]
    return Evaluation(
        system.domain,
        system.task,
        str(testset.path.resolve()),
        testset.sha256,
        seed,
        summaries,
        runs,
        system.recompute_price,
        [cpu for _, _, cpu in outcomes],
        dict(key.options) or None,
    )
