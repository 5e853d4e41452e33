"""The cart pendulum's `balance` task (the paper's), and the domain's suite of tasks.

The plant (``physics.py``) is ``models/cart_pendulum.xml`` simulated by MuJoCo (RK4, 0.025 s) under a 0.1 s control
interval. Each interval draws an unmeasured angular disturbance ``w ~ N(0, 1)`` rad/s^2 that enters
as the generalised force ``M(q) e_hinge w``, refreshed before every physics step, so it produces
the angular acceleration ``w`` the paper adds to ``omega_dot`` (exactly at the start of each
physics step; MuJoCo holds the force over the step's RK4 stages, so the cart coupling lags by up
to one 0.025 s step: ~1e-3 over 2 s, see tests/tasks/cart_pendulum/test_cart_pendulum_model.py).
Its standard deviation and a scale on every disturbance played are the task's options (:class:`Disturbances`).

Two plant settings, ``mismatched`` (the default) and ``matched``: see ``physics.py``.

**Action** ``[force]`` (N) on the cart. MuJoCo clamps it to the actuator's ``ctrlrange``
(+-25 N), as it does for every limited actuator of the suite; a non-finite force or an action of
another shape raises ``ValueError``.

**Observation** ``cart_position``, ``cart_velocity``, ``pole_angle``, ``pole_angular_velocity``
(m, m/s, rad, rad/s). The pole angle is the hinge's angle, **unwrapped**: it counts whole turns
(``2 pi`` is a full turn, not upright), so it stays continuous and the reward ``-beta^2`` keeps
growing worse after the pole falls rather than rewarding a pole that swings over the top.

**Failures**, "off balance" (:func:`off_balance_steps`): the steps that end with the pole more than
``OFF_BALANCE_RAD`` = 0.1 rad (5.7 degrees) from upright, but for the recovery from the drawn initial
tilt (up to 0.78 rad), which the first plan answers whatever the policy: the steps before the pole
first comes within 0.1 rad, for at most ``RECOVERY_STEPS`` (10 steps, 1 s). A fall (the kicks task's
1.2 rad) does not happen on the test set under any periodic schedule: the LQR holds the pole between
plans, and a plan is re-made at least every N steps. The line is drawn where a pole kept well stays,
and a plan kept too long lets it out. Each step is judged on the steps up to it, so the count never
decreases as the episode goes on.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from etmpc.common.declared import Checked
from etmpc.systems.cart_pendulum.model import NX, STATE_NAMES
from etmpc.systems.cart_pendulum.physics import Physics, load_model
from etmpc.systems.plants import PLANTS
from etmpc.systems.episodes import GAUSSIAN_BOUND_STD, drawn_setting, scale_setting
from etmpc.systems.tracking import TrackingTask, initial_state_range

__all__ = ["PLANTS", "Disturbances", "Episode", "Balance", "Physics", "load_model", "make_environment"]

CONTROL_DT_S = 0.1
EPISODE_STEPS = 100
DISTURBANCE_STD_RAD_S2 = 1.0
MAX_ANGULAR_STD_RAD_S2 = 100.0  # the largest an option may draw: 100 times the paper's
INITIAL_STATE_LOW = np.array([0.0, -1.0, -0.78, -1.0])  # eta, v, beta, omega
INITIAL_STATE_HIGH = np.array([0.0, 1.0, 0.78, 1.0])
OFF_BALANCE_RAD = 0.1  # a step ending with |beta| beyond this is a failure, but for the initial recovery:
RECOVERY_STEPS = 10  # the steps before the pole first comes within OFF_BALANCE_RAD, at most these first ones

_POLE_RGB = np.array([0.2, 0.45, 0.85])  # the MJCF's "pole" material
_FALLEN_RGB = np.array([0.85, 0.1, 0.1])


@dataclass(frozen=True)
class Disturbances(Checked):
    """The task's angular disturbance, as options (``--option disturbances.disturbance_scale=2``).
    ``angular_std_rad_s2`` says how episodes are drawn (``etmpc testset --option ...`` draws a test set with it; a
    rollout redraws a future with it); ``disturbance_scale`` multiplies every disturbance as it is played, a stored
    episode's too, so that one test set measures a trigger against a stronger or gentler disturbance, episode by
    episode (``etmpc robustness``)."""

    angular_std_rad_s2: float = drawn_setting(  # w ~ N(0, this) per control interval
        DISTURBANCE_STD_RAD_S2,
        MAX_ANGULAR_STD_RAD_S2,
        "the angular disturbance's standard deviation, drawn per control interval",
        "rad/s^2",
    )
    disturbance_scale: float = scale_setting("disturbance")


@dataclass(frozen=True)
class Episode:
    """Everything random about one episode, drawn in advance: a test-set row."""

    initial_state: np.ndarray  # (4,) [eta, v, beta, omega]
    disturbance: np.ndarray  # (EPISODE_STEPS,) rad/s^2, held over each control interval

    @classmethod
    def draw(cls, rng: np.random.Generator, steps: int = EPISODE_STEPS, disturbances: Disturbances | None = None) -> Episode:
        d = Disturbances() if disturbances is None else disturbances
        initial_state = rng.uniform(INITIAL_STATE_LOW, INITIAL_STATE_HIGH)
        disturbance = rng.normal(0.0, d.angular_std_rad_s2, size=steps)
        return cls(initial_state, disturbance)

    def arrays(self) -> dict[str, np.ndarray]:
        return {"initial_state": self.initial_state, "disturbance": self.disturbance}

    @classmethod
    def from_arrays(cls, arrays: dict[str, np.ndarray]) -> Episode:
        initial_state = np.asarray(arrays["initial_state"], dtype=float)
        disturbance = np.asarray(arrays["disturbance"], dtype=float)
        if initial_state.shape != (NX,) or disturbance.ndim != 1:
            raise ValueError(f"bad episode arrays: {initial_state.shape}, {disturbance.shape}")
        return cls(initial_state, disturbance)


def off_balance_steps(rewards: np.ndarray) -> int:
    """The failures of a ``balance`` episode, from its rewards (``-beta^2`` of the state each step leads
    to): the steps that ended with ``|beta| > OFF_BALANCE_RAD``, but for those of the initial recovery
    (before the first step that ended within it, and among the first ``RECOVERY_STEPS``)."""
    beyond = np.asarray(rewards) < -(OFF_BALANCE_RAD**2)
    recovering = (np.cumsum(~beyond) == 0) & (np.arange(beyond.size) < RECOVERY_STEPS)
    return int(np.sum(beyond & ~recovering))


class CartPendulumTask(TrackingTask):
    """What the cart pendulum's tasks share: the force as action, the state as observation, a
    non-finite state as the end (:meth:`EpisodeTask.get_termination`). A task that observes more
    names it in ``observation_names`` and extends :meth:`get_observation`."""

    observation_names: ClassVar[tuple[str, ...]] = STATE_NAMES
    action_name = "force"
    interval_s = CONTROL_DT_S


class Balance(CartPendulumTask):
    """Keep the pole upright; reward ``-beta^2`` of the state each step leads to.

    Each episode (initial state and disturbance sequence) is drawn from ``random`` on reset, or is
    a stored one queued with :meth:`use_episode` (see :class:`etmpc.systems.episodes.EpisodeTask`).
    ``disturbances`` (:class:`Disturbances`) says how they are drawn and how their disturbances are played.
    """

    episode_class = Episode
    disturbances_class = Disturbances
    intervals = ("disturbance", "disturbances")
    episode_steps = EPISODE_STEPS

    @staticmethod
    def make_physics(plant: str) -> Physics:
        root = load_model(plant)
        return Physics.from_xml_string(root.to_xml_string(), assets=root.get_assets())

    def resample_episode(self, episode: Episode, step: int, random: np.random.Generator) -> Episode:
        """``episode`` with the disturbances of intervals ``step..`` redrawn: at the decision of step
        ``step`` the controller has felt those of the earlier intervals only (they are i.i.d.)."""
        disturbance = np.array(episode.disturbance)
        disturbance[step:] = random.normal(0.0, self.disturbances.angular_std_rad_s2, size=disturbance.size - step)
        return Episode(episode.initial_state, disturbance)

    def episode_parameters(self) -> dict:
        """What the episodes are drawn from (recorded in the test set; the disturbances' scale where it is not 1)."""
        d = self.disturbances
        return {
            **initial_state_range(INITIAL_STATE_LOW, INITIAL_STATE_HIGH),
            "disturbance_std_rad_s2": d.angular_std_rad_s2,
            **({"disturbance_scale": d.disturbance_scale} if d.disturbance_scale != 1 else {}),
            "steps": EPISODE_STEPS,
        }

    def episode_ranges(self) -> dict:
        """What a stored episode may hold (checked before it is played): disturbances within ``GAUSSIAN_BOUND_STD``
        standard deviations, of the task's or the options' if larger."""
        bound = GAUSSIAN_BOUND_STD * max(DISTURBANCE_STD_RAD_S2, self.disturbances.angular_std_rad_s2)
        return {"initial_state": (INITIAL_STATE_LOW, INITIAL_STATE_HIGH), "disturbance": (-bound, bound)}

    def signals(self, episode: Episode) -> dict[str, np.ndarray]:
        """The episode's exogenous inputs, per step, for recordings."""
        return {"disturbance_rad_s2": episode.disturbance}

    def initialize_episode(self, physics: Physics) -> None:
        episode = self.next_episode()
        self._step = 0
        physics.set_state_vector(episode.initial_state)
        physics.set_disturbance(0.0)
        self._colour_pole(physics)

    def before_step(self, action, physics: Physics) -> None:
        physics.set_control(action)
        w, scale = self._episode.disturbance[self._step], self.disturbances.disturbance_scale
        physics.set_disturbance(w if scale == 1 else w * scale)
        self._step += 1

    def after_step(self, physics: Physics) -> None:
        if self.visualize_reward:
            self._colour_pole(physics)

    def _colour_pole(self, physics: Physics) -> None:
        """With ``visualize_reward``, the pole's colour goes from its own blue (upright) to red
        (fallen) by ``exp(reward)`` in (0, 1], as the suite colours its bodies; without, its own."""
        upright = 1.0
        if self.visualize_reward:
            reward = self.get_reward(physics)
            upright = math.exp(reward) if math.isfinite(reward) else 0.0
        physics.named.model.mat_rgba["pole", :3] = upright * _POLE_RGB + (1.0 - upright) * _FALLEN_RGB

    def get_reward(self, physics: Physics) -> float:
        return -(physics.pole_angle() ** 2)


make_environment = Balance.environment  # the task's dm-control environment (plant=, disturbances=, ...)
