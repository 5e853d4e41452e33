"""The worker side of a training run: every function here is a pure function of its arguments, so
a job gives the same result in any process, on any backend (see :mod:`etmpc.learning.train`). DPI's
labelling job is :func:`etmpc.learning.dpi.label_episode`, with the rest of DPI."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any, Callable

import numpy as np

from etmpc.evaluation.evaluate import scores
from etmpc.evaluation.workers import context, play_test_episode
from etmpc.learning.config import NORMALISATION_ENTROPY, TRAIN_ENTROPY
from etmpc.learning.gpomdp import Learner, Settings
from etmpc.loop import run_episode
from etmpc.policies import parse_policy, selftrigger
from etmpc.policies.features import raw_features
from etmpc.policies.learned import LogisticPolicy
from etmpc.systems import SystemKey
from etmpc.loop.records import EpisodeRecord


class _Coin:
    """Recompute with probability 1/2, keeping every raw feature vector it sees (for normalisation)."""

    spec, stochastic = "coin", True

    def __init__(self, features: str, domain: str):
        self.features, self.domain = features, domain
        self.states: list[np.ndarray] = []

    def decide(self, s, rng):
        self.states.append(raw_features(self.features, self.domain, s))
        return bool(rng.random() < 0.5)


def normalisation_states(domain: str, index: int, features: str = "paper") -> np.ndarray:
    system, env, _ = context(domain)
    rng = np.random.default_rng(np.random.SeedSequence(NORMALISATION_ENTROPY, spawn_key=(index, 0)))
    coin = _Coin(features, system.name)
    run_episode(
        system,
        env,
        coin,
        np.random.default_rng(np.random.SeedSequence(NORMALISATION_ENTROPY, spawn_key=(index, 1))),
        system.draw_episode(rng),
    )
    return np.array(coin.states)


def train_block(domain: str, policy_json: dict, learner_json: dict, seed: int, start: int, stop: int) -> tuple[dict, list]:
    """Train ``seed`` on its episodes ``start..stop-1``; returns the learner and per-episode stats."""
    system, env, _ = context(domain)
    policy = LogisticPolicy.from_json(policy_json)
    learner = _learner_from_json(learner_json)
    stats = []
    for e in range(start, stop):
        episode = system.draw_episode(np.random.default_rng(np.random.SeedSequence(TRAIN_ENTROPY, spawn_key=(seed, e, 0))))
        rng = np.random.default_rng(np.random.SeedSequence(TRAIN_ENTROPY, spawn_key=(seed, e, 1)))
        sample = play(system, env, policy.with_theta(learner.theta, record=True), rng, episode)
        learner.update(sample.features, sample.recompute, sample.keep_probability, sample.steps, sample.rewards)
        stats.append({"episode": e, "return": float(sample.rewards.sum()), "recomputes": sample.recomputes})
    return _learner_to_json(learner), stats


@dataclass(frozen=True)
class Sample:
    """What GPOMDP needs from one episode: the policy's decisions and the per-step rewards."""

    features: np.ndarray  # (d, p) phi(s) at each decision
    recompute: np.ndarray  # (d,) the action taken
    keep_probability: np.ndarray  # (d,)
    steps: np.ndarray  # (d,) step index of each decision
    rewards: np.ndarray  # (T,) the policy's rewards
    recomputes: int


def play(system, env, acting: LogisticPolicy, rng: np.random.Generator, episode) -> Sample:
    """One episode under ``acting`` (a recording policy), as GPOMDP sees it."""
    traj = run_episode(system, env, acting, rng, episode)
    steps = np.flatnonzero(~traj.forced[: traj.steps])
    if len(steps) != len(acting.decisions):
        raise RuntimeError("decisions and unforced steps disagree")  # a control-loop invariant
    return Sample(
        np.array([d[0] for d in acting.decisions]).reshape(len(steps), -1),
        np.array([d[1] for d in acting.decisions], dtype=bool),
        np.array([d[2] for d in acting.decisions]),
        steps,
        traj.policy_rewards(system.recompute_price),
        traj.recomputes,
    )


def evaluate_theta(
    domain: str, sha256: str, policy_json: dict, repeat: int, episode: int, identity: dict | None = None
) -> tuple[float, float, int, EpisodeRecord | None]:
    """(objective, control objective, recomputes, record) of one episode of the stored test set (whose
    digest must be ``sha256``), sense-aware as in evaluate. With ``identity``, ``record`` is what a
    recording keeps of the episode (else None)."""
    context(domain, None, sha256)  # the worker's test set is checked before the policy is read
    played = play_test_episode(domain, LogisticPolicy.from_json(policy_json), 0, repeat, episode, None, sha256)
    record = played.record(**identity) if identity is not None else None
    return (*scores(played.system, played.trajectory), played.trajectory.recomputes, record)


