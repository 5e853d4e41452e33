"""The cart pendulum's ``kicks`` task: keep the pole up and the cart on a reference that jumps, on a
rail, while kicks arrive at random times.

Where ``balance`` shakes the pole a little at every interval (Gaussian noise: no policy gains 1 %
over a periodic schedule there), ``kicks`` leaves the loop alone until something happens at a
random time: the cart's reference jumps, which a kept plan does not follow, or the pole is kicked.
The moment to recompute is right after it. Event-based sampling pays in proportion to how bursty the
disturbance is (Åström and Bernhardsson 2002); this task makes it bursty.

* **Plant**: the cart pendulum of ``physics.py`` (``mismatched`` by default), on a rail with bumpers
  at ``|eta| = 2.5 m`` (a spring-damper, 1000 N/m and 40 N s/m, past them), integrated by RK4 at
  0.01 s. The MPC predicts with the paper's analytic model, which knows neither the bumpers nor the
  plant's mismatch.
* **Episodes**: 150 intervals of 0.1 s. Initial state ``eta ~ U(+-0.5)``, ``v ~ U(+-0.3)``,
  ``beta ~ U(+-0.1)``, ``omega ~ U(+-0.3)``. The cart's reference ``r ~ U(+-1 m)``; at each later
  interval, with probability 0.04 (0.4 jumps per second), it jumps to a new one drawn alike; the
  reference of interval ``i`` is observed (``cart_reference_m``) at its decision, and a marker on
  the rail shows it. Kicks: a Poisson number per interval (rate 0.3 per second), each a jump of the
  pole's angular velocity by ``+-U(0.3, 0.8)`` rad/s of random sign, at the start of the interval,
  after its input is chosen. All drawn in advance (:class:`KickEpisode`).
* **Reward** ``-cost``, bounded (:func:`step_cost`): half ``sin^2(beta/2) / sin^2(0.6)`` (capped at
  1: 1.2 rad) plus half ``d^2 / (d^2 + 0.3^2)`` with ``d = eta - r`` (1/4 at 0.3 m off), or 1 while
  the cart presses a bumper. A **fall** (``|beta| > 1.2 rad``) costs 5 once, and the pole is caught
  and put back upright at rest where the cart is, so one fall costs an episode 5, not the rest of it;
  the controller then makes a new plan (the task says ``restarted``: the old plan no longer applies,
  and the loop's next decision is forced). Falls are counted (:func:`falls`) and reported beside the
  mean.
* **Tried first** (12 to 30 episodes each, before the reference existed): kicks alone, rate 0.5 per
  second of ``U(0.5, 1.2)`` rad/s. The periodic schedules then were not ordered by their rate (an
  aggressive new plan under mismatch did worse after a kick than the kept plan and its feedback), and
  falls (0.3 per episode even recomputing every step) ruled the variance: the rollout policy's gain
  had a CI including 0. Gentler kicks removed the falls and with them anything for a policy to gain.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import mujoco
import numpy as np

from etmpc.common.declared import Checked
from etmpc.systems.cart_pendulum.model import NX, STATE_NAMES
from etmpc.systems.cart_pendulum.physics import Bumpers, Physics, load_model
from etmpc.systems.cart_pendulum.task import CartPendulumTask
from etmpc.systems.tracking import initial_state_range
from etmpc.systems.episodes import MAX_EVENTS_PER_S, Random, drawn_setting, jump_process, jumps_setting, scale_setting

CONTROL_DT_S = 0.1
PHYSICS_DT_S = 0.01  # 10 RK4 steps per interval: the bumpers' spring (31 rad/s on the cart) needs them
EPISODE_STEPS = 150
INITIAL_STATE_LOW = np.array([-0.5, -0.3, -0.1, -0.3])  # eta, v, beta, omega
INITIAL_STATE_HIGH = -INITIAL_STATE_LOW
KICKS_PER_S = 0.3
KICK_RAD_S = (0.3, 0.8)  # |delta omega| ~ U(low, high), random sign
MAX_KICK_RAD_S = 100.0  # the largest kick an option may draw
MOST_KICKS = 10  # in one interval, for a stored episode's range (a Poisson count of mean 0.03: 11 has probability 4e-25)
BUMPERS = Bumpers(position_m=2.5, stiffness_n_m=1000.0, damping_n_s_m=40.0)
REFERENCE_M = 1.0  # the cart's reference ~ U(+-1 m)
REFERENCE_JUMPS_PER_S = 0.4
REFERENCE_JUMP_PROBABILITY = REFERENCE_JUMPS_PER_S * CONTROL_DT_S  # per interval after the first
POSITION_SCALE_M = 0.3  # tracking cost d^2 / (d^2 + 0.3^2)
OBSERVATION_NAMES = (*STATE_NAMES, "cart_reference_m")
FALL_RAD = 1.2
FALL_COST = 5.0
ANGLE_SCALE_RAD = 0.6  # cost sin^2(beta/2) / sin^2(0.6): 1 at beta = 1.2 rad


@dataclass(frozen=True)
class Disturbances(Checked):
    """The task's disturbances, as options (``--option disturbances.kick_scale=2``). The rates and sizes say how
    episodes are drawn (``etmpc testset --option ...`` draws a test set with them; a rollout redraws a future
    with them); ``kick_scale`` multiplies every kick as it is played, a stored episode's too, so that one test
    set measures a trigger against stronger or gentler kicks, episode by episode (``etmpc robustness``)."""

    kicks_per_s: float = drawn_setting(KICKS_PER_S, MAX_EVENTS_PER_S, "the kicks' Poisson rate, as episodes are drawn", "1/s")
    kick_rad_s: tuple[float, ...] = drawn_setting(  # |delta omega| ~ U(low, high), random sign
        KICK_RAD_S, MAX_KICK_RAD_S, "a kick's size on the pole's rate ~ U(low, high), random sign", "rad/s", True
    )
    kick_scale: float = scale_setting("kick")
    reference_jumps_per_s: float = jumps_setting(REFERENCE_JUMPS_PER_S, CONTROL_DT_S, "the cart reference")

    @property
    def reference_jump_probability(self) -> float:
        return self.reference_jumps_per_s * CONTROL_DT_S


@dataclass(frozen=True)
class KickEpisode:
    """Everything random about one episode, drawn in advance: a test-set row."""

    initial_state: np.ndarray  # (4,) [eta, v, beta, omega]
    kick: np.ndarray  # (steps,) rad/s: the sum of the kicks at the start of each interval (mostly 0)
    reference: np.ndarray  # (steps,) m: the cart's reference in each interval

    @classmethod
    def draw(cls, rng: np.random.Generator, steps: int = EPISODE_STEPS, disturbances: Disturbances | None = None) -> KickEpisode:
        d = Disturbances() if disturbances is None else disturbances
        initial_state = rng.uniform(INITIAL_STATE_LOW, INITIAL_STATE_HIGH)
        kick = draw_kicks(rng, steps, d)
        first = draw_reference(rng)
        return cls(initial_state, kick, np.concatenate([[first], continue_references(rng, first, steps - 1, d)]))

    def arrays(self) -> dict[str, np.ndarray]:
        return {"initial_state": self.initial_state, "kick": self.kick, "reference": self.reference}

    @classmethod
    def from_arrays(cls, arrays: dict[str, np.ndarray]) -> KickEpisode:
        initial_state = np.asarray(arrays["initial_state"], dtype=float)
        kick = np.asarray(arrays["kick"], dtype=float)
        reference = np.asarray(arrays["reference"], dtype=float)
        if initial_state.shape != (NX,) or kick.ndim != 1 or reference.shape != kick.shape:
            raise ValueError(f"bad episode arrays: {initial_state.shape}, {kick.shape}, {reference.shape}")
        return cls(initial_state, kick, reference)


def draw_kicks(rng: np.random.Generator, steps: int, disturbances: Disturbances | None = None) -> np.ndarray:
    """Each interval's kicks summed: a Poisson count (``kicks_per_s`` per second), each ``+-U(kick_rad_s)``."""
    d = Disturbances() if disturbances is None else disturbances
    counts = rng.poisson(d.kicks_per_s * CONTROL_DT_S, size=steps)
    n = int(counts.sum())
    low, high = d.kick_rad_s
    sizes = rng.uniform(low, high, size=n) * rng.choice([-1.0, 1.0], size=n)
    kick = np.zeros(steps)
    np.add.at(kick, np.repeat(np.arange(steps), counts), sizes)
    return kick


