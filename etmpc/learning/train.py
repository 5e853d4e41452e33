"""``etmpc train``: training of the logistic recomputation policy over several seeds.

Two learners (``--algorithm``): ``gpomdp``, the paper's policy gradient (:mod:`etmpc.learning.gpomdp`), and
``dpi``, direct policy iteration with rollout-labelled classification (:mod:`etmpc.learning.dpi`); and two
feature sets (``--features``, :mod:`etmpc.policies.learned`): ``error`` (the default) and ``paper``.

The run advances in *phases* of ``eval_every`` training episodes. In each phase every seed trains
its block of episodes (seeds run in parallel), then every seed's policy is evaluated on the test
set (its episodes run in parallel), then a checkpoint is written atomically. A killed run resumed
with ``--resume`` restarts from the last checkpoint and ends bit for bit where an uninterrupted run
would, because every random draw is keyed by ``(seed, episode)`` and never by history:

* training episode ``e`` of seed ``s``: the environment's episode from ``SeedSequence(TRAIN_ENTROPY,
  spawn_key=(s, e, 0))``, the policy's draws from ``spawn_key=(s, e, 1)``;
* evaluation: the stored test set, and the policy's draws from ``SeedSequence(0, spawn_key=(repeat,
  episode))``, exactly as ``etmpc evaluate --seed 0`` draws them, so ``etmpc evaluate --policy
  rl:DIR/seed0/best.json`` reproduces a point of the curve;
* the feature normalisation: measured once per run on ``normalisation_episodes`` episodes under a
  policy that recomputes with probability 1/2 (so plan ages vary), from ``NORMALISATION_ENTROPY``;
* DPI: training episode ``e`` of seed ``s`` and its rollouts from ``SeedSequence(DPI_ENTROPY,
  spawn_key=(s, e, k))``; its iteration-0 schedule is chosen on episodes from ``SELECTION_ENTROPY``;
* the choice of the run's policy (``selected.json``): every seed's final policy on
  ``validation_episodes`` training-distribution episodes from ``VALIDATION_ENTROPY`` (never the
  test set), the best one.

Outputs in ``DIR``: ``checkpoint.json``, ``curve.json`` and ``curve.png`` (mean and standard
deviation over seeds, the paper's Figure 2), ``seed<S>/last.json`` and ``seed<S>/best.json`` (the
best point of the test-set curve: a look back, not a model choice), ``selected.json`` (the final
policy of the seed that did best on the validation episodes: the run's answer); with
``--record N``, ``recordings/eval_<episodes>.rrd``: the first N test-set episodes of every seed's
evaluation, as Rerun recordings (see ``etmpc.views.recording``).
"""

from __future__ import annotations

import json
import re
import sys
import time
from dataclasses import asdict, dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np

from etmpc.learning import dpi
from etmpc.common.errors import EtmpcError
from etmpc.evaluation.evaluate import scores
from etmpc.learning.gpomdp import Learner, Settings
from etmpc.policies.learned import (DEFAULT_FEATURES, LogisticPolicy, Normalisation, PolicyFileError, check_features, raw_features,
                           write_json_atomically)
from etmpc.loop import run_episode
from etmpc.common.outputs import refuse_foreign
from etmpc.policies import parse_policy
from etmpc.views.record import EpisodeRecord
from etmpc.views.recording import Recorder
from etmpc.systems import make_system, system_key
from etmpc.evaluation.workers import context, make_backend, play_test_episode

TRAIN_ENTROPY = 0x6574_6D70_6321  # "etmpc!"
NORMALISATION_ENTROPY = 0x6E6F_726D  # "norm"
SELECTION_ENTROPY = 0x7365_6C65_6374  # "select"
VALIDATION_ENTROPY = 0x7661_6C69_64  # "valid"
ALGORITHMS = ("gpomdp", "dpi")
CHECKPOINT_FORMAT = "etmpc-train-checkpoint"


