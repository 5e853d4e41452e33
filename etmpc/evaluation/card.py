"""The scorecard's records (:mod:`etmpc.evaluation.scorecard` says what the numbers mean): a
:class:`TaskScore` per task and policy (a card's row), an :class:`Aggregate` per policy over the tasks,
and the :class:`Scorecard`, each with the JSON ``etmpc score --json`` writes and ``etmpc verify`` reads."""

from __future__ import annotations

import math
import platform
from dataclasses import asdict, dataclass

import numpy as np

from etmpc.common import checks
from etmpc.common.provenance import libm_rounding
from etmpc.evaluation import metrics
from etmpc.evaluation.references import SUITE_VERSION, software
from etmpc.systems import task_version


def _nan(value):
    """A number as strict JSON kept it: ``null`` (not scored) is NaN."""
    return math.nan if value is None else value


@dataclass(frozen=True)
class TaskScore:
    """One policy on one task. Its JSON (:meth:`to_json`, :meth:`from_json`) is a card's row."""

    task: str
    policy: str
    episodes: int
    objective_mean: float
    objective_sense: str  # the objective's, for display: the scores are higher-is-better whatever it is
    recomputes_mean: float
    failures_mean: float | None  # the task's own failures (falls, ...), if it counts them
    solver_failures: int
    nonfinite_episodes: int
    score: float  # NaN when not scored (non-finite episodes, or an error)
    score_ci95: float
    episode_scores: list[float]  # s_e
    better_share: float  # share of episodes with a lower cost than the best periodic schedule (ties: half)
    cpu_ms: dict[str, float]  # mean per episode: solve, feedback, decide, total ({}: not measured)
    reference: str  # the best periodic schedule
    error: str | None = None
    task_version: int = 0  # the task's version it was scored on (docs/versioning.md)
    # The task's failures, if it counts them (None: it does not, or a row of an older etmpc): the 95 % CI of
    # failures_mean, 1.96 sd / sqrt(n) over the episodes (NaN below two), and each episode's count, in the
    # order of episode_scores, so that two policies' failures can be paired episode by episode.
    failures_ci95: float | None = None
    episode_failures: list[float] | None = None
    # Each episode's objective (NaN: it ended non-finite), recomputes and solver failures, in the order of
    # episode_scores (a stochastic policy's passes: the mean, the mean, the sum), so that every number of the
    # row can be checked against its episodes, and each against a replay (etmpc verify). None: a row of an
    # older etmpc.
    episode_objectives: list[float] | None = None
    episode_recomputes: list[float] | None = None
    episode_solver_failures: list[int] | None = None

    @property
    def scores(self) -> np.ndarray:
        """The episode scores as an array, for :mod:`etmpc.evaluation.metrics`."""
        return np.asarray(self.episode_scores, dtype=float)

    @property
    def scored(self) -> bool:
        return math.isfinite(self.score)

    def to_json(self) -> dict:
        """The row as a card stores it (a number not scored is NaN here, ``null`` once written)."""
        return asdict(self)

    @classmethod
    def from_json(cls, data: dict) -> TaskScore:
        """A row as :meth:`to_json` gave it and strict JSON kept it (a number not scored is ``null``
        there, NaN here), every field of its type (else ``ValueError``, ``TypeError`` or ``KeyError``)."""
        fields = dict(data)
        for name in ("objective_mean", "recomputes_mean", "score", "score_ci95", "better_share"):
            fields[name] = _nan(fields[name])
        fields["episode_scores"] = [_nan(v) for v in fields["episode_scores"]]
        if fields.get("episode_objectives") is not None:
            fields["episode_objectives"] = [_nan(v) for v in fields["episode_objectives"]]
        fields["cpu_ms"] = {k: _nan(v) for k, v in dict(fields["cpu_ms"]).items()}
        if fields.get("episode_failures") is not None:  # the row counted failures: null is a number not known
            fields["failures_mean"], fields["failures_ci95"] = _nan(fields["failures_mean"]), _nan(fields.get("failures_ci95"))
        row = cls(**fields)
        checks.typed(row)
        return row


