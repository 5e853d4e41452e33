"""The MPC's optimum against a tightly converged Ipopt, plan consistency, and failure handling."""

import casadi as ca
import numpy as np
import pytest

from etmpc.loop import run_episode
from etmpc.control.plan import Plan
from etmpc.policies import parse_policy


def ipopt_reference(system, x, u_prev):
    """The OCP transcribed independently of the MPC (full multiple shooting: every state and input a
    variable, ``x_0 = x`` an equality), solved by Ipopt to 1e-12 from zero inputs rolled out."""
    model, c = system.model.discrete, system.config
    n, nx = c.horizon, 4
    X, U = ca.SX.sym("X", nx, n + 1), ca.SX.sym("U", 1, n)
    du = U - ca.horzcat(ca.DM(u_prev), U[:, :-1])
    nlp = {
        "x": ca.vertcat(ca.vec(X), ca.vec(U)),
        "f": ca.sumsqr(X[2, :]) + c.input_change_weight * ca.sumsqr(du),
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
    lbu, ubu = np.full(n, -c.force_limit_n), np.full(n, c.force_limit_n)
    sol = solver(
        x0=np.concatenate([states.ravel(), np.zeros(n)]),
        lbx=np.r_[np.full(nx * (n + 1), -np.inf), lbu],
        ubx=np.r_[np.full(nx * (n + 1), np.inf), ubu],
        lbg=0,
        ubg=0,
    )
    assert solver.stats()["success"]
    return float(sol["f"])


def random_state(rng):
    return np.array([rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-0.78, 0.78), rng.uniform(-1, 1)])


def test_optimum_matches_ipopt_on_random_states(cart_system):
    """Objective within 1e-6 relative (seen ~1e-9): both solve the same KKT conditions, ours to 1e-8."""
    mpc, rng = cart_system.mpc, np.random.default_rng(42)
    for _ in range(12):
        x, u_prev = random_state(rng), rng.uniform(-25, 25, 1)
        plan = mpc.solve(x, u_prev)
        assert plan.success, plan.status
        reference = ipopt_reference(cart_system, x, u_prev)
        assert abs(plan.cost - reference) <= 1e-6 * abs(reference)


def test_warm_started_solve_matches_cold_and_reference(cart_system):
    mpc, rng = cart_system.mpc, np.random.default_rng(5)
    x = random_state(rng)
    first = mpc.solve(x, np.zeros(1))
    x_next = first.states[1] + np.array([0, 0.01, 0.002, -0.05])  # the plant drifted a little
    warm = mpc.solve(x_next, first.inputs[0], first, 1)
    cold = mpc.solve(x_next, first.inputs[0])
    reference = ipopt_reference(cart_system, x_next, first.inputs[0])
    assert warm.success and cold.success
    assert abs(warm.cost - reference) <= 1e-6 * reference and abs(cold.cost - reference) <= 1e-6 * reference


def test_plan_is_consistent_with_the_predictor(cart_system):
    mpc = cart_system.mpc
    x = np.array([0.0, 0.3, 0.5, -0.4])
    plan = mpc.solve(x, np.zeros(1))
    assert plan.inputs.shape == (20, 1) and plan.states.shape == (21, 4)
    np.testing.assert_allclose(plan.states[0], x, atol=1e-9)
    np.testing.assert_allclose(plan.states, mpc.rollout(x, plan.inputs), atol=1e-7)
    assert np.all(np.abs(plan.inputs) <= 25 + 1e-9)
    cost = np.sum(plan.states[:, 2] ** 2) + 1e-4 * np.sum(np.diff(np.concatenate([[0.0], plan.inputs[:, 0]])) ** 2)
    assert plan.cost == pytest.approx(cost, rel=1e-6)
    assert np.abs(plan.inputs).max() > 5  # a 0.5 rad tilt needs real force: not a trivial plan


