"""The cart pendulum's ``kicks`` task: keep the pole up, on a rail, while kicks arrive at random times.

Where ``balance`` shakes the pole a little at every interval (Gaussian noise: no trigger gains 1 %
over a periodic schedule there), ``kicks`` leaves it alone until a kick comes, at a random time: the
moment to re-plan is right after it. Event-based sampling pays in proportion to how bursty the
disturbance is (Åström and Bernhardsson 2002); this task makes it bursty.

* **Plant**: the cart pendulum of ``physics.py`` (``mismatched`` by default), on a rail with bumpers
  at ``|eta| = 2.5 m`` (a spring-damper, 1000 N/m and 40 N s/m, past them), integrated by RK4 at
  0.01 s. The MPC predicts with the paper's analytic model, which knows neither the bumpers nor the
  plant's mismatch.
* **Episodes**: 150 intervals of 0.1 s. Initial state ``eta ~ U(+-0.5)``, ``v ~ U(+-0.3)``,
  ``beta ~ U(+-0.1)``, ``omega ~ U(+-0.3)``. Kicks: a Poisson number per interval (rate 0.5 per
  second), each a jump of the pole's angular velocity by ``+-U(0.5, 1.2)`` rad/s of random sign,
  at the start of the interval, after its input is chosen. Drawn in advance (:class:`KickEpisode`).
* **Reward** ``-cost``, bounded: ``sin^2(beta/2) / sin^2(0.6)`` (1 at 1.2 rad; 0 upright), or 1
  while the cart presses a bumper. A **fall** (``|beta| > 1.2 rad``) costs 5 once, and the pole is
  caught and put back upright at rest where the cart is, so one fall costs an episode 5, not the rest
  of it; the controller then makes a new plan (the task says ``restarted``: the old plan no longer
  applies, and the loop's next decision is forced). Falls are counted (:func:`falls`) and reported
  beside the mean.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np
from dm_control.rl import control

from etmpc.systems.cart_pendulum.model import NX
from etmpc.systems.cart_pendulum.physics import Bumpers, Physics, load_model
from etmpc.systems.cart_pendulum.task import SUITE, CartPendulumTask
from etmpc.systems.episodes import Environment, Random, environment_kwargs_for, steps_for

CONTROL_DT_S = 0.1
PHYSICS_DT_S = 0.01  # 10 RK4 steps per interval: the bumpers' spring (31 rad/s on the cart) needs them
EPISODE_STEPS = 150
INITIAL_STATE_LOW = np.array([-0.5, -0.3, -0.1, -0.3])  # eta, v, beta, omega
INITIAL_STATE_HIGH = -INITIAL_STATE_LOW
KICKS_PER_S = 0.5
KICK_RAD_S = (0.5, 1.2)  # |delta omega| ~ U(low, high), random sign
BUMPERS = Bumpers(position_m=2.5, stiffness_n_m=1000.0, damping_n_s_m=40.0)
FALL_RAD = 1.2
FALL_COST = 5.0
ANGLE_SCALE_RAD = 0.6  # cost sin^2(beta/2) / sin^2(0.6): 1 at beta = 1.2 rad


@dataclass(frozen=True)
class KickEpisode:
    """Everything random about one episode, drawn in advance: a test-set row."""

    initial_state: np.ndarray  # (4,) [eta, v, beta, omega]
    kick: np.ndarray  # (steps,) rad/s: the sum of the kicks at the start of each interval (mostly 0)

    @classmethod
    def draw(cls, rng: np.random.Generator, steps: int = EPISODE_STEPS) -> KickEpisode:
        initial_state = rng.uniform(INITIAL_STATE_LOW, INITIAL_STATE_HIGH)
        return cls(initial_state, draw_kicks(rng, steps))

    def arrays(self) -> dict[str, np.ndarray]:
        return {"initial_state": self.initial_state, "kick": self.kick}

    @classmethod
    def from_arrays(cls, arrays: dict[str, np.ndarray]) -> KickEpisode:
        initial_state = np.asarray(arrays["initial_state"], dtype=float)
        kick = np.asarray(arrays["kick"], dtype=float)
        if initial_state.shape != (NX,) or kick.ndim != 1:
            raise ValueError(f"bad episode arrays: {initial_state.shape}, {kick.shape}")
        return cls(initial_state, kick)


def draw_kicks(rng: np.random.Generator, steps: int) -> np.ndarray:
    """Each interval's kicks summed: a Poisson count (``KICKS_PER_S`` per second), each ``+-U(KICK_RAD_S)``."""
    counts = rng.poisson(KICKS_PER_S * CONTROL_DT_S, size=steps)
    n = int(counts.sum())
    sizes = rng.uniform(*KICK_RAD_S, size=n) * rng.choice([-1.0, 1.0], size=n)
    kick = np.zeros(steps)
    np.add.at(kick, np.repeat(np.arange(steps), counts), sizes)
    return kick


