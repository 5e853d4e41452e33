"""The battery's sampled futures: what the controller saw is kept, the rest follows the generators' law.

The law tests compare sample statistics of a few thousand futures drawn from one observed state with
the values the generators' parameters imply, allowing ``Z`` standard errors of the sample size.
"""

import numpy as np
import pytest

from etmpc.systems.battery.task import Episode
from etmpc.systems.battery.market import SIGNAL_ARRAYS, sample_future
from etmpc.systems.battery.parameters import SECONDS_PER_HOUR, Battery, Market

B, M = Battery(), Market()
DT = B.interval_s
KNOWN = 21  # rows 0..20 seen: the decision of step 20
K = KNOWN - 1
Z = 5  # standard errors allowed in a law test
SIGNALS = [(name, getattr(M, name), *arrays) for name, arrays in SIGNAL_ARRAYS.items()]
SIGNAL_IDS = list(SIGNAL_ARRAYS)


def assert_mean(sample, mean, std):
    """``sample`` (i.i.d., standard deviation ``std``) has mean ``mean``."""
    sample = np.ravel(sample)
    assert abs(sample.mean() - mean) < Z * std / np.sqrt(sample.size), (sample.mean(), mean)


def assert_std(sample, std):
    """``sample`` (i.i.d. normal) has standard deviation ``std``: the standard error is ``std / sqrt(2n)``."""
    sample = np.ravel(sample)
    assert abs(sample.std() - std) < Z * std / np.sqrt(2 * sample.size), (sample.std(), std)


def assert_frequency(hits, trials, p):
    """``hits`` of ``trials`` independent Bernoulli(``p``) trials."""
    assert abs(hits - trials * p) < Z * np.sqrt(trials * p * (1 - p)), (hits, trials * p)


def stack(futures, name):
    return np.array([getattr(f, name) for f in futures])


def observed_base(episode, forecast_name):
    return getattr(episode, forecast_name)[K, 1]  # the lead-1 forecast, as sample_future estimates it


def modified(episode, start_s=None, **lead1):
    """``episode`` with another clock and/or other lead-1 forecasts at row ``K``."""
    arrays = {name: np.array(value) for name, value in episode.arrays().items()}
    if start_s is not None:
        arrays["start_s"] = np.array(start_s)
    for name, value in lead1.items():
        arrays[name][K, 1] = value
    return Episode.from_arrays(arrays)


def scrambled(episode, known_rows, seed):
    arrays = {name: np.array(value) for name, value in episode.arrays().items()}
    rng = np.random.default_rng(seed)
    for name, value in arrays.items():
        if value.ndim:
            value[known_rows:] = rng.normal(size=value[known_rows:].shape)
    return Episode.from_arrays(arrays)


@pytest.fixture(scope="module")
def episode():
    """Its clock crosses an hour at row 37, inside the sampled future."""
    return Episode.draw(np.random.default_rng(7))


@pytest.fixture(scope="module")
def futures(episode):
    rng = np.random.default_rng(11)
    return [sample_future(rng, episode, KNOWN, B, M) for _ in range(3000)]


# -- what is kept ---------------------------------------------------------------------------------


@pytest.mark.parametrize("known_rows", [1, KNOWN, 100])
def test_known_rows_are_kept_and_the_rest_is_redrawn(episode, known_rows):
    future = sample_future(np.random.default_rng(0), episode, known_rows, B, M)
    assert isinstance(future, Episode)
    assert (future.initial_soc, future.start_s) == (episode.initial_soc, episode.start_s)
    for name, value in episode.arrays().items():
        new = future.arrays()[name]
        assert new.shape == value.shape and new.dtype == value.dtype
        if value.ndim:
            assert np.array_equal(new[:known_rows], value[:known_rows])  # bit for bit
    for name in ("production_kw", "price_eur_kwh", "production_forecast_kw", "price_forecast_eur_kwh"):
        assert np.all(getattr(future, name)[known_rows:] != getattr(episode, name)[known_rows:])
    again = Episode.from_arrays(future.arrays())  # a valid episode
    for name, value in future.arrays().items():
        assert np.array_equal(again.arrays()[name], value)


