"""Time in the loop: a latency delivers each plan d intervals late, from the state it started from;
compute levels price SQP iterations. Checked against a loop written here from the definition, the
predictor, the solver's own optimum and the bookkeeping of work and price."""

import copy
import re
from dataclasses import replace

import numpy as np
import pytest

from etmpc.common.errors import EtmpcError
from etmpc.control.timing import ITERATE, KEEP, SOLVE, Latency
from etmpc.evaluation import testsets
from etmpc.loop import ClosedLoop, play_on, run_episode
from etmpc.policies import parse_policy
from etmpc.systems import make_system

from tests.conftest import REPO
from tests.loop.test_rollout import SnapshotAt, _returns_from


def _kicks(**config):
    base = make_system("cart_pendulum/kicks")
    return type(base)(replace(base.config, **config))


def _episode(system, index: int):
    path = testsets.default_path(system.domain, "kicks")
    return system.episode_from_arrays(testsets.load(path, system.domain, "kicks").episode_arrays(index))


def _delayed_by_hand(system, episode, period: int, d: int):
    """The delayed loop from its definition, on the dm_env interface: the first plan is in force at once;
    a solve starts from the state measured at step k when nothing is in flight and the plan in force is
    ``period`` steps old (or would run out before a plan started now arrives), and its plan is in force
    from step k + d with age d. Returns the rewards, the steps a solve started at and whether the
    task put the plant back (which this hand-written loop does not model)."""
    env = system.make_env()
    env.task.use_episode(episode)
    timestep = env.reset()
    x, u_prev = system.state(timestep), np.zeros(1)
    plan, made, pending = system.plan(x, u_prev, None, 0, timestep), 0, None
    rewards, starts, restarted = [], [0], False
    for k in range(system.episode_steps):
        if pending is not None and pending[0] == k:
            assert pending[1].success
            plan, made, pending = pending[1], pending[2], None
        age = k - made
        if pending is None and k > 0 and (age >= period or age >= plan.horizon - d):
            pending = (k + d, system.plan(x, u_prev, plan, age, timestep), k)
            starts.append(k)
        correction = 0.0 if age == 0 else system.feedback.correction(x, plan.state_at(age), plan, age)
        u = np.clip(plan.input_at(age) + correction, system.u_min, system.u_max)
        timestep = env.step(u)
        restarted |= env.task.restarted
        x, u_prev = system.state(timestep), u
        rewards.append(timestep.reward)
    return np.array(rewards), starts, restarted


@pytest.mark.parametrize("d, period", [(1, 3), (2, 4), (3, 2)])
def test_a_late_plan_is_the_one_solved_d_intervals_earlier_applied_from_its_own_time_index(d, period):
    system = _kicks(latency=Latency(intervals=d))
    episode = _episode(system, 1)
    rewards, starts, restarted = _delayed_by_hand(system, episode, period, d)
    assert not restarted  # the pole stays up on this episode: the hand-written loop needs no restarts
    traj = run_episode(system, system.make_env(), parse_policy(f"every:{period}", system), None, episode)
    np.testing.assert_array_equal(traj.rewards[: traj.steps], rewards)
    assert np.flatnonzero(traj.recompute).tolist() == starts
    arrived = [0] + [k for k in starts[1:] if k + d <= traj.steps]  # one started near the end may not arrive
    assert [k for k, _ in traj.plans] == arrived and traj.arrivals == [0] + [k + d for k in arrived[1:]]
    assert set(traj.plan_age[[k for k in traj.arrivals[1:] if k < traj.steps]]) == {d}  # in force with age d
    flight = [k + j for k in starts[1:] for j in range(1, d)]
    assert np.flatnonzero(traj.in_flight).tolist() == [k for k in flight if k < traj.steps]
    # The price is the paper's: one per solve started (the one in flight at the end included).
    assert traj.policy_return(system.recompute_price) == rewards.sum() - system.recompute_price * len(starts)


