"""The quadrotor's waypoints task: the analytic rigid body against MuJoCo (pins the conventions), the
declared mismatch, the episode law (waypoints, gusts), the geofence's failures, the exogenous
features, and the MPC flying to a waypoint."""

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from etmpc.loop import run_episode
from etmpc.policies import parse_policy
from etmpc.systems.episodes import Environment, environment_kwargs_for
from etmpc.systems.quadrotor import physics as qp
from etmpc.systems.quadrotor import task as qt
from etmpc.systems.quadrotor.model import Parameters, ode
from etmpc.systems.quadrotor.system import QuadrotorSystem

HOVER = Parameters().hover_thrust_n


def environment(plant: str, episode: qt.Episode, physics_dt: float = qt.PHYSICS_DT_S) -> Environment:
    root = qt.load_model(plant, timestep_s=physics_dt)
    physics = qt.Physics.from_xml_string(root.to_xml_string(), assets=root.get_assets())
    env = Environment(
        physics, qt.Waypoints(), **environment_kwargs_for(qt.EPISODE_STEPS * qt.CONTROL_DT_S, qt.CONTROL_DT_S, None)
    )
    env.task.use_episode(episode)
    return env


def calm(x0, target=(0.0, 0.0, 1.0)) -> qt.Episode:
    """An episode with no gust and one waypoint."""
    steps = qt.EPISODE_STEPS
    return qt.Episode(np.asarray(x0, float), np.tile(target, (steps, 1)), np.zeros((steps, 3)), np.zeros(steps, dtype=np.int64))


def analytic(x0, inputs):
    """The model's ODE integrated to 1e-11 by scipy (independent of CasADi's RK4 and of MuJoCo)."""
    states, x = [np.asarray(x0, float)], np.asarray(x0, float)
    for u in inputs:
        rhs = lambda t, y: np.asarray(ode(y, u), dtype=float).ravel()  # noqa: E731
        x = solve_ivp(rhs, (0, qt.CONTROL_DT_S), x, method="DOP853", rtol=1e-11, atol=1e-12).y[:, -1]
        states.append(x)
    return np.array(states)


def played(plant, x0, inputs, physics_dt=qt.PHYSICS_DT_S):
    env = environment(plant, calm(x0), physics_dt)
    env.reset()
    env.physics.set_thrusts(inputs[0])  # no lag to start from: the matched plant has none anyway
    states = [env.physics.state()]
    for u in inputs:
        env.step(u)
        states.append(env.physics.state())
    return np.array(states)


X0 = np.array([0.1, -0.2, 1.0, 0.1, -0.05, 0.3, 0.2, -0.1, 0.05, 0.5, -0.3, 0.2])
INPUTS = [np.array([1.1, 1.0, 0.9, 1.0]) * HOVER, np.array([1.0, 1.2, 1.0, 0.8]) * HOVER, np.array([1.1, 0.9, 1.1, 0.9]) * HOVER]


def test_the_matched_plant_is_the_analytic_model():
    """Roll, pitch and yaw torques of each sign, and the gyroscopic coupling (all rates non-zero): the
    conventions of the MJCF and of model.py agree to the integrators' error. MuJoCo integrates the
    orientation to second order: at the task's 5 ms the angles differ by 2e-5 after three intervals,
    at 0.5 ms by 2e-7 (as dt^2)."""
    expected = analytic(X0, INPUTS)
    np.testing.assert_allclose(played("matched", X0, INPUTS, physics_dt=5e-4), expected, atol=1e-6)
    np.testing.assert_allclose(played("matched", X0, INPUTS), expected, atol=5e-5)


def test_the_default_plant_differs_as_declared():
    root = qt.load_model("mismatched")
    inertial = root.find("body", "drone").inertial
    assert inertial.mass == pytest.approx(0.030) and Parameters().mass_kg == pytest.approx(0.027)
    np.testing.assert_allclose(inertial.diaginertia, 1.2 * np.array(Parameters().inertia_kg_m2), rtol=1e-3)
    assert [root.find("actuator", r).dynprm[0] for r in qp.ROTORS] == [0.01] * 4
    assert root.option.density == pytest.approx(1.2)
    # the model's hover thrust cannot hold the heavier plant: it sinks, where the model would stay
    hover = [np.full(4, HOVER)] * 4
    level = np.array([0, 0, 1.0] + [0.0] * 9)
    assert played("mismatched", level, hover)[-1, 2] < 1.0 - 0.01
    assert analytic(level, hover)[-1, 2] == pytest.approx(1.0, abs=1e-9)


def test_euler_angles_and_quaternions_are_inverse():
    rng = np.random.default_rng(0)
    for _ in range(50):
        angles = rng.uniform([-math.pi, -1.5, -math.pi], [math.pi, 1.5, math.pi])
        np.testing.assert_allclose(qp.euler(qp.quaternion(angles)), angles, atol=1e-12)


