"""The reacher's ``jumps`` task: keep the fingertip on a target that jumps at random times, and the
domain's suite of tasks.

An event trigger on the state error sees the arm drift from its plan, but not the target move: after a
jump the kept plan still reaches for the old target, and the moment to recompute is right then. The jumps
come at random times (Bernoulli per interval), so a policy that knows when to recompute beats any
periodic schedule at the same rate of recomputes.

* **Plant**: the two-link arm of ``physics.py`` (``mismatched`` by default) in a horizontal plane,
  torques ``|u_i| <= 2`` N m (MuJoCo clamps to the actuators' ``ctrlrange``), integrated by RK4 at
  0.01 s under a 0.1 s control interval.
* **Episodes**: 100 intervals. Initial state at rest, ``q1 ~ U(+-pi)``, ``q2 ~ U(+-2.5)`` rad. A
  target is drawn at radius ``U(0.3, 0.95)`` m and angle ``U(+-pi)`` (the arm reaches 1 m); at each
  later interval, with probability 0.04 (0.4 jumps per second), it jumps to a new one drawn alike.
  All drawn in advance (:class:`Episode`). The target of interval ``i`` is observed at its decision.
  The rate of jumps and the radii are options (:class:`Disturbances`: ``--option disturbances.jumps_per_s=2``).
* **Observation**: the state (``model.STATE_NAMES``), the current target ``target_x_m``,
  ``target_y_m`` and the fingertip ``fingertip_x_m``, ``fingertip_y_m``.
* **Reward** ``-d^2 / (d^2 + 0.1^2)`` per step, in ``(-1, 0]``, with ``d`` the fingertip's distance
  from the interval's target after the step: -1/2 at 0.1 m, -0.8 at 0.2 m, and bounded, so one long
  reach does not rule an episode's mean. A step ending more than 0.1 m from the target (reward
  below -1/2) is counted a failure, "far from target" (:func:`far_steps`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from dm_control.utils import containers

from etmpc.common.declared import Checked
from etmpc.systems.episodes import drawn_setting, jump_process, jumps_setting
from etmpc.systems.reacher.model import NX, STATE_NAMES, Parameters
from etmpc.systems.plants import PLANTS
from etmpc.systems.reacher.physics import Physics, load_model
from etmpc.systems.tracking import TrackingTask, add_tracking_task, initial_state_range

__all__ = ["PLANTS", "SUITE", "Disturbances", "Episode", "Jumps", "Physics", "load_model", "make_environment"]

CONTROL_DT_S = 0.1
PHYSICS_DT_S = 0.01  # 10 RK4 steps per interval
EPISODE_STEPS = 100
INITIAL_STATE_LOW = np.array([-math.pi, -2.5, 0.0, 0.0])  # q1, q2 (rad), at rest
INITIAL_STATE_HIGH = np.array([math.pi, 2.5, 0.0, 0.0])
JUMPS_PER_S = 0.4
JUMP_PROBABILITY = JUMPS_PER_S * CONTROL_DT_S  # per interval after the first
TARGET_RADIUS_M = (0.3, 0.95)  # radius ~ U(low, high), angle ~ U(-pi, pi)
REACH_M = Parameters().upper_arm_length_m + Parameters().forearm_length_m  # the arm's (the MJCF's links are as long)
DISTANCE_SCALE_M = 0.1  # reward -d^2 / (d^2 + 0.1^2); farther than this is a failure
OBSERVATION_NAMES = (*STATE_NAMES, "target_x_m", "target_y_m", "fingertip_x_m", "fingertip_y_m")
SUITE = containers.TaggedTasks()


@dataclass(frozen=True)
class Disturbances(Checked):
    """The target's jumps, as options (``--option disturbances.jumps_per_s=2``): how episodes are drawn (``etmpc
    testset --option ...`` draws a test set with them; a rollout redraws a future with them)."""

    jumps_per_s: float = jumps_setting(JUMPS_PER_S, CONTROL_DT_S, "the target")  # jump_probability per interval after the first
    target_radius_m: tuple[float, ...] = drawn_setting(  # a target's radius ~ U(low, high), within the arm's reach
        TARGET_RADIUS_M, REACH_M, "a target's distance from the shoulder ~ U(low, high), within the arm's reach", "m", True
    )

    @property
    def jump_probability(self) -> float:
        return self.jumps_per_s * CONTROL_DT_S


@dataclass(frozen=True)
class Episode:
    """Everything random about one episode, drawn in advance: a test-set row."""

    initial_state: np.ndarray  # (4,) [q1, q2, q1dot, q2dot]
    target: np.ndarray  # (steps, 2) m: the target of each interval

    @classmethod
    def draw(cls, rng: np.random.Generator, steps: int = EPISODE_STEPS, disturbances: Disturbances | None = None) -> Episode:
        initial_state = rng.uniform(INITIAL_STATE_LOW, INITIAL_STATE_HIGH)
        first = draw_target(rng, disturbances)
        return cls(initial_state, np.vstack([first, continue_targets(rng, first, steps - 1, disturbances)]))

    def arrays(self) -> dict[str, np.ndarray]:
        return {"initial_state": self.initial_state, "target": self.target}

    @classmethod
    def from_arrays(cls, arrays: dict[str, np.ndarray]) -> Episode:
        initial_state = np.asarray(arrays["initial_state"], dtype=float)
        target = np.asarray(arrays["target"], dtype=float)
        if initial_state.shape != (NX,) or target.ndim != 2 or target.shape[1] != 2:
            raise ValueError(f"bad episode arrays: {initial_state.shape}, {target.shape}")
        return cls(initial_state, target)


def draw_target(rng: np.random.Generator, disturbances: Disturbances | None = None) -> np.ndarray:
    """A target ``(x, y)``: radius ``U(target_radius_m)`` (``TARGET_RADIUS_M`` by default), angle ``U(-pi, pi)``."""
    d = Disturbances() if disturbances is None else disturbances
    low, high = d.target_radius_m
    radius = rng.uniform(low, high)
    angle = rng.uniform(-math.pi, math.pi)
    return np.array([radius * math.cos(angle), radius * math.sin(angle)])


def continue_targets(
    rng: np.random.Generator, current: np.ndarray, steps: int, disturbances: Disturbances | None = None
) -> np.ndarray:
    """The targets of the ``steps`` intervals after one whose target is ``current``: each jumps to a
    new target with the disturbances' probability (``JUMP_PROBABILITY`` by default), else keeps the one before."""
    d = Disturbances() if disturbances is None else disturbances
    return jump_process(rng, current, steps, d.jump_probability, lambda r: draw_target(r, d))


