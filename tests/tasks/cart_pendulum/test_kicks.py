"""cart_pendulum/kicks: its MPC against Ipopt, its feedback against an independent Riccati recursion, the
kicks' and the reference's laws, the step cost, falls and the forced re-plan that follows, the bumpers,
the future a rollout samples, and the features that see a reference jump."""

import math

import casadi as ca
import numpy as np
import pytest

from etmpc.loop import ClosedLoop
from etmpc.policies.features import raw_features, raw_names
from etmpc.systems import make_system
from etmpc.systems.cart_pendulum import kicks
from etmpc.systems.cart_pendulum.kicks_system import EXOGENOUS_FEATURES


@pytest.fixture(scope="module")
def system():
    return make_system("cart_pendulum/kicks")


def ipopt_reference(system, x, u_prev, r, start=None):
    """The OCP for the cart reference ``r`` written out again (full multiple shooting, every state and
    input a variable), solved by Ipopt to 1e-12 from zero inputs with the state held (or from
    ``start``'s inputs and their states)."""
    model, c, n = system.model.discrete, system.config, system.config.horizon
    inside = kicks.BUMPERS.position_m - c.rail_margin_m
    X, U = ca.SX.sym("X", 4, n + 1), ca.SX.sym("U", 1, n)
    du = U - ca.horzcat(ca.DM(u_prev), U[:, :-1])
    rail = lambda eta: 5 * ca.fmax(0, ca.fabs(eta) - inside)  # noqa: E731
    f = sum(
        9 * ca.sin(X[2, k] / 2) ** 2
        + (c.position_weight * (X[0, k] - r)) ** 2
        + (0.03 * X[3, k]) ** 2
        + (c.input_weight * U[0, k]) ** 2
        + (0.01 * du[0, k]) ** 2
        + rail(X[0, k]) ** 2
        for k in range(n)
    )
    f += (
        81 * ca.sin(X[2, n] / 2) ** 2
        + (c.terminal_position_weight * (X[0, n] - r)) ** 2
        + 0.09 * X[3, n] ** 2
        + 0.09 * X[1, n] ** 2
        + rail(X[0, n]) ** 2
    )
    nlp = {
        "x": ca.vertcat(ca.vec(X), ca.vec(U)),
        "f": f,
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
            "ipopt.max_iter": 3000,
        },
    )
    inputs = np.zeros((n, 1)) if start is None else start
    states = np.tile(x, (n + 1, 1)) if start is None else system.mpc.rollout(x, inputs)  # the pole held up, or our plan
    sol = solver(
        x0=np.concatenate([states.ravel(), inputs.ravel()]),
        lbx=np.r_[np.full(4 * (n + 1), -np.inf), np.full(n, -c.force_limit_n)],
        ubx=np.r_[np.full(4 * (n + 1), np.inf), np.full(n, c.force_limit_n)],
        lbg=0,
        ubg=0,
    )
    assert solver.stats()["success"]
    return float(sol["f"])


def test_the_optimum_matches_a_tightly_converged_ipopt(system):
    """Near upright the OCP has one optimum, which both reach from zero inputs (objectives within 1e-6,
    relative). Far from it (a kicked pole, a reference that jumped) the OCP is not convex: there Ipopt,
    started from our plan, must not find anything better nearby, i.e. our plan is an optimum to 1e-6."""
    rng = np.random.default_rng(3)
    for far in (False,) * 6 + (True,) * 6:
        scale = (1.0, 0.5, 0.4, 1.5) if far else (0.5, 0.3, 0.1, 0.3)
        x, u_prev = rng.uniform(-1, 1, 4) * scale, rng.uniform(-10, 10, 1)
        r = rng.uniform(-kicks.REFERENCE_M, kicks.REFERENCE_M) if far else x[0] + rng.uniform(-0.2, 0.2)
        plan = system.mpc.solve(x, u_prev, parameters=np.array([r]))
        assert plan.success, plan.status
        reference = ipopt_reference(system, x, u_prev, r, plan.inputs if far else None)
        assert abs(plan.cost - reference) <= 1e-6 * abs(reference), (far, plan.cost, reference)
        # The plan's own cost, and its inputs rolled out (the shooting gaps close to 1e-6).
        assert plan.cost == pytest.approx(system.mpc.objective(x, u_prev, plan.inputs, np.array([r])), rel=1e-6)


