"""The condensed route (etmpc.control.condensed) against independent truths: its linearisation against the
single-shooting residual's Jacobian written out by CasADi, its optimum against a tightly converged Ipopt on
a multiple-shooting transcription, its warm start against the kept plan flown step by step."""

from dataclasses import replace

import casadi as ca
import numpy as np
import pytest

from etmpc.common.checks import BadValue
from etmpc.control.mpc import SolverSettings
from etmpc.systems.cart_pendulum.system import CartPendulumSystem
from etmpc.systems.quadrotor.system import QuadrotorSystem
from tests.control.test_mpc import ipopt_reference, random_state


@pytest.fixture(scope="module")
def quadrotor():
    return QuadrotorSystem()


def interpreted(system, **settings):
    """``system``'s task with its solver in CasADi's virtual machine (no compiler run), ``settings`` changed."""
    solver = replace(system.config.solver, compiled=False, **settings)
    return type(system)(replace(system.config, solver=solver))


def random_problem(rng):
    """A quadrotor state in flight, the previous thrusts and a waypoint."""
    x = np.concatenate(
        [rng.uniform(-1, 1, 2), rng.uniform(0.5, 1.5, 1), rng.uniform(-0.3, 0.3, 3), rng.uniform(-1, 1, 3), rng.uniform(-1, 1, 3)]
    )
    return x, rng.uniform(0.05, 0.1, 4), np.concatenate([rng.uniform(-1, 1, 2), rng.uniform(0.5, 1.5, 1)])


def single_shooting(system, x, u_prev, target):
    """``U -> (r, states)``: the OCP's residuals stacked over the horizon, the states rolled out from ``x``."""
    mpc, n, nu = system.mpc, system.config.horizon, len(u_prev)
    stage, terminal = system.residuals()
    U = ca.SX.sym("U", n * nu)
    x_k, previous, residuals, states = ca.DM(x), ca.DM(u_prev), [], [ca.DM(x)]
    for k in range(n):
        u_k = U[k * nu : (k + 1) * nu]
        residuals.append(stage(x_k, u_k, u_k - previous, target))
        x_k, previous = mpc.ocp.model(x_k, u_k), u_k
        states.append(x_k)
    residuals.append(terminal(x_k, target))
    return U, ca.vertcat(*residuals), ca.horzcat(*states)


def test_the_linearisation_is_the_gauss_newton_model_of_the_single_shooting_residual(quadrotor):
    """f = |r|^2, g = 2 J'r, H = 2 J'J + mu I with J = dr/dU (CasADi's AD of the rollout, no recursion),
    the rollout's states and the predictor's Jacobians along it; compiled and interpreted alike."""
    rng = np.random.default_rng(3)
    x, u_prev, target = random_problem(rng)
    U, r, states = single_shooting(quadrotor, x, u_prev, target)
    J = ca.jacobian(r, U)
    mu = quadrotor.config.solver.regularisation
    truth = ca.Function("truth", [U], [ca.sumsqr(r), 2 * J.T @ r, 2 * J.T @ J + mu * ca.DM.eye(U.numel()), states])
    xs, us = ca.SX.sym("x", 12), ca.SX.sym("u", 4)
    jacobians = ca.Function(
        "AB", [xs, us], [ca.jacobian(quadrotor.mpc.ocp.model(xs, us), xs), ca.jacobian(quadrotor.mpc.ocp.model(xs, us), us)]
    )
    z0 = np.concatenate([x, u_prev])
    for system in (quadrotor, interpreted(quadrotor)):
        solver = system.mpc.route
        assert solver.is_compiled is (system is quadrotor)
        guess = rng.uniform(0.03, 0.12, U.numel())
        f, g, H, rolled, A, B = (np.array(v) for v in solver._linearised(guess, z0, target, 0))
        f_t, g_t, H_t, states_t = (np.array(v) for v in truth(guess))
        assert f == pytest.approx(f_t.item(), rel=1e-12)
        np.testing.assert_allclose(g, g_t.ravel(), rtol=1e-10, atol=1e-12 * np.abs(g_t).max())
        np.testing.assert_allclose(H, H_t, rtol=1e-10, atol=1e-12 * np.abs(H_t).max())
        np.testing.assert_allclose(rolled.reshape(-1, 12), states_t.T, rtol=1e-12, atol=1e-12)
        for k in range(system.config.horizon):
            A_k, B_k = jacobians(states_t[:, k], guess[4 * k : 4 * k + 4])
            np.testing.assert_allclose(A.reshape(12, -1, order="F")[:, 12 * k : 12 * k + 12], A_k, rtol=1e-12, atol=1e-12)
            np.testing.assert_allclose(B.reshape(12, -1, order="F")[:, 4 * k : 4 * k + 4], B_k, rtol=1e-12, atol=1e-12)


