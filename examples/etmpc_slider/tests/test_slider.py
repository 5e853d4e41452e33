"""The slider's track task: the analytic model against MuJoCo (pins the conventions), the MPC against
Ipopt, the observation against the physics, the episode law and its sampled futures, the stored test
set, the scene and the driftage:X:T trigger."""

import casadi as ca
import numpy as np
import pytest
from absl.testing import absltest
from dm_env import test_utils
from scipy.integrate import solve_ivp

import etmpc_slider
from etmpc.common.errors import EtmpcError, UnknownNameError
from etmpc.control.discretise import rk4
from etmpc.evaluation import testsets
from etmpc.loop import AugmentedState, run_episode
from etmpc.policies import parse_policy
from etmpc.systems import make_system
from etmpc.systems.episodes import build_environment
from etmpc_slider import task as st
from etmpc_slider.model import AnalyticModel, ode
from etmpc_slider.system import SliderSystem
from etmpc_slider.trigger import DriftOrAge, build


@pytest.fixture(scope="module")
def system():
    return SliderSystem()


# -- the plant against the analytic model -------------------------------------------------------------
def f(x, u):
    return np.asarray(ode(x, u), dtype=float).ravel()


def rk4_trajectory(x0, inputs, h, dt=st.CONTROL_DT_S):
    """The model's ODE by classic RK4 of step ``h`` on numbers (MuJoCo's ``integrator="RK4"``), with
    etmpc's ``rk4`` (the scheme the MPC's model uses, here on numpy arrays, not CasADi)."""
    states, x = [np.asarray(x0, float)], np.asarray(x0, float)
    for u in inputs:
        x = rk4(f, x, u, dt, round(dt / h))
        states.append(x)
    return np.array(states)


def exact_trajectory(x0, inputs, dt=st.CONTROL_DT_S):
    """The model's ODE solved to 1e-11 by scipy (independent of CasADi's RK4 and of MuJoCo)."""
    states, x = [np.asarray(x0, float)], np.asarray(x0, float)
    for u in inputs:
        x = solve_ivp(lambda t, y: f(y, u), (0, dt), x, method="DOP853", rtol=1e-11, atol=1e-12).y[:, -1]
        states.append(x)
    return np.array(states)


def plant_trajectory(plant, x0, inputs, physics_dt=st.PHYSICS_DT_S):
    root = st.load_model(plant, timestep_s=physics_dt)
    physics = st.Physics.from_xml_string(root.to_xml_string(), assets=root.get_assets())
    env = build_environment(physics, st.Track(), round(3.0 / st.CONTROL_DT_S), st.CONTROL_DT_S)
    env.task.use_episode(st.Episode(np.asarray(x0, float), np.zeros(st.EPISODE_STEPS)))
    env.reset()
    states = [env.physics.state()]
    for u in inputs:
        env.step(np.atleast_1d(u))
        states.append(env.physics.state())
    return np.array(states)


@pytest.mark.parametrize("x0, seed", [([0.0, 0.0], 1), ([0.5, -0.4], 2), ([-0.8, 1.5], 3)])
def test_matched_plant_follows_the_analytic_model(x0, seed):
    """Over 1.5 s: the matched plant is the ODE by RK4 at its 0.01 s step, to rounding; against the
    ODE solved to 1e-11 it differs by RK4's truncation only (fourth order: 16 times less at half the
    step, asserted >= 12). The default plant is off by far more (its spring and damping)."""
    inputs = np.random.default_rng(seed).uniform(-10, 10, (30, 1))
    matched = plant_trajectory("matched", x0, inputs)
    np.testing.assert_allclose(matched, rk4_trajectory(x0, inputs, st.PHYSICS_DT_S), rtol=0, atol=1e-10)
    exact = exact_trajectory(x0, inputs)
    error, halved = (np.max(np.abs(plant_trajectory("matched", x0, inputs, h) - exact)) for h in (0.01, 0.005))
    assert error < 1e-5 and halved < error / 12, (error, halved)
    assert np.max(np.abs(plant_trajectory("mismatched", x0, inputs) - exact)) > 1e-2


def test_conventions():
    """A positive force pushes the block along +x; the spring pulls it back to 0."""
    pushed = plant_trajectory("matched", [0.0, 0.0], [[5.0]] * 4)
    assert np.all(np.diff(pushed[:, 0]) > 0)
    released = plant_trajectory("matched", [0.5, 0.0], [[0.0]])
    assert released[-1, 0] < 0.5 and released[-1, 1] < 0


