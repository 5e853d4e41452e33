"""Several SQP iterations at a decision (``Iterations(k)``, ``iterate:T:K``): the extra iterations of the
advanced-step RTI and an iteration budget per solve. Checked against the MPC's own one-iteration steps chained
by hand, the platform's delay formula and the price per iteration."""

import math

import numpy as np
import pytest

from etmpc.common.checks import BadValue
from etmpc.common.errors import EtmpcError
from etmpc.control.timing import ITERATE, KEEP, SOLVE, Iterations, iterations_of, level_of
from etmpc.evaluation import testsets
from etmpc.loop import ClosedLoop, run_episode
from etmpc.policies import parse_policy
from etmpc.systems import make_system


@pytest.fixture(scope="module")
def levels():
    return make_system("cart_pendulum/kicks_levels")


def _episode(system, index: int):
    path = testsets.default_path(system.domain, "kicks")
    return system.episode_from_arrays(testsets.load(path, system.domain, "kicks").episode_arrays(index))


def test_k_iterations_are_k_real_time_iterations_chained_bit_for_bit(levels):
    """At most k iterations from the plan shifted by its age is one iteration from it, then one from that, ...:
    the same bits, converged or not (each is one call of the compiled one-iteration SQP)."""
    mpc = levels.mpc
    rng = np.random.default_rng(11)
    for _ in range(4):
        x = rng.uniform([-1, -1, -0.4, -1], [1, 1, 0.4, 1])
        p = np.array([rng.uniform(-1, 1)])
        warm = mpc.iterate(x, np.zeros(1), None, 0, parameters=p, limit=1)
        moved = x + rng.normal(0.0, 0.05, 4)
        three = mpc.iterate(moved, np.zeros(1), warm, 2, parameters=p, limit=3)
        chained = mpc.iterate(moved, np.zeros(1), warm, 2, parameters=p, limit=1)
        for _ in range(three.iterations - 1):
            chained = mpc.iterate(moved, np.zeros(1), chained, 0, parameters=p, limit=1)
        assert 1 <= three.iterations <= 3
        np.testing.assert_array_equal(three.inputs, chained.inputs)
        np.testing.assert_array_equal(three.states, chained.states)


def test_iterate_with_one_iteration_at_a_time_is_iterate_bit_for_bit(levels):
    episode = _episode(levels, 2)
    a = run_episode(levels, levels.make_env(), parse_policy("iterate:2", levels), None, episode)
    b = run_episode(levels, levels.make_env(), parse_policy("iterate:2:1", levels), None, episode)
    np.testing.assert_array_equal(a.rewards, b.rewards)
    np.testing.assert_array_equal(a.work, b.work)
    assert parse_policy("iterate:2:1", levels).spec == "iterate:2"


@pytest.mark.parametrize("period, count", [(1, 3), (3, 4)])
def test_a_schedule_of_k_iterations_makes_at_most_k_each_priced_and_delayed_by_those_made(levels, period, count):
    episode = _episode(levels, 0)
    policy = parse_policy(f"iterate:{period}:{count}", levels)
    assert policy.spec == f"iterate:{period}:{count}"
    traj = run_episode(levels, levels.make_env(), policy, None, episode)
    n = traj.steps
    level, work = traj.level[:n], traj.work[:n]
    iterated = work[level == ITERATE]
    assert len(iterated) > 10 and iterated.min() >= 1 and iterated.max() == count  # the cap is reached, never passed
    assert set(level[~traj.forced[:n]]) <= {KEEP, ITERATE}
    price = levels.recompute_price
    assert traj.policy_return(price) == pytest.approx(traj.rewards[:n].sum() - price * work.sum(), rel=1e-12)
    # the platform's delay: ceil(iterations x 30 ms / 100 ms) intervals after the computation started
    step_s, interval_s = levels.config.latency.iteration_s, levels.control_interval_s
    checked = 0
    for (made, plan), arrived, started in zip(traj.plans, traj.arrivals, traj.starts):
        if started < n and level[started] == ITERATE:
            assert plan.iterations == work[started]
            assert arrived - started == math.ceil(plan.iterations * step_s / interval_s - 1e-9)
            checked += 1
    assert checked > 10


def test_a_python_policy_may_answer_iterations_and_plays_as_the_built_in_schedule(levels):
    from etmpc.policies.user import checked

    class Budget:
        spec, stochastic = "my-budget", False

        def decide(self, s, rng):
            return Iterations(2) if s.age >= 2 else KEEP

    episode = _episode(levels, 5)
    mine = run_episode(levels, levels.make_env(), checked(Budget()), None, episode)
    built_in = run_episode(levels, levels.make_env(), parse_policy("iterate:2:2", levels), None, episode)
    np.testing.assert_array_equal(mine.rewards, built_in.rewards)
    np.testing.assert_array_equal(mine.work, built_in.work)


def test_iterations_is_a_level_only_where_the_task_has_levels_and_a_count_of_at_least_one():
    assert level_of(Iterations(3), True) == ITERATE and iterations_of(Iterations(3)) == 3
    assert level_of(Iterations(3), False) is None
    assert iterations_of(ITERATE) == 1 and iterations_of(SOLVE) == 1
    assert iterations_of(Iterations(np.int64(2))) == 2
    for bad in (0, -1, 1.5, True, "2", None):
        with pytest.raises(BadValue, match="a whole number of SQP iterations >= 1"):
            Iterations(bad)


def test_a_keep_or_solve_task_refuses_iterations_naming_the_task():
    system = make_system("cart_pendulum/kicks")
    loop = ClosedLoop(system, system.make_env()).reset(_episode(system, 0))
    loop.step(True)
    with pytest.raises(BadValue, match="on task cart_pendulum/kicks, got Iterations Iterations\\(count=2\\)"):
        loop.step(Iterations(2))


@pytest.mark.parametrize(
    "spec, says",
    [
        ("iterate:2:0", "the SQP iterations at a time must be a whole number >= 1"),
        ("iterate:2:x", "'x' is not an integer"),
        ("iterate:2:", "'' is not an integer"),
        ("iterate:0:2", "the period must be a whole number of steps >= 1"),
    ],
)
def test_a_bad_iterate_spec_is_one_line(levels, spec, says):
    with pytest.raises(EtmpcError, match=f"bad policy '{spec}': .*{says}"):
        parse_policy(spec, levels)
