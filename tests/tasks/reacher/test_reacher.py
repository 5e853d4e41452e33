"""The reacher's jumps task: the analytic arm against MuJoCo (pins the conventions), the MPC against
Ipopt, the episode law and its sampled futures, exact replay, failures and the exogenous features."""

import casadi as ca
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from etmpc.evaluation import testsets as testset
from etmpc.loop import AugmentedState, run_episode
from etmpc.policies import parse_policy
from etmpc.policies.features import raw_features, raw_names
from etmpc.systems.episodes import Environment, environment_kwargs_for
from etmpc.systems.reacher import task as rt
from etmpc.systems.reacher.model import AnalyticModel, ode
from etmpc.systems.reacher.system import EXOGENOUS_FEATURES, ReacherSystem


@pytest.fixture(scope="module")
def system():
    return ReacherSystem()


@pytest.fixture(scope="module")
def stored(system):
    return testset.load(testset.default_path("reacher", "jumps"), "reacher", "jumps")


# -- the plant against the analytic model -------------------------------------------------------------
def analytic_trajectory(x0, inputs, dt=rt.CONTROL_DT_S):
    """The model's ODE integrated to 1e-11 by scipy (independent of CasADi's RK4 and of MuJoCo)."""
    states, x = [np.asarray(x0, float)], np.asarray(x0, float)
    for u in inputs:
        rhs = lambda t, y: np.asarray(ode(y, u), dtype=float).ravel()  # noqa: E731
        x = solve_ivp(rhs, (0, dt), x, method="DOP853", rtol=1e-11, atol=1e-12).y[:, -1]
        states.append(x)
    return np.array(states)


def rk4_trajectory(x0, inputs, h, dt=rt.CONTROL_DT_S):
    """The model's ODE integrated by classic RK4 of step ``h``, written out in numpy (MuJoCo's
    ``integrator="RK4"`` is this scheme, with the control held over the step)."""
    f = lambda x, u: np.asarray(ode(x, u), dtype=float).ravel()  # noqa: E731
    states, x = [np.asarray(x0, float)], np.asarray(x0, float)
    for u in inputs:
        for _ in range(round(dt / h)):
            k1 = f(x, u)
            k2 = f(x + h / 2 * k1, u)
            k3 = f(x + h / 2 * k2, u)
            k4 = f(x + h * k3, u)
            x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        states.append(x)
    return np.array(states)


def plant_trajectory(plant, x0, inputs, physics_dt=rt.PHYSICS_DT_S):
    root = rt.load_model(plant, timestep_s=physics_dt)
    physics = rt.Physics.from_xml_string(root.to_xml_string(), assets=root.get_assets())
    env = Environment(physics, rt.Jumps(), **environment_kwargs_for(rt.EPISODE_STEPS * rt.CONTROL_DT_S, rt.CONTROL_DT_S, None))
    env.task.use_episode(rt.Episode(np.asarray(x0, float), np.full((rt.EPISODE_STEPS, 2), 0.5)))
    env.reset()
    states = [env.physics.state()]
    for u in inputs:
        env.step(u)
        states.append(env.physics.state())
    return np.array(states)


CASES = [  # (initial state, input pattern)
    ([0.0, 0.0, 0.0, 0.0], "shoulder"),
    ([0.3, -1.0, 0.0, 0.0], "random"),
    ([2.0, 2.4, 1.5, -3.0], "random"),
    ([-1.0, 0.5, 0.0, 2.0], "bang"),
]


