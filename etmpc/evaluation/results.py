"""What an evaluation gives, as one type: each run (:class:`RunResult`), each policy's summary
(:class:`PolicySummary`), and the whole :class:`Evaluation`, which is saved and loaded as the JSON
``etmpc evaluate --json`` writes (:meth:`Evaluation.to_json`, :meth:`Evaluation.from_json`,
:meth:`Evaluation.save`, :meth:`Evaluation.load`), and gives a policy's objectives as an array
(:meth:`Evaluation.objectives`). The price of the recomputes is inside every objective; the sense
(a cost or a profit) is the task's, kept for display and for :mod:`etmpc.common.sense`."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields
from pathlib import Path

import numpy as np

from etmpc.common.wording import spread
from etmpc.common import checks
from etmpc.common.documents import loads
from etmpc.common.errors import EtmpcError
from etmpc.common.outputs import check_input, write_json
from etmpc.evaluation import metrics


@dataclass(frozen=True)
class RunResult:
    """One episode under one policy."""

    policy: str
    repeat: int
    episode: int
    objective: float  # sense-aware: cost (min) or profit (max), recomputes included
    control_objective: float  # the objective without the price of its recomputes (sense-aware)
    recomputes: int
    solver_failures: int
    steps: int
    finite: bool  # False: the episode ended early on a non-finite state or input
    failures: int | None = None  # the task's own failures in the episode (falls, ...), if it counts them


@dataclass(frozen=True)
class PolicySummary:
    policy: str
    objective_mean: float
    objective_std: float  # over test-set episodes (each averaged over repeats)
    objective_std_repeats: float  # over the repeats' means: the spread due to the policy's randomness
    objective_sense: str
    control_objective_mean: float
    recomputes_mean: float
    solver_failures: int  # total over all runs
    nonfinite_episodes: int  # runs that ended on a non-finite state or input; excluded from the means
    episodes: int
    repeats: int
    clairvoyant: bool = False  # an oracle: it knows the episode's future; a reference, not a policy
    failures_mean: float | None = None  # the task's failures per episode (failure_name), if it counts them
    failure_name: str | None = None
    failures_ci95: float | None = None  # 1.96 sd / sqrt(n) of the failures over the episodes (NaN below two)


def summarise(
    spec: str,
    runs: list[RunResult],
    sense: str,
    episodes: int,
    repeats: int,
    failure_name: str | None = None,
    clairvoyant: bool = False,
) -> PolicySummary:
    """Means over the runs that stayed finite; the others are counted, never averaged in. ``clairvoyant``:
    the policy knows each episode's future (an oracle's ``clairvoyant``)."""
    finite = [r for r in runs if r.finite]
    by_episode: dict[int, list[float]] = {}
    by_repeat: dict[int, list[float]] = {}
    failures_by_episode: dict[int, list[int | None]] = {}  # read only where every run counted
    for r in finite:
        by_episode.setdefault(r.episode, []).append(r.objective)
        by_repeat.setdefault(r.repeat, []).append(r.objective)
        failures_by_episode.setdefault(r.episode, []).append(r.failures)
    mean = lambda values: float(np.mean(values)) if len(values) else math.nan  # noqa: E731
    std = lambda values: float(np.std(values, ddof=1)) if len(values) > 1 else 0.0  # noqa: E731
    counted = failure_name is not None and all(r.failures is not None for r in finite)
    return PolicySummary(
        policy=spec,
        objective_mean=mean([r.objective for r in finite]),
        objective_std=std([mean(v) for v in by_episode.values()]),
        objective_std_repeats=std([mean(v) for v in by_repeat.values()]),
        objective_sense=sense,
        control_objective_mean=mean([r.control_objective for r in finite]),
        recomputes_mean=mean([r.recomputes for r in finite]),
        solver_failures=sum(r.solver_failures for r in runs),
        nonfinite_episodes=len(runs) - len(finite),
        episodes=episodes,
        repeats=repeats,
        clairvoyant=clairvoyant,
        failures_mean=mean([r.failures for r in finite]) if counted else None,
        failure_name=failure_name,
        # over the episodes, each averaged over its repeats (as objective_std)
        failures_ci95=metrics.mean_ci95([mean(v) for v in failures_by_episode.values()]) if counted else None,
    )


def failures_cell(mean: float | None, ci95: float | None = None) -> str:
    """A task's failures per episode as the tables show them: ``mean ± 95 % CI``; ``-`` where they are not
    known (a task that counts none), the mean alone where the CI is not (a row of an older etmpc), ``± n/a``
    where there is none (one episode)."""
    if mean is None or not math.isfinite(mean):
        return "-"
    if ci95 is None:
        return f"{mean:.2f}"
    return f"{mean:.2f} ± {spread(ci95)}"


@dataclass(frozen=True)
class Evaluation:
    domain: str
    task: str
    testset_path: str
    testset_sha256: str
    seed: int
    summaries: list[PolicySummary]
    runs: list[RunResult]
    recompute_price: float = math.nan  # the price of a recompute in every objective here
    # Per run, in the order of ``runs``: the controller's CPU seconds (solve, feedback, decide). Measured
    # wall time, so it depends on the machine and its load: kept out of ``to_json`` unless asked for.
    cpu: list[dict[str, float]] | None = None
    # the task's options (etmpc.systems.options: name -> canonical text) it was played with; none: the task as it is
    options: dict[str, str] | None = None

    def to_json(self, cpu: bool = False) -> dict:
        """The evaluation as JSON; with ``cpu``, also each run's CPU seconds (machine-dependent); the task's
        options where it was played with some."""
        extra: dict[str, object] = {"cpu_seconds": self.cpu} if cpu and self.cpu is not None else {}
        extra |= {"options": dict(self.options)} if self.options else {}
        return {
            "domain": self.domain,
            "task": self.task,
            "test_set": {"path": self.testset_path, "sha256": self.testset_sha256},
            "seed": self.seed,
            "recompute_price": self.recompute_price,
            "policies": {s.policy: _fields(s) for s in self.summaries},
            "runs": [_fields(r) for r in self.runs],
        } | extra

    @classmethod
    def from_json(cls, data: dict, where: str = "an evaluation") -> Evaluation:
        """The evaluation :meth:`to_json` gave, also as strict JSON wrote it (a missing number, NaN, is
        ``null`` there), every field of the type it is written with; a document that is not one raises
        :class:`EtmpcError` in one line naming what is wrong."""
        try:
            summaries = [_row(PolicySummary, s) for s in data["policies"].values()]
            runs = [_row(RunResult, r) for r in data["runs"]]
            evaluation = cls(
                data["domain"],
                data["task"],
                data["test_set"]["path"],
                data["test_set"]["sha256"],
                data["seed"],
                summaries,
                runs,
                _number(data.get("recompute_price")),
                data.get("cpu_seconds"),
                data.get("options"),
            )
            checks.typed(evaluation)
        except ValueError as exc:  # checks.BadValue: a field of another type
            raise EtmpcError(f"{where} is not an etmpc evaluation ({exc})") from None
        except (KeyError, TypeError, AttributeError) as exc:
            raise EtmpcError(f"{where} is not an etmpc evaluation (missing or wrong {exc})") from None
        return evaluation

    @classmethod
    def load(cls, path: str | Path) -> Evaluation:
        """The evaluation in ``path`` (as ``etmpc evaluate --json`` or :meth:`save` wrote it); a path that is no
        regular file (a FIFO, a device) is refused, never read."""
        check_input(Path(path), "evaluation")
        try:
            data = loads(Path(path).read_text())
        except (OSError, ValueError) as exc:
            raise EtmpcError(f"{path}: cannot read an evaluation ({exc})") from None
        if not isinstance(data, dict):
            raise EtmpcError(f"{path}: not an etmpc evaluation")
        return cls.from_json(data, str(path))

    def save(self, path: str | Path, cpu: bool = False) -> Path:
        """Write :meth:`to_json` to ``path``, atomically, as strict JSON."""
        return write_json(Path(path), self.to_json(cpu))

    def objectives(self, policy: str) -> np.ndarray:
        """``policy``'s objectives, ``[repeat, episode]`` (NaN where a run ended non-finite or was not made)."""
        runs = [r for r in self.runs if r.policy == policy]
        if not runs:
            raise EtmpcError(f"no runs of {policy!r} in this evaluation; it has {', '.join(s.policy for s in self.summaries)}")
        table = np.full((max(r.repeat for r in runs) + 1, max(r.episode for r in runs) + 1), np.nan)
        for r in runs:
            table[r.repeat, r.episode] = r.objective if r.finite else np.nan
        return table


