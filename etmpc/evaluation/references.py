"""A task's reference points for the scorecard, stored with the task: every periodic schedule and the
oracle over the best of them, per episode of its test set (see :mod:`etmpc.evaluation.scorecard`), and the
whole runs of the oracle and of the rollout meter over the best schedule as they were played (the
leaderboard's rows of both, which it does not play again).

``tasks/<domain>/<task>/references.json`` holds them with the suite's version, the test set's sha256,
the task's price and the software that computed them, sealed with the SHA-256 of its content. A file
that does not match what is being scored, was edited after it was written, or does not hold together
is refused in one line that says how to rebuild it (``etmpc score --references``). Holding together
means: a finite objective for every schedule ``every:1`` .. ``every:N`` (the task's horizon; and
``iterate:1`` .. ``iterate:N`` on a task with compute levels) and the oracle on every episode; the
named best schedule is the one with the best mean (the first on a tie);
and on every episode the oracle does no worse than that schedule, as a one-step lookahead over a
schedule with the episode's future known must (it can always answer as the schedule does).
"""

from __future__ import annotations

import functools
import math
import platform
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, replace
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

import numpy as np

from etmpc.common.documents import check_seal, read_document, sealed
from etmpc.common.errors import EtmpcError
from etmpc.common.numerics import fsum
from etmpc.common.outputs import write_json
from etmpc.common.progress import stage
from etmpc.common.sense import best as best_of, oriented
from etmpc.evaluation import testsets
from etmpc.evaluation.evaluate import Evaluation, evaluate
from etmpc.systems import SystemKey, make_system, spec, system_key
from etmpc.systems.capabilities import Experiments, Rollouts, offers

SUITE_VERSION = 4  # what changes it, and what changes a task's version instead: docs/versioning.md
FORMAT = "etmpc-references"
ROLLOUT_FUTURES = 4  # the rollout meter's sampled futures per decision

SOFTWARE = ("etmpc", "mujoco", "dm-control", "casadi", "daqp", "numpy", "scipy")


def software() -> dict[str, str]:
    found = {}
    for name in SOFTWARE:
        try:
            found[name] = version(name)
        except PackageNotFoundError:
            found[name] = "(not installed)"
    return found | {"python": platform.python_version()}


@dataclass(frozen=True)
class References:
    """A task's reference points on one test set (see the module's docstring)."""

    task: str
    test_set_sha256: str
    episodes: int
    recompute_price: float
    objective_sense: str
    periodic: dict[str, list[float]]  # every:T (and iterate:T on a task with compute levels) -> objective per episode
    best: str  # the periodic schedule with the best mean objective
    oracle: list[float]  # oracle:BEST's objective per episode
    suite_version: int = SUITE_VERSION
    software: dict[str, str] = field(default_factory=dict)
    # The oracle's evaluation as it was played for these references (``etmpc evaluate --json``'s document, with
    # each episode's CPU time): the leaderboard's oracle row, scored without playing it again. None in
    # references made before suite 3, and in :meth:`head`'s.
    oracle_evaluation: dict | None = None
    # Likewise the rollout meter's (:func:`rollout_meter_spec`), the leaderboard's row of it; None where the task
    # has no rollouts, in references made before it was kept, and in :meth:`head`'s.
    rollout_evaluation: dict | None = None

    @property
    def oracle_spec(self) -> str:
        return f"oracle:{self.best}"

    def kept_evaluation(self, spec: str) -> dict | None:
        """The evaluation of ``spec`` these references kept as it was played (the oracle's, the rollout
        meter's), or None."""
        if spec == self.oracle_spec:
            return self.oracle_evaluation
        if self.rollout_evaluation is not None and _played_spec(self.rollout_evaluation) == spec:
            return self.rollout_evaluation
        return None

    def costs(self, objectives) -> np.ndarray:
        """Objectives as costs (lower is better), whatever the task's sense."""
        return -oriented(np.asarray(objectives, dtype=float), self.objective_sense)

    @property
    def gap(self) -> float:
        """``D = mean_e (B_e - O_e)``: what the oracle gains over the best periodic schedule, per episode."""
        return mean(self.costs(self.periodic[self.best]) - self.costs(self.oracle))

    def head(self, episodes: int) -> References:
        """The references of the first ``episodes`` episodes only (the best schedule stays the one chosen
        on the whole test set; the gap is that of these episodes)."""
        if not 1 <= episodes <= self.episodes:
            raise EtmpcError(f"--episodes must be in 1..{self.episodes} for these references, got {episodes}")
        return replace(
            self,
            episodes=episodes,
            periodic={k: v[:episodes] for k, v in self.periodic.items()},
            oracle=self.oracle[:episodes],
            oracle_evaluation=self.oracle_evaluation if episodes == self.episodes else None,
            rollout_evaluation=self.rollout_evaluation if episodes == self.episodes else None,
        )

    def to_json(self) -> dict:
        """The file's content, sealed with the SHA-256 of the rest (no kept evaluation that there is not)."""
        content = {k: v for k, v in asdict(self).items() if not (k in KEPT and v is None)}
        return sealed({"format": FORMAT} | content)