def test_with_every_row_known_nothing_changes(episode):
    same = sample_future(np.random.default_rng(0), episode, episode.steps + 1, B, M)
    for name, value in episode.arrays().items():
        assert np.array_equal(same.arrays()[name], value)
    for known_rows in (0, episode.steps + 2):
        with pytest.raises(ValueError, match="known_rows"):
            sample_future(np.random.default_rng(0), episode, known_rows, B, M)


@pytest.mark.parametrize("known_rows", [1, KNOWN, 100])
def test_the_stored_future_is_never_read(episode, known_rows):
    other = scrambled(episode, known_rows, seed=3)
    a = sample_future(np.random.default_rng(5), episode, known_rows, B, M)
    b = sample_future(np.random.default_rng(5), other, known_rows, B, M)
    for name, value in a.arrays().items():
        assert np.array_equal(b.arrays()[name], value)


def test_same_seed_same_future_other_seed_other_future(episode):
    a, b, c = (sample_future(np.random.default_rng(seed), episode, KNOWN, B, M) for seed in (5, 5, 6))
    for name, value in a.arrays().items():
        assert np.array_equal(b.arrays()[name], value)
    for name in ("production_kw", "price_eur_kwh", "production_forecast_kw", "price_forecast_eur_kwh"):
        assert np.all(getattr(c, name)[KNOWN:] != getattr(a, name)[KNOWN:])


# -- the law of what is redrawn -------------------------------------------------------------------


@pytest.mark.parametrize("name, signal, true_name, base_name, forecast_name", SIGNALS, ids=SIGNAL_IDS)
def test_the_ou_deviation_continues_from_what_was_seen(episode, futures, name, signal, true_name, base_name, forecast_name):
    deviation = stack(futures, true_name) - stack(futures, base_name)
    rho = np.exp(-DT / signal.ou_time_constant_s)
    step_std = signal.ou_std * np.sqrt(1 - rho**2)
    # One step ahead of the deviation seen at row K, measured from the lead-1 forecast.
    seen = getattr(episode, true_name)[K] - observed_base(episode, forecast_name)
    assert_mean(deviation[:, KNOWN], rho * seen, step_std)
    assert_std(deviation[:, KNOWN], step_std)
    # Every later step is the exact OU transition: its innovations are i.i.d. N(0, step_std^2).
    innovation = deviation[:, KNOWN + 1 :] - rho * deviation[:, KNOWN:-1]
    assert_mean(innovation, 0.0, step_std)
    assert_std(innovation, step_std)
    # 80 rows ahead, the seen deviation is forgotten: the stationary law.
    far = deviation[:, -1]
    assert_mean(far, 0.0, signal.ou_std)
    assert_std(far, signal.ou_std)


def test_events_end_at_the_generators_rate(episode, futures):
    """The current event lasts ``Exp(mean)`` from row K; later ones end at rate ``1 / mean``. An
    interval of ``DT`` sees at least one end with probability ``1 - exp(-DT / mean)``."""
    for name, signal, _, base_name, forecast_name in SIGNALS:
        base = stack(futures, base_name)
        p_end = 1 - np.exp(-DT / signal.event_mean_duration_s)
        # Still the event seen at row K (the same base) one row later. (Row K's hour continues at row KNOWN.)
        kept = np.isclose(base[:, KNOWN], observed_base(episode, forecast_name), rtol=0, atol=1e-12)
        assert_frequency(kept.sum(), len(futures), 1 - p_end)
        # Between new rows: a change is an event ending, or a new clock hour (always a change).
        hour = np.floor((episode.start_s + DT * np.arange(KNOWN, episode.steps + 1)) / SECONDS_PER_HOUR)
        new_hour = np.diff(hour) != 0
        changed = np.diff(base[:, KNOWN:], axis=1) != 0
        assert_frequency(changed[:, ~new_hour].sum(), changed[:, ~new_hour].size, p_end)
        if signal.hourly_low < signal.hourly_high:
            assert new_hour.any() and changed[:, new_hour].all()  # the fixture's clock crosses an hour


