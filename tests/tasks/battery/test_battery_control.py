"""The battery's economic MPC, LQR and closed loop, against independent solutions."""

import dataclasses

import numpy as np
import pytest

from etmpc.systems.battery import task as battery_env
from etmpc.systems.battery.mpc import EconomicMPC
from etmpc.systems.battery.parameters import Battery
from etmpc.systems.battery.reference import solve_with_linprog
from etmpc.systems.battery.system import BatterySystem, Config
from etmpc.evaluation.evaluate import evaluate
from etmpc.loop import run_episode
from etmpc.policies import parse_policy

B = Battery()
MEAN_PRICE = 0.05


@pytest.mark.parametrize("seed", range(25))
def test_lp_matches_an_independent_linprog_formulation(seed):
    rng = np.random.default_rng(seed)
    soc = rng.uniform(0.0, 1.0)
    production = np.clip(rng.normal(0.0, 120.0, 20), -300.0, 300.0)
    price = MEAN_PRICE + 0.03 * rng.standard_normal(20)
    mpc = EconomicMPC(B, 20, MEAN_PRICE)
    plan = mpc.solve(soc, production, price)
    _, reference_profit, ok = solve_with_linprog(B, MEAN_PRICE, soc, production, price)
    assert plan.success and ok
    assert -plan.cost == pytest.approx(reference_profit, abs=1e-9)
    inputs = plan.inputs.ravel()
    assert np.all(np.abs(inputs) <= B.trade_limit_kw + 1e-9)
    free = mpc.rollout(soc, production, inputs)  # the plan's own states, unclipped
    assert free.min() >= -1e-9 and free.max() <= 1 + 1e-9
    np.testing.assert_allclose(plan.states.ravel(), free, atol=1e-9)
    np.testing.assert_array_equal(plan.forecasts["price_eur_kwh"], price)


def test_rising_price_buys_now_and_sells_later():
    """By hand: 1 kWh per full trade, prices below the 0.05 value of storage at first, above it later;
    SoC bounds far away, so it buys at full power, then sells at full power."""
    plan = EconomicMPC(B, 4, MEAN_PRICE).solve(0.5, np.zeros(4), np.array([0.02, 0.03, 0.07, 0.08]))
    np.testing.assert_allclose(plan.inputs.ravel(), [-360, -360, 360, 360], atol=1e-6)
    np.testing.assert_allclose(plan.states.ravel(), [0.5, 0.6, 0.7, 0.6, 0.5], atol=1e-9)
    # -0.02 - 0.03 + 0.07 + 0.08 EUR of trades, plus 5 kWh left at 0.05 EUR/kWh
    assert -plan.cost == pytest.approx(0.10 + 0.25, abs=1e-9)


def test_nearly_full_battery_buys_only_the_room_left():
    """x0 = 0.95: 0.5 kWh of room, bought at the cheapest price (step 0, 180 kW); step 1 can buy
    nothing; then two full sales."""
    plan = EconomicMPC(B, 4, MEAN_PRICE).solve(0.95, np.zeros(4), np.array([0.04, 0.045, 0.09, 0.10]))
    np.testing.assert_allclose(plan.inputs.ravel(), [-180, 0, 360, 360], atol=1e-6)
    np.testing.assert_allclose(plan.states.ravel(), [0.95, 1.0, 1.0, 0.9, 0.8], atol=1e-9)
    assert -plan.cost == pytest.approx(-0.04 * 0.5 + 0.09 + 0.10 + 0.05 * 10 * 0.8, abs=1e-9)


def test_infeasible_forecast_gives_a_failed_plan_that_holds_the_charge():
    production = np.full(20, 1000.0)  # more than can be sold: the SoC must exceed 1
    plan = EconomicMPC(B, 20, MEAN_PRICE).solve(1.0, production, np.full(20, MEAN_PRICE))
    assert not plan.success and plan.status
    np.testing.assert_allclose(plan.inputs.ravel(), 360.0)
    assert plan.states.max() <= 1.0


def test_lqr_gain_is_the_scalar_riccati_solution():
    """eps+ = eps + b u with b = -delta/C: P = Q + P - (bP)^2 / (R + b^2 P) has the positive root
    P = (Q b^2 + sqrt(Q^2 b^4 + 4 Q R b^2)) / (2 b^2), and K = b P / (R + b^2 P)."""
    b, q, r = -B.soc_per_kw, 1.0, 0.1
    p = (q * b**2 + np.sqrt(q**2 * b**4 + 4 * q * r * b**2)) / (2 * b**2)
    system = BatterySystem()
    assert system.feedback.gain[0, 0] == pytest.approx(b * p / (r + b**2 * p), rel=1e-9)
    assert system.feedback.correction(np.array([0.6]), np.array([0.5]))[0] > 0  # more charge than planned: sell


def test_bad_configurations_are_refused():
    from etmpc.common.errors import EtmpcError

    with pytest.raises(EtmpcError, match="exceeds the 20 forecast values"):
        BatterySystem(Config(horizon=21))
    with pytest.raises(ValueError, match="Config.lqr_input_weight: 0.0 is not a number in "):
        Config(lqr_input_weight=0.0)  # a Config holds what it may: R > 0
    with pytest.raises(ValueError, match="horizon must be >= 1"):
        EconomicMPC(B, 0, MEAN_PRICE)