def _number(value) -> float:
    return math.nan if value is None else value


def _row(kind: type, data: dict):
    """A :class:`RunResult` or :class:`PolicySummary` from its JSON: a float field that strict JSON wrote as
    ``null`` is NaN again (a field that may be None stays None)."""
    values = {f.name: data[f.name] for f in fields(kind) if f.name in data}
    if "upper_bound" in data and "clairvoyant" not in data and any(f.name == "clairvoyant" for f in fields(kind)):
        values["clairvoyant"] = data["upper_bound"]  # an older etmpc's name for it
    for f in fields(kind):
        if f.type == "float" and values.get(f.name, 0.0) is None:
            values[f.name] = math.nan
    if values.get("failure_name") is not None and values.get("failures_mean", 0.0) is None:
        values["failures_mean"] = math.nan  # a task that counts failures: null is a number not known
    if values.get("failure_name") is not None and "failures_ci95" in values and values["failures_ci95"] is None:
        values["failures_ci95"] = math.nan  # (a summary of an older etmpc has none: it stays None)
    row = kind(**values)
    checks.typed(row)
    return row


_TASK_FAILURES = ("failures", "failures_mean", "failure_name", "failures_ci95")


def _fields(row) -> dict:
    """A run or summary as JSON; the task's failure counts only for a task that counts them."""
    data = asdict(row)
    if data.get("failure_name", data.get("failures")) is None:
        for name in _TASK_FAILURES:
            data.pop(name, None)
    return data