def failed_task(task: str, spec: str, error: str) -> TaskScore:
    nan = math.nan
    return TaskScore(task, spec, 0, nan, "", nan, None, 0, 0, nan, nan, [], nan, {}, "", error, task_version(task))


@dataclass(frozen=True)
class Aggregate:
    """A policy over the suite's tasks scored (see the module's docstring)."""

    policy: str
    tasks: int
    iqm: float
    iqm_ci95: tuple[float, float]
    probability_of_improvement: float
    probability_of_improvement_ci95: tuple[float, float]

    def to_json(self) -> dict:
        return asdict(self)

    @classmethod
    def from_json(cls, data: dict) -> Aggregate:
        pair = lambda v: tuple(_nan(x) for x in v)  # noqa: E731
        return cls(
            data["policy"],
            data["tasks"],
            _nan(data["iqm"]),
            pair(data["iqm_ci95"]),
            _nan(data["probability_of_improvement"]),
            pair(data["probability_of_improvement_ci95"]),
        )


def aggregate(rows: list[TaskScore]) -> Aggregate:
    """The IQM and the probability of improvement over the tasks of ``rows`` that were scored."""
    scored = [r.scores for r in rows if r.scored]
    policy = rows[0].policy if rows else ""
    if not scored:
        return Aggregate(policy, 0, math.nan, (math.nan, math.nan), math.nan, (math.nan, math.nan))
    return Aggregate(
        policy,
        len(scored),
        metrics.iqm(scored),
        metrics.iqm_ci95(scored),
        metrics.probability_of_improvement(scored),
        metrics.probability_of_improvement_ci95(scored),
    )


def profile(rows: list[TaskScore], thresholds: np.ndarray) -> np.ndarray:
    """The performance profile (:func:`~etmpc.evaluation.metrics.performance_profile`) over the tasks
    of ``rows`` that were scored."""
    return metrics.performance_profile([r.scores for r in rows if r.scored], thresholds)


def by_policy(rows: list[TaskScore]) -> dict[str, list[TaskScore]]:
    """``rows`` grouped by policy, in the order the policies first appear."""
    groups: dict[str, list[TaskScore]] = {}
    for row in rows:
        groups.setdefault(row.policy, []).append(row)
    return groups


def profiles(card: Scorecard, thresholds: np.ndarray) -> dict[str, np.ndarray]:
    """Each policy's :func:`profile` over the tasks it was scored on."""
    return {policy: profile(rows, thresholds) for policy, rows in by_policy(card.rows).items()}


@dataclass(frozen=True)
class Scorecard:
    """The card: its rows and aggregates, and what each task was scored against. Its JSON
    (:meth:`to_json`, :meth:`from_json`) is what ``etmpc score --json`` writes."""

    tasks: list[str]
    references: dict[str, dict]  # task -> what it was scored against (best schedule, sha256, stored or computed)
    rows: list[TaskScore]
    aggregates: list[Aggregate]

    @property
    def complete(self) -> bool:
        """Every policy was played on every task (none failed)."""
        return all(r.error is None for r in self.rows)

    def to_json(self) -> dict:
        return {
            "format": "etmpc-scorecard",
            "suite_version": SUITE_VERSION,
            "tasks": self.tasks,
            "task_versions": {task: task_version(task) for task in self.tasks},
            "references": self.references,
            "rows": [r.to_json() for r in self.rows],
            "aggregates": [a.to_json() for a in self.aggregates],
            "software": software(),
            "machine": {
                "processor": platform.processor() or platform.machine(),
                "system": platform.platform(),
                "libm": libm_rounding(),  # which rounding of sin, cos, exp, log the episodes were played with
            },
        }

    @classmethod
    def from_json(cls, data: dict) -> Scorecard:
        """A card as :meth:`to_json` wrote it (its versions, software and machine are the JSON's to check)."""
        return cls(
            list(data["tasks"]),
            dict(data["references"]),
            [TaskScore.from_json(r) for r in data["rows"]],
            [Aggregate.from_json(a) for a in data["aggregates"]],
        )