def perfect_forecasts(episode):
    """The episode with every forecast replaced by the true future (the last value held past the end)."""
    arrays = episode.arrays()
    for signal, forecast in (("production_kw", "production_forecast_kw"), ("price_eur_kwh", "price_forecast_eur_kwh")):
        true = arrays[signal]
        index = np.minimum(np.arange(true.size)[:, None] + np.arange(arrays[forecast].shape[1]), true.size - 1)
        arrays[forecast] = true[index]
    return battery_env.Episode.from_arrays(arrays)


def test_with_perfect_forecasts_and_free_computing_the_plant_follows_the_plan(battery_testset):
    """With nothing the MPC does not know, the SoC equals the plan's prediction at every step, the
    LQR never acts, and the profit is the plans' trades at the true prices plus the stored energy."""
    system = BatterySystem(Config(battery=dataclasses.replace(Battery(), compute_power_kw=0.0)))
    episode = perfect_forecasts(system.episode_from_arrays(battery_testset.episode_arrays(2)))
    traj = run_episode(system, system.make_env(), parse_policy("never", system), None, episode)
    assert traj.steps == 100 and traj.recomputes == 5
    np.testing.assert_allclose(traj.states[:100, 0], traj.predicted[:, 0], atol=1e-12)
    np.testing.assert_allclose(traj.correction, 0.0, atol=1e-9)
    np.testing.assert_array_equal(traj.applied, traj.planned)
    trades = np.sum(episode.price_eur_kwh[:100] * traj.planned[:, 0]) * B.interval_h
    assert traj.rewards.sum() == pytest.approx(trades + MEAN_PRICE * 10.0 * traj.states[100, 0], abs=1e-12)


def test_every_computation_costs_the_battery_eta_c(battery_testset, battery_system):
    """Trading the production away holds the SoC; computing every step then drains exactly
    0.1 kW x 10 s per computation."""
    episode = battery_system.episode_from_arrays(battery_testset.episode_arrays(3))
    env = battery_system.make_env()
    final = []
    for computing in (False, True):
        env.task.use_episode(episode)
        timestep = env.reset()
        for _ in range(10):
            timestep = env.step(battery_system.action(np.array([timestep.observation["net_production_kw"]]), computing))
        final.append(timestep.observation["state_of_charge"])
    assert final[0] == pytest.approx(episode.initial_soc, abs=1e-14)
    assert final[0] - final[1] == pytest.approx(10 * 0.1 * B.soc_per_kw, abs=1e-14)


def test_evaluate_reports_profit_with_sense_max(battery_system, battery_testset):
    result = evaluate("battery", ["always", "every:5"], episodes=2, workers=1, progress=False)
    env = battery_system.make_env()
    for summary in result.summaries:
        assert summary.objective_sense == "max"
        profits = []
        for e in range(2):
            episode = battery_system.episode_from_arrays(battery_testset.episode_arrays(e))
            traj = run_episode(battery_system, env, parse_policy(summary.policy, battery_system), None, episode)
            profits.append(traj.rewards.sum())
        assert summary.objective_mean == pytest.approx(np.mean(profits), rel=1e-12)
        assert summary.control_objective_mean == summary.objective_mean  # no price per computation


def test_bench_compares_against_linprog():
    from etmpc.evaluation.bench import run_bench

    figures = run_bench("battery", episodes=1, reference_solves=30)
    assert figures["mpc_solve"]["samples"] == 100 and figures["solver_failures"] == 0
    (reference,) = figures["references"]
    assert reference["reference"]["samples"] == 30 and reference["reference_failures"] == 0
    assert reference["objective_gap_relative"]["max_abs"] < 1e-9


# -- failures: trades curtailed ---------------------------------------------------------------------------
@pytest.mark.parametrize("spec", ["always", "every:3", "never"])
def test_failures_are_the_intervals_whose_trade_the_battery_cut_by_more_than_1_percent_of_the_limit(
    battery_system, battery_testset, spec, monkeypatch
):
    """Counted from the played trajectory and the episode; checked against what the battery itself says it
    was commanded and executed at each interval."""
    traded = []
    reward = battery_env.Trading.get_reward

    def recorded(task, physics):
        traded.append((physics.commanded_trade_kw(), physics.executed_trade_kw()))
        return reward(task, physics)

    monkeypatch.setattr(battery_env.Trading, "get_reward", recorded)
    episode = battery_system.episode_from_arrays(battery_testset.episode_arrays(0))
    traj = run_episode(battery_system, battery_system.make_env(), parse_policy(spec, battery_system), None, episode)
    commanded, executed = np.array(traded).T
    np.testing.assert_allclose(battery_system.curtailments_kw(traj, episode), commanded - executed, rtol=0, atol=1e-9)
    cut = np.abs(commanded - executed) > 0.01 * B.trade_limit_kw  # 3.6 kW
    assert battery_system.failure_name == "curtailed" and battery_system.failures(traj, episode) == int(cut.sum())
    if spec == "always":  # only the computer's own draw, which the MPC does not predict, is ever cut
        assert int(cut.sum()) == 0 and np.abs(commanded - executed).max() <= B.compute_power_kw + 1e-9
    else:
        assert int(cut.sum()) > 0