@dataclass(frozen=True)
class TrainConfig:
    """One training run. Everything here must match when a run is resumed."""

    domain: str
    seeds: tuple[int, ...] = (0, 1, 2, 3, 4)
    episodes: int = 1500  # training episodes per seed
    eval_every: int = 150  # evaluate on the test set after every this many episodes (and at 0)
    eval_episodes: int | None = None  # first N test-set episodes (None: all)
    eval_repeats: int = 1  # passes over the test set per evaluation
    normalisation_episodes: int = 20
    gpomdp: Settings = field(default_factory=Settings)
    features: str = DEFAULT_FEATURES  # the policy's feature set (etmpc.policies.learned.FEATURE_SETS)
    algorithm: str = "gpomdp"  # "gpomdp" or "dpi"
    dpi: dpi.Settings = field(default_factory=dpi.Settings)  # used when algorithm == "dpi"
    validation_episodes: int = 50  # training-distribution episodes that choose selected.json
    recompute_price: float | None = None  # the price of a computation to train for (None: the system's)

    def __post_init__(self):
        if not self.seeds or len(set(self.seeds)) != len(self.seeds):
            raise EtmpcError(f"seeds must be distinct and at least one, got {self.seeds}")
        for name in ("episodes", "eval_every", "eval_repeats", "normalisation_episodes", "validation_episodes"):
            if getattr(self, name) < 1:
                raise EtmpcError(f"{name.replace('_', '-')} must be >= 1, got {getattr(self, name)}")
        check_features(self.features)
        if self.algorithm not in ALGORITHMS:
            raise EtmpcError(f"unknown algorithm {self.algorithm!r}; valid: {', '.join(ALGORITHMS)}")
        system_key(self.domain, self.recompute_price)  # a bad price fails here

    @property
    def system(self) -> str:
        """The key workers build the system by: the domain, at ``recompute_price`` if one is set."""
        return system_key(self.domain, self.recompute_price)

    def to_json(self) -> dict:
        data = asdict(self)
        data["seeds"] = list(self.seeds)
        data["dpi"]["bases"] = list(self.dpi.bases)
        return data

    @classmethod
    def from_json(cls, data: dict) -> TrainConfig:
        data = dict(data)
        data["seeds"] = tuple(data["seeds"])
        data["gpomdp"] = Settings(**data["gpomdp"])
        data.setdefault("features", "paper")  # checkpoints from before feature sets
        data.setdefault("recompute_price", None)  # checkpoints from before prices
        dpi_settings = dict(data.get("dpi", {}))
        if "bases" in dpi_settings:
            dpi_settings["bases"] = tuple(dpi_settings["bases"])
        data["dpi"] = dpi.Settings(**dpi_settings)
        return cls(**data)

    @property
    def milestones(self) -> list[int]:
        """Episode counts at which the policy is evaluated: 0, eval_every, ..., episodes."""
        points = list(range(0, self.episodes, self.eval_every)) + [self.episodes]
        return sorted(set(points))


# -- worker side: every function here is a pure function of its arguments -------------------------
class _Coin:
    """Recompute with probability 1/2, keeping every raw feature vector it sees (for normalisation)."""

    spec, stochastic = "coin", True

    def __init__(self, features: str, domain: str):
        self.features, self.domain = features, domain
        self.states = []

    def decide(self, s, rng):
        self.states.append(raw_features(self.features, self.domain, s))
        return bool(rng.random() < 0.5)


def normalisation_states(domain: str, index: int, features: str = "paper") -> np.ndarray:
    system, env, _ = context(domain)
    rng = np.random.default_rng(np.random.SeedSequence(NORMALISATION_ENTROPY, spawn_key=(index, 0)))
    coin = _Coin(features, system.domain)
    run_episode(system, env, coin, np.random.default_rng(np.random.SeedSequence(NORMALISATION_ENTROPY, spawn_key=(index, 1))),
                system.draw_episode(rng))
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
    return Sample(np.array([d[0] for d in acting.decisions]).reshape(len(steps), -1),
                  np.array([d[1] for d in acting.decisions], dtype=bool), np.array([d[2] for d in acting.decisions]),
                  steps, traj.policy_rewards(system.recompute_price), traj.recomputes)


