"""A training run's state on disk: ``checkpoint.json`` (:class:`RunState`), the policy files and the
learning curve, written so that the checkpoint never points past the files (see :func:`save`)."""

from __future__ import annotations

import re
from dataclasses import asdict, dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Callable

import numpy as np

from etmpc.common import checks
from etmpc.common.documents import loads
from etmpc.common.errors import EtmpcError
from etmpc.common.sense import best as best_of
from etmpc.learning.config import CHECKPOINT_FORMAT, TrainConfig
from etmpc.learning.resume import AGAIN, corrupt, number, numbers
from etmpc.policies.learned import LogisticPolicy, PolicyFileError, write_json_atomically
from etmpc.systems import has_levels, make_system


@dataclass
class RunState:
    """What ``checkpoint.json`` holds."""

    config: TrainConfig
    policy: dict  # the initial policy's JSON: normalisation, domain, hyperparameters
    learners: dict  # seed (str) -> learner JSON
    curve: list = field(default_factory=list)  # rows: {"episodes", "seed", "objective", "control", "recomputes"}
    best: dict = field(default_factory=dict)  # seed (str) -> {"episodes", "objective", "theta"[, "theta_level"]}
    training: list = field(default_factory=list)  # per-episode stats, all seeds
    base: str | None = None  # DPI: the fixed schedule iteration 0 rolls out over (chosen on training episodes)
    # candidate (str) -> its objective on the validation episodes: a seed's final policy ("SEED"), or, for a learner
    # that keeps every iteration's policy (DPI's history), the policy after EPISODES episodes ("SEED@EPISODES")
    validation: dict = field(default_factory=dict)

    @cached_property
    def objective_sense(self) -> str:
        return make_system(self.config.system).objective_sense

    @property
    def done(self) -> int:
        return min(int(data["episodes"]) for data in self.learners.values())

    def to_json(self) -> dict:
        return {
            "format": CHECKPOINT_FORMAT,
            "version": 1,
            "config": self.config.to_json(),
            "policy": self.policy,
            "learners": self.learners,
            "curve": self.curve,
            "best": self.best,
            "training": self.training,
            "base": self.base,
            "validation": self.validation,
        }


def load_checkpoint(path: Path) -> RunState:
    try:
        data = loads(path.read_text())
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise PolicyFileError(f"checkpoint {path} is corrupt or unreadable ({exc}); {AGAIN}") from None
    return state_from_json(data, f"checkpoint {path}")


# What checkpoint.json's records hold (checks.typed_json's hints): every field is checked when a run is resumed.
_STATE: dict[str, object] = dict(
    format=str, version=int, config=dict, policy=dict, learners=dict, curve=list, best=dict, training=list
)
_STATE.update(base=str | None, validation=dict[str, float])
# A number no result reads back may be null (a non-finite one, as strict JSON writes it): the control cost, a return.
_CURVE_ROW = dict(episodes=int, seed=int, objective=float, control=float | None, recomputes=float)
_POINT: dict[str, object] = dict(episodes=int, theta=list, theta_level=list)  # a policy DPI kept (its history)
_BEST = dict(_POINT, objective=float)  # a seed's best point on the test-set curve
_LEARNER = {
    "gpomdp": dict(
        theta=list,
        baseline_mean=list,
        episodes=int,
        settings=dict,
        value_gram=list,
        value_target=list,
        advantage_count=int,  # the "advantage" scale's running sums (only a run with that scale has them)
        advantage_square_sum=float,
    ),
    "dpi": dict(theta=list, theta_level=list, episodes=int, iterations=int, data=list, history=list),
}
_EPISODE: dict[str, dict[str, object]] = {
    "gpomdp": {"episode": int, "return": float | None, "recomputes": float, "seed": int},
    "dpi": dict(episode=int, seed=int, labels=int),
}


