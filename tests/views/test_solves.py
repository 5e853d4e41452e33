"""Time in the loop in a recording: each solve's start and arrival, the plan in force and each step's
work, read back with Rerun's own reader and checked against the live trajectory (the loop's own
records) and the latency's definition (etmpc.control.timing)."""

import numpy as np
import pytest

from etmpc.common.sense import oriented
from etmpc import evaluate
from etmpc.evaluation.workers import context, play_test_episode
from etmpc.loop import computation_cost
from etmpc.policies import parse_policy
from etmpc.loop.records import plan_starts
from etmpc.views.replay import read_recording, replay_summary
from etmpc.views.solves import frame_captions
from tests.views.test_recording import chunks_by_entity, column_chunk, read_blueprint, series, views_of

LATE, LEVELS = "cart_pendulum/kicks_late", "cart_pendulum/kicks_levels"
POLICIES = {LATE: ["every:3", "threshold:0.3"], LEVELS: ["every:4", "iterate:3", "threshold:0.3"]}


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """``{task: (path, live evaluation)}``: one episode per policy, recorded."""
    out = {}
    for task, policies in POLICIES.items():
        path = tmp_path_factory.mktemp("timed") / "t.rrd"
        out[task] = path, evaluate(task, policies, episodes=1, workers=1, progress=False, record=path)
    return out


def played(task, spec):
    system, _, _ = context(task)
    return system, play_test_episode(task, parse_policy(spec, system), 0, 0, 0)


def root_of(task, spec):
    return f"/{task.replace('/', '-')}/{spec.replace(':', chr(92) + ':')}/episode_000/repeat_0"


CASES = [(task, spec) for task, specs in POLICIES.items() for spec in specs]


@pytest.mark.parametrize("task, spec", CASES)
def test_each_solves_start_and_arrival_and_the_plan_in_force(recorded, task, spec):
    """Independent truth: the trajectory's computations and plans, and the loop's own input: the plan
    the recording says is in force at a step is the one whose input was applied then."""
    system, play = played(task, spec)
    traj, n = play.trajectory, play.trajectory.steps
    entities = chunks_by_entity(recorded[task][0])
    root = root_of(task, spec)
    made = np.array([k for k, _ in traj.plans])

    steps, started = series(entities, f"{root}/solve/started")
    np.testing.assert_array_equal(steps, np.flatnonzero(traj.recompute[:n]))
    np.testing.assert_array_equal(np.nanmax(started, axis=1), steps)  # at the step it started, one kind each
    assert (np.isfinite(started).sum(axis=1) == 1).all()
    if task == LEVELS:  # one SQP iteration, then a full solve: by the trajectory's level
        np.testing.assert_array_equal(np.isfinite(started[:, 0]), traj.level[steps] == 1)

    steps, arrived = series(entities, f"{root}/solve/arrived")
    assert not traj.solver_failures  # every solve's plan came into force
    np.testing.assert_array_equal(steps, traj.arrivals)
    np.testing.assert_array_equal(arrived[:, 0], made)  # y: the step it was made for
    assert np.isnan(arrived[:, 1]).all()
    np.testing.assert_array_equal(plan_starts(made, traj.arrivals, traj.forced[:n]), made)  # no compensation

    steps, in_force = series(entities, f"{root}/solve/in_force")
    np.testing.assert_array_equal(steps, np.arange(n))
    plans = dict(traj.plans)
    for i, k in enumerate(in_force[:, 0].astype(int)):
        assert traj.planned[i, 0] == plans[k].input_at(i - k)[0]  # its input was the one applied
    late = np.array(traj.arrivals) > made
    assert late[1:].all() and not late[0]  # the first plan is made before the interval; every other is late
    if task == LATE:
        np.testing.assert_array_equal((np.array(traj.arrivals) - made)[1:], 1)
    else:  # d = ceil(iterations x 30 ms / 0.1 s): the latency's own definition
        dt = system.control_interval_s
        assert [a - k for a, (k, p) in zip(traj.arrivals[1:], traj.plans[1:])] == [
            system.latency.delay(p.iterations, dt) for _, p in traj.plans[1:]
        ]

    steps, compute = series(entities, f"{root}/compute")
    np.testing.assert_array_equal(steps, np.arange(n))
    np.testing.assert_array_equal(compute, np.column_stack([traj.level[:n], traj.work[:n], traj.in_flight[:n]]))
    identity = entities[f"{root}/identity"][0].to_pydict()
    assert identity["compute_levels"] == [[task == LEVELS]] and identity["latency"] == [[system.latency.describe()]]

    text = column_chunk(entities, f"{root}/events/solves", "TextLog:text").column("TextLog:text").to_pylist()
    starts = [line for (line,) in text if " started at step " in line]
    assert len(starts) == traj.recomputes - 1  # all but the first plan, made before the interval
    for line, s, a in zip(starts, made[1:], traj.arrivals[1:]):
        assert line.endswith(f"started at step {s} (arrives step {a})")


