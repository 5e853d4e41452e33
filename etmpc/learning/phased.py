"""GPOMDP and DPI as :class:`~etmpc.learning.base.Learner` s: the logistic recomputation policy trained
over several seeds in lockstep, in phases of ``eval_every`` episodes, each ended by a test-set
evaluation (the learning curve) and a checkpoint; resumed bit for bit (see :mod:`etmpc.learning.train`
for the streams and the outputs)."""

from __future__ import annotations

import json
from dataclasses import asdict
from abc import abstractmethod
from typing import ClassVar

import numpy as np

from etmpc.common.errors import EtmpcError
from etmpc.common.outputs import refuse_foreign
from etmpc.evaluation.workers import context
from etmpc.learning import dpi, gpomdp
from etmpc.learning.base import Learner
from etmpc.learning.checkpoint import RunState, candidates, load_checkpoint, ours, save, state_from_json
from etmpc.learning.config import DEFAULT_SEEDS, SELECTION_ENTROPY, TrainConfig
from etmpc.learning.curve import add_points, evaluation_jobs, once_each
from etmpc.learning.jobs import _call, _learner_to_json, mean_scores
from etmpc.learning.phased_settings import (  # noqa: F401 (the settings re-exported, as before the split)
    SHARED,
    DpiSettings,
    GpomdpSettings,
    PhasedSettings,
    identity_of,
    train_config,
)
from etmpc.policies.learned import LogisticPolicy, Normalisation
from etmpc.systems import has_levels, make_system