def state_from_json(data: dict, where: str = "checkpoint") -> RunState:
    """A :class:`RunState` from ``checkpoint.json``'s content, each field checked: of its type (numbers finite), of
    the run's sizes (a parameter vector per feature, a label per field) and as the run wrote them (a learner and a
    curve point per seed at each milestone so far). One that is not is one line naming ``where`` and the field."""
    try:
        if not isinstance(data, dict) or data.get("format") != CHECKPOINT_FORMAT or data.get("version") != 1:
            found = data if not isinstance(data, dict) else {k: data.get(k) for k in ("format", "version")}
            raise checks.BadValue(f"not a training checkpoint of format {CHECKPOINT_FORMAT} version 1: {str(found)[:60]}")
        checks.typed_json(data, _STATE, "the checkpoint", optional=("base", "validation"), most=checks.MAX_SEED)
        try:
            config = TrainConfig.from_json(data["config"])
        except (EtmpcError, KeyError, TypeError, ValueError) as exc:
            raise checks.BadValue(f"config: {exc}") from None
        try:
            policy = LogisticPolicy.from_json(data["policy"], where="policy")  # each number, as rl: reads a policy's
        except PolicyFileError as exc:
            raise checks.BadValue(str(exc)) from None
        if data["policy"]["domain"] != config.domain or policy.levels != has_levels(config.domain):
            raise checks.BadValue(f"policy: not a policy of {config.domain}'s decisions")
        if not isinstance(data["policy"].get("hyperparameters", {}), dict):
            raise checks.BadValue("policy.hyperparameters must be an object")
        state = RunState(
            config,
            data["policy"],
            data["learners"],
            data["curve"],
            data["best"],
            data["training"],
            data.get("base"),
            data.get("validation", {}),
        )
        _check(state, policy.theta.size, policy.levels)
    except (checks.BadValue, KeyError, TypeError, ValueError) as exc:
        raise corrupt(where, exc, PolicyFileError) from None
    return state


def _check(state: RunState, p: int, levels: bool) -> None:
    """:func:`state_from_json`'s checks of the learners, the curve, the best points, the training episodes and the
    validation scores: ``p`` parameters per stage, two stages with compute ``levels``."""
    config, algorithm = state.config, state.config.algorithm
    milestones, seeds = config.milestones, [str(s) for s in config.seeds]
    if sorted(state.learners) != sorted(seeds) or sorted(state.best) != sorted(seeds):
        raise checks.BadValue(f"learners and best must hold one entry per seed of the run ({', '.join(seeds)})")
    steps = make_system(config.system).episode_steps if algorithm == "gpomdp" else 0
    for seed in seeds:
        name, learner = f"learners.{seed}", state.learners[seed]
        checks.typed_json(
            learner,
            _LEARNER[algorithm],
            name,
            optional=("theta_level", "history", "advantage_count", "advantage_square_sum"),
            most=checks.MAX_SEED,
        )
        _parameters(learner, name, p, levels)
        if learner["episodes"] not in milestones:
            raise checks.BadValue(f"{name}.episodes is {learner['episodes']}, not one of the run's milestones")
        if algorithm == "gpomdp":
            numbers(learner["baseline_mean"], f"{name}.baseline_mean", (steps,))
            numbers(learner["value_gram"], f"{name}.value_gram", (p, p))
            numbers(learner["value_target"], f"{name}.value_target", (p,))
            if learner["settings"] != asdict(config.gpomdp):
                raise checks.BadValue(f"{name}.settings are not the run's ({asdict(config.gpomdp)})")
            continue
        iterations, history = milestones.index(learner["episodes"]), learner.get("history", [])
        if learner["iterations"] != iterations or ("history" in learner and len(history) != iterations):
            raise checks.BadValue(f"{name} must have made {iterations} iterations at {learner['episodes']} episodes")
        _labels(learner["data"], f"{name}.data", p, levels)
        for i, entry in enumerate(history):
            checks.typed_json(entry, _POINT, f"{name}.history[{i}]", optional=("theta_level",), most=checks.MAX_SEED)
            _parameters(entry, f"{name}.history[{i}]", p, levels)
            if entry["episodes"] != milestones[i + 1]:
                raise checks.BadValue(f"{name}.history[{i}].episodes must be {milestones[i + 1]}")
    done = state.done
    evaluated = [(m, int(s)) for m in milestones if m <= done for s in seeds]
    for i, row in enumerate(state.curve):
        checks.typed_json(row, _CURVE_ROW, f"curve[{i}]", most=checks.MAX_SEED)
    if [(row["episodes"], row["seed"]) for row in state.curve] != evaluated:
        raise checks.BadValue("curve must hold a point per seed at each milestone so far")
    for seed in seeds:
        best = checks.typed_json(state.best[seed], _BEST, f"best.{seed}", optional=("theta_level",))
        _parameters(best, f"best.{seed}", p, levels)
        if best["episodes"] not in milestones or best["episodes"] > done:
            raise checks.BadValue(f"best.{seed}.episodes is {best['episodes']}, not a milestone so far")
    for i, row in enumerate(state.training):
        checks.typed_json(row, _EPISODE[algorithm], f"training[{i}]", most=checks.MAX_SEED)
    if sorted((row["seed"], row["episode"]) for row in state.training) != sorted((int(s), e) for s in seeds for e in range(done)):
        raise checks.BadValue("training must hold an entry per seed and episode so far")
    if (state.base is None) != (algorithm == "gpomdp") or (state.base is not None and state.base not in config.dpi.bases):
        raise checks.BadValue(f"base is {state.base!r}, not one of the run's first schedules")
    if state.validation and sorted(state.validation) != sorted(candidates(state)):
        raise checks.BadValue("validation must score each of the run's candidates")


