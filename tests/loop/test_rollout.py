"""Snapshots, the fast path and the rollout policies, against the dm_env loop and rollout's theorem."""

import copy
import dataclasses

import numpy as np
import pytest

from etmpc import loop
from etmpc.common.errors import EtmpcError, UnknownNameError
from etmpc.loop import Snapshot, play_on, run_episode
from etmpc.policies import parse_policy, rollout
from etmpc.evaluation.workers import play_test_episode

from tests.conftest import REPO


class SnapshotAt:
    """A policy that also freezes the running episode at one step (the loop hands it its context),
    with its generator as it is after that step's decision."""

    simulates = True

    def __init__(self, inner, step: int):
        self.inner, self.step, self.snapshot, self.decision, self.rng = inner, step, None, None, None
        self.spec, self.stochastic = inner.spec, inner.stochastic

    def decide(self, s, rng):
        decision = self.inner.decide(s, rng)
        if s.context.step == self.step:
            self.snapshot, self.decision, self.rng = Snapshot.take(s.context), decision, copy.deepcopy(rng)
        return decision


def _returns_from(traj, step: int, price: float) -> float:
    total = 0.0  # the same sum, in the same order, as play_on makes it
    for reward, recompute in zip(traj.rewards[step : traj.steps], traj.recompute[step : traj.steps]):
        total += reward - price * recompute
    return total


# Every kind of base a rollout plays: fixed schedules, the event trigger (reads the state only,
# ``observes = False``) and the shipped learned policies (read the observation, draw from the generator).
@pytest.mark.parametrize(
    "domain, spec, step",
    [
        ("cart_pendulum", "every:3", 37),
        ("battery", "every:4", 58),
        ("cart_pendulum", "never", 5),
        ("cart_pendulum", "threshold:0.3", 21),
        ("battery", "threshold:0.02", 40),
        ("cart_pendulum", "rl:policies/cart_pendulum/balance/learned.json", 12),
        ("battery", "rl:policies/battery/trading/learned.json", 30),
        ("battery", "rl:policies/battery/trading/learned.json+sample", 30),
    ],
)
def test_the_fast_path_replays_the_dm_env_loop_bit_for_bit(
    domain, spec, step, cart_system, battery_system, cart_testset, battery_testset
):
    system, testset = {"cart_pendulum": (cart_system, cart_testset), "battery": (battery_system, battery_testset)}[domain]
    episode = system.episode_from_arrays(testset.episode_arrays(3))
    inner = parse_policy(spec.replace("rl:", "rl:" + str(REPO) + "/").removesuffix("+sample"), system)
    if spec.endswith("+sample"):  # drawing each decision from pi, as in training
        inner = dataclasses.replace(inner, greedy=False)
        assert inner.stochastic
    spy = SnapshotAt(inner, step)
    original = run_episode(system, system.make_env(), spy, np.random.default_rng(7), episode)
    assert spy.snapshot is not None and original.steps == system.episode_steps
    twin = system.make_env()
    for _ in range(2):  # and again: a restore leaves nothing behind
        total = play_on(system, twin, spy.snapshot, inner, copy.deepcopy(spy.rng), spy.decision)
        assert total == _returns_from(original, step, system.recompute_price)
        np.testing.assert_array_equal(twin.physics.state(), original.states[original.steps])
    # Stopping early: the same steps, plus the truncation value of the state reached.
    stop = step + 10
    truncated = play_on(system, twin, spy.snapshot, inner, copy.deepcopy(spy.rng), spy.decision, stop=stop)
    partial = original.rewards[step:stop] - system.recompute_price * original.recompute[step:stop]
    assert truncated == pytest.approx(partial.sum() + system.truncation_value(original.states[stop]), rel=1e-12, abs=1e-15)


@pytest.mark.parametrize("domain", ["cart_pendulum", "battery"])
def test_measuring_the_physics_gives_the_state_the_observation_shows(domain, cart_system, battery_system):
    system = {"cart_pendulum": cart_system, "battery": battery_system}[domain]
    env = system.make_env(random=4)
    timestep = env.reset()
    rng = np.random.default_rng(0)
    while not timestep.last():
        x = system.measure(env.physics)
        assert x.dtype == np.float64
        np.testing.assert_array_equal(x, system.state(timestep))
        timestep = env.step(rng.uniform(env.action_spec().minimum, env.action_spec().maximum))


def test_a_sampled_future_changes_only_what_the_controller_has_not_seen(cart_system, cart_testset):
    episode = cart_system.episode_from_arrays(cart_testset.episode_arrays(0))
    future = cart_system.sample_future(episode, 40, np.random.default_rng(1))
    np.testing.assert_array_equal(future.initial_state, episode.initial_state)
    np.testing.assert_array_equal(future.disturbance[:40], episode.disturbance[:40])
    assert not np.any(future.disturbance[40:] == episode.disturbance[40:])


@pytest.mark.slow
@pytest.mark.parametrize("episode", [0, 5])
def test_the_oracle_never_does_worse_than_its_base(cart_system, episode):
    """Rollout's cost-improvement property: with the stored (deterministic) future, the one-step
    lookahead over a base policy costs at most what the base costs, on every episode, because the
    simulation is the plant, bit for bit (Bertsekas, Rollout algorithms, sequential consistency)."""
    base = play_test_episode("cart_pendulum", parse_policy("every:5", cart_system), 0, 0, episode)
    oracle = play_test_episode("cart_pendulum", parse_policy("oracle:every:5", cart_system), 0, 0, episode)
    price = cart_system.recompute_price
    assert -oracle.trajectory.policy_return(price) <= -base.trajectory.policy_return(price)
    assert oracle.trajectory.recomputes != base.trajectory.recomputes or not np.array_equal(
        oracle.trajectory.recompute, base.trajectory.recompute
    )  # it did decide something