def test_latency_zero_is_the_papers_loop_bit_for_bit():
    system, instant = make_system("cart_pendulum/kicks"), _kicks(latency=Latency())
    episode = _episode(system, 2)
    for spec in ("every:3", "threshold:0.6"):
        a = run_episode(system, system.make_env(), parse_policy(spec, system), None, episode)
        b = run_episode(instant, instant.make_env(), parse_policy(spec, instant), None, episode)
        np.testing.assert_array_equal(a.rewards, b.rewards)
        np.testing.assert_array_equal(a.recompute, b.recompute)
        assert a.arrivals == [k for k, _ in a.plans] and not a.in_flight.any()


def test_a_compensated_solve_starts_from_the_state_the_kept_plan_predicts_for_its_arrival():
    d = 2
    system = _kicks(latency=Latency(intervals=d, compensate=True))
    traj = run_episode(system, system.make_env(), parse_policy("every:5", system), None, _episode(system, 1))
    assert len(traj.plans) > 10
    for (made_before, before), (made, plan), arrived in zip(traj.plans, traj.plans[1:], traj.arrivals[1:]):
        start = made - d  # the solve started d steps before the step it was made for, and arrives then
        assert arrived == made and traj.plan_age[arrived] == 0
        ahead = np.array([before.input_at(start - made_before + j) for j in range(d)])
        predicted = np.asarray(system.model.discrete(system.model.discrete(traj.states[start], ahead[0]), ahead[1])).ravel()
        np.testing.assert_allclose(plan.states[0], predicted, rtol=0, atol=1e-12)


def test_the_counted_full_solve_reaches_the_solvers_optimum_and_the_optimum_is_a_fixed_point_of_one_iteration():
    system = make_system("cart_pendulum/kicks_levels")
    mpc = system.mpc
    rng = np.random.default_rng(3)
    for _ in range(5):
        x = np.array([rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-0.4, 0.4), rng.uniform(-1, 1)])
        p = np.array([rng.uniform(-1, 1)])
        once = mpc.solve(x, np.zeros(1), None, 0, parameters=p)
        counted = mpc.iterate(x, np.zeros(1), None, 0, parameters=p, limit=system.config.solver.max_iterations)
        assert once.success and counted.success and counted.iterations >= 1
        assert counted.cost == pytest.approx(once.cost, rel=1e-5)
        again = mpc.iterate(x, np.zeros(1), counted, 0, parameters=p, limit=1)
        assert again.iterations == 1 and again.success
        np.testing.assert_allclose(again.inputs, counted.inputs, atol=1e-2)  # within the solver's tolerance
        assert again.cost <= counted.cost * (1 + 1e-6)