class _Phased(Learner):
    """The run of :func:`etmpc.learning.train.train`, behind the learner interface."""

    seeding = "many"
    resumes_exactly = True
    policy_kind = "rl"
    algorithm: ClassVar[str]
    _testset: tuple[int, str]  # the test-set episodes each evaluation plays and the set's sha256 (check()'s)

    def __init__(self, settings=None, config: TrainConfig | None = None):
        super().__init__(settings)
        self._config = config  # kept as given (train(config) checkpoints it byte for byte)
        self.run_state: RunState | None = None  # None until set up or resumed
        self._summary: dict | None = None  # the learning curve's summary, as save() last wrote it

    @property
    def _run(self) -> RunState:
        """The run's state, once set up or resumed (the runner does one of them before it trains or chooses)."""
        if self.run_state is None:
            raise EtmpcError(f"{self.name}: the run is neither set up nor resumed")
        return self.run_state

    @classmethod
    def from_config(cls, config: TrainConfig, record_episodes: int = 0) -> _Phased:
        """The learner of a :class:`TrainConfig` (its algorithm's)."""
        learner = LEARNER_OF[config.algorithm]
        own = asdict(config.gpomdp) if config.algorithm == "gpomdp" else asdict(config.dpi)
        settings = learner.Settings(**{n: getattr(config, n) for n in SHARED}, **own, record_episodes=record_episodes)
        return learner(settings, config)

    def config(self) -> TrainConfig:
        if self._config is not None:
            return self._config
        return train_config(self.settings, self.algorithm, self.key, self.seeds)

    def default_seeds(self) -> tuple[int, ...]:
        return DEFAULT_SEEDS  # 0-4, as etmpc train's

    # The run's directory and state.

    def owns(self, name: str) -> bool:
        return ours(name)

    def check(self) -> None:
        config = self.config()
        if self._config is not None and (config.system != self.key or config.seeds != self.seeds):
            raise EtmpcError("the learner's configuration is for another task, price, options or seeds")
        refuse_foreign(self.out, ours, "training run")
        if self.settings.record_episodes and self.recorder is None:
            raise EtmpcError("record episodes: nothing to write them with: pass recorder=etmpc.views.recording.Recorder")
        _, _, testset = context(config.domain)
        n = testset.episodes if config.eval_episodes is None else config.eval_episodes
        if not 1 <= n <= testset.episodes:
            raise EtmpcError(f"eval episodes must be in 1..{testset.episodes}, got {n}")
        self._testset = (n, testset.sha256)

    def has_saved(self) -> bool:
        return (self.out / "checkpoint.json").exists()

    def saved_state(self) -> dict | None:
        checkpoint = self.out / "checkpoint.json"
        return load_checkpoint(checkpoint).to_json() if checkpoint.exists() else None

    def identity(self) -> dict:
        return identity_of(self.config())

    def saved_identity(self, state: dict) -> tuple[str, dict]:
        return str(self.out / "checkpoint.json"), identity_of(TrainConfig.from_json(state["config"]))

    def state(self) -> dict:
        return self._run.to_json()

    def load_state(self, state: dict) -> None:
        self.run_state = state_from_json(state)

    @property
    def done(self) -> int:
        return 0 if self.run_state is None else self.run_state.done

    def milestones(self) -> list[int]:
        return self.config().milestones

    def work(self) -> int:
        config = self.config()
        per_seed = len(config.milestones) - 1 if config.algorithm == "dpi" else 1  # DPI: every iteration's policy
        evaluations = len(config.milestones) * config.eval_repeats * self._testset[0]
        return len(config.seeds) * (config.episodes + evaluations + per_seed * config.validation_episodes)

    def work_done(self) -> int:
        config, done = self.config(), self.done
        return len(config.seeds) * (
            done + sum(1 for m in config.milestones if m <= done) * config.eval_repeats * self._testset[0]
        )

    # What each algorithm says: its policy's hyperparameters, its learners' start, a phase of training.

    @abstractmethod
    def _hyperparameters(self, config: TrainConfig) -> dict:
        """The algorithm's settings as its policy's hyperparameters keep them."""

    @abstractmethod
    def _start(self, config: TrainConfig, initial: LogisticPolicy) -> tuple[dict, str | None]:
        """A seed's learner at the start (JSON), from the ``initial`` policy, and DPI's first schedule (None: none)."""

    @abstractmethod
    def _advance(self, start: int, stop: int) -> None:
        """Train every seed on its episodes ``start..stop-1``, into the run's state."""

    def _tick(self, job) -> None:
        self.tick(job[1][5] - job[1][4] if job[0] == "train" else 1 if job[0] != "score" else 0)

    # Training.

    def setup(self) -> None:
        config, pool = self.config(), self.pool
        states = pool.map(
            _call, [("normalisation", (config.system, i, config.features)) for i in range(config.normalisation_episodes)]
        )
        normalisation = Normalisation.fit(np.concatenate(states))
        hyper = {
            "algorithm": config.algorithm,
            "features": config.features,
            "normalisation_episodes": config.normalisation_episodes,
        }
        if config.recompute_price is not None:  # trained for another price than the task's own
            hyper["recompute_price"] = config.recompute_price
        if config.options:  # trained with some of the task's options set
            hyper["options"] = dict(config.options)
        hyper.update(self._hyperparameters(config))
        greedy, levels = config.algorithm == "dpi", has_levels(config.domain)
        initial = LogisticPolicy.initial(normalisation, config.domain, hyper, config.features, greedy=greedy, levels=levels)
        learner, base = self._start(config, initial)
        # One learner per seed, sharing nothing (a DPI learner's labels grow in place).
        self.run_state = RunState(
            config, initial.to_json(), {str(s): json.loads(json.dumps(learner)) for s in config.seeds}, base=base
        )
        self._evaluate()

    def learn(self, budget: int, callback) -> None:
        self._advance(self._run.done, budget)
        self._evaluate()

    def save(self) -> None:
        self._summary = save(self.out, self._run, self.curve_png)

    def report(self) -> str:
        assert self._summary is not None  # the runner saves before each report
        point = self._summary["points"][-1]
        state = self._run
        return (
            f"{state.config.domain}: {state.done}/{state.config.episodes} episodes per seed, test objective "
            f"{point['objective_mean']:.5f} ± {point['objective_std']:.5f}, {point['recomputes_mean']:.1f} recomputes"
        )

    # Validation: every seed's final policy (DPI: every iteration's); the best becomes selected.json (written by save).

    @property
    def chosen(self) -> bool:
        return bool(self._run.validation)

    def validation_episodes(self) -> int:
        return self.config().validation_episodes

    def candidates(self) -> dict:
        return candidates(self._run)

    def choose(self, scores: list[float]) -> None:
        self._run.validation = dict(zip(candidates(self._run), scores, strict=True))

    def policy(self) -> str:
        return f"rl:{self.out / 'selected.json'}"

    def simulated_steps(self) -> int | None:
        config = self.config()
        steps = context(config.system)[0].episode_steps
        return None if self.run_state is None else (config.normalisation_episodes + self.done * len(config.seeds)) * steps

    # The test-set curve.

    def _evaluate(self) -> None:
        """Evaluate every seed's policy (a point of the test-set curve each: :mod:`etmpc.learning.curve`); with
        ``record_episodes``, also write the first that many test-set episodes of each seed into
        ``out/recordings/eval_<episodes>.rrd``."""
        state = self._run
        testset_n, sha256 = self._testset
        jobs = evaluation_jobs(state, testset_n, sha256, self.settings.record_episodes)
        results = once_each(self.pool, _call, jobs, self._tick)
        records = [c[3] for c in results if c[3] is not None]
        if records:
            assert self.recorder is not None  # check() refuses record episodes without one
            with self.recorder(self.out / "recordings" / f"eval_{state.done:05d}.rrd") as sink:
                for record in records:
                    sink.log_episode(record)
        add_points(state, results, state.config.eval_repeats * testset_n)