def _inputs(pattern, rng, steps=20):
    return {
        "shoulder": np.tile([1.0, 0.0], (steps, 1)),
        "random": rng.uniform(-2, 2, (steps, 2)),
        "bang": np.tile([[2.0, -2.0], [-2.0, 2.0]], (steps // 2, 1)),
    }[pattern]


@pytest.mark.parametrize("x0, pattern", CASES)
def test_matched_plant_follows_the_analytic_model(x0, pattern):
    """Over 2 s (up to 15 rad/s): the matched MuJoCo plant is the analytic ODE integrated by RK4 at
    its 0.01 s step, to rounding (1e-10 on every state; a sign, mass, inertia or damping error shows
    as 1e-2 or more, as the mismatched plant does). Against the ODE solved to 1e-11 it differs by
    RK4's truncation error only: up to 3e-4 rad/s at 0.01 s, and 16 times less at half the step
    (fourth order; asserted >= 12 times)."""
    rng = np.random.default_rng(int(100 * abs(x0[0])) + 7)
    inputs = _inputs(pattern, rng)
    matched = plant_trajectory("matched", x0, inputs)
    np.testing.assert_allclose(matched, rk4_trajectory(x0, inputs, rt.PHYSICS_DT_S), rtol=0, atol=1e-10)
    exact = analytic_trajectory(x0, inputs)
    error, halved = (
        np.max(np.abs(plant_trajectory("matched", x0, inputs, h) - exact)) for h in (rt.PHYSICS_DT_S, rt.PHYSICS_DT_S / 2)
    )
    assert error < 1e-3 and halved < error / 12, (error, halved)
    assert np.max(np.abs(plant_trajectory("mismatched", x0, inputs) - exact)) > 1e-2


def test_conventions_and_the_fingertip():
    """A positive shoulder torque turns the arm counter-clockwise (q1 grows); the fingertip is
    ``l1 (cos q1, sin q1) + l2 (cos(q1 + q2), sin(q1 + q2))``, where MuJoCo puts its site."""
    after = plant_trajectory("matched", np.zeros(4), [[1.0, 0.0]])[-1]
    assert after[0] > 0 and after[2] > 0 and after[1] < 0  # the forearm lags behind
    env = rt.make_environment(plant="matched")
    env.reset()
    for x in ([0.0, 0.0, 0, 0], [np.pi / 2, 0.0, 0, 0], [0.3, -2.0, 0, 0], [4.0, 1.0, 0, 0]):
        env.physics.set_state_vector(np.array(x, float))
        env.physics.forward()
        tip = env.physics.named.data.site_xpos["fingertip"][:2]
        np.testing.assert_allclose(env.physics.fingertip(), tip, atol=1e-12)
        np.testing.assert_allclose(AnalyticModel().fingertip(x), tip, atol=1e-12)
    np.testing.assert_allclose(AnalyticModel().fingertip([np.pi / 2, 0.0, 0, 0]), [0.0, 1.0], atol=1e-12)


def test_the_predictor_is_rk4_of_the_ode():
    """The MPC's predictor is RK4 of the ODE with two 0.05 s steps per interval, to rounding. Its
    truncation error is part of what the MPC does not know: near 13 rad/s, 0.06 rad/s in one interval
    (against the ODE solved to 1e-11)."""
    model = AnalyticModel()
    for x0, u in [([0.0, 1.0, 2.0, -3.0], [2.0, -2.0]), ([1.0, -2.0, -4.0, 6.0], [-1.0, 1.5])]:
        x0, u = np.array(x0, float), np.array(u, float)
        np.testing.assert_allclose(model.predict(x0, u), rk4_trajectory(x0, [u], rt.CONTROL_DT_S / 2)[-1], rtol=0, atol=1e-12)
        assert np.max(np.abs(model.predict(x0, u) - analytic_trajectory(x0, [u])[-1])) < 0.1


# -- the MPC against Ipopt --------------------------------------------------------------------------------
def ipopt_reference(system, x, u_prev, target, start=None):
    """The OCP transcribed independently of the MPC (full multiple shooting: every state and input a
    variable, ``x_0 = x`` an equality; the residuals written out here), solved by Ipopt to 1e-12 from
    zero inputs rolled out, as the MPC's cold start (or from ``start``'s inputs and their states, which
    Ipopt then keeps where they are: no push off the torque bounds, a barrier starting at 1e-9; pushed
    inwards, a start on the bounds slides to another local optimum)."""
    model, c = system.model.discrete, system.config
    n, nx, nu = c.horizon, 4, 2
    X, U = ca.SX.sym("X", nx, n + 1), ca.SX.sym("U", nu, n)
    du = U - ca.horzcat(ca.DM(u_prev), U[:, :-1])

    def error(k):
        q1, q12 = X[0, k], X[0, k] + X[1, k]
        return ca.vertcat(0.5 * ca.cos(q1) + 0.5 * ca.cos(q12) - target[0], 0.5 * ca.sin(q1) + 0.5 * ca.sin(q12) - target[1])

    f = sum(ca.sumsqr(error(k) / 0.3) for k in range(n)) + ca.sumsqr(0.02 * X[2:, :n]) + ca.sumsqr(0.01 * U)
    f += ca.sumsqr(0.02 * du) + ca.sumsqr(2 * error(n) / 0.3) + ca.sumsqr(0.1 * X[2:, n])
    nlp = {
        "x": ca.vertcat(ca.vec(X), ca.vec(U)),
        "f": f,
        "g": ca.vertcat(X[:, 0] - x, *[model(X[:, k], U[:, k]) - X[:, k + 1] for k in range(n)]),
    }
    stay = {} if start is None else {"ipopt.bound_push": 1e-12, "ipopt.bound_frac": 1e-12, "ipopt.mu_init": 1e-9}
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
            "ipopt.max_iter": 3000,
        }
        | stay,
    )
    inputs = np.zeros((n, nu)) if start is None else np.asarray(start, float)
    states = system.mpc.rollout(x, inputs)
    bound = np.full(nu * n, c.torque_limit_nm)
    sol = solver(
        x0=np.concatenate([states.ravel(), inputs.ravel()]),
        lbx=np.r_[np.full(nx * (n + 1), -np.inf), -bound],
        ubx=np.r_[np.full(nx * (n + 1), np.inf), bound],
        lbg=0,
        ubg=0,
    )
    assert solver.stats()["success"]
    return float(sol["f"])


