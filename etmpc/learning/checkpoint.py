"""A training run's state on disk: ``checkpoint.json`` (:class:`RunState`), the policy files and the
learning curve, written so that the checkpoint never points past the files (see :func:`save`)."""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Callable

import numpy as np

from etmpc.common.documents import loads
from etmpc.common.sense import best as best_of
from etmpc.learning.config import CHECKPOINT_FORMAT, TrainConfig
from etmpc.policies.learned import LogisticPolicy, PolicyFileError, write_json_atomically
from etmpc.systems import make_system


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
        raise PolicyFileError(f"checkpoint {path} is corrupt or unreadable ({exc}); move it away to start afresh") from None
    return state_from_json(data, f"checkpoint {path}")


def state_from_json(data: dict, where: str = "checkpoint") -> RunState:
    """A :class:`RunState` from ``checkpoint.json``'s content, checked."""
    try:
        if data.get("format") != CHECKPOINT_FORMAT or data.get("version") != 1:
            raise ValueError(f"format {data.get('format')!r} version {data.get('version')!r}")
        config = TrainConfig.from_json(data["config"])
        LogisticPolicy.from_json(data["policy"], where=where)
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
        if sorted(state.learners) != sorted(str(s) for s in config.seeds):
            raise ValueError("learners do not match the seeds")
        levels = "theta_level" in data["policy"]
        history = [entry for learner in state.learners.values() for entry in learner.get("history", [])]
        for learner in (*state.learners.values(), *state.best.values(), *history):
            if len(learner["theta"]) != len(data["policy"]["theta"]):
                raise ValueError("feature size differs between learners and policy")
            if levels != ("theta_level" in learner) or (levels and len(learner["theta_level"]) != len(learner["theta"])):
                raise ValueError("the learners' and the policy's compute levels (theta_level) differ")
    except (AttributeError, ValueError, KeyError, TypeError) as exc:
        raise PolicyFileError(f"{where} is corrupt or unreadable ({exc}); move it away to start afresh") from None
    return state


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
    rows = {}
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
