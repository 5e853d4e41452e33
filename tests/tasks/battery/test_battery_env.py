"""The battery-trading task: energy balance, curtailment, reward, generators, specs and seeding."""

import numpy as np
import pytest
from dm_control.rl import control

from etmpc import suite
from etmpc.systems.battery import task as battery_env
from etmpc.systems.battery.market import event_levels, ou_path
from etmpc.systems.battery.parameters import PRICE, Battery, Market

B = Battery()
DT_H = 10 / 3600  # delta in hours


def stepped(soc, production_kw, trade_kw, computing=0.0):
    physics = battery_env.Physics(B)
    physics.set_state_of_charge(soc)
    physics.set_net_production(production_kw)
    physics.set_control(np.array([trade_kw, computing]))
    physics.step()
    return physics


def test_constants_are_the_papers():
    assert B.trade_limit_kw == pytest.approx(360.0)  # 10 % of 10 kWh per 10 s
    assert B.soc_per_kw == pytest.approx(DT_H / 10.0)


def test_computing_drains_the_battery():
    # Computing consumes energy (the paper prints the opposite sign; docs/paper.md): 0.1 kW for 10 s out of 10 kWh.
    physics = stepped(0.5, 0.0, 0.0, computing=1.0)
    assert physics.state_of_charge() == pytest.approx(0.5 - 0.1 * DT_H / 10.0, abs=1e-15)
    assert stepped(0.5, 0.0, 0.0).state_of_charge() == 0.5


def test_selling_more_than_is_stored_is_curtailed_to_empty():
    physics = stepped(0.02, 0.0, 360.0)  # 0.2 kWh left, 1 kWh ordered
    assert physics.state_of_charge() == 0.0
    assert physics.executed_trade_kw() * DT_H == pytest.approx(0.2)
    assert physics.unbalanced_energy_kwh() == pytest.approx(0.0, abs=1e-12)


def test_buying_more_than_fits_is_curtailed_to_full():
    physics = stepped(0.97, 36.0, -360.0)  # room for 0.3 kWh; production brings 0.1 of it
    assert physics.state_of_charge() == 1.0
    assert physics.executed_trade_kw() * DT_H == pytest.approx(-0.2)


def test_production_beyond_the_trade_limit_is_spilled():
    physics = stepped(1.0, 1000.0, 0.0)  # even selling 360 kW cannot keep up
    assert physics.state_of_charge() == 1.0 and physics.executed_trade_kw() == pytest.approx(360.0)
    assert physics.unbalanced_energy_kwh() == pytest.approx((1000.0 - 360.0) * DT_H)


def test_commands_beyond_the_limit_are_clamped():
    assert stepped(0.5, 0.0, 1e6).executed_trade_kw() == pytest.approx(360.0)


def test_energy_balance_and_profit_over_an_episode_with_wild_trades(battery_testset, battery_system):
    """Every interval: C dx = (P - u_executed - eta_c a) delta - unbalanced; the rewards are the
    executed trades at the true prices plus lambda_bar C x_T at the end."""
    episode = battery_system.episode_from_arrays(battery_testset.episode_arrays(4))
    env = battery_system.make_env()
    env.task.use_episode(episode)
    timestep = env.reset()
    rng = np.random.default_rng(0)
    soc, rewards, revenue = [timestep.observation["state_of_charge"]], [], []
    for k in range(100):
        computing = float(rng.integers(2))
        timestep = env.step(np.array([rng.choice([-500.0, -360.0, 0.0, 120.0, 360.0, 500.0]), computing]))
        p = env.physics
        x0, x1 = soc[-1], p.state_of_charge()
        assert 0.0 <= x1 <= 1.0
        balance_kwh = (episode.production_kw[k] - p.executed_trade_kw() - 0.1 * computing) * DT_H - p.unbalanced_energy_kwh()
        assert 10.0 * (x1 - x0) == pytest.approx(balance_kwh, abs=1e-12)
        revenue.append(episode.price_eur_kwh[k] * p.executed_trade_kw() * DT_H)
        soc.append(x1)
        rewards.append(timestep.reward)
    assert timestep.last() and timestep.discount == 1.0
    np.testing.assert_allclose(rewards[:-1], revenue[:-1], rtol=0, atol=1e-15)
    assert rewards[-1] == pytest.approx(revenue[-1] + PRICE.mean * 10.0 * soc[-1], abs=1e-15)  # + lambda_bar C x_T


def test_ou_path_has_the_stationary_law():
    paths = ou_path(np.random.default_rng(1), steps=3, dt_s=10.0, time_constant_s=60.0, std=15.0, rows=40_000)
    assert np.std(paths, axis=0) == pytest.approx([15.0] * 3, rel=0.03)
    rho = np.corrcoef(paths[:, 0], paths[:, 1])[0, 1]
    assert rho == pytest.approx(np.exp(-10 / 60), abs=0.01)


def test_event_levels_switch_at_the_exponential_rate():
    times = np.arange(200_000) * 10.0
    levels = event_levels(np.random.default_rng(2), times, -1.0, 1.0, mean_duration_s=240.0)
    switched = np.mean(levels[1:] != levels[:-1])
    assert switched == pytest.approx(1 - np.exp(-10 / 240), abs=0.002)  # at least one event end in 10 s
    assert levels.min() >= -1.0 and levels.max() <= 1.0