def evaluate_theta(domain: str, sha256: str, policy_json: dict, repeat: int, episode: int,
                   identity: dict | None = None) -> tuple[float, float, int, EpisodeRecord | None]:
    """(objective, control objective, recomputes, record) of one episode of the stored test set (whose
    digest must be ``sha256``), sense-aware as in evaluate. With ``identity``, ``record`` is what a
    recording keeps of the episode (else None)."""
    context(domain, None, sha256)  # the worker's test set is checked before the policy is read
    played = play_test_episode(domain, LogisticPolicy.from_json(policy_json), 0, repeat, episode, None, sha256)
    record = played.record(**identity) if identity is not None else None
    return (*scores(played.system, played.trajectory), played.trajectory.recomputes, record)


def label_episode(domain: str, base, settings: dpi.Settings, policy_json: dict, seed: int, e: int) -> list:
    """DPI's training episode ``e`` of ``seed`` under ``base`` (a fixed spec or a policy's JSON):
    ``[(phi, q_keep, q_recompute, step), ...]`` at its picked decisions."""
    system, env, _ = context(domain)
    base = _policy(system, base)
    featurise = LogisticPolicy.from_json(policy_json).phi
    episode_rng, pick_rng, future_rng, policy_rng = dpi.episode_rngs(seed, e)
    picked = set(pick_rng.choice(system.episode_steps, size=min(settings.states_per_episode, system.episode_steps),
                                 replace=False).tolist())
    labeller = dpi.Labeller(base, featurise, picked, settings, future_rng)
    run_episode(system, env, labeller, policy_rng, system.draw_episode(episode_rng))
    return [(phi.tolist(), keep, recompute, step) for phi, keep, recompute, step in labeller.rows]


def training_return(domain: str, policy, entropy: int, index: int) -> float:
    """The policy's objective (sense-aware) on training-distribution episode ``index`` of ``entropy``'s
    stream (``policy``: a spec or a policy's JSON): how models are chosen without the test set."""
    system, env, _ = context(domain)
    policy = _policy(system, policy)
    episode = system.draw_episode(np.random.default_rng(np.random.SeedSequence(entropy, spawn_key=(index, 0))))
    traj = run_episode(system, env, policy, np.random.default_rng(np.random.SeedSequence(entropy, spawn_key=(index, 1))), episode)
    return scores(system, traj)[0]


def _policy(system, policy):
    """A policy from its spec (a fixed policy) or its JSON (a logistic policy being trained, or a
    self-trigger being chosen)."""
    if isinstance(policy, str):
        return parse_policy(policy, system.error_weights, system.domain)
    from etmpc.policies import selftrigger

    if policy.get("format") == selftrigger.FORMAT:
        return selftrigger.from_json(policy, "candidate", system.domain)
    return LogisticPolicy.from_json(policy)


def _call(job):
    name, args = job
    return {"normalisation": normalisation_states, "train": train_block, "evaluate": evaluate_theta, "label": label_episode,
            "score": training_return}[name](*args)


def _learner_to_json(learner: Learner) -> dict:
    return {"theta": learner.theta.tolist(), "baseline_mean": learner.baseline_mean.tolist(), "episodes": learner.episodes,
            "settings": asdict(learner.settings), "value_gram": learner.value_gram.tolist(),
            "value_target": learner.value_target.tolist()}


def _learner_from_json(data: dict) -> Learner:
    return Learner(np.asarray(data["theta"], float), Settings(**data["settings"]), np.asarray(data["baseline_mean"], float),
                   int(data["episodes"]), np.asarray(data["value_gram"], float), np.asarray(data["value_target"], float))


# -- driver side -----------------------------------------------------------------------------------
@dataclass
class RunState:
    """What ``checkpoint.json`` holds."""

    config: TrainConfig
    policy: dict  # the initial policy's JSON: normalisation, domain, hyperparameters
    learners: dict  # seed (str) -> learner JSON
    curve: list = field(default_factory=list)  # rows: {"episodes", "seed", "objective", "control", "recomputes"}
    best: dict = field(default_factory=dict)  # seed (str) -> {"episodes", "objective", "theta"}
    training: list = field(default_factory=list)  # per-episode stats, all seeds
    base: str | None = None  # DPI: the fixed schedule iteration 0 rolls out over (chosen on training episodes)
    validation: dict = field(default_factory=dict)  # seed (str) -> final policy's objective on the validation episodes

    @cached_property
    def objective_sense(self) -> str:
        return make_system(self.config.system).objective_sense

    @property
    def done(self) -> int:
        return min(int(data["episodes"]) for data in self.learners.values())

    def to_json(self) -> dict:
        return {"format": CHECKPOINT_FORMAT, "version": 1, "config": self.config.to_json(), "policy": self.policy,
                "learners": self.learners, "curve": self.curve, "best": self.best, "training": self.training,
                "base": self.base, "validation": self.validation}


