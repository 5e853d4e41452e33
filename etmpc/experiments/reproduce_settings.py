"""How big ``etmpc reproduce``'s run is: :class:`Settings`, the paper's protocol (:data:`FULL`) and the same steps
at small sizes (:data:`QUICK`). A run keeps them in its ``settings.json``; a second run with others is refused
(:mod:`etmpc.experiments.reproduce`)."""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace
from typing import Any

from etmpc.learning.config import TrainConfig


@dataclass(frozen=True)
class Settings:
    """How big the run is. ``full`` is the paper's protocol; ``quick`` the same steps, smaller."""

    seeds: tuple[int, ...] = (0, 1, 2, 3, 4)
    episodes: int = 1500  # training episodes per seed
    eval_every: int = 150
    eval_episodes: int | None = None  # test-set episodes per evaluation during training (None: all)
    test_episodes: int | None = None  # test-set episodes for the baselines and the final evaluation
    repeats: int = 5  # passes over the test set for the learned policy
    record_episodes: int = 3  # representative episodes per policy in the recording
    video_size: tuple[int, int] = (640, 480)
    # The default learner (DPI on the error features): each None is the task's recipe's (policies/<task>/dpi.yml,
    # the shipped policy's; etmpc.learning.dpi_recipe), a number sets it on every task.
    dpi_seeds: tuple[int, ...] | None = None
    dpi_episodes: int | None = None  # training episodes per seed
    dpi_eval_every: int | None = None  # episodes per DPI iteration
    dpi_labels: int | None = None  # decisions labelled per training episode
    dpi_futures: int | None = None
    dpi_horizon: int | None = None  # at most the task's Benchmark.lookahead
    dpi_selection_episodes: int | None = None  # training episodes that choose DPI's first policy among its bases
    validation_episodes: int = 50  # training-distribution episodes that choose the shipped seed
    rollout_episodes: int = 30  # first test-set episodes for rollout:BEST and oracle:BEST
    rollout_futures: int = 4  # K: 8 doubles its cost (2 K H simulated steps per decision)
    rollout_horizon: int | None = 20  # None: to the episode's end; at most the task's Benchmark.lookahead
    ppo_timesteps: int | None = None  # PPO (Stable-Baselines3, the 'rl' extra): None, its ppo.yml's budget; 0: none
    smoke: bool = False  # a smoke run: its report gives no verdicts

    def to_json(self) -> dict:
        data = asdict(self)
        data["seeds"], data["video_size"] = list(self.seeds), list(self.video_size)
        if self.dpi_seeds is not None:
            data["dpi_seeds"] = list(self.dpi_seeds)
        if self.dpi_selection_episodes is None:  # as a run made before it was a setting
            del data["dpi_selection_episodes"]
        return data

    def dpi(self, recipe: TrainConfig, capped) -> TrainConfig:
        """The task's DPI ``recipe`` with what these settings set (``capped``: the task's cap on a horizon)."""
        run: dict[str, Any] = {"eval_episodes": self.eval_episodes, "validation_episodes": self.validation_episodes}
        sizes: dict[str, Any] = {}
        for name, value in (("seeds", self.dpi_seeds), ("episodes", self.dpi_episodes), ("eval_every", self.dpi_eval_every)):
            if value is not None:
                run[name] = value
        for name, value in (
            ("states_per_episode", self.dpi_labels),
            ("futures", self.dpi_futures),
            ("horizon", None if self.dpi_horizon is None else capped(self.dpi_horizon)),
            ("selection_episodes", self.dpi_selection_episodes),
        ):
            if value is not None:
                sizes[name] = value
        return replace(recipe, **run, dpi=replace(recipe.dpi, **sizes))


FULL = Settings()
QUICK = Settings(
    episodes=30,
    eval_every=15,
    eval_episodes=10,
    test_episodes=20,
    repeats=2,
    record_episodes=2,
    video_size=(320, 240),
    dpi_seeds=(0, 1),
    dpi_episodes=4,
    dpi_eval_every=2,
    dpi_labels=5,
    dpi_futures=2,
    dpi_horizon=10,
    validation_episodes=5,
    rollout_episodes=3,
    rollout_futures=2,
    rollout_horizon=10,
    ppo_timesteps=2048,
    smoke=True,
)