def test_optimum_matches_ipopt(system):
    """The OCP is not convex (the elbow may bend either way, the arm reach round either way). Near the
    target it has one optimum, which both solvers reach from zero inputs (objectives within 1e-6,
    relative). Across the workspace, from a cold start and after a drift and a jump of the target from
    a warm one, Ipopt started from our plan must not find anything better nearby: the plan is an
    optimum to 1e-6. (From the same cold guess far from the target, the two solvers' paths reach
    different optima in about half the cases; either may be the lower.)"""
    rng = np.random.default_rng(11)
    for near in (True,) * 6 + (False,) * 6:
        x = np.array([rng.uniform(-np.pi, np.pi), rng.uniform(-2.5, 2.5), rng.uniform(-2, 2), rng.uniform(-2, 2)])
        u_prev = rng.uniform(-2, 2, 2)
        if near:
            x[1], x[2:] = rng.choice([-1, 1]) * rng.uniform(0.6, 2.5), rng.uniform(-0.3, 0.3, 2)  # elbow bent, slow
            target = system.model.fingertip(x) + rng.uniform(-0.1, 0.1, 2)
        else:
            target = rt.draw_target(rng)
        plan = system.mpc.solve(x, u_prev, parameters=target)
        assert plan.success, plan.status
        reference = ipopt_reference(system, x, u_prev, target, start=None if near else plan.inputs)
        assert abs(plan.cost - reference) <= 1e-6 * abs(reference), (near, plan.cost, reference)
        # The plan's own cost is its inputs' objective rolled out (the shooting gaps close to 1e-6).
        assert plan.cost == pytest.approx(system.mpc.objective(x, u_prev, plan.inputs, target), rel=1e-6)
        if near:
            continue
        # One step on, after a drift and a jump of the target: the warm start lands on an optimum.
        x_next, target_next = plan.states[1] + np.array([0.01, -0.01, 0.05, 0.0]), target[::-1].copy()
        warm = system.mpc.solve(x_next, plan.inputs[0], plan, 1, parameters=target_next)
        assert warm.success, warm.status
        nearby = ipopt_reference(system, x_next, plan.inputs[0], target_next, start=warm.inputs)
        assert abs(warm.cost - nearby) <= 1e-6 * abs(nearby), (warm.cost, nearby)


