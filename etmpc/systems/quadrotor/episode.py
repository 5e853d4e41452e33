"""One ``waypoints`` episode, drawn in advance: the drone's start, the waypoint of each interval and the gusts,
and the :class:`Disturbances` options they are drawn with (``task.py``'s docstring says how, and plays them).

Draws are ordered so that a future redrawn from an interval on (a rollout's) uses the generator as an
episode's own draw did: the waypoints' jumps first, then their new values; the gusts' onsets first, then each
gust's peak, direction and length.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from etmpc.common.declared import Checked
from etmpc.systems.episodes import drawn_setting, jump_process, scale_setting
from etmpc.systems.quadrotor.model import NX

CONTROL_DT_S = 0.05
EPISODE_STEPS = 100
BOX_LOW = np.array([-1.0, -1.0, 0.5])  # where the drone starts and the waypoints are drawn (m)
BOX_HIGH = np.array([1.0, 1.0, 1.5])
INITIAL_YAW_RAD = 0.3
CHANGE_PROBABILITY = 0.05  # a waypoint change per interval after the first
GUST_PROBABILITY = 0.03  # a gust's onset per interval
GUST_PEAK_N = (0.06, 0.15)
GUST_DURATION_S = (0.3, 0.8)
MAX_GUST_N = 10.0  # the strongest gust an option may draw (the drone weighs 0.26 N)
MAX_GUST_S = 10.0  # and the longest


@dataclass(frozen=True)
class Disturbances(Checked):
    """The task's disturbances, as options (``--option disturbances.gust_scale=1.5``). The probabilities, peaks
    and durations say how episodes are drawn (``etmpc testset --option ...``; a rollout redraws a future with
    them); ``gust_scale`` multiplies every gust's force as it is played, a stored episode's too, so that one test
    set measures a trigger against stronger or weaker gusts, episode by episode (``etmpc robustness``)."""

    change_probability: float = drawn_setting(CHANGE_PROBABILITY, 1, "a waypoint change's probability per interval")
    gust_probability: float = drawn_setting(GUST_PROBABILITY, 1, "a gust's onset's probability per interval")
    gust_peak_n: tuple[float, ...] = drawn_setting(GUST_PEAK_N, MAX_GUST_N, "a gust's peak force ~ U(low, high)", "N", True)
    gust_duration_s: tuple[float, ...] = drawn_setting(
        GUST_DURATION_S, MAX_GUST_S, "a gust's length ~ U(low, high), in whole intervals", "s", True
    )
    gust_scale: float = scale_setting("gust")


@dataclass(frozen=True)
class Episode:
    """Everything random about one episode, drawn in advance: a test-set row."""

    initial_state: np.ndarray  # (12,)
    target: np.ndarray  # (steps, 3) m: the waypoint of each interval
    gust_peak: np.ndarray  # (steps, 3) N: the peak force of a gust beginning at that interval (0: none)
    gust_intervals: np.ndarray  # (steps,) its length in intervals (0: none)

    @classmethod
    def draw(cls, rng: np.random.Generator, steps: int = EPISODE_STEPS, disturbances: Disturbances | None = None) -> Episode:
        d = Disturbances() if disturbances is None else disturbances
        position = rng.uniform(BOX_LOW, BOX_HIGH)
        yaw = rng.uniform(-INITIAL_YAW_RAD, INITIAL_YAW_RAD)
        initial_state = np.concatenate([position, [0.0, 0.0, yaw], np.zeros(6)])
        first = draw_target(rng)
        target = np.vstack([first, jump_process(rng, first, steps - 1, d.change_probability, draw_target)])
        peak, intervals = draw_gusts(rng, steps, d)
        return cls(initial_state, target, peak, intervals)

    def arrays(self) -> dict[str, np.ndarray]:
        return {
            "initial_state": self.initial_state,
            "target": self.target,
            "gust_peak": self.gust_peak,
            "gust_intervals": self.gust_intervals,
        }

    @classmethod
    def from_arrays(cls, arrays: dict[str, np.ndarray]) -> Episode:
        initial_state = np.asarray(arrays["initial_state"], dtype=float)
        target = np.asarray(arrays["target"], dtype=float)
        peak = np.asarray(arrays["gust_peak"], dtype=float)
        intervals = np.asarray(arrays["gust_intervals"])
        steps = target.shape[0] if target.ndim == 2 else -1
        if (
            initial_state.shape != (NX,)
            or target.shape != (steps, 3)
            or peak.shape != (steps, 3)
            or intervals.shape != (steps,)
            or not np.issubdtype(intervals.dtype, np.integer)
            or np.any(intervals < 0)
        ):
            raise ValueError(f"bad episode arrays: {initial_state.shape}, {target.shape}, {peak.shape}, {intervals.shape}")
        return cls(initial_state, target, peak, intervals.astype(np.int64, copy=False))  # no copy: a stored set stays read-only

    def gusts(self) -> np.ndarray:
        """The gust force (N, world frame) held over each interval: every gust's 1-cosine profile, added."""
        steps = self.target.shape[0]
        force = np.zeros((steps, 3))
        for start in np.flatnonzero(self.gust_intervals):
            n = int(self.gust_intervals[start])
            # math.cos, not np.cos: NumPy's vectorised cosine differs in its last bits from one CPU to another
            shape = np.array([(1 - math.cos(2 * math.pi * (k + 0.5) / n)) / 2 for k in range(n)])
            end = min(start + n, steps)
            force[start:end] += shape[: end - start, None] * self.gust_peak[start]
        return force


def draw_target(rng: np.random.Generator) -> np.ndarray:
    """A waypoint, uniform in the box."""
    return rng.uniform(BOX_LOW, BOX_HIGH)


def draw_gusts(rng: np.random.Generator, steps: int, disturbances: Disturbances | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``steps`` intervals of gusts: onsets first, then each gust's peak, direction and length in order,
    so a future redrawn from an interval on (a rollout's) uses the generator as an episode's own draw did."""
    d = Disturbances() if disturbances is None else disturbances
    onsets = np.flatnonzero(rng.random(steps) < d.gust_probability)
    peak_low, peak_high = d.gust_peak_n
    shortest, longest = d.gust_duration_s
    peak = np.zeros((steps, 3))
    intervals = np.zeros(steps, dtype=np.int64)
    for j in onsets:
        size = rng.uniform(peak_low, peak_high)
        angle = rng.uniform(-math.pi, math.pi)
        peak[j] = [size * math.cos(angle), size * math.sin(angle), 0.0]
        intervals[j] = max(1, round(rng.uniform(shortest, longest) / CONTROL_DT_S))
    return peak, intervals