def load_checkpoint(path: Path) -> RunState:
    try:
        data = json.loads(path.read_text())
        if data.get("format") != CHECKPOINT_FORMAT or data.get("version") != 1:
            raise ValueError(f"format {data.get('format')!r} version {data.get('version')!r}")
        config = TrainConfig.from_json(data["config"])
        LogisticPolicy.from_json(data["policy"], where=f"checkpoint {path}")
        state = RunState(config, data["policy"], data["learners"], data["curve"], data["best"], data["training"],
                         data.get("base"), data.get("validation", {}))
        if sorted(state.learners) != sorted(str(s) for s in config.seeds):
            raise ValueError("learners do not match the seeds")
        for learner in state.learners.values():
            if len(learner["theta"]) != len(data["policy"]["theta"]):
                raise ValueError("feature size differs between learners and policy")
    except (OSError, UnicodeDecodeError, ValueError, KeyError, TypeError) as exc:
        raise PolicyFileError(f"checkpoint {path} is corrupt or unreadable ({exc}); move it away to start afresh") from None
    return state


def _policy_at(state: RunState, theta) -> dict:
    return dict(state.policy, theta=list(theta))


def _evaluate_phase(state: RunState, backend, progress, testset: tuple[int, str], out: Path, record_episodes: int) -> None:
    """Evaluate every seed's policy; with ``record_episodes``, also write the first that many test-set
    episodes of each seed into ``out/recordings/eval_<episodes>.rrd``."""
    config, done = state.config, state.done
    testset_n, sha256 = testset

    def identity(seed: int, e: int) -> dict | None:
        if e >= record_episodes:
            return None
        return {"policy": f"seed{seed}/episodes{done:05d}", "training_seed": seed, "training_episodes": done}

    jobs = [("evaluate", (config.system, sha256, _policy_at(state, state.learners[str(s)]["theta"]), r, e, identity(s, e)))
            for s in config.seeds for r in range(config.eval_repeats) for e in range(testset_n)]
    results = backend.map(_call, jobs, progress)
    records = [c[3] for c in results if c[3] is not None]
    if records:
        with Recorder(out / "recordings" / f"eval_{done:05d}.rrd") as recorder:
            for record in records:
                recorder.log_episode(record)
    per_seed = config.eval_repeats * testset_n
    sense = state.objective_sense
    for i, seed in enumerate(config.seeds):
        chunk = results[i * per_seed:(i + 1) * per_seed]
        row = {"episodes": done, "seed": seed, "objective": float(np.mean([c[0] for c in chunk])),
               "control": float(np.mean([c[1] for c in chunk])), "recomputes": float(np.mean([c[2] for c in chunk]))}
        state.curve.append(row)
        best = state.best.get(str(seed))
        better = best is None or (row["objective"] > best["objective"] if sense == "max" else row["objective"] < best["objective"])
        if better:
            state.best[str(seed)] = {"episodes": done, "objective": row["objective"], "theta": state.learners[str(seed)]["theta"]}


def _eval_episodes(config: TrainConfig) -> tuple[int, str]:
    """How many test-set episodes each evaluation plays, and the test set's digest (loads and checks
    the test set)."""
    _, _, testset = context(config.domain)
    n = testset.episodes if config.eval_episodes is None else config.eval_episodes
    if not 1 <= n <= testset.episodes:
        raise EtmpcError(f"eval episodes must be in 1..{testset.episodes}, got {n}")
    return n, testset.sha256