KEPT = ("oracle_evaluation", "rollout_evaluation")  # written only when there is one


def mean(values) -> float:
    """The mean, summed exactly (``fsum``): the same on every machine, and ``mean(x) / mean(x)`` is 1."""
    values = list(np.asarray(values, dtype=float))
    return fsum(values) / len(values)


def best_schedule(periodic: dict[str, list[float]], sense: str) -> str:
    """The schedule with the best mean objective (``sense``: ``min`` or ``max``), the first of a tie."""
    return best_of(list(periodic), sense, key=lambda spec: mean(periodic[spec]))


def periodic_schedules(system) -> list[str]:
    """The fixed schedules a task's references play: ``every:1`` .. ``every:N`` (N its horizon) and, on a
    task with compute levels, ``iterate:1`` .. ``iterate:N`` too (the best of them all is the one scored
    against)."""
    periods = range(1, system.horizon + 1)
    return [f"every:{t}" for t in periods] + ([f"iterate:{t}" for t in periods] if system.compute_levels else [])


def rollout_meter_spec(system, best: str) -> str | None:
    """The rollout meter over ``best``: ``rollout:BEST:4:H``, the one-step lookahead over sampled futures with
    the task's lookahead ``H``; None for a task without rollouts or a benchmark's lookahead."""
    if not (offers(system, Rollouts) and offers(system, Experiments)):
        return None
    return f"rollout:{best}:{ROLLOUT_FUTURES}:{system.benchmark.lookahead}"


def references_path(task: str) -> Path:
    """Where task ``task``'s references are stored: ``tasks/DOMAIN/TASK/references.json``."""
    return spec(task).data_file("references.json")


def _objectives(evaluation: Evaluation, spec: str) -> list[float]:
    runs = sorted((r for r in evaluation.runs if r.policy == spec), key=lambda r: r.episode)
    if not all(r.finite for r in runs):
        raise EtmpcError(
            f"{evaluation.domain}/{evaluation.task}: {spec} ended an episode on a non-finite state; it cannot be a reference"
        )
    return [r.objective for r in runs]