def ipopt_quadrotor(system, x, u_prev, target) -> tuple[float, np.ndarray]:
    """The OCP transcribed independently (full multiple shooting, every state and input a variable, the
    regularisation-free objective), solved by Ipopt to 1e-12: the objective and the first input."""
    n, model = system.config.horizon, system.mpc.ocp.model
    stage, terminal = system.residuals()
    X, U = ca.SX.sym("X", 12, n + 1), ca.SX.sym("U", 4, n)
    previous = ca.horzcat(ca.DM(u_prev), U[:, :-1])
    f = sum(ca.sumsqr(stage(X[:, k], U[:, k], U[:, k] - previous[:, k], target)) for k in range(n))
    f += ca.sumsqr(terminal(X[:, n], target))
    gaps = [X[:, 0] - x] + [model(X[:, k], U[:, k]) - X[:, k + 1] for k in range(n)]
    nlp = {"x": ca.vertcat(ca.vec(X), ca.vec(U)), "f": f, "g": ca.vertcat(*gaps)}
    options = {"print_time": False, "ipopt.print_level": 0, "ipopt.sb": "yes", "ipopt.tol": 1e-12, "ipopt.acceptable_iter": 0}
    solver = ca.nlpsol("reference", "ipopt", nlp, options)
    hover = np.full(4 * n, system.params.hover_thrust_n)
    rolled = system.mpc.rollout(x, hover.reshape(n, 4))
    sol = solver(
        x0=np.concatenate([rolled.ravel(), hover]),
        lbx=np.r_[np.full(12 * (n + 1), -np.inf), np.tile(system.u_min, n)],
        ubx=np.r_[np.full(12 * (n + 1), np.inf), np.tile(system.u_max, n)],
        lbg=0,
        ubg=0,
    )
    assert solver.stats()["success"]
    return float(sol["f"]), np.array(sol["x"][12 * (n + 1) : 12 * (n + 1) + 4]).ravel()


def test_the_optimum_is_ipopts_on_random_flights(quadrotor):
    """Converged to a tight tolerance, the objective agrees with Ipopt's to 1e-7 relative (only the 1e-3 I
    regularisation of H separates them: it changes the steps, not the fixed point); at the task's own
    settings (a step within 0.3 % of the thrust range, or 10 QPs from a cold start), to 1e-4, and the first
    thrusts to 1e-3 of the range."""
    tight = interpreted(quadrotor, step_tolerance=1e-7, max_iterations=200)
    span = quadrotor.u_max - quadrotor.u_min
    rng = np.random.default_rng(11)
    for _ in range(3):
        x, u_prev, target = random_problem(rng)
        reference, first = ipopt_quadrotor(quadrotor, x, u_prev, target)
        exact = tight.mpc.solve(x, u_prev, parameters=target)
        assert exact.success and exact.status == "converged"
        assert exact.cost == pytest.approx(reference, rel=1e-7)
        plan = quadrotor.mpc.solve(x, u_prev, parameters=target)  # converged, or stopped at the task's 10 QPs
        assert plan.success and (plan.status == "converged" or plan.iterations == quadrotor.config.solver.max_iterations)
        assert plan.cost == pytest.approx(reference, rel=1e-4)
        assert np.all(np.abs(plan.inputs[0] - first) <= 1e-3 * span)
        # the plan is what the predictor flies: its states are the rollout of its inputs
        np.testing.assert_allclose(plan.states, quadrotor.mpc.rollout(x, plan.inputs), rtol=0, atol=1e-12)