def distance_reward(distance_m: float) -> float:
    """``-d^2 / (d^2 + 0.1^2)``: 0 on the target, -1/2 at 0.1 m, towards -1 far away."""
    d2 = distance_m * distance_m
    return -d2 / (d2 + DISTANCE_SCALE_M**2)


def far_steps(rewards: np.ndarray) -> int:
    """The steps of an episode that ended farther than 0.1 m from the target (reward below -1/2)."""
    return int(np.sum(np.asarray(rewards) < distance_reward(DISTANCE_SCALE_M)))


class Jumps(TrackingTask):
    """Keep the fingertip on a target that jumps at random times (see the module's docstring)."""

    episode_class = Episode
    disturbances_class = Disturbances
    intervals = ("target", "targets")
    observation_names = OBSERVATION_NAMES
    action_name = "torque"
    interval_s = CONTROL_DT_S
    episode_steps = EPISODE_STEPS

    @staticmethod
    def make_physics(plant: str) -> Physics:
        root = load_model(plant, timestep_s=PHYSICS_DT_S)
        return Physics.from_xml_string(root.to_xml_string(), assets=root.get_assets())

    def resample_episode(self, episode: Episode, step: int, random: np.random.Generator) -> Episode:
        """``episode`` with the targets of intervals after ``step`` redrawn: at the decision of step
        ``step`` the controller sees that interval's target, and jumps are memoryless."""
        target = np.array(episode.target)
        target[step + 1 :] = continue_targets(random, target[step], target.shape[0] - step - 1, self.disturbances)
        return Episode(episode.initial_state, target)

    def episode_parameters(self) -> dict:
        """What the episodes are drawn from (recorded in the test set): the disturbances' jump probability and radii."""
        d = self.disturbances
        return {
            **initial_state_range(INITIAL_STATE_LOW, INITIAL_STATE_HIGH),
            "jump_probability": d.jump_probability,
            "target_radius_m": list(d.target_radius_m),
            "steps": EPISODE_STEPS,
            "distance_scale_m": DISTANCE_SCALE_M,
        }

    def episode_ranges(self) -> dict:
        """What a stored episode may hold (checked before it is played): each target's coordinates within
        the largest radius (the task's default, or the disturbances' if larger)."""
        reach = max(TARGET_RADIUS_M[1], self.disturbances.target_radius_m[1])
        return {"initial_state": (INITIAL_STATE_LOW, INITIAL_STATE_HIGH), "target": (-reach, reach)}

    def signals(self, episode: Episode) -> dict[str, np.ndarray]:
        """The episode's target, per step, for recordings."""
        return {"target_x_m": episode.target[:, 0], "target_y_m": episode.target[:, 1]}

    def current_target(self) -> np.ndarray:
        """The target of the interval about to be played (the last one's once the episode is over)."""
        return self.current("target")

    def initialize_episode(self, physics: Physics) -> None:
        episode = self.next_episode()
        self._step = 0
        physics.set_state_vector(episode.initial_state)
        physics.set_target(self.current_target())

    def before_step(self, action, physics: Physics) -> None:
        physics.set_control(action)
        physics.set_target(self.current_target())
        self._step += 1

    def get_reward(self, physics: Physics) -> float:
        """Against the target of the interval just played."""
        target = self._episode.target[self._step - 1]
        return distance_reward(float(np.hypot(*(physics.fingertip() - target))))

    def observation_values(self, physics: Physics) -> np.ndarray:
        return np.concatenate([physics.state(), self.current_target(), physics.fingertip()])


make_environment = Jumps.environment  # the task's dm-control environment (plant=, disturbances=, ...)


add_tracking_task(
    SUITE, "jumps", Jumps, "Keep the fingertip on a jumping target: 100 control intervals of 0.1 s by default (plant=...)."
)
add_tracking_task(
    SUITE,
    "jumps_late",
    Jumps,
    "The jumps world, for the task whose solves take one control interval (the latency is the controller's).",
    tags=("benchmarking", "timing"),
)