def _save(out: Path, state: RunState) -> dict:
    """Policies and curve first, the checkpoint last: the checkpoint never points past the files.
    Returns the curve's summary."""
    for seed in state.config.seeds:
        key = str(seed)
        hyper = dict(state.policy["hyperparameters"], seed=seed)
        write_json_atomically(out / f"seed{seed}" / "last.json",
                              dict(_policy_at(state, state.learners[key]["theta"]), hyperparameters=dict(hyper, episodes=state.done)))
        best = state.best[key]
        write_json_atomically(out / f"seed{seed}" / "best.json",
                              dict(_policy_at(state, best["theta"]), hyperparameters=dict(hyper, episodes=best["episodes"])))
    if state.validation:
        sense = state.objective_sense
        pick = (max if sense == "max" else min)(state.config.seeds, key=lambda seed: state.validation[str(seed)])
        hyper = dict(state.policy["hyperparameters"], seed=pick, episodes=state.done,
                     validation_objective=state.validation[str(pick)], validation_episodes=state.config.validation_episodes)
        write_json_atomically(out / "selected.json", dict(_policy_at(state, state.learners[str(pick)]["theta"]), hyperparameters=hyper))
    summary = curve_summary(state)
    write_json_atomically(out / "curve.json", summary)
    write_curve_png(out / "curve.png", summary, len(state.config.seeds))
    write_json_atomically(out / "checkpoint.json", state.to_json())
    return summary


def curve_summary(state: RunState) -> dict:
    rows = {}
    for row in state.curve:
        rows.setdefault(row["episodes"], []).append(row)
    points = []
    for episodes, group in sorted(rows.items()):
        values = np.array([r["objective"] for r in group])
        points.append({"episodes": episodes, "objective_mean": float(values.mean()),
                       "objective_std": float(values.std(ddof=1)) if len(values) > 1 else 0.0,
                       "recomputes_mean": float(np.mean([r["recomputes"] for r in group])), "seeds": len(group)})
    return {"domain": state.config.domain, "objective_sense": state.objective_sense, "algorithm": state.config.algorithm,
            "features": state.config.features, "points": points, "per_seed": state.curve}


def write_curve_png(path: Path, summary: dict, seeds: int) -> None:
    from etmpc.views.figures import save_png_atomically  # first: it selects the Agg backend

    import matplotlib.pyplot as plt

    x = np.array([p["episodes"] for p in summary["points"]])
    mean = np.array([p["objective_mean"] for p in summary["points"]])
    std = np.array([p["objective_std"] for p in summary["points"]])
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.plot(x, mean, marker="o", label=f"mean over {seeds} seeds")
    ax.fill_between(x, mean - std, mean + std, alpha=0.25, label="± 1 std")
    ax.set_xlabel("training episodes")
    ax.set_ylabel(f"test-set objective ({'higher' if summary['objective_sense'] == 'max' else 'lower'} is better)")
    learner = {"gpomdp": "GPOMDP", "dpi": "DPI"}.get(summary.get("algorithm", "gpomdp"), summary.get("algorithm"))
    ax.set_title(f"{summary['domain']}: {learner} learning curve ({summary.get('features', 'paper')} features)")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    save_png_atomically(fig, path, dpi=110)


_OUTPUTS = {"checkpoint.json", "curve.json", "curve.png", "selected.json", "recordings"}


def _ours(name: str) -> bool:
    """What a training run writes in its directory."""
    return name in _OUTPUTS or re.fullmatch(r"seed\d+", name) is not None