def training_return(domain: str, policy, entropy: int, index: int) -> float:
    """The policy's objective (sense-aware) on training-distribution episode ``index`` of ``entropy``'s
    stream (``policy``: a spec or a policy's JSON): how models are chosen without the test set."""
    return training_outcome(domain, policy, entropy, index)[0]


def training_outcome(domain: str, policy, entropy: int, index: int) -> tuple[float, float, float]:
    """:func:`training_return`'s episode: ``(objective, failures, recomputes)`` (failures NaN on a task that
    counts none)."""
    system, env, _ = context(domain)
    policy = _policy(system, policy)
    episode = system.draw_episode(np.random.default_rng(np.random.SeedSequence(entropy, spawn_key=(index, 0))))
    traj = run_episode(system, env, policy, np.random.default_rng(np.random.SeedSequence(entropy, spawn_key=(index, 1))), episode)
    failures = float(system.failures(traj, episode)) if system.failures is not None else float("nan")
    return scores(system, traj)[0], failures, float(traj.recomputes)


def _policy(system, policy):
    """A policy from its spec (a fixed policy) or its JSON (a logistic policy being trained, or a
    self-trigger being chosen)."""
    if isinstance(policy, str):
        return parse_policy(policy, system)
    if policy.get("format") == selftrigger.FORMAT:
        return selftrigger.from_json(policy, "candidate", system.name)
    return LogisticPolicy.from_json(policy)


def _call(job: tuple[str, tuple]):
    """``job``, ``(name, arguments)``, played: the worker function of that name on its arguments."""
    name, args = job
    functions: dict[str, Callable[..., Any]] = {
        "normalisation": normalisation_states,
        "train": train_block,
        "evaluate": evaluate_theta,
        "score": training_return,
        "outcome": training_outcome,
    }
    return functions[name](*args)


def _learner_to_json(learner: Learner) -> dict:
    assert learner.value_gram is not None and learner.value_target is not None  # made by Learner.__post_init__
    data = {
        "theta": learner.theta.tolist(),
        "baseline_mean": learner.baseline_mean.tolist(),
        "episodes": learner.episodes,
        "settings": asdict(learner.settings),
        "value_gram": learner.value_gram.tolist(),
        "value_target": learner.value_target.tolist(),
    }
    if learner.settings.scale != "none":  # the running RMS of the advantages (the paper's runs keep none: their bytes as before)
        data.update(advantage_count=learner.advantage_count, advantage_square_sum=learner.advantage_square_sum)
    return data


def _learner_from_json(data: dict) -> Learner:
    return Learner(
        np.asarray(data["theta"], float),
        Settings(**data["settings"]),
        np.asarray(data["baseline_mean"], float),
        int(data["episodes"]),
        np.asarray(data["value_gram"], float),
        np.asarray(data["value_target"], float),
        int(data.get("advantage_count", 0)),
        float(data.get("advantage_square_sum", 0.0)),
    )


def episode_scores(
    pool, domain: str | SystemKey, policies: list, entropy: int, episodes: int, on_result=None
) -> list[np.ndarray]:
    """Each policy's objective on each of the first ``episodes`` episodes of ``entropy``'s stream."""
    return _per_policy(pool, "score", domain, policies, entropy, episodes, on_result)


def episode_outcomes(
    pool, domain: str | SystemKey, policies: list, entropy: int, episodes: int, on_result=None
) -> list[np.ndarray]:
    """Each policy's ``(objective, failures, recomputes)`` rows on the first ``episodes`` episodes of ``entropy``'s stream."""
    return _per_policy(pool, "outcome", domain, policies, entropy, episodes, on_result)


def _per_policy(
    pool, job: str, domain: str | SystemKey, policies: list, entropy: int, episodes: int, on_result
) -> list[np.ndarray]:
    """Job ``job`` (``"score"``, ``"outcome"``) on each policy's first ``episodes`` episodes, an array per policy."""
    jobs = [(job, (domain, policy, entropy, i)) for policy in policies for i in range(episodes)]
    values = pool.map(_call, jobs, on_result)
    return [np.array(values[k * episodes : (k + 1) * episodes], dtype=float) for k in range(len(policies))]


def mean_scores(pool, domain: str | SystemKey, policies: list, entropy: int, episodes: int, on_result=None) -> list[float]:
    """Each policy's mean objective on the first ``episodes`` episodes of ``entropy``'s stream."""
    return [float(np.mean(values)) for values in episode_scores(pool, domain, policies, entropy, episodes, on_result)]