def draw_reference(rng: np.random.Generator) -> float:
    """A cart reference: ``U(-REFERENCE_M, REFERENCE_M)``."""
    return float(rng.uniform(-REFERENCE_M, REFERENCE_M))


def continue_references(
    rng: np.random.Generator, current: float, steps: int, disturbances: Disturbances | None = None
) -> np.ndarray:
    """The references of the ``steps`` intervals after one whose reference is ``current``: each
    jumps to a new one with the disturbances' probability per interval, else keeps the one before."""
    probability = (Disturbances() if disturbances is None else disturbances).reference_jump_probability
    return jump_process(rng, np.float64(current), steps, probability, draw_reference)


def step_cost(angle_rad: float, position_error_m: float, on_bumper: bool) -> float:
    """A step's cost in [0, 1] (see the module's docstring): half the angle's, half the tracking's;
    1 on a bumper."""
    if on_bumper:
        return 1.0
    angle = min(math.sin(0.5 * angle_rad) ** 2 / math.sin(ANGLE_SCALE_RAD) ** 2, 1.0)
    d2 = position_error_m * position_error_m
    return 0.5 * angle + 0.5 * d2 / (d2 + POSITION_SCALE_M**2)


def fall_margin(x: np.ndarray) -> float:
    """How far (rad) the pole keeps from a fall one control interval on at its current rate:
    ``FALL_RAD - |beta + omega dt|`` (at most 0: it would fall). A shield's reading (``shield:``)."""
    return FALL_RAD - abs(float(x[2]) + float(x[3]) * CONTROL_DT_S)