def test_the_predictor_is_rk4_of_the_ode():
    model = AnalyticModel()
    for x0, u in [([0.1, 2.0], [10.0]), ([-0.7, -1.0], [-3.0])]:
        x0, u = np.array(x0, float), np.array(u, float)
        expected = rk4_trajectory(x0, [u], st.CONTROL_DT_S)[-1]
        np.testing.assert_allclose(model.predict(x0, u), expected, rtol=0, atol=1e-12)


def test_with_the_matched_plant_a_kept_plan_predicts_the_plant(system):
    """Kept to its end (``never``), a plan predicts the matched plant to RK4's truncation (< 1e-4 per
    state); the default plant drifts from it by far more, and more the older the plan."""
    episode = st.Episode.draw(np.random.default_rng(5))
    errors = {}
    for plant in ("matched", "mismatched"):
        sys_ = SliderSystem(SliderSystem.Config(plant=plant))
        traj = run_episode(sys_, sys_.make_env(), parse_policy("never", sys_), None, episode)
        errors[plant] = np.abs(traj.states[: traj.steps] - traj.predicted)
    assert errors["matched"].max() < 1e-4
    assert errors["mismatched"].max() > 5e-3


# -- the loop's view ------------------------------------------------------------------------------------
def test_state_from_the_observation_is_the_physics_state_bit_for_bit(system):
    env = system.make_env(random=3)
    timestep = env.reset()
    rng = np.random.default_rng(0)
    for _ in range(st.EPISODE_STEPS):
        assert np.array_equal(system.state(timestep), system.measure(env.physics))
        assert timestep.observation[st.REFERENCE] == env.task.current_reference()
        timestep = env.step(rng.uniform(-10, 10, 1))
    assert timestep.last()


def test_the_system_has_every_member_etmpc_asks_for(system):
    from etmpc.systems.base import DERIVED, REQUIRED, SystemBase
    from etmpc.systems.capabilities import CAPABILITIES, feature, offers

    assert isinstance(system, SystemBase) and [m for m in REQUIRED + DERIVED if not hasattr(system, m)] == []
    offered = {feature(c) for c in CAPABILITIES if offers(system, c)}
    assert offered == {"experiments", "rollouts", "exogenous features", "scene", "bench", "time in the loop", "failures"}
    assert (system.name, system.objective_sense, system.horizon, system.recompute_price) == ("slider/track", "min", 10, 0.13)
    assert system.u_min.shape == system.u_max.shape == (1,) and system.error_weights.shape == (2,)


def test_failures_are_the_steps_ending_farther_than_a_tenth_of_a_metre_from_the_reference(system):
    episode = system.draw_episode(np.random.default_rng(5))
    traj = run_episode(system, system.make_env(), parse_policy("every:5", system), None, episode)
    far = np.abs(traj.states[1:, 0] - episode.reference) > 0.1  # the block's position against each interval's reference
    assert system.failures(traj, episode) == int(far.sum()) > 0


def test_the_registry_and_the_suite_know_the_slider():
    assert etmpc_slider.TASKS == ("track",) == tuple(etmpc_slider.SUITE) == tuple(etmpc_slider.SYSTEMS)
    assert isinstance(make_system("slider"), SliderSystem)
    assert make_system("slider").name == "slider/track"
    env = etmpc_slider.SUITE["track"](random=0)
    assert env.reset().observation["reference_m"] == env.task.episode.reference[0]
    assert set(etmpc_slider.SUITE.tagged("benchmarking")) == {"track"}
    with pytest.raises(UnknownNameError):
        st.load_model("stiff")


class TrackContractTest(test_utils.EnvironmentTestMixin, absltest.TestCase):
    """dm_env's contract, over two episode ends of 10 steps."""

    def make_object_under_test(self):
        return etmpc_slider.SUITE["track"](random=0, time_limit=0.5)

    def make_action_sequence(self):
        rng = np.random.default_rng(1)
        for _ in range(23):
            yield rng.uniform(-10, 10, 1)


