"""The lognormal profile against scipy.stats.lognorm and quadrature (independent oracles)."""

import numpy as np
import pytest
from scipy import stats
from scipy.integrate import quad

from tagbot.model.lognormal import characteristic_times, lognormal, lognormal_cdf, lognormal_time

PARAMS = [(0.0, np.log(0.2), np.log(1.4)), (1.3, -0.5, 0.1), (-2.0, np.log(0.05), 0.9)]


@pytest.mark.parametrize(("t0", "mu", "sigma"), PARAMS)
def test_profile_and_cdf_match_scipy_lognorm(t0, mu, sigma):
    ref = stats.lognorm(s=sigma, loc=t0, scale=np.exp(mu))
    t = t0 + np.linspace(-0.5, 6.0, 2001) * np.exp(mu)
    np.testing.assert_allclose(lognormal(t, t0, mu, sigma), ref.pdf(t), rtol=1e-12, atol=1e-300)
    np.testing.assert_allclose(lognormal_cdf(t, t0, mu, sigma), ref.cdf(t), rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize(("t0", "mu", "sigma"), PARAMS)
def test_unit_area_and_cdf_is_the_integral(t0, mu, sigma):
    area, _ = quad(lognormal, t0, np.inf, args=(t0, mu, sigma), epsabs=1e-13, limit=200)
    assert area == pytest.approx(1.0, abs=1e-10)
    t1 = t0 + 1.7 * np.exp(mu)
    partial, _ = quad(lognormal, t0, t1, args=(t0, mu, sigma), epsabs=1e-13, limit=200)
    assert lognormal_cdf(t1, t0, mu, sigma) == pytest.approx(partial, abs=1e-10)


def test_zero_before_and_at_onset():
    t = np.array([-1.0, 0.0, 0.5])
    assert np.all(lognormal(t, 0.5, -1.0, 0.3) == 0.0)
    assert np.all(lognormal_cdf(t, 0.5, -1.0, 0.3) == 0.0)


@pytest.mark.parametrize(("t0", "mu", "sigma"), PARAMS)
def test_characteristic_times(t0, mu, sigma):
    times = characteristic_times(t0, mu, sigma, eps=1e-6)
    assert times.onset == t0
    h = 1e-6 * np.exp(mu)
    peak = lognormal(times.peak, t0, mu, sigma)
    assert peak > lognormal(times.peak - h, t0, mu, sigma)
    assert peak > lognormal(times.peak + h, t0, mu, sigma)
    assert lognormal_cdf(times.median, t0, mu, sigma) == pytest.approx(0.5, abs=1e-14)
    assert lognormal_cdf(times.start, t0, mu, sigma) == pytest.approx(1e-6, rel=1e-9)
    assert 1.0 - lognormal_cdf(times.end, t0, mu, sigma) == pytest.approx(1e-6, rel=1e-6)
    assert times.onset < times.start < times.peak < times.median < times.end


def test_inverse_cdf():
    fractions = np.array([1e-9, 0.1, 0.5, 0.9, 1 - 1e-9])
    t = lognormal_time(fractions, 0.2, -1.2, 0.4)
    np.testing.assert_allclose(lognormal_cdf(t, 0.2, -1.2, 0.4), fractions, rtol=1e-7)


def test_characteristic_times_rejects_bad_eps():
    with pytest.raises(ValueError, match="eps"):
        characteristic_times(0.0, 0.0, 1.0, eps=0.7)