def falls(rewards: np.ndarray) -> int:
    """The falls of an episode, from its rewards (a fall's step costs ``FALL_COST``; no other reaches it)."""
    return int(np.sum(np.asarray(rewards) <= -FALL_COST))


class Kicks(CartPendulumTask):
    """Keep the pole upright and the cart on its reference, on the rail, through random kicks and
    reference jumps (see the module's docstring)."""

    episode_class = KickEpisode
    disturbances_class = Disturbances
    intervals = ("kick", "kicks")
    observation_names = OBSERVATION_NAMES
    interval_s = CONTROL_DT_S
    episode_steps = EPISODE_STEPS

    def __init__(self, random: Random = None, steps: int = EPISODE_STEPS, disturbances: Disturbances | None = None):
        super().__init__(random, steps, disturbances)
        self._fell = False

    @staticmethod
    def make_physics(plant: str) -> Physics:
        root = load_model(plant, timestep_s=PHYSICS_DT_S, bumpers=BUMPERS, reference=True)
        physics = Physics.from_xml_string(root.to_xml_string(), assets=root.get_assets())
        physics.bumpers = BUMPERS
        return physics

    def resample_episode(self, episode: KickEpisode, step: int, random: np.random.Generator) -> KickEpisode:
        """``episode`` with the kicks of intervals ``step..`` and the references after ``step``
        redrawn: at the decision of step ``step`` the controller has felt only the earlier kicks and
        sees that interval's reference (kicks and jumps are memoryless)."""
        kick, reference = np.array(episode.kick), np.array(episode.reference)
        kick[step:] = draw_kicks(random, kick.size - step, self.disturbances)
        reference[step + 1 :] = continue_references(random, reference[step], reference.size - step - 1, self.disturbances)
        return KickEpisode(episode.initial_state, kick, reference)

    def episode_parameters(self) -> dict:
        """What the episodes are drawn from (recorded in the test set; the kicks' scale where it is not 1)."""
        d = self.disturbances
        return {
            **initial_state_range(INITIAL_STATE_LOW, INITIAL_STATE_HIGH),
            "kicks_per_s": d.kicks_per_s,
            "kick_rad_s": list(d.kick_rad_s),
            **({"kick_scale": d.kick_scale} if d.kick_scale != 1 else {}),
            "steps": EPISODE_STEPS,
            "reference_m": REFERENCE_M,
            "reference_jump_probability": d.reference_jump_probability,
            "position_scale_m": POSITION_SCALE_M,
            "bumpers": asdict(BUMPERS),
            "fall_rad": FALL_RAD,
            "fall_cost": FALL_COST,
        }

    def episode_ranges(self) -> dict:
        """What a stored episode may hold (checked before it is played)."""
        kick = MOST_KICKS * max(KICK_RAD_S[1], self.disturbances.kick_rad_s[1])
        return {
            "initial_state": (INITIAL_STATE_LOW, INITIAL_STATE_HIGH),
            "kick": (-kick, kick),
            "reference": (-REFERENCE_M, REFERENCE_M),
        }

    def signals(self, episode: KickEpisode) -> dict[str, np.ndarray]:
        """The episode's kicks and the cart's reference, per step, for recordings."""
        return {"kick_rad_s": episode.kick, OBSERVATION_NAMES[-1]: episode.reference}

    def current_reference(self) -> float:
        """The reference of the interval about to be played (the last one's once the episode is over)."""
        return float(self.current("reference"))

    def initialize_episode(self, physics: Physics) -> None:
        episode = self.next_episode()
        self._step, self._fell, self.restarted = 0, False, False
        physics.bumpers = BUMPERS
        physics.set_state_vector(episode.initial_state)
        physics.set_disturbance(0.0)
        physics.set_reference(self.current_reference())

    def before_step(self, action, physics: Physics) -> None:
        physics.set_control(action)
        kick = self._episode.kick[self._step]
        if kick:
            scale = self.disturbances.kick_scale
            physics.add_angular_velocity(kick if scale == 1 else kick * scale)
        self._step += 1

    def after_step(self, physics: Physics) -> None:
        """A fall: the pole is caught and put back upright, at rest, where the cart is. The marker
        moves to the next interval's reference, as the observation shows it."""
        physics.set_reference(self.current_reference())
        self._fell = self.restarted = abs(physics.pole_angle()) > FALL_RAD  # restarted: the loop recomputes
        if self._fell:
            physics.set_state_vector(np.array([physics.cart_position(), 0.0, 0.0, 0.0]))
            mujoco.mj_forward(physics.model.ptr, physics.data.ptr)

    def get_reward(self, physics: Physics) -> float:
        """Against the reference of the interval just played."""
        if self._fell:
            return -FALL_COST
        error = physics.cart_position() - float(self._episode.reference[self._step - 1])
        return -step_cost(physics.pole_angle(), error, physics.touches_bumper())

    def observation_values(self, physics: Physics) -> np.ndarray:
        return np.append(physics.state(), self.current_reference())


make_environment = Kicks.environment  # the task's dm-control environment (plant=, disturbances=, ...)