def train(config: TrainConfig, out: Path, workers: int = 1, resume: bool = False, backend: str = "local",
          address: str | None = None, progress: bool = True, record_episodes: int = 0) -> RunState:
    """Train ``config`` into ``out`` (see the module docstring). With ``record_episodes``, each
    evaluation also writes that many test-set episodes per seed into a Rerun recording,
    ``out/recordings/eval_<episodes>.rrd`` (not part of the config: it changes no result)."""
    out = Path(out)
    if record_episodes < 0:
        raise EtmpcError(f"record episodes must be >= 0, got {record_episodes}")
    checkpoint = out / "checkpoint.json"
    refuse_foreign(out, _ours, "training run")
    if checkpoint.exists():
        if not resume:
            raise EtmpcError(f"{out} already holds a training run; pass --resume to continue it, or choose another --out")
        state = load_checkpoint(checkpoint)
        if state.config != config:
            raise EtmpcError(f"{checkpoint} was made with different settings ({_difference(state.config, config)}); "
                             "resume with the same ones, or choose another --out")
    else:
        state = None
    testset = _eval_episodes(config)  # fails on a bad test set or size before any work
    testset_n = testset[0]
    total = len(config.seeds) * (config.episodes + len(config.milestones) * config.eval_repeats * testset_n
                                 + config.validation_episodes)
    started = time.perf_counter()
    with make_backend(backend, workers, address) as pool, _Progress(total, f"train {config.domain}", progress) as bar:
        tick = lambda job: bar.update(job[1][5] - job[1][4] if job[0] == "train" else 1 if job[0] != "score" else 0)  # noqa: E731
        if state is None:
            states = pool.map(_call, [("normalisation", (config.system, i, config.features)) for i in range(config.normalisation_episodes)])
            normalisation = Normalisation.fit(np.concatenate(states))
            hyper = {"algorithm": config.algorithm, "features": config.features,
                     "normalisation_episodes": config.normalisation_episodes}
            if config.recompute_price is not None:  # trained for another price than the system's own
                hyper["recompute_price"] = config.recompute_price
            if config.algorithm == "gpomdp":
                hyper.update(discount=config.gpomdp.discount, learning_rate=config.gpomdp.learning_rate, baseline=config.gpomdp.baseline)
            else:
                hyper.update(asdict(config.dpi), bases=list(config.dpi.bases))
            initial = LogisticPolicy.initial(normalisation, config.domain, hyper, config.features, greedy=config.algorithm == "dpi")
            if config.algorithm == "gpomdp":
                learner = _learner_to_json(Learner.start(initial.theta, config.gpomdp, context(config.system)[0].episode_steps))
                base = None
            else:
                learner = {"theta": initial.theta.tolist(), "episodes": 0, "iterations": 0, "data": []}
                base = _choose_base(config, pool)
            # One learner per seed, sharing nothing (a DPI learner's labels grow in place).
            state = RunState(config, initial.to_json(), {str(s): json.loads(json.dumps(learner)) for s in config.seeds}, base=base)
            _evaluate_phase(state, pool, tick, testset, out, record_episodes)
            _save(out, state)
            resumed_from = 0
        else:
            bar.update(len(config.seeds) * (state.done + sum(1 for m in config.milestones if m <= state.done) * config.eval_repeats * testset_n))
            resumed_from = bar.n
        for start, stop in zip(config.milestones, config.milestones[1:]):
            if stop <= state.done:
                continue
            if config.algorithm == "gpomdp":
                jobs = [("train", (config.system, state.policy, state.learners[str(s)], s, start, stop)) for s in config.seeds]
                for seed, (learner, stats) in zip(config.seeds, pool.map(_call, jobs, tick)):
                    state.learners[str(seed)] = learner
                    state.training += [dict(s, seed=seed) for s in stats]
            else:
                _dpi_iteration(state, pool, tick, start, stop)
            _evaluate_phase(state, pool, tick, testset, out, record_episodes)
            summary = _save(out, state)
            _report(state, summary["points"][-1], started, bar, resumed_from)
        if not state.validation:
            policies = [_policy_at(state, state.learners[str(s)]["theta"]) for s in config.seeds]
            means = _mean_scores(pool, config.system, policies, VALIDATION_ENTROPY, config.validation_episodes,
                                 lambda job: bar.update(1))
            state.validation = {str(s): mean for s, mean in zip(config.seeds, means)}
            _save(out, state)
    return state


def _mean_scores(pool, domain: str, policies: list, entropy: int, episodes: int, on_result=None) -> list[float]:
    """Each policy's mean objective on the first ``episodes`` episodes of ``entropy``'s stream."""
    jobs = [("score", (domain, policy, entropy, i)) for policy in policies for i in range(episodes)]
    values = pool.map(_call, jobs, on_result)
    return [float(np.mean(values[k * episodes:(k + 1) * episodes])) for k in range(len(policies))]


def _choose_base(config: TrainConfig, pool) -> str:
    """DPI's iteration-0 schedule: the best of ``config.dpi.bases`` on training-distribution episodes."""
    means = _mean_scores(pool, config.system, list(config.dpi.bases), SELECTION_ENTROPY, config.dpi.selection_episodes)
    pick = int(np.argmax(means) if make_system(config.system).objective_sense == "max" else np.argmin(means))
    return config.dpi.bases[pick]


