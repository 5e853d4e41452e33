"""Evaluation: results independent of the worker count, and equal to a direct run."""

import json

import numpy as np
import pytest

from etmpc.common.errors import EtmpcError
from etmpc.evaluation import backends
from etmpc.evaluation.evaluate import evaluate
from etmpc.loop import run_episode
from etmpc.policies import parse_policy

POLICIES = ["always", "every:5", "threshold:0.3"]


@pytest.fixture(scope="module")
def serial():
    return evaluate("cart_pendulum", POLICIES, episodes=4, workers=1, progress=False)


def test_same_numbers_for_any_worker_count(serial):
    parallel = evaluate("cart_pendulum", POLICIES, episodes=4, workers=2, progress=False)
    assert json.dumps(serial.to_json(), sort_keys=True) == json.dumps(parallel.to_json(), sort_keys=True)


def test_stages_in_shared_pools_use_one_pool_and_give_the_same_numbers(serial):
    """Inside ``shared_pools`` two stages run on the same worker processes, with the numbers of a
    serial run; a stage that fails ends its pool (the next stage starts another), and leaving the
    block ends every worker."""
    with backends.shared_pools():
        first = evaluate("cart_pendulum", POLICIES, episodes=4, workers=2, progress=False)
        pool = backends._SHARED_POOLS[2]
        processes = list(pool._processes.values())
        second = evaluate("cart_pendulum", POLICIES, episodes=4, workers=2, progress=False)
        assert backends._SHARED_POOLS[2] is pool and list(pool._processes.values()) == processes
        with pytest.raises(RuntimeError, match="a stage failed"):
            with backends.make_backend("local", 2):
                raise RuntimeError("a stage failed")
        assert 2 not in backends._SHARED_POOLS
        with backends.make_backend("local", 2) as backend:
            assert backend._pool is not pool and backends._SHARED_POOLS[2] is backend._pool
        last = backends._SHARED_POOLS[2]
    assert backends._SHARED_POOLS is None
    for result in (first, second):
        assert json.dumps(serial.to_json(), sort_keys=True) == json.dumps(result.to_json(), sort_keys=True)
    for process in processes:
        process.join(timeout=10)
        assert not process.is_alive()
    with pytest.raises(RuntimeError, match="shutdown"):
        last.submit(abs, -1)  # ended too


def test_summary_equals_a_direct_run(serial, cart_system, cart_testset):
    env = cart_system.make_env()
    for summary in serial.summaries:
        policy = parse_policy(summary.policy, cart_system)
        objectives, recomputes = [], []
        for e in range(4):
            traj = run_episode(cart_system, env, policy, None, cart_system.episode_from_arrays(cart_testset.episode_arrays(e)))
            beta = traj.states[1:101, 2]
            objectives.append(np.sum(beta**2) + 5e-5 * traj.recomputes)
            recomputes.append(traj.recomputes)
        assert summary.objective_mean == pytest.approx(np.mean(objectives), rel=1e-12)
        assert summary.objective_std == pytest.approx(np.std(objectives, ddof=1), rel=1e-9)
        assert summary.recomputes_mean == pytest.approx(np.mean(recomputes))
        assert summary.objective_sense == "min" and summary.episodes == 4 and summary.repeats == 1


def test_json_has_the_documented_fields(serial, cart_testset):
    data = serial.to_json()
    assert data["test_set"]["sha256"] == cart_testset.sha256
    for policy in POLICIES:
        entry = data["policies"][policy]
        for key in (
            "objective_mean",
            "objective_std",
            "objective_sense",
            "control_objective_mean",
            "recomputes_mean",
            "solver_failures",
            "episodes",
            "repeats",
            "nonfinite_episodes",
            "failure_name",  # every built-in task counts its failures: per run, and per policy with a 95 % CI
            "failures_mean",
            "failures_ci95",
        ):
            assert key in entry
    assert len(data["runs"]) == 3 * 4 and all(isinstance(r["failures"], int) for r in data["runs"])


def test_the_table_shows_the_failures_per_episode_with_their_95_percent_ci(serial):
    from statistics import fmean, stdev

    from etmpc.evaluation.evaluate import format_table

    table = format_table(serial)
    assert "off balance/episode" in table
    for spec in POLICIES:
        counts = [r.failures for r in serial.runs if r.policy == spec]
        line = next(line for line in table.splitlines() if line.startswith(spec + " "))
        assert f"{fmean(counts):.2f} ± {1.96 * stdev(counts) / 2:.2f}" in line  # n = 4 episodes


def test_a_recording_is_written_by_the_recorder_it_is_given(tmp_path):
    """Evaluation draws nothing itself: with ``record`` it opens the recording with the recorder it is given
    (etmpc.evaluate gives Rerun's), hands it what each run kept, in the runs' order, and closes it keeping
    the file; without a recorder, a record path is refused before any work."""
    opened = []

    class Sink:  # an EpisodeSink that keeps what it is given
        def __init__(self, path):
            self.path, self.records, self.kept = path, [], None
            opened.append(self)

        def log_episode(self, record):
            self.records.append(record)

        def close(self, keep=True):
            self.kept = keep

    path = tmp_path / "r.rrd"
    result = evaluate("battery", ["every:5", "never"], episodes=2, workers=1, progress=False, record=path, recorder=Sink)
    (sink,) = opened
    assert sink.path == path and sink.kept is True
    kept = [(r.identity["policy"], r.identity["episode"], int(r.recompute.sum())) for r in sink.records]
    assert kept == [(run.policy, run.episode, run.recomputes) for run in result.runs]
    assert list(tmp_path.iterdir()) == []  # nothing written but by the recorder
    with pytest.raises(EtmpcError, match="^record: nothing to write it with: pass recorder="):
        evaluate("battery", ["never"], episodes=1, workers=1, progress=False, record=path)
    assert list(tmp_path.iterdir()) == []


def test_the_task_is_called_task_and_the_old_keyword_domain_still_works_with_a_warning():
    new = evaluate(task="cart_pendulum", policies=["every:5"], episodes=1, workers=1, progress=False)
    with pytest.warns(DeprecationWarning, match="domain= is deprecated: call it task="):
        old = evaluate(domain="cart_pendulum", policies=["every:5"], episodes=1, workers=1, progress=False)
    assert old.to_json()["runs"] == new.to_json()["runs"]
    with pytest.raises(EtmpcError, match=r"^task: give it once \(domain= is its old name\)$"):
        evaluate("cart_pendulum", ["every:5"], domain="cart_pendulum", episodes=1, workers=1, progress=False)
    with pytest.raises(EtmpcError, match="^task: missing$"):
        evaluate(policies=["every:5"], episodes=1, workers=1, progress=False)
