"""The quadrotor's ``waypoints`` task: hold a nano quadrotor on a waypoint that changes at random
times while gusts push it, inside a geofence, and the domain's suite.

Two kinds of event call for a new plan, and no schedule knows when they come: a waypoint change
(observed: the kept plan still flies to the old waypoint) and a gust (not observed: the drone drifts
from its plan). Both arrive at random times (Bernoulli per interval).

* **Plant**: the quadrotor of ``physics.py`` (``mismatched`` by default: heavier, more inertia,
  rotor lag, air) lifted by four rotor thrusts ``0 <= u_i <= 0.149`` N (MuJoCo clamps to the
  actuators' ``ctrlrange``), integrated by RK4 at 5 ms under a 0.05 s control interval.
* **Episodes**: 100 intervals (5 s). The drone starts at rest, level, hovering on its rotors, at a
  position drawn uniformly in the waypoint box ``|x|, |y| <= 1`` m, ``0.5 <= z <= 1.5`` m, with yaw
  ``U(+-0.3)`` rad. A waypoint is drawn uniformly in the same box; at each later interval, with
  probability 0.05 (one change per second), it changes to a new one drawn alike.
* **Gusts**: at each interval, with probability 0.03 (0.6 per second), a gust begins: a horizontal
  force on the drone's centre, of peak ``U(0.06, 0.15)`` N (20 % to 51 % of the plant's weight) in
  a direction ``U(+-pi)``, lasting ``U(0.3, 0.8)`` s rounded to whole intervals, with the 1-cosine
  profile of aviation's discrete gust (``peak (1 - cos(2 pi t / T)) / 2``, evaluated at each
  interval's middle and held over it). Gusts overlap by adding. They are not observed.
* **Geofence**: ``|x|, |y| <= 2`` m and ``z <= 2.5`` m; the ground is ``z < 0.05`` m (the centre of
  a drone resting on the floor is at 0.012 m). A step ending outside the geofence or on the ground
  is a **failure**.
* **Observation**: the state (``model.STATE_NAMES``) and the current waypoint ``target_x_m``,
  ``target_y_m``, ``target_z_m``.
* **Reward** ``-d^2 / (d^2 + 0.5^2)`` per step, ``d`` the drone's distance from the interval's
  waypoint after the step (-1/2 at 0.5 m, bounded by -1: a new waypoint is up to 3 m from the last,
  the box's diagonal, and a scale of 0.2 m made every distance beyond 0.5 m cost nearly the same, so
  that how soon the drone set off after a change hardly counted), and 1 more off on a failure step:
  so a step's reward is at most -1 exactly when it is a failure (:func:`failure_steps`).
"""

from __future__ import annotations

import math

import numpy as np
from dm_control.utils import containers

from etmpc.systems.episodes import Random, jump_process
from etmpc.systems.plants import PLANTS
from etmpc.systems.quadrotor.episode import (
    BOX_HIGH,
    BOX_LOW,
    CHANGE_PROBABILITY,
    CONTROL_DT_S,
    EPISODE_STEPS,
    GUST_DURATION_S,
    GUST_PEAK_N,
    GUST_PROBABILITY,
    INITIAL_YAW_RAD,
    Disturbances,
    Episode,
    draw_gusts,
    draw_target,
)
from etmpc.systems.quadrotor.model import NX, STATE_NAMES
from etmpc.systems.quadrotor.physics import Physics, load_model
from etmpc.systems.tracking import TrackingTask, add_tracking_task

# The episode's pieces (episode.py) are read here too, as the docs and a test read the task's numbers.
__all__ = [
    "CHANGE_PROBABILITY",
    "GUST_PROBABILITY",
    "PLANTS",
    "SUITE",
    "Disturbances",
    "Episode",
    "Physics",
    "Waypoints",
    "load_model",
    "make_environment",
]