class FlakySolver:
    """Wraps the system so that chosen solves fail (returning garbage marked unsuccessful)."""

    def __init__(self, system, fail_at):
        self._system, self.fail_at, self.calls = system, set(fail_at), 0

    def __getattr__(self, name):
        return getattr(self._system, name)

    def plan(self, x, u_prev, warm, age, timestep):
        self.calls += 1
        plan = self._system.plan(x, u_prev, warm, age, timestep)
        if self.calls in self.fail_at:
            return Plan(plan.inputs * 0 + 25, plan.states, np.nan, plan.solve_time_s, False, status="injected failure")
        return plan


def test_solver_failure_keeps_the_previous_plan_and_is_counted(cart_system, cart_testset):
    episode = cart_system.episode_from_arrays(cart_testset.episode_arrays(0))
    env = cart_system.make_env()
    flaky = FlakySolver(cart_system, fail_at={3, 4, 10})
    traj = run_episode(flaky, env, parse_policy("always", cart_system), None, episode)
    assert traj.steps == 100 and not traj.nonfinite
    assert traj.solver_failures == 3 and traj.recomputes == 100
    # After the failed solve at step 2 (the 3rd call), steps 2 and 3 follow the plan made at step 1.
    assert traj.plan_age[1] == 0 and traj.plan_age[2] == 1 and traj.plan_age[3] == 2 and traj.plan_age[4] == 0
    assert np.all(np.abs(traj.applied[2:4]) < 25)  # the failed (all-25) plan was not used
    assert all(plan.success for _, plan in traj.plans)


def test_failed_first_solve_still_controls(cart_system, cart_testset):
    episode = cart_system.episode_from_arrays(cart_testset.episode_arrays(1))
    flaky = FlakySolver(cart_system, fail_at={1})
    traj = run_episode(flaky, cart_system.make_env(), parse_policy("every:5", cart_system), None, episode)
    assert traj.solver_failures == 1 and traj.steps == 100


def test_every_transcription_and_engine_reaches_the_same_optimum(cart_system):
    """Shooting nodes every 1, 4 (default) or 20 steps are the same NLP; compiled C and CasADi's
    virtual machine run the same function. All land on Ipopt's optimum."""
    from dataclasses import replace

    from etmpc.systems.cart_pendulum.system import CartPendulumSystem

    default = cart_system.mpc
    assert default.is_compiled and default.settings.block == 4
    variants = {
        (block, compiled): CartPendulumSystem(
            replace(cart_system.config, solver=replace(cart_system.config.solver, block=block, compiled=compiled))
        ).mpc
        for block, compiled in [(1, False), (4, False), (20, False)]
    }
    rng = np.random.default_rng(7)
    for _ in range(4):
        x, u_prev = random_state(rng), rng.uniform(-25, 25, 1)
        reference = ipopt_reference(cart_system, x, u_prev)
        plan = default.solve(x, u_prev)
        assert plan.success and plan.status == "converged"
        for mpc in variants.values():
            other = mpc.solve(x, u_prev)
            assert other.success and abs(other.cost - reference) <= 1e-6 * reference
        same_function = variants[(4, False)].solve(x, u_prev)  # the compiled function, interpreted
        np.testing.assert_allclose(plan.inputs, same_function.inputs, rtol=0, atol=1e-9)
        np.testing.assert_allclose(plan.states, same_function.states, rtol=0, atol=1e-9)


def test_unconverged_solve_is_a_failure_with_its_residuals(cart_system):
    """Two SQP iterations from a cold start cannot converge: the plan says so, with the residuals."""
    from dataclasses import replace

    from etmpc.systems.cart_pendulum.system import CartPendulumSystem

    capped = CartPendulumSystem(replace(cart_system.config, solver=replace(cart_system.config.solver, max_iterations=2))).mpc
    plan = capped.solve(np.array([0.0, 0.5, 0.6, -0.5]), np.zeros(1))
    assert not plan.success and plan.status.startswith("not converged: constraint violation")
    assert np.all(np.isfinite(plan.inputs))