# -- the MPC against Ipopt --------------------------------------------------------------------------------
def ipopt_reference(system, x, u_prev, r):
    """The OCP transcribed independently (full multiple shooting, the residuals written out here),
    solved by Ipopt to 1e-12 from zero inputs rolled out."""
    model, c = system.model.discrete, system.config
    n = c.horizon
    X, U = ca.SX.sym("X", 2, n + 1), ca.SX.sym("U", 1, n)
    du = U - ca.horzcat(ca.DM(u_prev), U[:, :-1])
    e = (X[0, :] - r) / 0.2
    obj = ca.sumsqr(e[:n]) + ca.sumsqr(0.05 * X[1, :n]) + ca.sumsqr(0.02 * (U - 4.0 * r)) + ca.sumsqr(0.02 * du)
    obj += ca.sumsqr(2 * e[n]) + ca.sumsqr(0.3 * X[1, n])
    nlp = {
        "x": ca.vertcat(ca.vec(X), ca.vec(U)),
        "f": obj,
        "g": ca.vertcat(X[:, 0] - x, *[model(X[:, k], U[:, k]) - X[:, k + 1] for k in range(n)]),
    }
    solver = ca.nlpsol(
        "reference",
        "ipopt",
        nlp,
        {
            "print_time": False,
            "ipopt.print_level": 0,
            "ipopt.sb": "yes",
            "ipopt.tol": 1e-12,
            "ipopt.acceptable_iter": 0,
            "ipopt.max_iter": 1000,
        },
    )
    states = system.mpc.rollout(x, np.zeros((n, 1)))
    bound = np.full(n, c.force_limit_n)
    sol = solver(
        x0=np.concatenate([states.ravel(), np.zeros(n)]),
        lbx=np.r_[np.full(2 * (n + 1), -np.inf), -bound],
        ubx=np.r_[np.full(2 * (n + 1), np.inf), bound],
        lbg=0,
        ubg=0,
    )
    assert solver.stats()["success"]
    return float(sol["f"]), np.asarray(sol["x"]).ravel()[2 * (n + 1) :]


def test_optimum_matches_ipopt(system):
    """The OCP is a convex QP: one optimum, which both reach (objectives within 1e-7, relative; inputs
    within 1e-5 N), from a cold start and warm, after a drift and a jump of the reference."""
    rng = np.random.default_rng(11)
    for _ in range(12):
        x, u_prev, r = rng.uniform([-1, -2], [1, 2]), rng.uniform(-10, 10, 1), rng.uniform(-0.8, 0.8)
        plan = system.mpc.solve(x, u_prev, parameters=[r])
        assert plan.success, plan.status
        cost, inputs = ipopt_reference(system, x, u_prev, r)
        assert abs(plan.cost - cost) <= 1e-7 * abs(cost), (plan.cost, cost)
        np.testing.assert_allclose(plan.inputs.ravel(), inputs, atol=1e-5)
        assert plan.cost == pytest.approx(system.mpc.objective(x, u_prev, plan.inputs, [r]), rel=1e-7)
        x_next, r_next = plan.states[1] + np.array([0.01, -0.05]), rng.uniform(-0.8, 0.8)
        warm = system.mpc.solve(x_next, plan.inputs[0], plan, 1, parameters=[r_next])
        cost, _ = ipopt_reference(system, x_next, plan.inputs[0], r_next)
        assert warm.success and abs(warm.cost - cost) <= 1e-7 * abs(cost), (warm.cost, cost)


def test_the_feedback_gains_are_the_riccati_recursion_along_the_plan(system):
    """The model is linear: the gains are numpy's Riccati recursion on its exact ``(A, B)`` from ``P_N = 10 Q``."""
    plan = system.mpc.solve(np.array([0.3, 0.0]), np.zeros(1), parameters=[-0.6])
    x, u = ca.SX.sym("x", 2), ca.SX.sym("u", 1)
    nxt = system.model.discrete(x, u)
    A = np.array(ca.Function("A", [x, u], [ca.jacobian(nxt, x)])(0, 0))
    B = np.array(ca.Function("B", [x, u], [ca.jacobian(nxt, u)])(0, 0))
    Q, R = np.diag(system.config.feedback_state_weights), np.diag(system.config.feedback_input_weights)
    P, gains = 10 * Q, []
    for _ in range(system.horizon):
        K = np.linalg.solve(R + B.T @ P @ B, B.T @ P @ A)
        P = Q + A.T @ P @ (A - B @ K)
        gains.append(K)
    np.testing.assert_allclose(plan.gains, np.array(gains[::-1]), rtol=1e-9)