def _parameters(entry: dict, name: str, p: int, levels: bool) -> None:
    """A learner's, a best point's or a kept policy's ``theta`` (and ``theta_level`` with compute levels): ``p`` numbers."""
    numbers(entry["theta"], f"{name}.theta", (p,))
    if levels != ("theta_level" in entry):
        raise checks.BadValue(f"{name}.theta_level must be there {'with' if levels else 'only with'} compute levels")
    if levels:
        numbers(entry["theta_level"], f"{name}.theta_level", (p,))


def _labels(rows: list, name: str, p: int, levels: bool) -> None:
    """DPI's labels (:func:`etmpc.learning.dpi.label_episode`'s rows): ``[phi, q_keep, q_recompute, step]``, and
    ``q_iterate`` last with compute levels; ``phi`` ``p`` numbers. Checked all at once (a run holds many), and,
    where that fails, one by one to name the one at fault."""
    fields = "[phi, q_keep, q_solve, step, q_iterate]" if levels else "[phi, q_keep, q_recompute, step]"
    width = 5 if levels else 4
    for i, row in enumerate(rows):
        if type(row) is not list or len(row) != width or type(row[3]) is not int or row[3] < 0:
            raise checks.BadValue(f"{name}[{i}] must be a label {fields} (step a whole number >= 0), got {str(row)[:40]}")
    try:
        numbers([row[0] for row in rows], name, (len(rows), p))
        numbers([[row[j] for j in (1, 2, 4)[: width - 2]] for row in rows], name)
    except checks.BadValue:
        for i, row in enumerate(rows):  # the one at fault, by its place
            numbers(row[0], f"{name}[{i}][0]", (p,))
            for j in (1, 2, 4)[: width - 2]:
                number(row[j], f"{name}[{i}][{j}]")
        raise


def policy_at(state: RunState, theta, theta_level=None) -> dict:
    """The run's policy at parameters ``theta`` (and, on a task with compute levels, ``theta_level``)."""
    if theta_level is None:
        return dict(state.policy, theta=list(theta))
    return dict(state.policy, theta=list(theta), theta_level=list(theta_level))


def policy_of(state: RunState, params: dict) -> dict:
    """The run's policy at a learner's or a best point's parameters (``params``: their JSON)."""
    return policy_at(state, params["theta"], params.get("theta_level"))


