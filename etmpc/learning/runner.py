"""One runner for every :class:`~etmpc.learning.base.Learner`: ``etmpc train --algorithm NAME``.

:func:`run` checks the seeds and the run's directory, resumes from the learner's saved state if it is
the run asked for (:func:`etmpc.learning.resume.same_run`: its task, price, options and settings) or sets
it up afresh, advances it milestone by milestone (saving after each: a killed run resumed with
``resume=True`` continues from the last one, bit for bit where the learner says so,
:attr:`~etmpc.learning.base.Learner.resumes_exactly`), then scores the learner's candidates on
validation episodes of the training distribution (:func:`validate`: never the test set) and lets it
keep the best (:func:`best`). It returns a :class:`Run`: the learner, its policy spec and the cost
(wall time, simulated steps). :class:`timed` keeps a stage's wall time in a file beside it.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from etmpc.common.progress import Progress
from etmpc.common.sense import oriented
from etmpc.common.errors import EtmpcError
from etmpc.evaluation.backends import make_backend
from etmpc.learning.base import Learner, check_decisions, learner_class
from etmpc.learning.config import VALIDATION_ENTROPY
from etmpc.learning.jobs import mean_scores
from etmpc.learning.resume import same_run
from etmpc.loop.records import EpisodeSink
from etmpc.policies.learned import write_json_atomically
from etmpc.systems import SystemKey, system_key


@dataclass
class Run:
    """What :func:`run` returns: the trained learner, its answer and what it cost."""

    learner: Learner
    policy: str  # the spec etmpc evaluate scores
    wall_seconds: float  # this invocation's
    simulated_steps: int | None


def run(
    learner: Learner | str,
    task: str | SystemKey,
    out: Path,
    seeds: tuple[int, ...] | None = None,
    workers: int = 1,
    resume: bool = False,
    backend: str = "local",
    address: str | None = None,
    progress: bool = True,
    say: Callable[[str], None] = lambda line: None,
    settings=None,
    recorder: Callable[[Path], EpisodeSink] | None = None,
    curve_png: Callable[[Path, dict, int], None] | None = None,
) -> Run:
    """Train ``learner`` (an instance, or a registered name with ``settings``) on ``task`` into ``out``.
    ``recorder`` and ``curve_png``: what the run's recordings and learning curve are drawn with
    (:class:`etmpc.views.recording.Recorder`, :func:`etmpc.views.curves.write_curve_png`; None: not drawn)."""
    if isinstance(learner, str):
        learner = learner_class(learner)(settings)
    started = time.perf_counter()
    learner.key, learner.seeds, learner.out, learner.say = system_key(task), _seeds(learner, seeds), Path(out), say
    learner.recorder, learner.curve_png = recorder, curve_png
    learner.workers = workers
    check_decisions(learner, learner.key.task)
    learner.check()
    if learner.has_saved() and not resume:
        raise EtmpcError(f"{out} already holds a training run; pass --resume to continue it, or choose another --out")
    saved = learner.saved_state()  # each field checked as it is read
    if saved is not None:
        same_run(learner, saved)  # the run asked for: its task, price, options and settings
    total = learner.work()
    with make_backend(backend, workers, address) as pool, Progress(total, enabled=progress, unit=learner.unit) as bar:
        learner.pool, learner.tick = pool, bar.update
        try:
            if saved is None:
                learner.out.mkdir(parents=True, exist_ok=True)
                learner.setup()
                learner.save()
            else:
                learner.load_state(saved)
                bar.skip(learner.work_done())  # done before: not in the estimate's rate
            for milestone in learner.milestones():
                if milestone <= learner.done:
                    continue
                learner.learn(milestone, bar.update)
                learner.save()
                line = learner.report()
                if line is not None:
                    bar.write(f"{line}; {bar.times()}")
            if not learner.chosen:
                scores = learner.scores(
                    lambda policies: validate(
                        pool, learner.key, policies, learner.validation_episodes(), lambda job: bar.update(1)
                    )
                )
                learner.choose(scores)
                learner.save()
        finally:
            learner.close()
            learner.pool = None  # released: the backend is closed
            learner.tick = _no_progress  # the bar is closed
    return Run(learner, learner.policy(), time.perf_counter() - started, learner.simulated_steps())


def _no_progress(n: int) -> None:
    """A learner's :attr:`~etmpc.learning.base.Learner.tick` outside a run: its units go nowhere."""


def _seeds(learner: Learner, seeds) -> tuple[int, ...]:
    if learner.seeding == "none":
        if seeds not in (None, ()):
            raise EtmpcError(f"{learner.name} takes no seed (its draws are one fixed stream), got {seeds}")
        return ()
    seeds = learner.default_seeds() if seeds is None else tuple(int(s) for s in seeds)
    if learner.seeding == "one" and len(seeds) != 1:
        raise EtmpcError(f"{learner.name} trains one seed at a time: give one seed, got {','.join(map(str, seeds))}")
    if not seeds or len(set(seeds)) != len(seeds) or min(seeds) < 0:
        raise EtmpcError(f"seeds must be distinct, non-negative and at least one, got {seeds}")
    return seeds


def validate(pool, key: SystemKey, policies: list, episodes: int, on_result=None) -> list[float]:
    """Each policy's (a spec or a policy's JSON) mean objective on the first ``episodes`` episodes of the
    validation stream: training-distribution episodes, the same for every learner, never the test set."""
    return mean_scores(pool, key, policies, VALIDATION_ENTROPY, episodes, on_result)


def best(scores: list[float], sense: str) -> int:
    """The index of the best score (``sense``: ``"max"`` or ``"min"``); the first wins a tie."""
    return int(np.argmax(oriented(np.asarray(scores, dtype=float), sense)))


def cost_path(stage: Path) -> Path:
    """Where the wall time of training stage ``stage`` (a folder) is kept: ``<stage>_cost.json`` beside it."""
    return stage.with_name(f"{stage.name}_cost.json")


class timed:
    """Times a training stage into :func:`cost_path` (wall seconds, workers), unless an earlier invocation
    finished it (the file is there): a resumed stage keeps its first, partial, count."""

    def __init__(self, folder: Path, workers: int):
        self.path, self.workers = cost_path(Path(folder)), workers

    def __enter__(self):
        self.started = time.perf_counter()

    def __exit__(self, kind, *_):
        if kind is None and not self.path.exists():
            self.path.parent.mkdir(parents=True, exist_ok=True)
            write_json_atomically(self.path, {"wall_seconds": time.perf_counter() - self.started, "workers": self.workers})
