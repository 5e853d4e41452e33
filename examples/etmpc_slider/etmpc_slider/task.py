"""The slider's ``track`` task: keep the block on a reference position that jumps at random times, and
the domain's suite of tasks.

A state-error trigger sees the block drift from its plan (the plan's model has the wrong spring), but
not the reference move: after a jump the kept plan still holds the old reference, and the moment to
re-plan is right then. The jumps come at random times (Bernoulli per interval), so a trigger that
knows when to re-plan beats any periodic schedule at the same rate of computations.

* **Plant**: the block of ``physics.py`` (``mismatched`` by default), force ``|u| <= 10`` N (MuJoCo
  clamps to the actuator's ``ctrlrange``), integrated by RK4 at 0.01 s under a 0.05 s control interval.
* **Episodes**: 60 intervals (3 s). Initial state ``p ~ U(+-0.5)`` m, ``v ~ U(+-0.5)`` m/s. A reference
  is drawn ``U(+-0.8)`` m; at each later interval, with probability 0.05 (1 jump per second), it jumps
  to a new one drawn alike. All drawn in advance (:class:`Episode`). The reference of interval ``i``
  is observed at its decision.
* **Observation**: the state (``model.STATE_NAMES``) and the current reference ``reference_m``.
* **Reward** ``-e^2 / (e^2 + 0.1^2)`` per step, in ``(-1, 0]``, with ``e`` the block's distance from the
  interval's reference after the step: -1/2 at 0.1 m, -0.8 at 0.2 m, and bounded, so that a long
  move after a far jump does not rule an episode's mean.
* **Failures**, "far from reference": the steps that end more than 0.1 m from the interval's reference
  (reward below -1/2; :func:`far_steps`), counted from the rewards.
"""

from __future__ import annotations

import collections
from dataclasses import dataclass

import numpy as np
from dm_control.rl import control
from dm_control.utils import containers
from dm_env import specs

from etmpc.systems.episodes import EpisodeTask, Random, add_task, build_environment, jump_process
from etmpc.systems.plants import PLANTS
from etmpc_slider.model import NX, STATE_NAMES
from etmpc_slider.physics import Physics, load_model

__all__ = ["PLANTS", "SUITE", "Episode", "Physics", "Track", "load_model", "make_environment"]

CONTROL_DT_S = 0.05
PHYSICS_DT_S = 0.01  # 5 RK4 steps per interval
EPISODE_STEPS = 60
INITIAL_STATE_LOW = np.array([-0.5, -0.5])  # p (m), v (m/s)
INITIAL_STATE_HIGH = np.array([0.5, 0.5])
REFERENCE_RANGE_M = (-0.8, 0.8)  # a reference ~ U(low, high)
JUMPS_PER_S = 1.0
JUMP_PROBABILITY = JUMPS_PER_S * CONTROL_DT_S  # per interval after the first
ERROR_SCALE_M = 0.1  # reward -e^2 / (e^2 + 0.1^2)
REFERENCE = "reference_m"
OBSERVATION_NAMES = (*STATE_NAMES, REFERENCE)
SUITE = containers.TaggedTasks()


@dataclass(frozen=True)
class Episode:
    """Everything random about one episode, drawn in advance: a test-set row."""

    initial_state: np.ndarray  # (2,) [p, v]
    reference: np.ndarray  # (steps,) m: the reference of each interval

    @classmethod
    def draw(cls, rng: np.random.Generator, steps: int = EPISODE_STEPS) -> Episode:
        initial_state = rng.uniform(INITIAL_STATE_LOW, INITIAL_STATE_HIGH)
        first = draw_reference(rng)
        return cls(initial_state, np.concatenate([[first], continue_references(rng, first, steps - 1)]))

    def arrays(self) -> dict[str, np.ndarray]:
        return {"initial_state": self.initial_state, "reference": self.reference}

    @classmethod
    def from_arrays(cls, arrays: dict[str, np.ndarray]) -> Episode:
        initial_state = np.asarray(arrays["initial_state"], dtype=float)
        reference = np.asarray(arrays["reference"], dtype=float)
        if initial_state.shape != (NX,) or reference.ndim != 1:
            raise ValueError(f"bad episode arrays: {initial_state.shape}, {reference.shape}")
        return cls(initial_state, reference)


def draw_reference(rng: np.random.Generator) -> float:
    """A reference position (m): ``U(REFERENCE_RANGE_M)``."""
    return float(rng.uniform(*REFERENCE_RANGE_M))


def continue_references(rng: np.random.Generator, current: float, steps: int) -> np.ndarray:
    """The references of the ``steps`` intervals after one whose reference is ``current``: each jumps
    to a new reference with probability ``JUMP_PROBABILITY``, else keeps the one before."""
    return jump_process(rng, np.asarray(current, dtype=float), steps, JUMP_PROBABILITY, draw_reference)