# -- episodes, futures and the stored test set -----------------------------------------------------------
def test_episodes_are_drawn_from_the_generator_and_stored_exactly(system):
    a, b = (system.draw_episode(np.random.default_rng(7)) for _ in range(2))
    assert np.array_equal(a.initial_state, b.initial_state) and np.array_equal(a.reference, b.reference)
    back = system.episode_from_arrays(a.arrays())
    assert np.array_equal(back.reference, a.reference) and a.reference.shape == (st.EPISODE_STEPS,)
    with pytest.raises(ValueError):
        system.episode_from_arrays({"initial_state": np.zeros(3), "reference": np.zeros(60)})
    with pytest.raises(ValueError):
        system.make_env().task.use_episode(st.Episode(np.zeros(2), np.zeros(10)))


def test_a_sampled_future_keeps_what_was_seen_and_redraws_the_rest_by_the_task_law(system):
    episode = system.draw_episode(np.random.default_rng(2))
    futures = [system.sample_future(episode, 20, np.random.default_rng(s)) for s in range(200)]
    for future in futures:
        assert np.array_equal(future.reference[:21], episode.reference[:21])
        assert np.array_equal(future.initial_state, episode.initial_state)
    # Jumps after step 20 come at the task's rate (0.05 per interval, 39 intervals).
    jumps = np.mean([np.count_nonzero(np.diff(f.reference[20:])) for f in futures])
    assert jumps == pytest.approx(39 * st.JUMP_PROBABILITY, rel=0.2)
    assert any(not np.array_equal(f.reference, episode.reference) for f in futures)


def test_the_stored_test_set_regenerates_bit_for_bit(system):
    path = testsets.default_path("slider", "track")
    assert path == etmpc_slider.DATA / "track" / "testset.npz"
    stored = testsets.load(path, "slider", "track")
    assert stored.episodes == 100
    arrays, meta = testsets.generate(system, etmpc_slider.TEST_SET_SEEDS["track"], 100)
    assert testsets.encode(arrays, meta) == path.read_bytes()
    stored.check_playable(system, system.make_env().task)


# -- the scene --------------------------------------------------------------------------------------------
def test_a_frame_renders(system):
    """The side camera shows the block (blue) where ``show`` puts it: further right for a larger ``p``."""
    env = system.make_env(random=0)
    env.reset()

    def block_column(p):
        system.show(env.physics, np.array([p, 0.0]))
        frame = env.physics.render(240, 320, camera_id=system.camera).astype(int)
        blue = frame[..., 2] > frame[..., 0] + 80
        assert blue.sum() > 20 and frame.std() > 5
        return np.nonzero(blue)[1].mean()

    assert block_column(-0.6) + 50 < block_column(0.0) < block_column(0.6) - 50


# -- driftage:X:T -------------------------------------------------------------------------------------------
def test_driftage_parses_its_argument(system):
    policy = build("0.5:4", "driftage:0.5:4", system)
    assert policy == DriftOrAge(0.5, 4, policy.weights) and policy.spec == "driftage:0.5:4" and not policy.stochastic
    np.testing.assert_array_equal(policy.weights, system.error_weights)
    bad_args = ("", "0.5", "0.5:", ":4", "x:4", "0.5:0", "0.5:2.5", "-1:4", "inf:4", "nan:4", "0.5:4:1", " 0.5:4", "0.5: 4")
    for bad in bad_args:
        with pytest.raises(EtmpcError, match="bad policy"):
            build(bad, f"driftage:{bad}", system)


def test_driftage_recomputes_on_drift_or_age(system):
    policy = build("0.5:3", "driftage:0.5:3", system)
    w = system.error_weights

    def s(error, age):
        return AugmentedState(np.array(error, float) / w, np.zeros(2), age, np.zeros(2))

    assert not policy.decide(s([0.3, 0.3], 1), None)  # |W e| = 0.42
    assert policy.decide(s([0.4, 0.4], 1), None)  # 0.57
    assert policy.decide(s([0.0, 0.0], 3), None)
    traj = run_episode(system, system.make_env(), policy, None, system.draw_episode(np.random.default_rng(0)))
    assert traj.plan_age.max() <= 2 and traj.recomputes >= st.EPISODE_STEPS // 3