def test_the_feedback_gains_are_the_riccati_recursion_along_the_plan(system):
    """Independent truth: the linearisation by finite differences of the predictor and the recursion in
    numpy, against the gains the compiled solve returns."""
    x = np.array([0.3, 0.2, 0.25, -0.8])
    plan = system.mpc.solve(x, np.zeros(1), parameters=np.array([-0.5]))
    Q, R = np.diag(system.config.feedback_state_weights), np.array([[system.config.feedback_input_weight]])
    predict = lambda xx, uu: np.asarray(system.model.discrete(xx, uu)).ravel()  # noqa: E731
    P, h = 10 * Q, 1e-6
    for k in range(system.horizon - 1, -1, -1):
        xk, uk = plan.states[k], plan.inputs[k]
        A = np.column_stack([(predict(xk + h * e, uk) - predict(xk - h * e, uk)) / (2 * h) for e in np.eye(4)])
        B = ((predict(xk, uk + h) - predict(xk, uk - h)) / (2 * h))[:, None]
        K = np.linalg.solve(R + B.T @ P @ B, B.T @ P @ A)
        P = Q + A.T @ P @ (A - B @ K)
        np.testing.assert_allclose(plan.gains[k], K, rtol=1e-5, atol=1e-7)


def test_kicks_follow_their_law():
    rng = np.random.default_rng(0)
    draws = np.concatenate([kicks.draw_kicks(rng, 1000) for _ in range(60)])
    rate = kicks.KICKS_PER_S * kicks.CONTROL_DT_S  # Poisson per interval: P(none) = exp(-rate)
    assert np.mean(draws == 0) == pytest.approx(math.exp(-rate), abs=0.003)
    sizes = np.abs(draws[draws != 0])  # mostly one kick: two in one interval happen in 2.5 % of them
    assert np.quantile(sizes, 0.03) >= kicks.KICK_RAD_S[0] and np.quantile(sizes, 0.97) <= kicks.KICK_RAD_S[1]
    assert abs(np.mean(np.sign(draws[draws != 0]))) < 0.05  # either sign, equally


def test_the_reference_jumps_by_its_law():
    """A jump into each interval with probability 0.04 (0.4 per second), within 4 binomial standard
    deviations over 100 000 intervals; every reference inside +-1 m, spread over it."""
    rng = np.random.default_rng(0)
    p = kicks.REFERENCE_JUMP_PROBABILITY
    assert p == pytest.approx(0.04)
    runs = [kicks.continue_references(rng, kicks.draw_reference(rng), 1000) for _ in range(100)]
    jumps = sum(int(np.sum(np.diff(r) != 0)) for r in runs)  # a new draw equals the old with probability 0
    n = 100 * 999
    assert abs(jumps - n * p) <= 4 * math.sqrt(n * p * (1 - p))
    values = np.concatenate(runs)
    assert np.all(np.abs(values) <= kicks.REFERENCE_M) and values.min() < -0.9 and values.max() > 0.9


def test_the_step_cost_weighs_angle_and_tracking_and_is_bounded():
    assert kicks.step_cost(0.0, 0.0, False) == 0.0
    assert kicks.step_cost(1.2, 0.0, False) == pytest.approx(0.5)  # sin^2(0.6) / sin^2(0.6), halved
    assert kicks.step_cost(0.0, 0.3, False) == pytest.approx(0.25)  # d = the scale: 1/2 of 1/2
    assert kicks.step_cost(3.0, 100.0, False) < 1.0 and kicks.step_cost(0.0, 0.0, True) == 1.0