@pytest.mark.parametrize("task, spec", CASES)
def test_replay_prices_the_work_as_the_live_run(recorded, task, spec):
    """Bit for bit: the replayed objective is ``Trajectory.policy_return`` and the live run's; on a task
    with compute levels a computation costs its SQP iterations, not one."""
    system, play = played(task, spec)
    traj = play.trajectory
    path, live = recorded[task]
    (again,) = [r for r in replay_summary(path) if r.policy == spec]
    (run,) = [r for r in live.runs if r.policy == spec]
    assert again.objective == run.objective == oriented(traj.policy_return(system.recompute_price), system.objective_sense)
    assert again.work == traj.total_work and again.recomputes == traj.recomputes
    data = read_recording(path)[root_of(task, spec)]
    price = data["identity"]["recompute_price"]
    _, rewards = data["reward"]
    _, work = data["work"]
    ret = float(rewards.sum() - computation_cost(work.sum(), price))  # Trajectory.policy_return's expression
    assert ret == traj.policy_return(system.recompute_price) and again.objective == oriented(ret, system.objective_sense)
    if task == LEVELS:
        assert work.sum() > traj.recomputes  # a full solve takes several iterations
        assert ret != float(rewards.sum() - computation_cost(traj.recomputes, price))
    _, running = data["running"]
    assert running[-1] == pytest.approx(again.objective, rel=1e-12)  # the running objective prices the work too


@pytest.mark.parametrize("task", [LATE, LEVELS])
def test_the_prediction_error_is_against_the_plan_the_late_trigger_saw(recorded, task):
    """Independent truth: ``threshold:X`` on a late task recomputes by choice exactly where the recorded
    error exceeds X (a late plan counts from the step it arrived), and keeps its plan where it does not
    (the steps in flight, where it is not asked, aside)."""
    data = read_recording(recorded[task][0])[root_of(task, "threshold:0.3")]
    steps, errors = data["prediction_error"]
    _, recompute = data["recompute"]
    _, forced = data["forced"]
    _, in_flight = data["in_flight"]
    asked = (forced[steps] == 0) & (in_flight[steps] == 0)
    chosen, kept = asked & (recompute[steps] > 0), asked & (recompute[steps] == 0)
    assert chosen.sum() > 5 and kept.sum() > 5
    assert np.all(errors[chosen] > 0.3) and np.all(errors[kept] <= 0.3)


@pytest.mark.parametrize("task, spec", CASES)
def test_the_prediction_error_is_against_the_plan_in_force(recorded, task, spec):
    """Independent truth: the loop's own prediction ``x̂_i`` (``Trajectory.predicted``, from the plan whose
    input it applied): a late plan counts from the step it arrived, also while the next solve is in
    flight; the steps where a plan made before the interval came into force aside (none precedes it)."""
    system, play = played(task, spec)
    traj, n = play.trajectory, play.trajectory.steps
    steps, errors = read_recording(recorded[task][0])[root_of(task, spec)]["prediction_error"]
    instant = {a for a, (k, _) in zip(traj.arrivals, traj.plans) if a == k}
    check = [j for j, i in enumerate(steps) if i not in instant]
    assert len(check) == n - 1
    w = system.error_weights
    expected = [np.linalg.norm(w * (traj.states[i] - traj.predicted[i])) for i in steps[check]]
    np.testing.assert_allclose(errors[check], expected, rtol=0, atol=1e-12)


def test_solves_in_flight_on_the_levels_task(recorded):
    """Steps in flight (the trigger not asked) lie between a solve's start and its plan's arrival."""
    _, play = played(LEVELS, "every:4")
    traj, n = play.trajectory, play.trajectory.steps
    between = np.zeros(n, bool)
    for k, a in zip([k for k, _ in traj.plans], traj.arrivals):
        between[k + 1 : a] = True
    assert between.any()
    np.testing.assert_array_equal(traj.in_flight[:n], between)
    data = read_recording(recorded[LEVELS][0])[root_of(LEVELS, "every:4")]
    np.testing.assert_array_equal(data["in_flight"][1] > 0, between)


