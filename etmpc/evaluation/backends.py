"""Backends that spread jobs over workers and keep their order (``make_backend``), and the worker processes.

Work is a list of jobs for a module-level function; results come back in job order whatever the
number of worker processes or the backend, and every random draw is seeded by the job itself
(:mod:`etmpc.evaluation.workers`), so results never depend on where they ran.

Backends (``make_backend``):

- ``local``: this process (one worker) or a pool of spawned processes, one per stage or, inside
  :func:`shared_pools`, one for the whole command;
- ``ray``: Ray tasks (the optional ``ray`` extra), on a Ray instance started for the run, or on an
  existing cluster given by its address. Every node of a cluster needs the same etmpc installed.
"""

from __future__ import annotations

import contextlib
import ctypes
import functools
import importlib
import logging
import os
import pickle
import signal
import socket
import sys
import threading
import time
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from multiprocessing.context import SpawnContext, SpawnProcess
from typing import TYPE_CHECKING, Any, Callable, Iterator

from etmpc.common.errors import EtmpcError
from etmpc.common.interrupts import described
from etmpc.evaluation.mainscript import UNGUARDED, UNGUARDED_EXIT, UnguardedScript, missing_main_script, refuse_in_rerun_main

if TYPE_CHECKING:  # the type of a Ray remote function of two arguments (Ray names no public one)
    from ray import ObjectRef
    from ray._private.worker import RemoteFunction1


class _QuietSpawnProcess(SpawnProcess):
    """A spawned worker that ignores Ctrl-C from its first instruction: the disposition is set to
    SIG_IGN around the fork and exec, and a Python that starts with SIGINT ignored keeps it so
    (a worker still importing would otherwise print a KeyboardInterrupt traceback)."""

    def start(self):
        if threading.current_thread() is not threading.main_thread():
            return super().start()
        previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
        try:
            return super().start()
        finally:
            signal.signal(signal.SIGINT, signal.default_int_handler if previous is None else previous)


class _QuietSpawnContext(SpawnContext):
    Process = _QuietSpawnProcess


THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def single_threaded():
    """Run the numerical libraries (both OpenBLAS builds of numpy and scipy) on one thread each: the
    parallelism is across episodes, and a BLAS reduction split over threads adds in an order that
    depends on how many the machine has. Returns a context manager (``threadpoolctl``'s)."""
    from threadpoolctl import threadpool_limits

    importlib.import_module("scipy.linalg")  # scipy's own OpenBLAS is loaded here, so that it is limited too
    return threadpool_limits(limits=1)


def die_with_parent(parent: int) -> None:
    """Worker initialiser: end this process as soon as ``parent`` (the process that started it)
    ends, however it ends (SIGTERM, SIGKILL, a crash), so no worker outlives its command. On Linux
    the kernel sends SIGKILL (``PR_SET_PDEATHSIG``); everywhere, a watchdog thread also checks.
    Ctrl-C is left to the parent. The worker's numerical libraries run on one thread
    (:func:`single_threaded`; libraries it loads later read the environment variables)."""
    for name in THREAD_VARIABLES:
        os.environ.setdefault(name, "1")
    single_threaded()
    # Ctrl-C reaches the whole process group: the command stops its workers itself, which must
    # not print a KeyboardInterrupt traceback each.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if sys.platform.startswith("linux"):
        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL)  # 1 = PR_SET_PDEATHSIG
    if os.getppid() != parent:  # it died before that took effect
        os._exit(1)

    def watch():
        while os.getppid() == parent:
            time.sleep(0.5)
        os._exit(1)

    threading.Thread(target=watch, name="die-with-parent", daemon=True).start()


_SHARED_POOLS: dict[int, ProcessPoolExecutor] | None = None  # by size, inside shared_pools()


@contextlib.contextmanager
def shared_pools():
    """Within it, every local backend of the same size runs its jobs on one pool of worker processes,
    started once. A command of many stages (``reproduce``, ``sweep``: a hundred evaluations and
    trainings) then pays a worker's start (imports, the compiled MPC, the test set: about 2 s here) once
    rather than at every stage. Results are the same: every job seeds itself, and a worker's cache
    (:func:`context`) is keyed by what it holds. A stage that fails or is interrupted ends the pool;
    the next stage starts another. Nested uses share the outermost one's pools."""
    global _SHARED_POOLS
    if _SHARED_POOLS is not None:
        yield
        return
    _SHARED_POOLS = {}
    try:
        yield
    finally:
        pools, _SHARED_POOLS = _SHARED_POOLS, None
        for pool in pools.values():
            pool.shutdown(cancel_futures=True)