def test_a_rollouts_future_keeps_what_the_controller_has_felt(system):
    """Kicks before the decision's interval and references up to it (the one it observes) are kept;
    the rest is redrawn."""
    episode = system.draw_episode(np.random.default_rng(1))
    futures = [system.sample_future(episode, 40, np.random.default_rng(s)) for s in range(50)]
    for future in futures:
        np.testing.assert_array_equal(future.kick[:40], episode.kick[:40])
        np.testing.assert_array_equal(future.reference[:41], episode.reference[:41])
        np.testing.assert_array_equal(future.initial_state, episode.initial_state)
    assert len({f.kick[40:].tobytes() for f in futures}) == 50
    assert len({f.reference[41:].tobytes() for f in futures}) > 40  # no jump in 109 intervals: 1 % of futures


def test_the_observation_shows_the_reference_of_the_interval_about_to_be_played(system):
    reference = np.repeat([0.5, -0.7, 0.2], [2, 2, kicks.EPISODE_STEPS - 4])
    episode = kicks.KickEpisode(np.zeros(4), np.zeros(kicks.EPISODE_STEPS), reference)
    env = system.make_env()
    env.task.use_episode(episode)
    timestep = env.reset()
    for i in range(5):
        assert system.reference(timestep)[0] == reference[i]
        assert env.physics.named.data.mocap_pos["reference", 0] == reference[i]  # the marker in the video
        timestep = env.step(np.zeros(1))
        expected = kicks.step_cost(env.physics.pole_angle(), env.physics.cart_position() - reference[i], False)
        assert timestep.reward == -expected  # the reward is for interval i's reference


def test_exogenous_features_see_a_jump_that_the_state_error_cannot(system, features_while_kept):
    reference = np.repeat([0.4, -0.6], [3, kicks.EPISODE_STEPS - 3])
    episode = kicks.KickEpisode(np.zeros(4), np.zeros(kicks.EPISODE_STEPS), reference)
    seen, s = features_while_kept(system, episode)  # a plan for 0.4 at step 0, kept
    assert len(EXOGENOUS_FEATURES) == seen[0].size == 4
    np.testing.assert_allclose(seen[0], [0.4, 0.4, 0, 0])  # step 1: the same reference
    np.testing.assert_allclose(seen[2], [-0.6, 0.4, -1.0, 1.0])  # step 3: it jumped
    assert raw_features("error", "cart_pendulum/kicks", s).size == 4 + 1 + 4
    assert raw_names("error", "cart_pendulum/kicks", system.state_names)[-4:] == EXOGENOUS_FEATURES


def test_a_fall_costs_its_price_puts_the_pole_back_and_forces_a_new_plan(system):
    """No control at all (never re-planning after a zero plan would still solve; here a policy that
    keeps every plan and a first plan that pushes the pole over)."""
    env = system.make_env()
    episode = kicks.KickEpisode(np.array([0.0, 0.0, 1.0, 2.0]), np.zeros(kicks.EPISODE_STEPS), np.zeros(kicks.EPISODE_STEPS))
    loop = ClosedLoop(system, env).reset(episode)
    loop.step(True)
    for _ in range(8):
        if env.task.restarted:
            break
        loop.step(False)
    assert env.task.restarted and loop.trajectory.rewards[loop.step_index - 1] == -kicks.FALL_COST
    assert loop.x[1:].tolist() == [0.0, 0.0, 0.0]  # upright, at rest, where the cart was
    assert loop.forced  # the old plan no longer applies: the next decision is the loop's
    loop.step(False)
    assert loop.trajectory.recompute[loop.step_index - 1] and loop.trajectory.forced[loop.step_index - 1]


def test_the_bumpers_push_back_past_the_rails_end(system):
    physics = system.make_env().physics
    physics.set_state_vector(np.array([2.6, 1.0, 0.0, 0.0]))
    b = kicks.BUMPERS
    assert physics._bumper_force() == pytest.approx(-b.stiffness_n_m * 0.1 - b.damping_n_s_m * 1.0)
    physics.set_state_vector(np.array([2.4, 1.0, 0.0, 0.0]))
    assert physics._bumper_force() == 0.0
