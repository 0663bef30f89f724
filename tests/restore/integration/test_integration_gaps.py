"""Gaps: observed samples, coverage, filling from differentials and neighbours."""
import numpy as np
import pytest

from restore.integration import coverage, integrate
from restore.integration.gaps import (estimable_mask, fill_from_differentials, interpolate_gaps,
                                      nan_runs, observed_mask)

DT = 0.4e-3
TAUS = [7.4e-3, 14.8e-3, 22.2e-3]


def theta(t):
    return np.sin(2 * np.pi * 53.0 * t + 0.2) + 0.5 * np.sin(2 * np.pi * 77.0 * t + 1.0)


def make(n, taus=TAUS, sigma=0.0, seed=0):
    t = np.arange(n) * DT
    rng = np.random.default_rng(seed)
    return [theta(t + tau) - theta(t) + sigma * rng.standard_normal(n) for tau in taus], theta(t)


def test_observed_mask_integer_and_fractional_lags():
    valid = np.zeros((1, 100), dtype=bool)
    valid[0, 10] = True
    np.testing.assert_array_equal(np.flatnonzero(observed_mask(valid, [5 * DT], DT)), [10, 15])
    np.testing.assert_array_equal(np.flatnonzero(observed_mask(valid, [5.5 * DT], DT)),
                                  [10, 15, 16])


def test_estimable_mask_never_extrapolates():
    valid = np.zeros((1, 200), dtype=bool)
    valid[0, 50:80] = valid[0, 90:150] = True
    m = estimable_mask(valid, [3 * DT], DT, max_gap=20)
    assert not m[:50].any() and not m[153:].any()
    assert m[50:153].all()                      # interior gap of 7 samples filled
    m0 = estimable_mask(valid, [3 * DT], DT, max_gap=0)
    assert not m0[83:90].any()
    assert nan_runs(np.array([0, 1, 1, 0, 1], bool)) == [(1, 3), (4, 5)]


def test_integrate_returns_nan_where_nothing_is_observed():
    diffs, truth = make(3000)
    for d in diffs:
        d[1000:1400] = np.nan
        d[:100] = np.nan
    est = integrate(diffs, TAUS, DT, method="wiener", max_gap_s=0.0)
    obs = observed_mask(np.isfinite(np.vstack(diffs)), TAUS, DT)
    np.testing.assert_array_equal(np.isfinite(est), obs)
    assert coverage(est) == pytest.approx(obs.mean())
    assert np.isnan(est[:100]).all()
    e = est[obs] - truth[obs]
    assert np.std(e) < 5e-3 * np.std(truth)


def test_fill_from_differentials_is_exact_without_noise():
    diffs, truth = make(2000, taus=[20 * DT, 37 * DT])
    est = truth.copy()
    est[500:700] = np.nan          # no estimate there, but the differentials are valid
    filled = fill_from_differentials(est, diffs, [20 * DT, 37 * DT], DT)
    np.testing.assert_allclose(filled, truth, atol=1e-9)


def test_fill_from_differentials_fractional_lag_and_limits():
    lag = 18.5 * DT
    diffs, truth = make(2000, taus=[lag])
    est = truth.copy()
    est[800:830] = np.nan
    diffs[0][805:830] = np.nan     # the links into the gap are partly missing
    filled = fill_from_differentials(est, diffs, [lag], DT)
    ok = np.isfinite(filled[800:830])
    assert 0 < ok.sum() < 30
    np.testing.assert_allclose(filled[800:830][ok], truth[800:830][ok], atol=2e-3)


def test_interpolate_gaps_ar_and_no_extrapolation():
    t = np.arange(4000) * DT
    x = theta(t)
    y = x.copy()
    y[2000:2050] = np.nan
    y[:30] = np.nan
    y[-30:] = np.nan
    f = interpolate_gaps(y, max_gap=60)
    np.testing.assert_allclose(f[2000:2050], x[2000:2050], atol=2e-3 * np.std(x))
    assert np.isnan(f[:30]).all() and np.isnan(f[-30:]).all()
    assert np.isnan(interpolate_gaps(y, max_gap=40)[2000:2050]).all()
    lin = interpolate_gaps(y, max_gap=60, method="linear")
    assert np.isfinite(lin[2000:2050]).all()
    with pytest.raises(ValueError, match="^method"):
        interpolate_gaps(y, max_gap=5, method="spline")


@pytest.mark.parametrize("method", ["wiener", "harmonic", "kalman", "local"])
def test_methods_tolerate_30_percent_gaps(method):
    diffs, truth = make(3000, sigma=0.01, seed=5)
    rng = np.random.default_rng(6)
    keep = np.ones(3000, dtype=bool)
    while (~keep).mean() < 0.3:
        a = rng.integers(0, 3000)
        keep[a:a + rng.integers(20, 200)] = False
    diffs = [np.where(keep, d, np.nan) for d in diffs]
    est = integrate(diffs, TAUS, DT, method=method)
    cov = coverage(est)
    assert 0.6 < cov < 0.9
    e = est[np.isfinite(est)] - truth[np.isfinite(est)]
    assert np.std(e) < 0.03 * np.std(truth)