def test_the_feedback_gains_are_the_riccati_recursion_along_the_plan(system):
    """Independent truth: the predictor linearised by central differences and the Riccati recursion in
    numpy (``P_N = 10 Q``), against the gains the compiled solve returns, along a plan that swings the
    arm at the torque limits (far from any one operating point)."""
    x, target = np.array([0.4, 1.2, 1.0, -2.0]), np.array([0.5, -0.4])
    plan = system.mpc.solve(x, np.zeros(2), parameters=target)
    assert plan.success and np.any(np.abs(plan.inputs) > 2 - 1e-6)
    Q, R = np.diag(system.config.feedback_state_weights), np.diag(system.config.feedback_input_weights)
    predict = lambda xx, uu: np.asarray(system.model.discrete(xx, uu)).ravel()  # noqa: E731
    P, h = 10 * Q, 1e-6
    for k in range(system.horizon - 1, -1, -1):
        xk, uk = plan.states[k], plan.inputs[k]
        A = np.column_stack([(predict(xk + h * e, uk) - predict(xk - h * e, uk)) / (2 * h) for e in np.eye(4)])
        B = np.column_stack([(predict(xk, uk + h * e) - predict(xk, uk - h * e)) / (2 * h) for e in np.eye(2)])
        K = np.linalg.solve(R + B.T @ P @ B, B.T @ P @ A)
        P = Q + A.T @ P @ (A - B @ K)
        P = 0.5 * (P + P.T)
        np.testing.assert_allclose(plan.gains[k], K, rtol=1e-5, atol=1e-7)
    assert np.abs(plan.gains[0] - plan.gains[-1]).max() > 0.1  # time-varying indeed


def test_a_plan_carries_its_target_and_follows_the_predictor(system):
    env = system.make_env()
    env.task.use_episode(system.draw_episode(np.random.default_rng(3)))
    timestep = env.reset()
    x = system.state(timestep)
    plan = system.plan(x, np.zeros(2), None, 0, timestep)
    assert plan.success and plan.gains.shape == (20, 2, 4)
    target = system.observed(timestep)
    for name, value in zip(("target_x_m", "target_y_m"), target):
        np.testing.assert_array_equal(plan.forecasts[name], np.full(20, value))
    np.testing.assert_allclose(plan.states, system.mpc.rollout(x, plan.inputs), atol=1e-7)
    assert np.all(np.abs(plan.inputs) <= 2 + 1e-9)
    assert np.linalg.norm(system.model.fingertip(plan.states[-1]) - target) < 0.05  # it reaches the target
    assert plan.cost == pytest.approx(system.plan_cost(x, np.zeros(2), timestep, plan.inputs), rel=1e-9)


# -- episodes, futures, replay ----------------------------------------------------------------------------
def _jumps(targets):
    return np.any(np.diff(targets, axis=0) != 0, axis=1)


