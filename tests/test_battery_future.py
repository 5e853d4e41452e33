"""The battery's sampled futures: what the controller saw is kept, the rest follows the generators' law."""

import numpy as np
import pytest

from etmpc.battery.env import Episode
from etmpc.battery.market import sample_future
from etmpc.battery.parameters import PRICE, PRODUCTION, Battery, Market

B, M = Battery(), Market()
DT = B.interval_s


@pytest.fixture(scope="module")
def episode():
    return Episode.draw(np.random.default_rng(7))


def test_known_rows_are_kept_and_the_rest_is_redrawn(episode):
    future = sample_future(np.random.default_rng(0), episode, 41, B, M)
    for name, value in episode.arrays().items():
        new = future.arrays()[name]
        assert new.shape == value.shape
        if value.ndim:
            np.testing.assert_array_equal(new[:41], value[:41])
    assert not np.any(future.price_eur_kwh[41:] == episode.price_eur_kwh[41:])
    same = sample_future(np.random.default_rng(0), episode, episode.steps + 1, B, M)
    for name, value in episode.arrays().items():
        np.testing.assert_array_equal(same.arrays()[name], value)


def test_the_stored_future_is_never_read(episode):
    arrays = {name: np.array(value) for name, value in episode.arrays().items()}
    for name in ("production_kw", "price_eur_kwh", "production_forecast_kw", "price_forecast_eur_kwh", "price_base_eur_kwh"):
        arrays[name][41:] = np.random.default_rng(3).normal(size=arrays[name][41:].shape)
    scrambled = Episode.from_arrays(arrays)
    a = sample_future(np.random.default_rng(5), episode, 41, B, M)
    b = sample_future(np.random.default_rng(5), scrambled, 41, B, M)
    c = sample_future(np.random.default_rng(6), episode, 41, B, M)
    for name, value in a.arrays().items():
        np.testing.assert_array_equal(b.arrays()[name], value)
    assert not np.array_equal(a.price_eur_kwh, c.price_eur_kwh)


@pytest.fixture(scope="module")
def futures(episode):
    rng = np.random.default_rng(11)
    return [sample_future(rng, episode, 21, B, M) for _ in range(3000)]


def _se(n):  # tolerance of a sample standard deviation's relative error: 5 standard errors
    return 5 / np.sqrt(2 * n)


@pytest.mark.parametrize("prefix, unit, signal", [("production", "kw", PRODUCTION), ("price", "eur_kwh", PRICE)])
def test_the_ou_deviation_follows_its_law(episode, futures, prefix, unit, signal):
    true = np.array([getattr(f, f"{prefix}_{unit}") for f in futures])
    base = np.array([getattr(f, f"{prefix}_base_{unit}") for f in futures])
    deviation = true - base
    # One step ahead, conditioned on the deviation seen at row 20 (with the base read off the lead-1 forecast).
    forecast = getattr(episode, f"{prefix}_forecast_{unit}")
    o = getattr(episode, f"{prefix}_{unit}")[20] - forecast[20, 1]
    rho = np.exp(-DT / signal.ou_time_constant_s)
    step = deviation[:, 21]
    n = len(step)
    assert abs(step.mean() - rho * o) < 5 * signal.ou_std * np.sqrt(1 - rho**2) / np.sqrt(n)
    assert step.std() == pytest.approx(signal.ou_std * np.sqrt(1 - rho**2), rel=_se(n))
    # Far ahead, stationary: the generator's standard deviation.
    far = deviation[:, 100]
    assert far.std() == pytest.approx(signal.ou_std, rel=_se(n))
    assert abs(far.mean()) < 5 * signal.ou_std / np.sqrt(n)


def test_events_come_at_the_generators_rate(futures):
    """Production has no hourly level: each change of its base is an event ending."""
    base = np.array([f.production_base_kw[21:] for f in futures])
    changes = (np.diff(base, axis=1) != 0).sum()
    expected = base.shape[0] * (base.shape[1] - 1) * (1 - np.exp(-DT / PRODUCTION.event_mean_duration_s))  # P(>= 1 end per step)
    assert changes == pytest.approx(expected, rel=5 / np.sqrt(expected))
    price_base = np.array([f.price_base_eur_kwh[21:] for f in futures])
    low, high = PRICE.hourly_low + PRICE.event_low, PRICE.hourly_high + PRICE.event_high
    assert price_base.min() >= low and price_base.max() <= high


@pytest.mark.parametrize("lead", [1, 5, 19])
def test_forecast_noise_grows_with_the_lead(futures, lead):
    rows = np.concatenate([f.price_forecast_eur_kwh[21:, lead] - f.price_base_eur_kwh[21:] for f in futures])
    sample = rows[:: 20]  # rows of one future are correlated along the episode only through the base
    expected = PRICE.forecast_std_per_step * lead
    assert sample.std() == pytest.approx(expected, rel=_se(len(sample)))
    assert abs(sample.mean()) < 5 * expected / np.sqrt(len(sample))
    first = np.concatenate([f.price_forecast_eur_kwh[21:, 0] - f.price_eur_kwh[21:] for f in futures])
    assert np.all(first == 0)  # lead 0 is the true value