PHYSICS_DT_S = 0.005  # 10 RK4 steps per interval
FENCE_HALF_WIDTH_M = 2.0  # |x|, |y| <= 2
FENCE_HEIGHT_M = 2.5
GROUND_M = 0.05  # z below this is on the ground
DISTANCE_SCALE_M = 0.5  # reward -d^2 / (d^2 + 0.5^2)
FAILURE_PENALTY = 1.0
OBSERVATION_NAMES = (*STATE_NAMES, "target_x_m", "target_y_m", "target_z_m")
SUITE = containers.TaggedTasks()


def distance_reward(distance_m: float) -> float:
    """``-d^2 / (d^2 + 0.5^2)``: 0 on the waypoint, -1/2 at 0.5 m, towards -1 far away."""
    d2 = distance_m * distance_m
    return -d2 / (d2 + DISTANCE_SCALE_M**2)


def outside(position_m: np.ndarray) -> bool:
    """Outside the geofence, or on the ground."""
    x, y, z = position_m
    return bool(abs(x) > FENCE_HALF_WIDTH_M or abs(y) > FENCE_HALF_WIDTH_M or z > FENCE_HEIGHT_M or z < GROUND_M)


def fence_margin(x: np.ndarray) -> float:
    """How far (m) the drone keeps from the geofence, the ceiling and the ground one control interval on at
    its current velocity (at most 0: outside, or on the ground). A shield's reading (``shield:``)."""
    px, py, pz = np.asarray(x[:3], dtype=float) + np.asarray(x[6:9], dtype=float) * CONTROL_DT_S
    return float(min(FENCE_HALF_WIDTH_M - abs(px), FENCE_HALF_WIDTH_M - abs(py), FENCE_HEIGHT_M - pz, pz - GROUND_M))


def failure_steps(rewards: np.ndarray) -> int:
    """The steps of an episode that ended outside the geofence or on the ground (reward at most -1)."""
    return int(np.sum(np.asarray(rewards) <= -FAILURE_PENALTY))


