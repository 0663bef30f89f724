"""The public `integrate` entry point: dispatch, defaults, input checks, NaN handling."""
import numpy as np
import pytest

import restore.integration as ri
from restore.integration import DEFAULT_METHOD, METHODS, integrate

DT = 0.4e-3
TAUS = [7.4e-3, 14.8e-3, 22.2e-3]


def make(n=2000, sigma=0.01, seed=0):
    t = np.arange(n) * DT
    th = lambda x: np.sin(2 * np.pi * 61.0 * x) + 0.3 * np.sin(2 * np.pi * 122.0 * x + 1)
    rng = np.random.default_rng(seed)
    return [th(t + tau) - th(t) + sigma * rng.standard_normal(n) for tau in TAUS], th(t)


def test_methods_and_default():
    assert set(METHODS) == {"wiener", "wiener_fft", "inverse", "local", "harmonic", "kalman",
                            "polynomial", "lsq", "parametric"}
    assert DEFAULT_METHOD in METHODS
    diffs, truth = make()
    a = integrate(diffs, TAUS, DT)
    b = integrate(diffs, TAUS, DT, method=DEFAULT_METHOD)
    np.testing.assert_array_equal(a, b)
    assert abs(np.nanmean(a)) < 1e-12                     # mean removed
    assert np.std(a - truth) < 0.01


@pytest.mark.parametrize("method", sorted(METHODS))
def test_every_method_runs_and_keeps_shape(method):
    diffs, _ = make(1200)
    diffs[1][300:340] = np.nan
    est = integrate(diffs, TAUS, DT, method=method)
    assert est.shape == (1200,) and est.dtype == np.float64
    assert np.isfinite(est).mean() > 0.9


def test_input_errors_name_the_parameter():
    diffs, _ = make(500)
    with pytest.raises(ValueError, match="^method"):
        integrate(diffs, TAUS, DT, method="magic")
    with pytest.raises(ValueError, match="^dt"):
        integrate(diffs, TAUS, 0.0)
    with pytest.raises(ValueError, match="^taus"):
        integrate(diffs, TAUS[:2], DT)
    with pytest.raises(ValueError, match="^taus"):
        integrate(diffs, [1e-3, -1e-3, 2e-3], DT)
    with pytest.raises(ValueError, match=r"^diffs\[1\]"):
        integrate([diffs[0], diffs[1][:-1], diffs[2]], TAUS, DT)
    with pytest.raises(ValueError, match="^diffs"):
        integrate([np.full(500, np.nan)] * 3, TAUS, DT)
    with pytest.raises(TypeError):
        integrate(diffs, TAUS, DT, method="wiener", not_an_option=1)


def test_single_array_and_infinities():
    diffs, _ = make(800)
    d = diffs[2].copy()
    d[100] = np.inf
    est = integrate(d, [TAUS[2]], DT)
    assert est.shape == (800,)
    assert np.isfinite(est).all()        # one missing sample is interpolated (short gap)


def test_public_helpers_exported():
    for name in ("coverage", "pair_transfer", "wiener_gain", "chain_gain", "blind_frequencies",
                 "fused_gains", "fused_chain_gain", "fill_from_differentials", "interpolate_gaps"):
        assert callable(getattr(ri, name))