def test_the_jump_law_from_the_generator():
    """Jumps drawn by the task's own generator: a jump into each interval with probability p = 0.04
    (Bernoulli), within 4 binomial standard deviations over 200 000 intervals; gaps between jumps
    geometric (mean 1/p); new targets at radius U(0.3, 0.95) and a uniform angle. The same seed draws
    the same episode, and the global numpy generator is neither used nor disturbed."""
    rng = np.random.default_rng(2024)
    state = np.random.get_state()[1].copy()
    targets = [rt.continue_targets(rng, rt.draw_target(rng), 1000) for _ in range(200)]
    np.testing.assert_array_equal(np.random.get_state()[1], state)
    p, n = rt.JUMP_PROBABILITY, sum(t.shape[0] - 1 for t in targets)
    count = sum(int(_jumps(t).sum()) for t in targets)  # a jump into interval j: its target differs from j - 1's
    assert p == pytest.approx(0.04) and abs(count - n * p) <= 4 * np.sqrt(n * p * (1 - p)), (count, n * p)
    gaps = np.concatenate([np.diff(np.flatnonzero(_jumps(t))) for t in targets])
    assert abs(gaps.mean() - 1 / p) <= 4 * np.sqrt((1 - p) / p**2 / gaps.size)
    new = np.concatenate([t[1:][_jumps(t)] for t in targets])
    radius, angle = np.hypot(new[:, 0], new[:, 1]), np.arctan2(new[:, 1], new[:, 0])
    assert radius.min() >= 0.3 and radius.max() <= 0.95 and abs(radius.mean() - 0.625) < 0.01
    assert np.histogram(angle, bins=4, range=(-np.pi, np.pi))[0].min() > 0.22 * new.shape[0]
    first, again = rt.Episode.draw(np.random.default_rng(5)), rt.Episode.draw(np.random.default_rng(5))
    np.testing.assert_array_equal(first.target, again.target)
    np.testing.assert_array_equal(first.initial_state, again.initial_state)


def test_episodes_follow_the_law(stored):
    episodes = [rt.Episode.from_arrays(stored.episode_arrays(i)) for i in range(stored.episodes)]
    x0 = np.array([e.initial_state for e in episodes])
    assert np.all(np.abs(x0[:, 0]) <= np.pi) and np.all(np.abs(x0[:, 1]) <= 2.5) and np.all(x0[:, 2:] == 0)
    targets = np.concatenate([e.target for e in episodes])
    radius = np.hypot(targets[:, 0], targets[:, 1])
    assert radius.min() >= 0.3 and radius.max() <= 0.95
    jumps = np.concatenate([_jumps(e.target) for e in episodes])
    assert jumps.size == 100 * 99 and abs(jumps.mean() - 0.04) < 3 * np.sqrt(0.04 * 0.96 / jumps.size)


def test_sample_future_keeps_what_is_known_and_redraws_the_rest_from_the_law(system, stored):
    episode = system.episode_from_arrays(stored.episode_arrays(5))
    rng, step = np.random.default_rng(0), 37
    futures = [system.sample_future(episode, step, rng) for _ in range(400)]
    for future in futures:
        np.testing.assert_array_equal(future.initial_state, episode.initial_state)
        np.testing.assert_array_equal(future.target[: step + 1], episode.target[: step + 1])  # seen at the decision
        assert future.target.shape == episode.target.shape
    after = np.array([f.target[step:] for f in futures])  # from the known target on
    jumps = np.array([_jumps(t) for t in after])  # (400, 62): a jump into each interval after step
    rate, n = jumps.mean(), jumps.size
    assert abs(rate - rt.JUMP_PROBABILITY) < 3 * np.sqrt(rt.JUMP_PROBABILITY * (1 - rt.JUMP_PROBABILITY) / n)
    assert abs(jumps[:, 0].mean() - rt.JUMP_PROBABILITY) < 0.04  # the very next interval may jump too
    new = np.concatenate([t[1:][j] for t, j in zip(after, jumps)])
    radius, angle = np.hypot(new[:, 0], new[:, 1]), np.arctan2(new[:, 1], new[:, 0])
    assert radius.min() >= 0.3 and radius.max() <= 0.95 and abs(radius.mean() - 0.625) < 0.03
    assert abs(np.mean(angle > 0) - 0.5) < 0.06
    assert len({f.target[-1].tobytes() for f in futures}) > 100  # futures differ
    last = system.sample_future(episode, rt.EPISODE_STEPS - 1, rng)
    np.testing.assert_array_equal(last.target, episode.target)