def _dpi_iteration(state: RunState, pool, tick, start: int, stop: int) -> None:
    """One DPI iteration per seed: label episodes ``start..stop-1`` by rollouts over the current
    policy (over the chosen schedule at iteration 0), then refit ``theta`` on every label so far."""
    config = state.config
    def base(seed):
        learner = state.learners[str(seed)]
        return state.base if learner["iterations"] == 0 else _policy_at(state, learner["theta"])
    jobs = [("label", (config.system, base(s), config.dpi, state.policy, s, e)) for s in config.seeds for e in range(start, stop)]
    results = pool.map(_call, jobs, tick)
    per_seed = stop - start
    for k, seed in enumerate(config.seeds):
        learner = state.learners[str(seed)]
        for rows in results[k * per_seed:(k + 1) * per_seed]:
            learner["data"] += [list(row) for row in rows]
        phi = np.array([row[0] for row in learner["data"]])
        advantage = np.array([row[1] - row[2] for row in learner["data"]])
        learner["theta"] = dpi.fit(phi, advantage, config.dpi.ridge).tolist()
        learner["iterations"] += 1
        learner["episodes"] = stop
        state.training += [{"episode": e, "seed": seed, "labels": len(rows)}
                           for e, rows in zip(range(start, stop), results[k * per_seed:(k + 1) * per_seed])]


class _Progress:
    """A tqdm bar (on a terminal) with its own count, so the ETA line works when the bar is off."""

    def __init__(self, total: int, desc: str, enabled: bool):
        from tqdm import tqdm

        self.n, self.total = 0, total
        self._bar = tqdm(total=total, unit="ep", desc=desc, disable=None if enabled else True)
        self._quiet = not enabled

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self._bar.close()

    def update(self, n: int) -> None:
        self.n += n
        self._bar.update(n)

    def write(self, line: str) -> None:
        if not self._quiet:
            self._bar.write(line, file=sys.stderr)


def _report(state: RunState, point: dict, started: float, bar, resumed_from: int) -> None:
    """One line per phase on stderr, for logs where the progress bar is off."""
    elapsed = time.perf_counter() - started
    done_here, left = bar.n - resumed_from, bar.total - bar.n
    eta = elapsed * left / done_here if done_here > 0 else float("nan")
    bar.write(f"{state.config.domain}: {state.done}/{state.config.episodes} episodes per seed, test objective "
              f"{point['objective_mean']:.5f} ± {point['objective_std']:.5f}, {point['recomputes_mean']:.1f} recomputes; "
              f"elapsed {elapsed:.0f} s, ETA {eta:.0f} s")


def _difference(a: TrainConfig, b: TrainConfig) -> str:
    da, db = a.to_json(), b.to_json()
    return ", ".join(f"{k}: {da[k]} vs {db[k]}" for k in da if da[k] != db[k])


MAX_SEEDS = 1000


def parse_seeds(text: str) -> tuple[int, ...]:
    """``"0-4"`` -> (0, 1, 2, 3, 4); ``"1,3,7"``; ``"2"``."""
    seeds = []
    try:
        for part in text.split(","):
            lo, sep, hi = part.partition("-")
            lo, hi = int(lo), int(hi) if sep else int(lo)
            if hi - lo + 1 + len(seeds) > MAX_SEEDS:
                raise EtmpcError(f"bad --seeds {text!r}: at most {MAX_SEEDS} seeds")
            seeds += range(lo, hi + 1)
    except ValueError:
        raise EtmpcError(f"bad --seeds {text!r}: use a range like 0-4 or a list like 0,2,5") from None
    if not seeds or min(seeds) < 0 or len(set(seeds)) != len(seeds):
        raise EtmpcError(f"bad --seeds {text!r}: non-negative and distinct")
    return tuple(seeds)


def format_summary(state: RunState) -> str:
    summary = curve_summary(state)
    lines = [f"{state.config.domain}: objective ({'higher' if summary['objective_sense'] == 'max' else 'lower'} is better) on the test set",
             f"{'episodes':>9}{'mean':>12}{'std':>10}{'recomputes':>12}"]
    lines += [f"{p['episodes']:>9}{p['objective_mean']:>12.5f}{p['objective_std']:>10.5f}{p['recomputes_mean']:>12.2f}" for p in summary["points"]]
    return "\n".join(lines)