def test_the_blueprint_shows_the_plan_in_force_on_timed_tasks_only(recorded, tmp_path):
    root = root_of(LATE, "every:3")
    views = views_of(read_blueprint(recorded[LATE][0])[0])
    (view,) = [v for v in views if v["name"].startswith("plan in force") and v["origin"] == root]
    assert view["contents"] == [f"{root}/solve/in_force", f"{root}/solve/started", f"{root}/solve/arrived"]
    assert any(v["contents"] == [f"{root}/compute"] for v in views)
    # The paper's tasks: no new entity, no new panel, the identity as it was.
    path = tmp_path / "k.rrd"
    evaluate("cart_pendulum/kicks", ["every:3"], episodes=1, workers=1, progress=False, record=path)
    entities = chunks_by_entity(path)
    assert not [e for e in entities if e.endswith(("/compute", "/events/solves")) or "/solve/" in e]
    assert {"latency", "compute_levels"}.isdisjoint(
        entities[f"{root_of('cart_pendulum/kicks', 'every:3')}/identity"][0].schema.names
    )
    assert not [v for v in views_of(read_blueprint(path)[0]) if v["name"].startswith(("plan in force", "recompute per step"))]
    assert "work" not in read_recording(path)[root_of("cart_pendulum/kicks", "every:3")]


def test_each_frame_says_which_plan_is_in_force_and_which_solve_is_in_flight():
    """Frame i shows step i's state: a solve started at step k is "solving (started step k, arrives step
    k+d)" on frames k..k+d-1, and frame k+d says its plan came into force."""
    for task, spec in (("cart_pendulum/kicks_late", "every:3"), ("cart_pendulum/kicks_levels", "every:4")):
        system, play = played(task, spec)
        traj, n = play.trajectory, play.trajectory.steps
        captions = frame_captions(play.record(spec), system.compute_levels)
        assert len(captions) == n + 1
        current = -1
        arrivals = dict(zip(traj.arrivals, [k for k, _ in traj.plans]))
        for i, lines in enumerate(captions):
            current = arrivals.get(i, current)
            texts = [t for t, _ in lines]
            assert texts[0] == f"step {i} · plan in force: made for step {current}"
            new = [t for t in texts if t.startswith("NEW PLAN")]
            assert new == (
                [f"NEW PLAN in force (made for step {arrivals[i]}, started step {arrivals[i]})"] if i in arrivals else []
            )
            solving = [t for t in texts if t.startswith("solving")]
            pending = [(k, a) for k, a in zip([k for k, _ in traj.plans], traj.arrivals) if k <= i < a]
            assert [t.split(")")[0] + ")" for t in solving] == [
                f"solving (started step {k}, arrives step {a})" for k, a in pending
            ]
            if i < n:
                assert bool(pending) == bool(traj.in_flight[i] or (traj.recompute[i] and i > 0))


def test_a_compensated_plan_started_its_latency_earlier_and_a_failed_solve_gave_no_plan():
    """From the loop's definition: delay-compensated, a plan is made for the step its solve started plus
    the latency's intervals, unless it was made before the interval (forced: the first, or after a
    restart); a solve whose plan never came into force ends where its steps in flight end."""
    from types import SimpleNamespace

    from etmpc.views.solves import solves

    forced = np.zeros(20, bool)
    forced[[0, 12]] = True
    made, arrivals = [0, 5, 9, 12], [0, 5, 10, 12]  # latency 2 intervals (+1 for the third), compensated
    np.testing.assert_array_equal(plan_starts(made, arrivals, forced, shift=2), [0, 3, 7, 12])
    np.testing.assert_array_equal(plan_starts(made, arrivals, forced), made)  # not compensated
    recompute, in_flight = np.zeros(20, bool), np.zeros(20, bool)
    recompute[[0, 3, 7, 12, 15]] = True
    in_flight[[4, 8, 9, 16, 17]] = True  # the solve of step 15 is in flight until step 18, and gives no plan
    record = SimpleNamespace(
        steps=20,
        plans=[(k,) for k in made],
        starts=(0, 3, 7, 12),
        arrivals=tuple(arrivals),
        recompute=recompute,
        in_flight=in_flight,
        level=np.where(recompute, 2, 0),
        work=recompute.astype(float),
    )
    assert [(v.start, v.due, v.made_for, v.delivered) for v in solves(record)] == [
        (0, 0, 0, True),
        (3, 5, 5, True),
        (7, 10, 9, True),
        (12, 12, 12, True),
        (15, 18, -1, False),
    ]
    captions = frame_captions(record, False)
    assert [t for t, _ in captions[16]] == ["step 16 · plan in force: made for step 12", "solving (started step 15, due step 18)"]
    assert [t for t, _ in captions[18]][1] == "solve started at step 15 gave no plan in force"