def test_a_stored_episode_replays_exactly(system, stored):
    episode = system.episode_from_arrays(stored.episode_arrays(2))
    np.testing.assert_array_equal(rt.Episode.from_arrays(episode.arrays()).target, episode.target)
    policy = parse_policy("every:3", system)
    first = run_episode(system, system.make_env(), policy, None, episode)
    again = run_episode(system, system.make_env(), policy, None, episode)
    assert first.steps == 100 and not first.nonfinite
    np.testing.assert_array_equal(first.rewards, again.rewards)
    np.testing.assert_array_equal(first.states, again.states)


def test_an_episode_is_recorded_with_both_torques_bounds(system, stored):
    """The first task with two inputs: a recording keeps each input's bounds (and the plan's target)."""
    from etmpc.loop.records import EpisodeRecord

    episode = system.episode_from_arrays(stored.episode_arrays(1))
    traj = run_episode(system, system.make_env(), parse_policy("every:4", system), None, episode)
    record = EpisodeRecord.from_trajectory(system, traj, {"policy": "every:4"}, episode)
    np.testing.assert_array_equal(record.input_bounds[0], [-2.0, -2.0])
    np.testing.assert_array_equal(record.input_bounds[1], [2.0, 2.0])
    assert record.applied.shape == (100, 2) and set(record.plans[0][3]) == {"target_x_m", "target_y_m"}


def test_the_observation_shows_the_target_of_the_interval_about_to_be_played(system):
    episode = rt.Episode(np.zeros(4), np.repeat(np.array([[0.5, 0.0], [0.0, 0.7], [-0.4, 0.1]]), [2, 2, 96], axis=0))
    env = system.make_env()
    env.task.use_episode(episode)
    timestep = env.reset()
    for i in range(5):
        np.testing.assert_array_equal(system.observed(timestep), episode.target[i])
        timestep = env.step(np.zeros(2))
        d = np.linalg.norm(env.physics.fingertip() - episode.target[i])  # the reward is for interval i's target
        assert timestep.reward == pytest.approx(-(d**2) / (d**2 + 0.01), rel=1e-12)


# -- failures and features --------------------------------------------------------------------------------
def test_failures_are_the_steps_farther_than_a_tenth_of_a_metre(system, stored):
    assert rt.distance_reward(0.1) == -0.5 and rt.distance_reward(0.0) == 0.0
    assert rt.far_steps(np.array([-0.49, -0.5, -0.51, -0.9, 0.0])) == 2
    episode = system.episode_from_arrays(stored.episode_arrays(0))
    traj = run_episode(system, system.make_env(), parse_policy("every:5", system), None, episode)
    tips = np.array([system.model.fingertip(x) for x in traj.states[1:]])  # the model's arm has the plant's lengths
    far = np.linalg.norm(tips - episode.target, axis=1) > 0.1
    assert system.failures(traj, episode) == int(far.sum()) > 0


def test_exogenous_features_see_a_jump_that_the_state_error_cannot(system, features_while_kept):
    episode = rt.Episode(np.array([0.5, 1.0, 0.0, 0.0]), np.repeat(np.array([[0.6, 0.2], [-0.3, 0.5]]), [3, 97], axis=0))
    seen, s = features_while_kept(system, episode)  # a plan for (0.6, 0.2) at step 0, kept
    assert len(EXOGENOUS_FEATURES) == seen[0].size == 7
    np.testing.assert_allclose(seen[0], [0.6, 0.2, 0.6, 0.2, 0, 0, 0])  # step 1: same target
    np.testing.assert_allclose(seen[2], [-0.3, 0.5, 0.6, 0.2, -0.9, 0.3, np.hypot(0.9, 0.3)])  # step 3: it jumped
    s = AugmentedState(s.x, s.x_plan, s.age, s.x_predicted, s.plan, s.observation)
    assert raw_features("error", "reacher", s).size == 4 + 1 + 7
    assert raw_names("error", "reacher", system.state_names)[-7:] == EXOGENOUS_FEATURES
