"""CNES local integration: exact on stationary harmonics, learned weights, gaps."""
import numpy as np
import pytest

from restore.integration import integrate
from restore.integration.local import LocalIntegrator, default_offsets

DT = 0.4e-3
TAUS = [7.4e-3, 14.8e-3, 22.2e-3]
FREQS = [53.0, 77.0]


def theta(t):
    return np.sin(2 * np.pi * 53.0 * t + 0.2) + 0.5 * np.sin(2 * np.pi * 77.0 * t + 1.0)


def make(n, sigma=0.0, seed=0):
    t = np.arange(n) * DT
    rng = np.random.default_rng(seed)
    return np.vstack([theta(t + tau) - theta(t) + sigma * rng.standard_normal(n)
                      for tau in TAUS]), theta(t)


def test_default_offsets_cover_both_appearances_of_theta():
    offs = default_offsets(TAUS, DT, 2)
    assert set(offs[0]) >= {-2, -1, 0, 1, 2, -18, -19, -20, -16}
    assert offs[2].min() == -58


def test_stationary_harmonics_are_an_exact_linear_combination():
    # paper eq. (5): n stationary lines = a combination of 2n independent differentials
    D, truth = make(2000)
    loc = LocalIntegrator(TAUS, DT, FREQS, [1.0, 0.5], 1e-7, half_window=1,
                          frequency_spread=1e-6, amplitude_noise=0.0, n_train=4000)
    est, _ = loc.apply(D)
    ok = np.isfinite(est)
    assert ok[100:-100].all()
    e = est[ok] - truth[ok]
    assert np.max(np.abs(e - e.mean())) < 1e-3


def test_weights_do_not_depend_on_phases_or_amplitudes():
    D, _ = make(1500)
    a = LocalIntegrator(TAUS, DT, FREQS, [1.0, 0.5], 1e-7, half_window=1,
                        frequency_spread=1e-6, amplitude_noise=0.0, n_train=4000, seed=1)
    b = LocalIntegrator(TAUS, DT, FREQS, [0.2, 2.0], 1e-7, half_window=1,
                        frequency_spread=1e-6, amplitude_noise=0.0, n_train=4000, seed=2)
    ea, _ = a.apply(D)
    eb, _ = b.apply(D)
    ok = np.isfinite(ea) & np.isfinite(eb)
    np.testing.assert_allclose(ea[ok] - ea[ok].mean(), eb[ok] - eb[ok].mean(), atol=2e-3)


def test_noisy_with_estimated_frequencies():
    D, truth = make(4000, sigma=0.02, seed=3)
    est = integrate(list(D), TAUS, DT, method="local")
    ok = np.isfinite(est)
    assert ok.mean() > 0.95
    e = est[ok] - truth[ok]
    assert np.std(e) < 0.015


def test_gap_patterns_relearn_weights():
    D, truth = make(2000, sigma=0.01, seed=4)
    D[:, 900:1000] = np.nan
    loc = LocalIntegrator(TAUS, DT, FREQS, [1.0, 0.5], 0.01, half_window=8, n_train=8000)
    est, err = loc.apply(D)
    assert np.isnan(est[960:970]).all()                     # nothing measured around
    assert err[1500] < err[1005] < err[960]                 # predicted error grows near the gap
    ok = np.isfinite(est)
    e = est[ok] - truth[ok]
    assert np.std(e - e.mean()) < 0.02


def test_local_bad_options():
    with pytest.raises(ValueError, match="^frequencies_hz"):
        LocalIntegrator(TAUS, DT, [-1.0], [1.0], 0.01)
    with pytest.raises(ValueError, match="^noise_std"):
        LocalIntegrator(TAUS, DT, [50.0], [1.0], [0.01, 0.02])
    with pytest.raises(ValueError, match="^half_window"):
        LocalIntegrator(TAUS, DT, [50.0], [1.0], 0.01, half_window=-1)