def test_gusts_are_one_minus_cosine_pulses_that_add():
    steps = qt.EPISODE_STEPS
    peak, intervals = np.zeros((steps, 3)), np.zeros(steps, dtype=np.int64)
    peak[10], intervals[10] = (0.1, 0.0, 0.0), 8
    peak[14], intervals[14] = (0.0, -0.05, 0.0), 4
    episode = qt.Episode(np.zeros(12), np.zeros((steps, 3)), peak, intervals)
    force = episode.gusts()
    first = 0.1 * (1 - np.cos(2 * np.pi * (np.arange(8) + 0.5) / 8)) / 2
    second = -0.05 * (1 - np.cos(2 * np.pi * (np.arange(4) + 0.5) / 4)) / 2
    np.testing.assert_allclose(force[10:18, 0], first)
    np.testing.assert_allclose(force[14:18, 1], second)
    assert not force[:10].any() and not force[18:].any() and not force[:, 2].any()


def test_the_episode_law_and_its_arrays():
    episode = qt.Episode.draw(np.random.default_rng(1))
    again = qt.Episode.from_arrays(episode.arrays())
    for name, values in episode.arrays().items():
        np.testing.assert_array_equal(values, again.arrays()[name])
    assert np.all((qt.BOX_LOW <= episode.target) & (episode.target <= qt.BOX_HIGH))
    bad = episode.arrays() | {"gust_intervals": episode.gust_intervals.astype(float)}
    with pytest.raises(ValueError, match="bad episode arrays"):
        qt.Episode.from_arrays(bad)
    # over many episodes, the waypoint changes and the gusts' onsets come at their stated rates
    rng = np.random.default_rng(2)
    draws = [qt.Episode.draw(rng) for _ in range(300)]
    changes = np.mean([np.any(np.diff(e.target, axis=0) != 0, axis=1).sum() for e in draws]) / (qt.EPISODE_STEPS - 1)
    onsets = np.mean([np.count_nonzero(e.gust_intervals) for e in draws]) / qt.EPISODE_STEPS
    assert changes == pytest.approx(qt.CHANGE_PROBABILITY, rel=0.1)
    assert onsets == pytest.approx(qt.GUST_PROBABILITY, rel=0.15)
    peaks = np.concatenate([np.linalg.norm(e.gust_peak[e.gust_intervals > 0], axis=1) for e in draws])
    assert qt.GUST_PEAK_N[0] <= peaks.min() and peaks.max() <= qt.GUST_PEAK_N[1]


def test_a_step_outside_the_geofence_or_on_the_ground_is_a_failure():
    system = QuadrotorSystem()
    for position, failed in [
        ((0, 0, 1), False),
        ((2.1, 0, 1), True),
        ((0, -2.1, 1), True),
        ((0, 0, 2.6), True),
        ((0, 0, 0.03), True),
    ]:
        env = environment("matched", calm([*position] + [0.0] * 9, target=(0.0, 0.0, 1.0)))
        env.reset()
        reward = env.step(np.zeros(4)).reward  # rotors off: it falls by less than 2 cm in an interval
        d = np.linalg.norm(env.physics.position() - (0, 0, 1))
        assert reward == pytest.approx(-(d**2) / (d**2 + 0.25) - (1.0 if failed else 0.0))
        assert (qt.failure_steps([reward]) == 1) is failed
    assert system.failure_name == "outside geofence"


@pytest.fixture(scope="module")
def system():
    return QuadrotorSystem()


def test_the_mpc_flies_to_the_waypoint_and_the_features_see_a_change(system):
    """On the matched plant, re-planning every step, the drone reaches a waypoint 1.2 m away and holds
    it; a kept plan's features show the change as its length."""
    steps = qt.EPISODE_STEPS
    target = np.tile((0.5, 0.5, 1.2), (steps, 1))
    target[60:] = (-0.5, 0.0, 0.8)
    episode = qt.Episode(np.array([-0.3, -0.4, 0.8] + [0.0] * 9), target, np.zeros((steps, 3)), np.zeros(steps, dtype=np.int64))
    matched = QuadrotorSystem(system.Config(plant="matched"))
    trajectory = run_episode(matched, matched.make_env(), parse_policy("always", matched), episode=episode)
    position = trajectory.states[1 : steps + 1, :3]
    assert np.linalg.norm(position[55] - target[55]) < 0.05
    assert np.linalg.norm(position[-1] - target[-1]) < 0.05
    assert matched.failures(trajectory, episode) == 0
    names = list(system.exogenous_feature_names)
    assert names[-1] == "target_change_m"