def test_mean_price_is_the_terminal_value():
    rng = np.random.default_rng(3)
    prices = [battery_env.Episode.draw(rng).price_eur_kwh.mean() for _ in range(1500)]
    assert np.mean(prices) == pytest.approx(PRICE.mean, abs=1e-3)
    assert PRICE.mean == pytest.approx(0.05)


def test_forecasts_start_true_and_their_noise_grows_linearly_with_lead(battery_testset):
    arrays = battery_testset.arrays
    for signal, base, forecast, per_step in (
        ("production_kw", "production_base_kw", "production_forecast_kw", 2.0),
        ("price_eur_kwh", "price_base_eur_kwh", "price_forecast_eur_kwh", 0.001),
    ):
        np.testing.assert_array_equal(arrays[forecast][:, :, 0], arrays[signal])
        noise = arrays[forecast] - arrays[base][:, :, None]
        for lead in (1, 5, 19):
            assert np.std(noise[:, :, lead]) == pytest.approx(per_step * lead, rel=0.04)
            assert abs(np.mean(noise[:, :, lead])) < 4 * per_step * lead / np.sqrt(noise[:, :, lead].size) + 1e-12


def test_suite_loads_a_dm_control_environment():
    env = suite.load("battery", "trading", task_kwargs={"random": 0})
    assert isinstance(env, control.Environment) and suite.tasks("battery") == ("trading",)
    assert env.control_timestep() == pytest.approx(10.0)
    assert "trading" in battery_env.SUITE.tagged("benchmarking")
    spec = env.action_spec()
    np.testing.assert_allclose(spec.minimum, [-360.0, 0.0])
    np.testing.assert_allclose(spec.maximum, [360.0, 1.0])


def test_specs_match_what_it_returns_over_a_whole_episode():
    env = suite.load("battery", "trading", task_kwargs={"random": 5})
    timestep, specs, steps = env.reset(), env.observation_spec(), 0
    while True:
        for name, spec in specs.items():
            spec.validate(np.asarray(timestep.observation[name], dtype=np.float64))
        if timestep.last():
            break
        timestep = env.step(np.array([0.0, 0.0]))
        steps += 1
    assert steps == 100


def test_same_seed_same_episodes_and_stored_episodes_replay_exactly():
    a, b = (suite.load("battery", "trading", task_kwargs={"random": 11}) for _ in range(2))
    for _ in range(2):
        oa, ob = a.reset().observation, b.reset().observation
        np.testing.assert_array_equal(oa["price_forecast_eur_kwh"], ob["price_forecast_eur_kwh"])
    episode = a.task.episode
    replay = suite.load("battery", "trading", task_kwargs={"random": 99})
    replay.task.use_episode(battery_env.Episode.from_arrays(episode.arrays()))
    first = replay.reset()
    assert first.observation["state_of_charge"] == episode.initial_soc
    np.testing.assert_array_equal(first.observation["production_forecast_kw"], episode.production_forecast_kw[0])


def test_bad_episodes_are_refused():
    episode = battery_env.Episode.draw(np.random.default_rng(0))
    arrays = episode.arrays()
    with pytest.raises(ValueError, match="missing price_eur_kwh"):
        battery_env.Episode.from_arrays({k: v for k, v in arrays.items() if k != "price_eur_kwh"})
    with pytest.raises(ValueError, match="inconsistent shapes"):
        battery_env.Episode.from_arrays(dict(arrays, price_eur_kwh=arrays["price_eur_kwh"][:50]))
    short = battery_env.Episode.draw(np.random.default_rng(0), steps=10)
    with pytest.raises(ValueError, match="need 100"):
        battery_env.make_environment().task.use_episode(short)
    with pytest.raises(ValueError, match=r"in \[0, 1\]"):
        battery_env.Physics().set_state_of_charge(1.5)
    assert Market().forecast_steps == 20


def test_the_trigger_features_revise_the_kept_plans_forecasts_with_todays(battery_testset, battery_system, features_while_kept):
    """The last three exogenous features, by hand from the stored forecasts: the forecasts made at the
    current step against those made at step 0 (the plan's), over the steps the plan has left."""
    from etmpc.systems.battery.system import EXOGENOUS_FEATURES

    arrays = {k: v[4] for k, v in battery_testset.arrays.items()}
    episode = battery_system.episode_from_arrays(battery_testset.episode_arrays(4))
    seen, s = features_while_kept(battery_system, episode)
    n = battery_system.config.horizon
    assert EXOGENOUS_FEATURES[-3:] == (
        "price_forecast_revision_eur_kwh",
        "production_forecast_revision_kw",
        "plan_value_revision_eur",
    )
    for age, features in enumerate(seen, start=1):
        left = n - age
        price = arrays["price_forecast_eur_kwh"][age, :left] - arrays["price_forecast_eur_kwh"][0, age : age + left]
        production = arrays["production_forecast_kw"][age, :left] - arrays["production_forecast_kw"][0, age : age + left]
        trades = s.plan.inputs[age : age + left, 0]  # the plan made at step 0 is the one still kept
        assert features[-3] == pytest.approx(np.sqrt(np.mean(price**2)), rel=1e-12)
        assert features[-2] == pytest.approx(np.sqrt(np.mean(production**2)), rel=1e-12)
        assert features[-1] == pytest.approx(np.dot(price, trades) * DT_H, rel=1e-12, abs=1e-15)
        assert features[-3] > 0  # the forecasts were revised (their noise is fresh at every step)