class Waypoints(TrackingTask):
    """Hold the drone on a waypoint that changes at random times, under gusts (see the module's docstring)."""

    episode_class = Episode
    disturbances_class = Disturbances
    intervals = ("target", "waypoints")
    observation_names = OBSERVATION_NAMES
    action_name = "thrust"
    interval_s = CONTROL_DT_S
    episode_steps = EPISODE_STEPS

    def __init__(self, random: Random = None, steps: int = EPISODE_STEPS, disturbances: Disturbances | None = None):
        super().__init__(random, steps, disturbances)
        self._gusts = np.zeros((steps, 3))

    @staticmethod
    def make_physics(plant: str) -> Physics:
        root = load_model(plant, timestep_s=PHYSICS_DT_S)
        return Physics.from_xml_string(root.to_xml_string(), assets=root.get_assets())

    def resample_episode(self, episode: Episode, step: int, random: np.random.Generator) -> Episode:
        """``episode`` with what comes after interval ``step`` redrawn: the waypoints (the controller
        sees interval ``step``'s at its decision) and the gusts that begin later (one that has begun
        goes on as drawn: a future that forgot it would be as wrong the other way)."""
        steps = episode.target.shape[0]
        target = np.array(episode.target)
        d = self.disturbances
        target[step + 1 :] = jump_process(random, target[step], steps - step - 1, d.change_probability, draw_target)
        peak, intervals = np.array(episode.gust_peak), np.array(episode.gust_intervals)
        peak[step + 1 :], intervals[step + 1 :] = draw_gusts(random, steps - step - 1, d)
        return Episode(episode.initial_state, target, peak, intervals)

    def episode_parameters(self) -> dict:
        """What the episodes are drawn from (recorded in the test set; the gusts' scale where it is not 1)."""
        d = self.disturbances
        return {
            "box_low_m": BOX_LOW.tolist(),
            "box_high_m": BOX_HIGH.tolist(),
            "initial_yaw_rad": INITIAL_YAW_RAD,
            "change_probability": d.change_probability,
            "gust_probability": d.gust_probability,
            "gust_peak_n": list(d.gust_peak_n),
            "gust_duration_s": list(d.gust_duration_s),
            **({"gust_scale": d.gust_scale} if d.gust_scale != 1 else {}),
            "fence_half_width_m": FENCE_HALF_WIDTH_M,
            "fence_height_m": FENCE_HEIGHT_M,
            "ground_m": GROUND_M,
            "steps": EPISODE_STEPS,
            "distance_scale_m": DISTANCE_SCALE_M,
        }

    def episode_ranges(self) -> dict:
        """What a stored episode may hold (checked before it is played): the drone at rest and level but
        for its yaw, in the box; waypoints in the box; horizontal gusts of at most the largest peak, each
        lasting at most the longest gust's whole intervals (0: none begins)."""
        rest = np.zeros(NX - 6)
        d = self.disturbances
        peak = max(GUST_PEAK_N[1], d.gust_peak_n[1])
        longest = max(1, round(max(GUST_DURATION_S[1], d.gust_duration_s[1]) / CONTROL_DT_S))
        return {
            "initial_state": (
                np.concatenate([BOX_LOW, [0.0, 0.0, -INITIAL_YAW_RAD], rest]),
                np.concatenate([BOX_HIGH, [0.0, 0.0, INITIAL_YAW_RAD], rest]),
            ),
            "target": (BOX_LOW, BOX_HIGH),
            "gust_peak": (np.array([-peak, -peak, 0.0]), np.array([peak, peak, 0.0])),
            "gust_intervals": (0, longest),
        }

    def signals(self, episode: Episode) -> dict[str, np.ndarray]:
        """The episode's waypoints and gusts, per step, for recordings."""
        gusts = episode.gusts()
        return {
            "target_x_m": episode.target[:, 0],
            "target_y_m": episode.target[:, 1],
            "target_z_m": episode.target[:, 2],
            "gust_x_n": gusts[:, 0],
            "gust_y_n": gusts[:, 1],
        }

    def current_target(self) -> np.ndarray:
        """The waypoint of the interval about to be played (the last one's once the episode is over)."""
        return self.current("target")

    def resume(self, episode: Episode, step: int) -> None:
        super().resume(episode, step)
        self._gusts = episode.gusts()

    def initialize_episode(self, physics: Physics) -> None:
        episode = self.next_episode()
        self._step = 0
        self._gusts = episode.gusts()
        physics.set_state_vector(episode.initial_state)
        physics.set_thrusts(np.full(4, physics.weight_n() / 4))
        physics.set_gust(np.zeros(3))
        physics.set_target(self.current_target())

    def before_step(self, action, physics: Physics) -> None:
        physics.set_control(action)
        scale = self.disturbances.gust_scale
        physics.set_gust(self._gusts[self._step] if scale == 1 else self._gusts[self._step] * scale)
        physics.set_target(self.current_target())
        self._step += 1

    def get_reward(self, physics: Physics) -> float:
        """Against the waypoint of the interval just played; 1 more off outside the geofence or on the ground."""
        position = physics.position()
        dx, dy, dz = (float(v) for v in position - self._episode.target[self._step - 1])
        reward = distance_reward(math.sqrt(dx * dx + dy * dy + dz * dz))  # no BLAS: the same bits on any CPU
        return reward - FAILURE_PENALTY if outside(position) else reward

    def observation_values(self, physics: Physics) -> np.ndarray:
        return np.concatenate([physics.state(), self.current_target()])


make_environment = Waypoints.environment  # the task's dm-control environment (plant=, disturbances=, ...)


add_tracking_task(
    SUITE,
    "waypoints",
    Waypoints,
    "Hold a quadrotor on changing waypoints under gusts, inside a geofence: 100 control intervals of 0.05 s (plant=...).",
)
add_tracking_task(
    SUITE,
    "waypoints_noisy",
    Waypoints,
    "The waypoints world, for the task whose controller reads the drone through noisy sensors and a Kalman filter.",
    tags=("benchmarking", "sensing"),
)