class GpomdpLearner(_Phased):
    """GPOMDP (:mod:`etmpc.learning.gpomdp`), the paper's policy gradient, one update per episode."""

    name = "gpomdp"
    algorithm = "gpomdp"
    Settings = GpomdpSettings
    keep_or_solve_only = True  # its gradient is of the keep-or-solve policy
    shipped = (
        "GPOMDP (shipped)",
        "gpomdp.json",
        "the paper's learner on its features (5 seeds x 1500 episodes), the seed chosen on validation episodes",
    )

    def _hyperparameters(self, config: TrainConfig) -> dict:
        g = config.gpomdp
        scale = {} if g.scale == "none" else {"scale": g.scale}  # the paper's step: its policies' files as before
        return dict(discount=g.discount, learning_rate=g.learning_rate, baseline=g.baseline, **scale)

    def _start(self, config: TrainConfig, initial: LogisticPolicy) -> tuple[dict, None]:
        steps = context(config.system)[0].episode_steps
        return _learner_to_json(gpomdp.Learner.start(initial.theta, config.gpomdp, steps)), None

    def _advance(self, start: int, stop: int) -> None:
        state = self._run
        config = state.config
        jobs = [("train", (config.system, state.policy, state.learners[str(s)], s, start, stop)) for s in config.seeds]
        for seed, (learner, stats) in zip(config.seeds, self.pool.map(_call, jobs, self._tick)):
            state.learners[str(seed)] = learner
            state.training += [dict(s, seed=seed) for s in stats]


class DpiLearner(_Phased):
    """Direct policy iteration (:mod:`etmpc.learning.dpi`): rollout-labelled classification, one
    iteration per phase."""

    name = "dpi"
    algorithm = "dpi"
    Settings = DpiSettings
    shipped = ("DPI (shipped)", "learned.json", "the default learner, chosen on validation episodes")

    def _hyperparameters(self, config: TrainConfig) -> dict:
        # eval_every: the episodes of one policy iteration (each phase ends in one), and the run's length (a policy's own
        # "episodes" is those it was trained on: an earlier iteration's may be shipped), so the recipe is whole
        return dict(
            asdict(config.dpi), bases=list(config.dpi.bases), eval_every=config.eval_every, episodes_per_seed=config.episodes
        )

    def _start(self, config: TrainConfig, initial: LogisticPolicy) -> tuple[dict, str]:
        learner = {"theta": initial.theta.tolist()}
        if initial.theta_level is not None:  # compute levels (initial.levels): the second stage's parameters
            learner["theta_level"] = initial.theta_level.tolist()
        learner.update(episodes=0, iterations=0, data=[])
        base = dpi.choose_base(
            config.dpi,
            make_system(config.system).objective_sense,
            lambda bases, n: mean_scores(self.pool, config.system, bases, SELECTION_ENTROPY, n),
        )
        return learner, base

    def _advance(self, start: int, stop: int) -> None:
        dpi.iteration(self._run, self.pool, self._tick, start, stop)

    def simulated_steps(self) -> int | None:
        return None  # the rollouts' steps are counted from the labels (etmpc.experiments.efficiency)


LEARNER_OF = {"gpomdp": GpomdpLearner, "dpi": DpiLearner}
