"""DPI on a task with compute levels (``cart_pendulum/kicks_levels``: keep, one SQP iteration, a full
solve): the second stage's fit against data drawn from a known model, the labels, the first schedules,
the learners that refuse such a task, and a tiny training run whose policy iterates."""

import json

import numpy as np
import pytest

from etmpc.cli import main
from etmpc.control.timing import ITERATE, KEEP, SOLVE
from etmpc.evaluation.workers import context, play_test_episode
from etmpc.learning import dpi
from etmpc.learning.train import TrainConfig, train
from etmpc.policies import parse_policy

LEVELS = "cart_pendulum/kicks_levels"


def test_stage_two_recovers_the_model_its_labels_were_drawn_from():
    """A full solve with probability sigma(theta . phi), unit weights: the maximum-likelihood fit finds theta."""
    rng = np.random.default_rng(0)
    n, theta = 20000, np.array([-1.0, 2.5, 0.7])
    phi = np.column_stack([rng.normal(size=(n, 2)), np.ones(n)])
    solve = rng.random(n) < 1 / (1 + np.exp(-phi @ theta))
    iterate_advantage = np.where(solve, -1.0, 1.0)  # q_iterate - q_solve: negative where a solve is better
    np.testing.assert_allclose(dpi.fit_level(phi, iterate_advantage, ridge=0.0), theta, atol=0.08)


def test_stage_two_finds_the_direction_that_separates_costly_mistakes():
    """q_solve - q_iterate = w . phi (a solve pays where the state is far off): the fitted boundary's normal is w's."""
    rng = np.random.default_rng(1)
    w = np.array([0.6, -0.8, 0.0, 0.3])
    phi = np.column_stack([rng.normal(size=(4000, 3)), np.ones(4000)])
    theta_level = dpi.fit_level(phi, -(phi @ w), ridge=1e-3)
    cosine = theta_level[:3] @ w[:3] / np.linalg.norm(theta_level[:3]) / np.linalg.norm(w[:3])
    assert cosine > 0.99
    assert np.mean((phi @ theta_level > 0) == (phi @ w > 0)) > 0.99


def test_the_advantage_of_keeping_is_against_the_better_computation():
    binary = [[1.0], -2.0, -3.0, 7]  # (phi, q_keep, q_recompute, step)
    levels = [[1.0], -2.0, -3.0, 7, -1.5]  # (phi, q_keep, q_solve, step, q_iterate)
    assert dpi.keep_advantage(binary) == 1.0 and dpi.keep_advantage(levels) == -0.5


def test_stage_two_is_fitted_where_stage_one_computes():
    """Rows where the fitted stage 1 keeps do not move stage 2 (a wrong level there costs nothing); if it
    keeps everywhere, every row counts."""
    rng = np.random.default_rng(2)
    phi = np.column_stack([rng.normal(size=(200, 2)), np.ones(200)])
    theta = np.array([1.0, 0.0, 0.0])  # stage 1 computes where phi[0] < 0
    rows = [[p.tolist(), 0.0, -abs(p[1]) * (p[1] > 0), 5, -abs(p[1]) * (p[1] <= 0)] for p in phi]
    flipped = [row if p[0] < 0 else [row[0], row[1], row[4], row[3], row[2]] for row, p in zip(rows, phi)]
    fitted = dpi.fit_level_labels(rows, 1e-2, theta)
    np.testing.assert_array_equal(fitted, dpi.fit_level_labels(flipped, 1e-2, theta))
    assert np.mean((phi[phi[:, 0] < 0] @ fitted > 0) == (phi[phi[:, 0] < 0, 1] <= 0)) > 0.95  # solve where q_solve wins
    everywhere = dpi.fit_level_labels(rows, 1e-2, np.array([0.0, 0.0, 1.0]))  # stage 1 keeps at every row
    np.testing.assert_array_equal(everywhere, dpi.fit_level(phi, np.array([r[4] - r[2] for r in rows]), 1e-2))


def test_the_first_schedules_include_real_time_iterations_on_a_task_with_levels_only():
    assert TrainConfig("cart_pendulum/kicks", algorithm="dpi").dpi.bases == dpi.BASES
    levels = ("iterate:1", "iterate:2", "iterate:3", "iterate:4", "iterate:5")
    assert TrainConfig(LEVELS, algorithm="dpi").dpi.bases == dpi.BASES + levels
    chosen = dpi.Settings(bases=("always", "iterate:3"))
    assert TrainConfig(LEVELS, algorithm="dpi", dpi=chosen).dpi == chosen  # chosen candidates stay as they are
    config = TrainConfig(LEVELS, algorithm="dpi")
    assert TrainConfig.from_json(json.loads(json.dumps(config.to_json()))) == config