def falls(rewards: np.ndarray) -> int:
    """The falls of an episode, from its rewards (a fall's step costs ``FALL_COST``; no other reaches it)."""
    return int(np.sum(np.asarray(rewards) <= -FALL_COST))


class Kicks(CartPendulumTask):
    """Keep the pole upright on the rail through random kicks (see the module's docstring)."""

    def __init__(self, random: Random = None, steps: int = EPISODE_STEPS):
        super().__init__(random, steps)
        self._fell = False

    def check_episode(self, episode: KickEpisode) -> None:
        if episode.kick.shape[0] < self._steps:
            raise ValueError(f"episode has {episode.kick.shape[0]} kicks, need {self._steps}")

    def draw_episode(self, random: np.random.Generator) -> KickEpisode:
        return KickEpisode.draw(random, self._steps)

    def initialize_episode(self, physics: Physics) -> None:
        episode = self.next_episode()
        self._step, self._fell, self.restarted = 0, False, False
        physics.bumpers = BUMPERS
        physics.set_state_vector(episode.initial_state)
        physics.set_disturbance(0.0)

    def before_step(self, action, physics: Physics) -> None:
        physics.set_control(action)
        kick = self._episode.kick[self._step]
        if kick:
            physics.add_angular_velocity(kick)
        self._step += 1

    def after_step(self, physics: Physics) -> None:
        """A fall: the pole is caught and put back upright, at rest, where the cart is."""
        self._fell = self.restarted = abs(physics.pole_angle()) > FALL_RAD  # restarted: the loop re-plans
        if self._fell:
            physics.set_state_vector(np.array([physics.cart_position(), 0.0, 0.0, 0.0]))
            mujoco.mj_forward(physics.model.ptr, physics.data.ptr)

    def get_reward(self, physics: Physics) -> float:
        if self._fell:
            return -FALL_COST
        angle = math.sin(0.5 * physics.pole_angle()) ** 2 / math.sin(ANGLE_SCALE_RAD) ** 2
        return -max(min(angle, 1.0), 1.0 if physics.touches_bumper() else 0.0)



def make_environment(random: Random = None, plant: str = "mismatched", steps: int = EPISODE_STEPS,
                     environment_kwargs: dict | None = None) -> control.Environment:
    root = load_model(plant, timestep_s=PHYSICS_DT_S, bumpers=BUMPERS)
    physics = Physics.from_xml_string(root.to_xml_string(), assets=root.get_assets())
    physics.bumpers = BUMPERS
    task = Kicks(random=random, steps=steps)
    return Environment(physics, task, **environment_kwargs_for(steps * CONTROL_DT_S, CONTROL_DT_S, environment_kwargs))


@SUITE.add("benchmarking")
def kicks(time_limit: float = EPISODE_STEPS * CONTROL_DT_S, random: Random = None, plant: str = "mismatched",
          environment_kwargs: dict | None = None):
    """Keep the pole up on a 5 m rail through random kicks: 150 control intervals of 0.1 s by default."""
    return make_environment(random=random, plant=plant, steps=steps_for(time_limit, CONTROL_DT_S),
                            environment_kwargs=environment_kwargs)