def test_compute_levels_price_each_sqp_iteration_and_iterate_asks_for_one():
    system = make_system("cart_pendulum/kicks_levels")
    episode = _episode(system, 0)
    traj = run_episode(system, system.make_env(), parse_policy("iterate:2", system), None, episode)
    n = traj.steps
    levels, work = traj.level[:n], traj.work[:n]
    assert set(levels[~traj.forced[:n]]) == {KEEP, ITERATE} and set(levels[traj.forced[:n]]) == {SOLVE}
    assert np.all(work[levels == ITERATE] == 1) and np.all(work[levels == KEEP] == 0)
    assert np.all(work[levels == SOLVE] >= 1)
    price = system.recompute_price
    assert traj.policy_return(price) == pytest.approx(traj.rewards[:n].sum() - price * work.sum(), rel=1e-12)
    # The delay is the platform's: ceil(iterations x 30 ms / 100 ms) intervals.
    made = {k: plan for k, plan in traj.plans}
    for (k, plan), arrived in zip(traj.plans, traj.arrivals):
        expected = 0 if k == 0 or traj.forced[k] and traj.plan_age[k] >= plan.horizon else -(-plan.iterations * 3 // 10)
        if k > 0 and not (traj.forced[k] and k in made and arrived == k):
            assert arrived - k == expected
    with pytest.raises(EtmpcError, match="compute level"):
        parse_policy("iterate:2", make_system("cart_pendulum/kicks"))


@pytest.mark.parametrize(
    "task, spec, step", [("cart_pendulum/kicks_late", "threshold:0.6", 31), ("cart_pendulum/kicks_levels", "iterate:2", 40)]
)
def test_the_fast_path_replays_a_loop_with_time_in_it_bit_for_bit(task, spec, step):
    system = make_system(task)
    episode = _episode(system, 3)
    spy = SnapshotAt(parse_policy(spec, system), step)
    original = run_episode(system, system.make_env(), spy, np.random.default_rng(7), episode)
    assert spy.snapshot is not None
    total = play_on(system, system.make_env(), spy.snapshot, spy.inner, copy.deepcopy(spy.rng), spy.decision)
    expected = 0.0
    for reward, work in zip(original.rewards[step : original.steps], original.work[step : original.steps]):
        expected += reward - system.recompute_price * work
    assert total == expected
    if not system.compute_levels:
        assert total == _returns_from(original, step, system.recompute_price)


def test_the_oracle_with_compute_levels_chooses_among_three_and_never_does_worse_than_its_base():
    system = make_system("cart_pendulum/kicks_levels")
    episode = _episode(system, 4)
    base = run_episode(system, system.make_env(), parse_policy("iterate:2", system), None, episode)
    oracle = run_episode(system, system.make_env(), parse_policy("oracle:iterate:2", system), None, episode)
    price = system.recompute_price
    assert oracle.policy_return(price) >= base.policy_return(price)
    assert set(oracle.level[: oracle.steps]) == {KEEP, ITERATE, SOLVE}


def test_while_a_solve_is_in_flight_the_trigger_is_not_asked_and_a_loop_takes_levels_only_where_the_task_has_them():
    system = _kicks(latency=Latency(intervals=2))
    loop = ClosedLoop(system, system.make_env()).reset(_episode(system, 0))
    loop.step(True)  # the first plan: made before the first interval
    loop.step(True)  # a solve starts at step 1; its plan is in force from step 3
    assert loop.in_flight and loop.augmented_state() is None and not loop.forced
    loop.step(True)  # ignored
    assert not loop.recomputed and loop.trajectory.in_flight[2] and loop.age == 2
    assert not loop.in_flight and loop.augmented_state() is not None
    levels = ClosedLoop(make_system("cart_pendulum/kicks_levels"), system.make_env()).reset(_episode(system, 0))
    levels.step(SOLVE)
    with pytest.raises(ValueError, match=r"0 \(keep\), 1 \(iterate\), Iterations\(k\) or 2 \(solve\)"):
        levels.step(5)


@pytest.mark.parametrize(
    "arguments, says",
    [
        ({"intervals": -1}, "Latency.intervals: -1 is not a whole number in 0..99"),
        ({"intervals": 1.5}, "Latency.intervals: 1.5 is not a whole number in 0..99"),
        ({"iteration_s": float("nan"), "platform": "x"}, "Latency.iteration_s: nan is not a number in [0, 10]"),
        ({"iteration_s": 0.01}, "platform"),
    ],
)
def test_a_bad_latency_is_one_line(arguments, says):
    with pytest.raises(EtmpcError, match=re.escape(says)) as raised:
        Latency(**arguments)
    assert "\n" not in str(raised.value)


@pytest.mark.parametrize(
    "arguments, says",
    [
        ({"compensate": "no"}, "Latency.compensate: 'no' is not true or false"),
        ({"intervals": 1, "compensate": 1}, "Latency.compensate: 1 is not true or false"),
        ({"compensate": None}, "Latency.compensate: None is not true or false"),
        ({"platform": 3}, "Latency.platform: 3 is not a label of at most 80 characters"),
        ({"iteration_s": True, "platform": "x"}, "Latency.iteration_s: True is not a number in [0, 10]"),
    ],
)
def test_a_latencys_flag_and_names_are_of_their_kind_not_read_by_their_truth(arguments, says):
    """compensate="no" is a true string: read by its truth it turned compensation on."""
    from etmpc.common.checks import BadType

    with pytest.raises(BadType, match=re.escape(says)):
        Latency(**arguments)
    assert Latency(intervals=1, compensate=np.bool_(True)).compensate is True  # a numpy bool is a bool


def test_a_policy_learned_at_latency_zero_plays_on_its_timing_variant_and_nowhere_else():
    from etmpc.policies.learned import PolicyFileError

    path = f"rl:{REPO}/policies/cart_pendulum/kicks/learned.json"
    late = make_system("cart_pendulum/kicks_late")
    policy = parse_policy(path, late)
    assert policy.domain == "cart_pendulum/kicks"
    traj = run_episode(late, late.make_env(), policy, None, _episode(late, 0))
    assert traj.steps == late.episode_steps and 0 < traj.recomputes < late.episode_steps
    with pytest.raises(PolicyFileError, match="trained on 'cart_pendulum/kicks', not 'reacher/jumps_late'"):
        parse_policy(path, make_system("reacher/jumps_late"))


def test_a_python_trigger_answers_a_compute_level_as_the_built_in_schedule_does():
    from etmpc.policies.user import checked

    class RealTime:
        spec, stochastic = "my-rti", False

        def decide(self, s, rng):
            return ITERATE if s.age >= 2 else KEEP

    system = make_system("cart_pendulum/kicks_levels")
    episode = _episode(system, 5)
    mine = run_episode(system, system.make_env(), checked(RealTime()), None, episode)
    built_in = run_episode(system, system.make_env(), parse_policy("iterate:2", system), None, episode)
    np.testing.assert_array_equal(mine.rewards, built_in.rewards)
    np.testing.assert_array_equal(mine.level, built_in.level)


class _Answers:
    spec, stochastic = "answers", False

    def __init__(self, answer):
        self.answer = answer

    def decide(self, s, rng):
        return self.answer


@pytest.mark.parametrize("answer", [2, np.int64(2), 1.0, 0.0, "no", None, np.array(1), -1])
def test_an_answer_a_keep_or_solve_task_does_not_take_is_refused_naming_the_trigger_and_the_answer(answer):
    """Read by its truth, 2 (a compute level) was a full solve on a task without levels, "no" a solve too."""
    from etmpc.common.checks import BadValue
    from etmpc.policies.user import checked

    system = make_system("cart_pendulum/kicks")
    episode = _episode(system, 0)
    said = f"it returned {type(answer).__name__} {answer!r}"
    with pytest.raises(EtmpcError, match="^policy answers: decide must return a bool.*" + re.escape(said)):
        run_episode(system, system.make_env(), checked(_Answers(answer), levels=False), None, episode)
    # The loop refuses it too, naming the task, for a policy that is not checked (the one check: level_of).
    loop = ClosedLoop(system, system.make_env()).reset(episode)
    loop.step(True)
    with pytest.raises(BadValue, match=re.escape(f"on task cart_pendulum/kicks, got {type(answer).__name__} {answer!r}")):
        loop.step(answer)


def test_a_trigger_answers_a_bool_or_a_level_by_its_value_python_or_numpy():
    from etmpc.control.timing import level_of

    for answer, plain, levels in [
        (False, KEEP, KEEP),
        (True, SOLVE, SOLVE),
        (0, KEEP, KEEP),
        (1, SOLVE, ITERATE),
        (np.bool_(True), SOLVE, SOLVE),
        (np.int64(1), SOLVE, ITERATE),
        (np.uint8(0), KEEP, KEEP),
        (2, None, SOLVE),
        (np.int32(2), None, SOLVE),
        (3, None, None),
        (2.0, None, None),
    ]:
        assert (level_of(answer, False), level_of(answer, True)) == (plain, levels), answer
    # A user's trigger is checked as its task takes answers (not known: as a task with levels; the loop checks the rest).
    from types import SimpleNamespace

    from etmpc.policies.user import checked

    s = SimpleNamespace(context=None)
    assert checked(_Answers(np.int64(2)), levels=True).decide(s, None) == SOLVE
    assert checked(_Answers(np.int64(2))).decide(s, None) == SOLVE
    with pytest.raises(EtmpcError, match=r"policy answers: .* on a task without compute levels; it returned int64 np.int64\(2\)"):
        checked(_Answers(np.int64(2)), levels=False).decide(s, None)


def test_the_trajectory_keeps_when_each_plans_computation_started_and_when_it_came_into_force():
    d = 2
    system = _kicks(latency=Latency(intervals=d, compensate=True))
    traj = run_episode(system, system.make_env(), parse_policy("every:4", system), None, _episode(system, 1))
    assert len(traj.starts) == len(traj.plans) == len(traj.arrivals) and traj.starts[0] == 0
    for start, (made, _), arrived in zip(traj.starts[1:], traj.plans[1:], traj.arrivals[1:]):
        assert traj.recompute[start] and made == start + d == arrived  # compensated: made for its arrival


@pytest.mark.parametrize(
    "config, error, says",
    [
        ({"latency": 2}, "BadType", "latency: a Latency(...) is needed (etmpc.control.timing.Latency), got int 2"),
        (
            {"latency": Latency(intervals=25)},
            "BadValue",
            "latency: 25 intervals is not shorter than the MPC's horizon of 20 steps",
        ),
        (
            {"latency": Latency(intervals=20)},
            "BadValue",
            "latency: 20 intervals is not shorter than the MPC's horizon of 20 steps",
        ),
    ],
)
def test_a_tasks_time_in_the_loop_is_refused_when_its_system_is_made_not_mid_episode(config, error, says, monkeypatch):
    """One check for every task (SystemBase reads a Config's latency and compute_levels): an int for a Latency
    failed with an AttributeError mid-episode, compute_levels="no" turned levels on, and a latency as long as the
    horizon played a whole episode of plans that arrived after they ran out."""
    from etmpc.common import checks
    from etmpc.systems.cart_pendulum.timing import KicksLateSystem, LateConfig

    system = _kicks(**config)
    with pytest.raises(getattr(checks, error), match=re.escape(says)):
        ClosedLoop(system, system.make_env())  # refused before an episode starts
    # A task whose Config() holds it is refused by the registry when the system is made.
    monkeypatch.setattr(KicksLateSystem, "Config", lambda: replace(LateConfig(), **config))
    with pytest.raises(getattr(checks, error), match=re.escape(says)):
        make_system("cart_pendulum/kicks_late")
    assert make_system("cart_pendulum/kicks").latency.instant  # the default is none, and is a Latency


@pytest.mark.parametrize("value", ["no", 1, None])
def test_compute_levels_that_is_not_a_bool_is_refused_when_the_config_is_made(value):
    """compute_levels="no" is a true string: read by its truth it turned levels on. A Config holds what it may (its
    declared fields: etmpc.common.declared), so such a Config is never made, let alone a system of it."""
    from etmpc.common.checks import BadType
    from etmpc.systems.cart_pendulum.timing import LateConfig

    with pytest.raises(BadType, match=re.escape(f"LateConfig.compute_levels: {value!r} is not true or false")):
        replace(LateConfig(), compute_levels=value)


def test_a_task_that_counts_iterations_builds_their_code_with_its_mpc_so_no_measured_solve_holds_a_build(monkeypatch):
    from etmpc.control import sqpmethod  # the route the kicks fly builds their compiled code

    made = []

    class Counted(sqpmethod.CompiledFunction):
        def __init__(self, function, *args, **kwargs):
            made.append(function.name())
            super().__init__(function, *args, **kwargs)

    monkeypatch.setattr(sqpmethod, "CompiledFunction", Counted)
    system = make_system("cart_pendulum/kicks_levels")
    system.mpc
    assert made == ["cart_pendulum_kicks_mpc", "cart_pendulum_kicks_mpc_step"]
    loop = ClosedLoop(system, system.make_env()).reset(_episode(system, 0))
    for level in (SOLVE, ITERATE, KEEP, SOLVE):
        loop.step(level)
    assert len(made) == 2 and list(loop.trajectory.level[:4]) == [SOLVE, ITERATE, KEEP, SOLVE]  # played, nothing built
    kicks = make_system("cart_pendulum/kicks")
    kicks.mpc
    assert made[2:] == ["cart_pendulum_kicks_mpc"]  # a task priced per solve never makes the one-iteration code