def candidates(state: RunState) -> dict[str, dict]:
    """The policies validation chooses among, by name: each seed's final policy (``"SEED"``), or, where a
    learner kept every iteration's (DPI), each of them (``"SEED@EPISODES"``)."""
    found = {}
    for seed in state.config.seeds:
        learner = state.learners[str(seed)]
        if learner.get("history"):
            found.update({f"{seed}@{entry['episodes']}": policy_of(state, entry) for entry in learner["history"]})
        else:
            found[str(seed)] = policy_of(state, learner)
    return found


def candidate(state: RunState, name: str) -> tuple[int, int, dict]:
    """``(seed, episodes, parameters)`` of a candidate named as :func:`candidates` names it."""
    seed, _, episodes = name.partition("@")
    learner = state.learners[seed]
    if not episodes:
        return int(seed), state.done, learner
    entry = next(entry for entry in learner["history"] if entry["episodes"] == int(episodes))
    return int(seed), int(episodes), entry


def save(out: Path, state: RunState, curve_png: Callable[[Path, dict, int], None] | None = None) -> dict:
    """Policies and curve first (``curve_png`` draws ``curve.png``: :func:`etmpc.views.curves.write_curve_png`),
    the checkpoint last: the checkpoint never points past the files. Returns the curve's summary."""
    for seed in state.config.seeds:
        key = str(seed)
        hyper = dict(state.policy["hyperparameters"], seed=seed)
        write_json_atomically(
            out / f"seed{seed}" / "last.json",
            dict(policy_of(state, state.learners[key]), hyperparameters=dict(hyper, episodes=state.done)),
        )
        best = state.best[key]
        write_json_atomically(
            out / f"seed{seed}" / "best.json",
            dict(policy_of(state, best), hyperparameters=dict(hyper, episodes=best["episodes"])),
        )
    if state.validation:
        sense = state.objective_sense

        def chosen(names: list[str]) -> dict:  # the best of names on validation, with what chose it
            pick = best_of(names, sense, key=state.validation.get)
            seed, episodes, params = candidate(state, pick)
            hyper = dict(
                state.policy["hyperparameters"],
                seed=seed,
                episodes=episodes,
                validation_objective=state.validation[pick],
                validation_episodes=state.config.validation_episodes,
            )
            return dict(policy_of(state, params), hyperparameters=hyper)

        for seed in state.config.seeds:  # each seed's own choice: a learner is a distribution of runs
            own = [name for name in state.validation if name.partition("@")[0] == str(seed)]
            write_json_atomically(out / f"seed{seed}" / "selected.json", chosen(own))
        write_json_atomically(out / "selected.json", chosen(list(state.validation)))
    summary = curve_summary(state)
    write_json_atomically(out / "curve.json", summary)
    if curve_png is not None:
        curve_png(out / "curve.png", summary, len(state.config.seeds))
    write_json_atomically(out / "checkpoint.json", state.to_json())
    return summary


def curve_summary(state: RunState) -> dict:
    rows: dict[int, list[dict]] = {}
    for row in state.curve:
        rows.setdefault(row["episodes"], []).append(row)
    points = []
    for episodes, group in sorted(rows.items()):
        values = np.array([r["objective"] for r in group])
        points.append(
            {
                "episodes": episodes,
                "objective_mean": float(values.mean()),
                "objective_std": float(values.std(ddof=1)) if len(values) > 1 else 0.0,
                "recomputes_mean": float(np.mean([r["recomputes"] for r in group])),
                "seeds": len(group),
            }
        )
    return {
        "domain": state.config.domain,
        "objective_sense": state.objective_sense,
        "algorithm": state.config.algorithm,
        "features": state.config.features,
        "points": points,
        "per_seed": state.curve,
    }


_OUTPUTS = {"checkpoint.json", "curve.json", "curve.png", "selected.json", "recordings"}


def ours(name: str) -> bool:
    """What a training run writes in its directory."""
    return name in _OUTPUTS or re.fullmatch(r"seed\d+", name) is not None