@pytest.mark.parametrize("task, base", [("cart_pendulum", "every:3"), ("battery", "every:5")])
def test_the_oracles_memo_changes_no_decision_and_halves_its_plays(task, base, monkeypatch):
    """The memo hands the oracle, at step i + 1, the rest of the play it took at step i. Against the
    oracle that plays both answers at every decision (the memo never consulted), the episode is the
    same bit for bit, and the memo answers for almost every decision (all but the first and those
    after a forced one), so the oracle plays about half as many steps."""
    played = []

    def counting_play_on(*args, **kwargs):
        played.append(1)
        return loop.play_on(*args, **kwargs)

    monkeypatch.setattr(rollout, "play_on", counting_play_on)
    lookups = []
    real_lookup = rollout.OracleMemo.lookup

    def counting_lookup(memo, snapshot):
        lookups.append(real_lookup(memo, snapshot))
        return lookups[-1]

    monkeypatch.setattr(rollout.OracleMemo, "lookup", counting_lookup)
    with_memo = play_test_episode(task, parse_policy(f"oracle:{base}", task), 0, 0, 2).trajectory
    plays_with_memo = len(played)
    hits = sum(known is not None for known in lookups)
    monkeypatch.setattr(rollout.OracleMemo, "lookup", lambda memo, snapshot: real_lookup(rollout.OracleMemo(), snapshot))
    played.clear()
    without = play_test_episode(task, parse_policy(f"oracle:{base}", task), 0, 0, 2).trajectory
    np.testing.assert_array_equal(with_memo.recompute, without.recompute)
    np.testing.assert_array_equal(with_memo.rewards, without.rewards)
    np.testing.assert_array_equal(with_memo.states, without.states)
    decisions = len(lookups)
    assert hits >= 0.9 * decisions
    assert len(played) == 2 * decisions and plays_with_memo == 2 * decisions - hits


def test_rollout_is_deterministic_given_its_generator(battery_system):
    policy = parse_policy("rollout:every:5:2:10", battery_system)
    a = play_test_episode("battery", policy, 3, 0, 1).trajectory
    b = play_test_episode("battery", policy, 3, 0, 1).trajectory
    c = play_test_episode("battery", policy, 4, 0, 1).trajectory
    np.testing.assert_array_equal(a.recompute, b.recompute)
    assert a.policy_return(0.0) == b.policy_return(0.0)
    assert not np.array_equal(a.recompute, c.recompute) or a.policy_return(0.0) != c.policy_return(0.0)


@pytest.mark.parametrize(
    "spec, canonical",
    [
        ("rollout:always", "rollout:always:8"),
        ("rollout:every:3", "rollout:every:3:8"),
        ("rollout:every:3:4", "rollout:every:3:4"),
        ("rollout:always:2:30", "rollout:always:2:30"),
        ("rollout:threshold:0.3:5", "rollout:threshold:0.3:5"),
        ("oracle:every:3", "oracle:every:3"),
        ("oracle:never", "oracle:never"),
    ],
)
def test_rollout_specs(cart_system, spec, canonical):
    policy = parse_policy(spec, cart_system)
    assert policy.spec == canonical
    assert policy.oracle == spec.startswith("oracle")


@pytest.mark.parametrize(
    "spec",
    [
        "rollout",
        "rollout:",
        "oracle:",
        "rollout:bogus",
        "rollout:every:0",
        "rollout:every:3:0",
        "rollout:every:3:-2",
        "rollout:always:x",
        "rollout:always:8:0",
        "rollout:always:8:101",
        "rollout:always:8:20:3",
        "rollout:always:1e3",
        "rollout:rollout:always",
        "oracle:oracle:always",
        "oracle:rollout:always",
        "oracle:every:3:8",
        "rollout:rl:/no/such.json",
        "rollout:always:100000",
    ],
)
def test_bad_rollout_specs_are_one_line_errors(cart_system, spec):
    with pytest.raises(EtmpcError) as info:
        parse_policy(spec, cart_system)
    assert "\n" not in str(info.value) and spec in str(info.value)


def test_unknown_policy_lists_the_rollouts(cart_system):
    with pytest.raises(UnknownNameError, match="rollout:BASE"):
        parse_policy("rollouts:always", cart_system)


def test_the_oracle_is_labelled_clairvoyant_in_the_table_json_and_figure(tmp_path, capsys):
    import json

    from etmpc.cli import main
    from etmpc.views.figures import policy_bars

    out = tmp_path / "ev.json"
    assert (
        main(
            [
                "evaluate",
                "--task",
                "battery",
                "--policy",
                "every:10",
                "--policy",
                "oracle:every:10",
                "--episodes",
                "1",
                "--workers",
                "1",
                "--json",
                str(out),
            ]
        )
        == 0
    )
    table = capsys.readouterr().out
    assert "oracle:every:10 (oracle)" in table and "not a policy" in table
    data = json.loads(out.read_text())
    assert data["policies"]["oracle:every:10"]["clairvoyant"] is True and data["policies"]["every:10"]["clairvoyant"] is False
    bars = {b.policies[0]: b for b in policy_bars([data])}
    assert bars["oracle:every:10"].clairvoyant and "(oracle)" in bars["oracle:every:10"].label
    assert not bars["every:10"].clairvoyant
    # With the stored future, the bound is never below its base (profit: higher is better).
    assert data["policies"]["oracle:every:10"]["objective_mean"] >= data["policies"]["every:10"]["objective_mean"]
