"""Time synchronisation inside the MAP Wiener: per-line lags in the forward model (large amplitude)."""
import dataclasses

import numpy as np
import pytest

from restore.axis_integration import integrate_axis
from restore.integration import methods
from restore.integration.wiener import integrate_wiener, lag_interpolation

DT = 4e-4
TAUS = (0.0074, 0.0148, 0.0222)
IFOV = 4e-6
#: the CMG lines of the stress suite (first and second harmonics)
LINES_HZ = (52.7, 58.9, 63.4, 74.1, 105.4, 117.8, 126.8, 148.2)


def _theta(t, amplitude):
    return amplitude * sum((1.0 if f < 100 else 0.5) * np.sin(2 * np.pi * f * t + k) for k, f in enumerate(LINES_HZ))


def _record(amplitude, noise_px, n=4000, seed=0):
    """Differentials seen at per-line lags: band B sees line n of A at t + τ + λ(n), λ the along-track
    differential in lines (one pixel of pitch differential moves the ground one line)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * DT
    diffs, lags, sigmas = [], [], []
    for tau in TAUS:
        lag = (_theta(t + tau, amplitude) - _theta(t, amplitude)) / IFOV * DT
        diffs.append(_theta(t + tau + lag, amplitude) - _theta(t, amplitude)
                     + noise_px * IFOV * rng.standard_normal(n))
        lags.append(lag)
        sigmas.append(np.full(n, noise_px * IFOV))
    return t, diffs, lags, sigmas


def _error_px(est, truth):
    e = (est - truth)[400:-400]
    return float(np.sqrt(np.mean((e - e.mean()) ** 2))) / IFOV


def test_lag_interpolation_samples_a_smooth_signal_at_the_lagged_times():
    m, n = 600, 500
    k = np.arange(m)
    x = np.sin(2 * np.pi * k / 37.5)                            # periodic on the grid (16 periods)
    lam = 3.0 * np.sin(2 * np.pi * np.arange(n) / 91.0) + 0.3
    op = lag_interpolation(lam, m)
    expected = np.sin(2 * np.pi * (np.arange(n) + lam) / 37.5)
    assert np.max(np.abs(op @ x - expected)) < 2e-3          # 4-point Lagrange at 37.5 samples per period
    y = np.random.default_rng(0).standard_normal(n)
    assert float(y @ (op @ x)) == pytest.approx(float((op.T @ y) @ x), rel=1e-12)  # the transpose is the adjoint


def test_wiener_models_the_lags_exactly():
    """Nearly noise-free, ~2 px RMS (lags up to ~9 lines): ignoring the lags costs about a pixel,
    modelling them leaves thousandths."""
    t, diffs, lags, _ = _record(4e-6, noise_px=1e-3)
    truth = _theta(t, 4e-6)
    assert _error_px(integrate_wiener(diffs, TAUS, DT), truth) > 0.3
    assert _error_px(integrate_wiener(diffs, TAUS, DT, lags=lags), truth) < 0.01


def test_wiener_refuses_lags_of_the_wrong_shape():
    t, diffs, lags, _ = _record(1e-6, noise_px=0.05, n=800)
    with pytest.raises(ValueError, match="lags"):
        integrate_wiener(diffs, TAUS, DT, lags=lags[:2])


# 45–60 s each on 2 cores: slow (the lags are modelled in every restore of tests/restore/test_restore_pipeline.py)
@pytest.mark.parametrize("amplitude", [pytest.param(6e-6, marks=pytest.mark.slow), pytest.param(10e-6, marks=pytest.mark.slow)])
def test_pipeline_integration_models_the_lags_rather_than_correcting_the_data(monkeypatch, amplitude):
    """integrate_axis with the Wiener (prior_lags): the prior from differentials corrected once, then the
    measured ones with the lags modelled, beats the correction alone (the first fit's error times the lag)."""
    t, diffs, lags, sigmas = _record(amplitude, noise_px=0.05)
    truth = _theta(t, amplitude)
    modelled = integrate_axis(diffs, TAUS, DT, method="wiener", lags=lags, sigmas=sigmas).theta
    spec = methods.INTEGRATION_METHODS["wiener"]
    monkeypatch.setitem(methods.INTEGRATION_METHODS, "wiener", dataclasses.replace(spec, prior_lags=False))
    corrected = integrate_axis(diffs, TAUS, DT, method="wiener", lags=lags, sigmas=sigmas).theta
    assert _error_px(modelled, truth) < 0.6 * _error_px(corrected, truth)
    assert _error_px(modelled, truth) < 0.01


@pytest.mark.slow
def test_the_prior_is_estimated_again_on_differentials_corrected_with_the_lag_aware_estimate():
    """At ~3.5 px of jitter the least-squares first estimate, which fits the noise too, corrects part of
    the noise out of the differentials (noise levels ~8 % low) and leaves the lags' sidebands, which the
    prior takes for attitude away from the lines; estimated again on differentials corrected with the
    lag-aware Wiener estimate, the noise is at its true level, the prior is 0 away from the lines and
    their harmonics, and the restoration is better."""
    noise_px = 0.3
    t, diffs, lags, sigmas = _record(10e-6, noise_px=noise_px)
    truth = _theta(t, 10e-6)
    once = integrate_axis(diffs, TAUS, DT, method="wiener", lags=lags, sigmas=sigmas, prior_passes=0)
    again = integrate_axis(diffs, TAUS, DT, method="wiener", lags=lags, sigmas=sigmas)
    f = again.spectrum.freq
    off_lines = (f > 160) & (f < 1000)
    for line in LINES_HZ:
        for h in (1, 2, 3):
            off_lines &= np.abs(f - h * line) > 5
    assert np.mean(once.spectrum.psd[off_lines]) > 0
    assert np.mean(again.spectrum.psd[off_lines]) < 0.2 * np.mean(once.spectrum.psd[off_lines])
    assert np.mean(once.spectrum.noise_std) / IFOV < 0.95 * noise_px
    assert np.mean(again.spectrum.noise_std) / IFOV == pytest.approx(noise_px, rel=0.05)
    assert _error_px(again.theta, truth) < 0.97 * _error_px(once.theta, truth)