@pytest.mark.parametrize("algorithm", ["gpomdp", "self"])
def test_learners_of_keep_or_solve_refuse_a_task_with_levels_in_one_line(tmp_path, capsys, algorithm):
    assert main(["train", "--task", LEVELS, "--algorithm", algorithm, "--out", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{algorithm} needs a task whose decisions are keep or solve" in err
    assert not (tmp_path / "run").exists()


TINY = TrainConfig(
    LEVELS,
    seeds=(0,),
    episodes=2,
    eval_every=1,
    eval_episodes=1,
    normalisation_episodes=2,
    validation_episodes=1,
    algorithm="dpi",
    dpi=dpi.Settings(futures=2, horizon=8, states_per_episode=8, selection_episodes=1),
)


def _files(out):
    return {p.relative_to(out).as_posix(): p.read_bytes() for p in sorted(out.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    """A tiny DPI run on kicks_levels: two iterations of one seed (made once for this file's tests)."""
    out = tmp_path_factory.mktemp("levels") / "run"
    return out, train(TINY, out, workers=1, progress=False)


def test_a_tiny_dpi_run_on_a_task_with_levels_learns_a_policy_that_iterates(tiny_run):
    out, state = tiny_run
    learner = state.learners["0"]
    assert learner["iterations"] == 2 and len(learner["theta_level"]) == len(learner["theta"])
    rows = learner["data"]
    assert rows and all(len(row) == 5 for row in rows)  # (phi, q_keep, q_solve, step, q_iterate)
    selected = json.loads((out / "selected.json").read_text())
    assert selected["version"] == 3 and selected["theta_level"] == learner["theta_level"]
    assert selected["hyperparameters"]["bases"] == list(TINY.dpi.bases) and state.base in TINY.dpi.bases
    assert TINY.dpi.bases[-5:] == dpi.LEVEL_BASES
    # Where a labelled computation's iteration did at least as well as the full solve, and the fitted
    # policy computes, it iterates there (stage 2 follows its labels on the states it was fitted on).
    system = context(LEVELS)[0]
    policy = parse_policy(f"rl:{out / 'selected.json'}", system)
    phi = np.array([row[0] for row in rows])
    computes = [policy.decision_value(p) < 0 for p in phi]
    iterate_wins = [row[4] >= row[2] for row in rows]
    agree = [(policy.level_value(p) <= 0) == w for p, w, c in zip(phi, iterate_wins, computes) if c]
    assert not agree or np.mean(agree) >= 0.75
    # It plays its task (etmpc evaluate's rl:PATH), answering levels, and iterates at some of its decisions.
    traj = play_test_episode(LEVELS, policy, 0, 0, 0).trajectory  # as etmpc evaluate plays it
    asked = ~(traj.forced[: traj.steps] | traj.in_flight[: traj.steps])
    assert traj.steps == system.episode_steps and np.any(traj.level[: traj.steps][asked] == ITERATE)
    assert set(np.unique(traj.level[: traj.steps][asked])) <= {KEEP, ITERATE, SOLVE}


def test_a_run_on_a_task_with_levels_stopped_after_a_milestone_resumes_bit_for_bit(tiny_run, tmp_path, monkeypatch):
    """The checkpoint keeps the second stage (each learner's and each best point's theta_level) and the
    q_iterate column: the resumed run writes the uninterrupted one's files, byte for byte."""
    from etmpc.learning.phased import DpiLearner

    learn, calls = DpiLearner.learn, []

    class Stop(Exception):
        pass

    def learn_once(self, budget, callback):  # the first milestone is learnt and saved; the second is killed
        calls.append(budget)
        if len(calls) > 1:
            raise Stop
        learn(self, budget, callback)

    monkeypatch.setattr(DpiLearner, "learn", learn_once)
    with pytest.raises(Stop):
        train(TINY, tmp_path / "cut", workers=1, progress=False)
    cut = json.loads((tmp_path / "cut" / "checkpoint.json").read_text())
    assert cut["learners"]["0"]["iterations"] == 1 and "theta_level" in cut["best"]["0"]
    monkeypatch.setattr(DpiLearner, "learn", learn)
    train(TINY, tmp_path / "cut", workers=1, resume=True, progress=False)
    assert _files(tmp_path / "cut") == _files(tiny_run[0])