def test_the_bases_stay_in_the_generators_range(episode, futures):
    for name, signal, _, base_name, forecast_name in SIGNALS:
        low, high = signal.hourly_low + signal.event_low, signal.hourly_high + signal.event_high
        assert low <= observed_base(episode, forecast_name) <= high  # so its event level is feasible too
        base = stack(futures, base_name)[:, KNOWN:]
        assert base.min() >= low - 1e-12 and base.max() <= high + 1e-12


def test_the_hourly_level_is_drawn_from_its_posterior(episode):
    """A high price base seen (0.085 EUR/kWh) forces a high spot price: U[0.055, 0.06]. Once the
    event ends (in the same hour), the base is that spot price plus a fresh event level of mean 0."""
    signal = M.price
    seen = 0.085
    one_hour = modified(episode, start_s=0.0, price_forecast_eur_kwh=seen)  # rows 0..100: 0..1000 s
    rng = np.random.default_rng(12)
    last = np.array([sample_future(rng, one_hour, KNOWN, B, M).price_base_eur_kwh[-1] for _ in range(2000)])
    ended = last[~np.isclose(last, seen, rtol=0, atol=1e-12)]
    low, high = max(signal.hourly_low, seen - signal.event_high), min(signal.hourly_high, seen - signal.event_low)
    event_mean = 0.5 * (signal.event_low + signal.event_high)
    std = np.sqrt((high - low) ** 2 / 12 + (signal.event_high - signal.event_low) ** 2 / 12)
    assert_mean(ended, 0.5 * (low + high) + event_mean, std)
    assert ended.min() >= low + signal.event_low and ended.max() <= high + signal.event_high


@pytest.mark.parametrize("price, production", [(0.2, 150.0), (-0.1, -150.0)])
def test_a_base_beyond_the_range_keeps_the_nearest_hourly_level(episode, price, production):
    """Forecast noise can put the seen base beyond ``hourly + event``: it is kept until the event
    ends, with the nearest feasible hourly level (production: 0; price: its bound on that side)."""
    one_hour = modified(episode, start_s=0.0, price_forecast_eur_kwh=price, production_forecast_kw=production)
    rng = np.random.default_rng(13)
    futures = [sample_future(rng, one_hour, KNOWN, B, M) for _ in range(300)]
    for seen, signal, base_name in ((price, M.price, "price_base_eur_kwh"), (production, M.production, "production_base_kw")):
        hourly = signal.hourly_high if seen > 0 else signal.hourly_low
        base = stack(futures, base_name)[:, KNOWN:]
        kept = np.isclose(base, seen, rtol=0, atol=1e-12)
        assert kept[:, 0].any() and not kept[:, -1].all()
        later = base[~kept]
        assert later.min() >= hourly + signal.event_low and later.max() <= hourly + signal.event_high


@pytest.mark.parametrize("name, signal, true_name, base_name, forecast_name", SIGNALS, ids=SIGNAL_IDS)
def test_forecast_noise_grows_with_the_lead(futures, name, signal, true_name, base_name, forecast_name):
    forecast, base = stack(futures, forecast_name)[:, KNOWN:], stack(futures, base_name)[:, KNOWN:]
    assert np.array_equal(forecast[..., 0], stack(futures, true_name)[:, KNOWN:])  # lead 0: the true value
    noise = forecast - base[..., None]  # i.i.d. over rows and futures: a fresh path per row
    for lead in (1, 5, 19):
        std = signal.forecast_std_per_step * lead
        assert_mean(noise[..., lead], 0.0, std)
        assert_std(noise[..., lead], std)
    # Along the lead, z is a unit OU: corr(z_1, z_5) = exp(-4 DT / tau), Fisher's z has std 1/sqrt(n - 3).
    r = np.corrcoef(noise[..., 1].ravel(), noise[..., 5].ravel())[0, 1]
    expected = np.exp(-4 * DT / signal.forecast_time_constant_s)
    assert abs(np.arctanh(r) - np.arctanh(expected)) < Z / np.sqrt(noise[..., 1].size - 3)