def build_references(
    task: str | SystemKey,
    test_set: str | None = None,
    workers: int | None = None,
    progress: bool = True,
    say: Callable[[str], None] = lambda line: None,
    episodes: int | None = None,
    meter: bool = True,
) -> References:
    """Play every periodic schedule, then the oracle and the rollout meter over the best of them, on ``task``'s
    test set (the stored one by default; its first ``episodes`` only, if given). ``task``: a name, or a
    :class:`~etmpc.systems.SystemKey` (a task with its options: the references are then those of the task so
    set). Without ``meter``, no rollout meter: the scale alone, what a scorecard needs (the leaderboard's
    meter row is the stored references')."""
    key = system_key(task)
    system = key.make()
    periodic = periodic_schedules(system)
    after = "the oracle and the rollout meter" if meter else "the oracle"
    say(f"{system.name}: references: {len(periodic)} periodic schedules, then {after} over the best")
    play = functools.partial(evaluate, key, episodes=episodes, workers=workers, test_set=test_set, progress=progress)
    with stage(f"{system.name}: references: {len(periodic)} periodic schedules"):  # each named in the progress lines
        fixed = play(periodic)
    table = {spec: _objectives(fixed, spec) for spec in periodic}
    best = best_schedule(table, system.objective_sense)
    with stage(f"{system.name}: references: the oracle"):
        oracle = play([f"oracle:{best}"])
    meter_spec = rollout_meter_spec(system, best) if meter else None
    with stage(f"{system.name}: references: the rollout meter"):
        rollout = play([meter_spec]) if meter_spec else None
    refs = References(
        system.name,
        fixed.testset_sha256,
        len(table[best]),
        system.recompute_price,
        system.objective_sense,
        table,
        best,
        _objectives(oracle, f"oracle:{best}"),
        software=software(),
        oracle_evaluation=oracle.to_json(cpu=True),
        rollout_evaluation=None if rollout is None else rollout.to_json(cpu=True),
    )
    if not refs.gap > 0:
        raise EtmpcError(
            f"{system.name}: the oracle over {best} does not improve on it on this test set "
            f"(gap {refs.gap:g}): there is no scale to score against"
        )
    return refs


def replay_meter(
    task: str, workers: int | None = None, progress: bool = True, say: Callable[[str], None] = lambda line: None
) -> References:
    """``task``'s stored references with the rollout meter played again over their best schedule, the schedules
    and the oracle (the score's scale) kept as stored: after a change to the meter alone, which moves no score."""
    refs, system = stored(task), make_system(task)
    meter = rollout_meter_spec(system, refs.best)
    if meter is None:
        raise EtmpcError(f"{system.name} has no rollout meter to play again")
    say(f"{system.name}: references: the rollout meter ({meter}) again, the schedules and the oracle as stored")
    with stage(f"{system.name}: references: the rollout meter"):
        rollout = evaluate(system_key(task), [meter], workers=workers, progress=progress)
    return replace(refs, rollout_evaluation=rollout.to_json(cpu=True))


def load_references(task: str, test_set_sha256: str, path: Path | None = None) -> References:
    """The stored references of ``task``, checked against the test set (its sha256), the suite's version
    and the task's price; a mismatch is one line that says how to rebuild them."""
    path = references_path(task) if path is None else Path(path)
    rebuild = f"rebuild them with: etmpc score --references --task {task}"
    data = read_document(
        path,
        FORMAT,
        missing=f"{task}: no stored references ({path}); {rebuild}",
        unreadable=f"{task}: references {path} cannot be read ({{error}}); {rebuild}",
        foreign=f"{task}: {path} is not an etmpc references file; {rebuild}",
    )
    if data.get("suite_version") != SUITE_VERSION:
        raise EtmpcError(
            f"{task}: references {path} are of suite version {data.get('suite_version')!r}, this etmpc's is "
            f"{SUITE_VERSION}; {rebuild}"
        )
    if data.get("test_set_sha256") != test_set_sha256:
        raise EtmpcError(
            f"{task}: references {path} were made on test set {str(data.get('test_set_sha256'))[:12]}…, not "
            f"{test_set_sha256[:12]}…; {rebuild}"
        )
    system = make_system(task)
    if data.get("recompute_price") != system.recompute_price:
        raise EtmpcError(
            f"{task}: references {path} are at price {data.get('recompute_price')!r}, the task's is "
            f"{system.recompute_price!r}; {rebuild}"
        )
    check_seal(data, f"{task}: references {path}", rebuild)
    problem = _problem(data, system)
    if problem is not None:
        raise EtmpcError(f"{task}: references {path} are inconsistent ({problem}); {rebuild}")
    return References(
        **{
            k: data[k]
            for k in (
                "task",
                "test_set_sha256",
                "episodes",
                "recompute_price",
                "objective_sense",
                "periodic",
                "best",
                "oracle",
                "suite_version",
                "software",
            )
        },
        oracle_evaluation=data.get("oracle_evaluation"),
        rollout_evaluation=data.get("rollout_evaluation"),
    )