def error_reward(error_m: float) -> float:
    """``-e^2 / (e^2 + 0.1^2)``: 0 on the reference, -1/2 at 0.1 m, towards -1 far away."""
    e2 = error_m * error_m
    return -e2 / (e2 + ERROR_SCALE_M**2)


def far_steps(rewards: np.ndarray) -> int:
    """The steps of an episode that ended farther than 0.1 m from the reference (reward below -1/2)."""
    return int(np.sum(np.asarray(rewards) < error_reward(ERROR_SCALE_M)))


class Track(EpisodeTask):
    """Keep the block on a reference that jumps at random times (see the module's docstring)."""

    def __init__(self, random: Random = None, steps: int = EPISODE_STEPS):
        super().__init__(random)
        self._steps = steps
        self._step = 0

    def check_episode(self, episode: Episode) -> None:
        if episode.reference.shape[0] < self._steps:
            raise ValueError(f"episode has {episode.reference.shape[0]} references, need {self._steps}")

    def draw_episode(self, random: np.random.Generator) -> Episode:
        return Episode.draw(random, self._steps)

    # What rollouts, test sets and recordings read of the world: a task that offers resample_episode
    # can be rolled out (rollout:, DPI, the self-trigger); the other two are optional.
    def resample_episode(self, episode: Episode, step: int, random: np.random.Generator) -> Episode:
        """``episode`` with the references of intervals after ``step`` redrawn: at the decision of step
        ``step`` the controller sees that interval's reference, and jumps are memoryless."""
        reference = np.array(episode.reference)
        reference[step + 1 :] = continue_references(random, reference[step], reference.shape[0] - step - 1)
        return Episode(episode.initial_state, reference)

    def episode_parameters(self) -> dict:
        """What the episodes are drawn from (recorded in the test set)."""
        return {
            "initial_state_low": INITIAL_STATE_LOW.tolist(),
            "initial_state_high": INITIAL_STATE_HIGH.tolist(),
            "jump_probability": JUMP_PROBABILITY,
            "reference_range_m": list(REFERENCE_RANGE_M),
            "steps": EPISODE_STEPS,
            "error_scale_m": ERROR_SCALE_M,
        }

    def episode_ranges(self) -> dict:
        """What a test set's episode may hold: they are checked against it before they are played."""
        return {"initial_state": (INITIAL_STATE_LOW, INITIAL_STATE_HIGH), "reference": REFERENCE_RANGE_M}

    def signals(self, episode: Episode) -> dict[str, np.ndarray]:
        """The reference, per step, for recordings."""
        return {REFERENCE: episode.reference}

    def current_reference(self) -> float:
        """The reference of the interval about to be played (the last one's once the episode is over)."""
        return float(self._episode.reference[min(self._step, self._episode.reference.shape[0] - 1)])

    def initialize_episode(self, physics: Physics) -> None:
        episode = self.next_episode()
        self._step = 0
        physics.set_state_vector(episode.initial_state)
        physics.set_reference(self.current_reference())

    def before_step(self, action, physics: Physics) -> None:
        physics.set_control(action)
        physics.set_reference(self.current_reference())
        self._step += 1

    def get_reward(self, physics: Physics) -> float:
        """Against the reference of the interval just played."""
        return error_reward(physics.position() - float(self._episode.reference[self._step - 1]))

    def action_spec(self, physics: Physics) -> specs.BoundedArray:
        low, high = physics.model.actuator_ctrlrange.T
        return specs.BoundedArray((1,), np.float64, low, high, name="force")

    def observation_spec(self, physics: Physics) -> collections.OrderedDict:
        return collections.OrderedDict((name, specs.Array((), np.float64, name=name)) for name in OBSERVATION_NAMES)

    def get_observation(self, physics: Physics) -> collections.OrderedDict:
        values = np.append(physics.state(), self.current_reference())
        return collections.OrderedDict(zip(OBSERVATION_NAMES, values))


def make_environment(
    random: Random = None, plant: str = "mismatched", steps: int = EPISODE_STEPS, environment_kwargs: dict | None = None
) -> control.Environment:
    root = load_model(plant, timestep_s=PHYSICS_DT_S)
    physics = Physics.from_xml_string(root.to_xml_string(), assets=root.get_assets())
    return build_environment(physics, Track(random=random, steps=steps), steps, CONTROL_DT_S, environment_kwargs)


add_task(
    SUITE,
    "track",
    make_environment,
    EPISODE_STEPS,
    CONTROL_DT_S,
    "Keep the block on a jumping reference: 60 control intervals of 0.05 s by default (plant=...).",
    episode=Episode,
)