def test_compiled_and_interpreted_plans_agree(quadrotor):
    rng = np.random.default_rng(5)
    x, u_prev, target = random_problem(rng)
    compiled = quadrotor.mpc.solve(x, u_prev, parameters=target)
    vm = interpreted(quadrotor).mpc.solve(x, u_prev, parameters=target)
    assert compiled.iterations == vm.iterations
    np.testing.assert_allclose(compiled.inputs, vm.inputs, rtol=0, atol=1e-10)
    np.testing.assert_allclose(compiled.gains, vm.gains, rtol=1e-9, atol=1e-9)


def test_each_iteration_descends_and_a_short_run_is_a_plan_that_says_so(quadrotor):
    """The objective never rises with more iterations; a run stopped short is a plan (every iterate is a
    descent from the guess), its status naming the limit."""
    rng = np.random.default_rng(8)
    x, u_prev, target = random_problem(rng)
    costs = []
    for limit in (1, 2, 3, 100):
        plan = quadrotor.mpc.iterate(x, u_prev, parameters=target, limit=limit)
        assert plan.success and plan.iterations <= limit
        if plan.status != "converged":
            assert plan.iterations == limit and plan.status == f"not converged in {limit} iteration(s)"
        costs.append(plan.cost)
    assert costs == sorted(costs, reverse=True) and costs[0] > costs[-1]
    assert plan.status == "converged"


def test_the_warm_start_is_the_kept_plan_flown_under_its_gains(quadrotor):
    """The guess from a kept plan of age 3: the predictor driven from the measured state by the plan's
    inputs corrected by its gains, clipped to the bounds, step by step; past the plan's end, its last."""
    rng = np.random.default_rng(9)
    x, u_prev, target = random_problem(rng)
    plan = quadrotor.mpc.solve(x, u_prev, parameters=target)
    measured, age, n = plan.states[3] + rng.normal(0, 0.05, 12), 3, quadrotor.config.horizon
    guess = quadrotor.mpc.route.warm_start(measured, plan.inputs[2], plan, age, target)
    model, state, expected = quadrotor.mpc.ocp.model, measured, []
    for k in range(n):
        j = min(k + age, n - 1)
        u = plan.inputs[j] - plan.gains[j] @ (state - plan.states[min(k + age, n)])
        u = np.clip(u, quadrotor.u_min, quadrotor.u_max)
        expected.append(u)
        state = np.array(model(state, u)).ravel()
    np.testing.assert_allclose(guess, np.concatenate(expected), rtol=0, atol=1e-9)  # an unstable flight: rounding grows


def test_a_task_without_parameters_or_gains_reaches_ipopts_optimum():
    """The cart pendulum's OCP (no parameters, no plan feedback: the warm start is the plan shifted) on the
    condensed route, warm started from the multiple-shooting route's plan with its inputs moved by up to 2 N:
    back to Ipopt's objective (tests/control/test_mpc.py's transcription). From a cold start, single
    shooting can end in another local optimum of this OCP (a pole swung over the top): why the cart's
    tasks stay on multiple shooting."""
    cart = CartPendulumSystem()
    condensed = CartPendulumSystem(
        replace(cart.config, solver=SolverSettings(route="condensed", compiled=False, step_tolerance=1e-8))
    )
    rng = np.random.default_rng(42)
    for _ in range(3):
        x, u_prev = random_state(rng), rng.uniform(-25, 25, 1)
        start = cart.mpc.solve(x, u_prev)
        moved = replace(start, inputs=np.clip(start.inputs + rng.uniform(-2, 2, start.inputs.shape), -25, 25))
        plan = condensed.mpc.solve(x, u_prev, moved, 0)
        assert plan.success and plan.status == "converged"
        assert plan.cost == pytest.approx(ipopt_reference(cart, x, u_prev), rel=1e-7)


def test_an_unknown_route_is_refused_by_the_settings_before_any_mpc_is_built():
    with pytest.raises(BadValue, match="^SolverSettings.route: 'hpipm' is not one of sqpmethod, condensed"):
        SolverSettings(route="hpipm")