def _new_pool(workers: int) -> ProcessPoolExecutor:
    return ProcessPoolExecutor(workers, _QuietSpawnContext(), initializer=die_with_parent, initargs=(os.getpid(),))


class LocalBackend:
    """Jobs in this process (``workers=1``) or a pool of spawned processes (its own, or inside
    :func:`shared_pools` the shared one of its size), results in job order."""

    def __init__(self, workers: int):
        self.workers = workers
        self._pool: ProcessPoolExecutor | None = None
        self._shared = False
        self._limits = None

    def __enter__(self):
        if self.workers > 1 and (script := missing_main_script()) is not None:
            raise EtmpcError(
                f"worker processes cannot start from {script}: each re-runs the main script, which is "
                "not a file: save it as one, or use workers=1"
            )
        if self.workers > 1:
            if _SHARED_POOLS is None:
                self._pool = _new_pool(self.workers)
            else:
                if self.workers not in _SHARED_POOLS:
                    _SHARED_POOLS[self.workers] = _new_pool(self.workers)
                self._pool, self._shared = _SHARED_POOLS[self.workers], True
        self._limits = single_threaded()  # this process runs jobs (one worker) or the driver's own sums
        return self

    def __exit__(self, kind, value, traceback):
        if self._limits is not None:
            self._limits.restore_original_limits()
        if self._pool is None:
            return
        if self._shared and kind is None:
            return  # kept for the next stage
        if self._shared and _SHARED_POOLS is not None and _SHARED_POOLS.get(self.workers) is self._pool:
            del _SHARED_POOLS[self.workers]  # a failed or interrupted stage: its jobs may still be queued
        self._pool.shutdown(cancel_futures=True)

    def map(self, fn, jobs: list, on_result=None, chunksize: int = 1) -> list:
        results = []
        iterator: Iterator[object]
        if self._pool is None:
            iterator = map(fn, jobs)
        else:  # each job pickled here and unpickled by _call_pickled: a job a worker cannot load fails in one line
            iterator = self._pool.map(
                functools.partial(_call_pickled, fn), [pickle.dumps(job) for job in jobs], chunksize=chunksize
            )
        try:
            for job, result in zip(jobs, iterator):
                results.append(result)
                if on_result is not None:
                    on_result(job)
        except EtmpcError as exc:
            if self._pool is None:
                raise
            raise exc from None  # a worker's one-line error, without the worker's traceback as its cause
        except BrokenProcessPool:  # a worker was killed or exited (os._exit in someone's code, out of memory)
            if self._ended_with(UNGUARDED_EXIT):
                raise UnguardedScript(UNGUARDED) from None
            raise EtmpcError(
                "a worker process ended abruptly (killed, out of memory, or code in it called os._exit): "
                "run with --workers 1 (workers=1 in Python) to see where"
            ) from None
        return results

    def _ended_with(self, code: int) -> bool:
        """Whether a worker of the (broken) pool exited with ``code``. The pool's own thread reaps its
        workers: the pool is shut down first (which waits for that thread), then their exit codes are known."""
        assert self._pool is not None  # only a pool of workers breaks
        processes = list((getattr(self._pool, "_processes", None) or {}).values())
        self._pool.shutdown(wait=True, cancel_futures=True)
        return any(process.exitcode == code for process in processes)


BACKENDS = ("local", "ray")