def _numbers(values, episodes: int) -> bool:
    return (
        isinstance(values, list)
        and len(values) == episodes
        and all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in values)
    )


def _problem(data: dict, system) -> str | None:
    """What does not hold together in a references file's ``data`` (see the module's docstring), or None."""
    episodes, periodic, sense = data.get("episodes"), data.get("periodic"), data.get("objective_sense")
    if not (isinstance(episodes, int) and not isinstance(episodes, bool) and episodes >= 1):
        return f"episodes {episodes!r} is not a count"
    if sense != system.objective_sense:
        return f"objective_sense {sense!r}, the task's is {system.objective_sense!r}"
    if not isinstance(data.get("task"), str) or not isinstance(data.get("software"), dict):
        return "task or software missing"
    schedules = periodic_schedules(system)
    if not isinstance(periodic, dict) or list(periodic) != schedules:
        return f"periodic must hold {schedules[0]} .. {schedules[-1]} in order"
    if not all(_numbers(v, episodes) for v in periodic.values()) or not _numbers(data.get("oracle"), episodes):
        return f"every schedule and the oracle need {episodes} finite objectives"
    best = best_schedule(periodic, sense)
    if data.get("best") != best:
        return f"best names {data.get('best')!r}, but {best} has the best mean objective"
    played = data.get("oracle_evaluation")
    if played is not None and _played_objectives(played, f"oracle:{best}") != data["oracle"]:
        return "oracle_evaluation does not hold the oracle's objectives"
    meter, spec = data.get("rollout_evaluation"), rollout_meter_spec(system, best)
    if meter is not None and not (spec and _played_spec(meter) == spec and _numbers(_played_objectives(meter, spec), episodes)):
        return f"rollout_evaluation is not {spec or 'a rollout meter'}'s run on {episodes} episodes"
    worse = [e for e, (o, b) in enumerate(zip(data["oracle"], periodic[best])) if oriented(o - b, sense) < 0]
    if worse:
        return f"the oracle does worse than {best} on episode {worse[0]}, which the oracle over it cannot"
    if not mean([oriented(o, sense) - oriented(b, sense) for o, b in zip(data["oracle"], periodic[best])]) > 0:
        return f"the oracle does not improve on {best}: there is no scale to score against"
    return None


def _played_spec(evaluation) -> str | None:
    """The one policy an evaluation's JSON played, or None."""
    try:
        specs = {r["policy"] for r in evaluation["runs"]}
    except (KeyError, TypeError):
        return None
    return specs.pop() if len(specs) == 1 else None


def _played_objectives(evaluation, spec: str) -> list | None:
    """``spec``'s objective per episode, in episode order, in an evaluation's JSON; None if it is not one."""
    try:
        runs = sorted((r for r in evaluation["runs"] if r["policy"] == spec), key=lambda r: r["episode"])
        return [r["objective"] for r in runs]
    except (KeyError, TypeError):
        return None


def stored(task: str, episodes: int | None = None) -> References:
    """``task``'s stored references, checked against its stored test set; of its first ``episodes`` only, if given."""
    system = make_system(task)
    sha = testsets.load(testsets.default_path(system.domain, system.task), system.domain, system.task).sha256
    refs = load_references(task, sha)
    return refs if episodes is None else refs.head(episodes)


def write_references(refs: References, path: Path | None = None) -> Path:
    path = references_path(refs.task) if path is None else Path(path)
    return write_json(path, refs.to_json())