class RayBackend:
    """Jobs as Ray tasks, in chunks, with at most ``2 * workers`` chunks in flight; results in job order. Without
    ``address`` it starts its own Ray instance of ``workers`` CPUs for the run (``"local"``: never one that ``RAY_ADDRESS``
    or a Ray running on the machine names) and stops it afterwards; with one (``auto``, ``HOST:PORT`` or
    ``ray://HOST:PORT``) it joins that cluster, and ``workers`` only bounds how much work is queued at once."""

    def __init__(self, workers: int, address: str | None = None):
        self.workers, self.address = workers, address
        self._started = False
        self._remote: RemoteFunction1[list, Callable[[Any], Any], list] | None = None  # set on entering

    def __enter__(self):
        try:
            import ray
        except ImportError:
            raise EtmpcError("--backend ray needs Ray: pip install 'etmpc[ray]'") from None
        if not ray.is_initialized():
            own = self.address is None  # a Ray of our own for the run, sized here
            if self.address is not None:
                _check_reachable(self.address)
            try:
                ray.init(
                    address=self.address or "local",
                    include_dashboard=False,
                    logging_level=logging.WARNING,
                    log_to_driver=True,
                    num_cpus=self.workers if own else None,
                    # The object store only carries jobs and results (kilobytes): keep it small.
                    object_store_memory=100 * 2**20 if own else None,
                )
            except ConnectionError as exc:
                raise EtmpcError(
                    f"cannot join the Ray cluster at {self.address}: {exc} (a cluster with token "
                    "authentication also needs RAY_AUTH_MODE=token and its token in etmpc's environment)"
                ) from None
            self._started = True
        self._remote = ray.remote(num_cpus=1, max_retries=0)(_run_chunk)
        return self

    def __exit__(self, *exc):
        if self._started:
            import ray

            ray.shutdown()

    def map(self, fn, jobs: list, on_result=None, chunksize: int = 1) -> list:
        import ray

        remote = self._remote
        assert remote is not None, "map is called inside the backend's with block"
        chunks = [jobs[i : i + chunksize] for i in range(0, len(jobs), chunksize)]
        window = 2 * self.workers
        pending: list[ObjectRef[list] | None] = [remote.remote(fn, chunk) for chunk in chunks[:window]]
        results: list = []
        for i, chunk in enumerate(chunks):
            ref = pending[i]
            assert ref is not None  # freed only once its results are in
            try:
                done: list = ray.get(ref)
                results += done
            except ray.exceptions.RayTaskError as exc:
                if isinstance(exc.cause, EtmpcError):  # bad input found on a worker: the same one-line error as locally
                    raise exc.cause from None
                raise
            pending[i] = None  # let Ray free the result
            if i + window < len(chunks):
                pending.append(remote.remote(fn, chunks[i + window]))
            if on_result is not None:
                for job in chunk:
                    on_result(job)
        return results


def _check_reachable(address: str, timeout: float = 10.0) -> None:
    """Fail fast on a cluster address nobody answers at (Ray itself retries for minutes)."""
    if address == "auto":
        return
    host, sep, port = address.removeprefix("ray://").rpartition(":")
    if not sep or not port.isdigit():
        raise EtmpcError(f"bad --address {address!r}: use auto, HOST:PORT or ray://HOST:PORT")
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=timeout).close()
    except OSError as exc:
        raise EtmpcError(f"cannot reach the Ray cluster at {address}: {exc.strerror or exc}") from None


def _call_pickled(fn, job: bytes):
    """``fn`` of a job pickled by the driver, in a worker: a job that does not unpickle here (a policy whose
    class the worker cannot import: defined under the script's ``if __name__ == "__main__":``, or in a
    ``__main__`` it cannot re-run) raises a one-line error rather than killing the worker."""
    try:
        job = pickle.loads(job)
    except Exception as exc:
        raise EtmpcError(
            f"a worker process cannot load its job ({described(exc)}): define your policy's "
            'class in a module (or at the top level of a script run under `if __name__ == "__main__":`), '
            "or use workers=1"
        ) from None
    return fn(job)


def _run_chunk(fn: Callable[[Any], Any], chunk: list) -> list:
    with single_threaded():
        return [fn(job) for job in chunk]


def make_backend(name: str, workers: int, address: str | None = None) -> LocalBackend | RayBackend:
    """A context manager with ``.map(fn, jobs, on_result=None, chunksize=1)``."""
    refuse_in_rerun_main()  # a worker re-running an unguarded script: it must not start this work (or workers) again
    if name == "local":
        if address is not None:
            raise EtmpcError("--address needs --backend ray")
        return LocalBackend(workers)
    if name == "ray":
        return RayBackend(workers, address)
    raise EtmpcError(f"unknown backend {name!r}: {' | '.join(BACKENDS)}")
