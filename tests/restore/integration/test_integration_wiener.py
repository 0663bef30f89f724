"""Fourier-domain integration: pseudo-inverse, one-shot Wiener, exact Wiener (MAP)."""
import numpy as np
import pytest

from restore.integration import integrate
from restore.integration.spectrum import estimate_differential_noise, estimate_spectrum
from restore.integration.transfer import pair_transfer
from restore.integration.wiener import integrate_wiener

DT = 0.4e-3
TAUS = [7.4e-3, 14.8e-3, 22.2e-3]          # 18.5, 37, 55.5 samples


def sines(freqs, amps, phases):
    return lambda t: sum(a * np.sin(2 * np.pi * f * t + p) for f, a, p in zip(freqs, amps, phases))


def make(theta, n, taus=TAUS, sigma=0.0, seed=0):
    t = np.arange(n) * DT
    rng = np.random.default_rng(seed)
    diffs = [theta(t + tau) - theta(t) + sigma * rng.standard_normal(n) for tau in taus]
    return diffs, theta(t)


def err(est, truth):
    ok = np.isfinite(est)
    e = est[ok] - truth[ok]
    return e - e.mean()


THETA = sines([52.3, 74.1, 104.6, 148.2], [1.0, 0.8, 0.3, 0.2], [0.1, 1.0, 2.0, 3.0])


def test_wiener_noise_free_fractional_lags():
    diffs, truth = make(THETA, 4000)
    est = integrate(diffs, TAUS, DT, method="wiener")
    assert np.isfinite(est).all()
    assert np.sqrt(np.mean(err(est, truth) ** 2)) < 2e-3


def test_wiener_noisy_close_to_cramer_rao():
    # Cramér–Rao bound for known-frequency sinusoids: var = 2 sigma² / (N sum_j |G_j(f)|²) each
    sigma, n = 0.04, 5000
    diffs, truth = make(THETA, n, sigma=sigma, seed=1)
    est = integrate(diffs, TAUS, DT, method="wiener")
    freqs = [52.3, 74.1, 104.6, 148.2]
    crb = np.sqrt(sum(2 * sigma**2 / (n * sum(abs(pair_transfer(f, tau)) ** 2 for tau in TAUS))
                      for f in freqs))
    rms = np.sqrt(np.mean(err(est, truth) ** 2))
    assert crb < rms < 6 * crb          # measured ~3.5x: the prior spans a few bins per line


def test_wiener_pure_noise_gives_zero():
    rng = np.random.default_rng(2)
    diffs = [0.05 * rng.standard_normal(3000) for _ in TAUS]
    est = integrate(diffs, TAUS, DT, method="wiener")
    assert np.max(np.abs(est)) < 0.005


def test_noise_estimate_from_blind_frequencies():
    diffs, _ = make(THETA, 6000, sigma=0.03, seed=3)
    np.testing.assert_allclose(estimate_differential_noise(diffs, TAUS, DT), 0.03, rtol=0.1)
    spec = estimate_spectrum(diffs, TAUS, DT)
    var_lines = sum(a**2 / 2 for a in [1.0, 0.8, 0.3, 0.2])
    assert spec.variance == pytest.approx(var_lines, rel=0.05)
    # detected only around the lines
    assert spec.detected.mean() < 0.05


def test_inverse_interior_amplitude_is_the_chain_gain():
    f, k = 61.0, 0.5
    diffs, truth = make(sines([f], [1.0], [0.3]), 8000)
    est = integrate(diffs, TAUS, DT, method="inverse", k=k)
    g2 = sum(abs(pair_transfer(f, tau)) ** 2 for tau in TAUS)
    mid = slice(2000, 6000)
    gain = np.std(est[mid]) / np.std(truth[mid])
    assert gain == pytest.approx(g2 / (g2 + k), rel=0.01)


def test_wiener_fft_with_flat_prior_is_constant_k():
    f, sigma, s = 61.0, 0.1, 1e-4     # k = sigma² dt / S
    diffs, truth = make(sines([f], [1.0], [0.3]), 8000)
    est = integrate(diffs, TAUS, DT, method="wiener_fft", psd=lambda fr: np.full(fr.shape, s),
                    noise_std=sigma)
    k = sigma**2 * DT / s
    g2 = sum(abs(pair_transfer(f, tau)) ** 2 for tau in TAUS)
    mid = slice(2000, 6000)
    assert np.std(est[mid]) / np.std(truth[mid]) == pytest.approx(g2 / (g2 + k), rel=0.01)


def test_wiener_single_pair_and_details():
    diffs, truth = make(THETA, 3000, taus=[22.2e-3], sigma=0.02, seed=4)
    res = integrate_wiener(diffs, [22.2e-3], DT, return_details=True)
    assert res.iterations >= 1 and res.spectrum.noise_std.shape == (1,)
    assert np.sqrt(np.mean(err(res.theta, truth) ** 2)) < 0.02


def test_wiener_bad_options():
    diffs, _ = make(THETA, 500)
    with pytest.raises(ValueError, match="^maxiter"):
        integrate(diffs, TAUS, DT, method="wiener", maxiter=0)
    with pytest.raises(ValueError, match="^noise_std"):
        integrate(diffs, TAUS, DT, method="wiener", noise_std=[1, 2])
    with pytest.raises(ValueError, match="^psd"):
        integrate(diffs, TAUS, DT, method="wiener", psd=lambda f: -np.ones_like(f))
    with pytest.raises(ValueError, match="^k"):
        integrate(diffs, TAUS, DT, method="inverse", k=0)


def test_wiener_long_lag_many_blind_frequencies():
    # PAN/B2-like lag: blind every 5.8 Hz; a strong line's leakage must not blow up the prior
    tau = 0.1722
    theta = sines([61.0, 13.0], [1.0, 0.3], [0.0, 1.0])
    diffs, truth = make(theta, 3000, taus=[tau], sigma=0.01, seed=5)
    est = integrate(diffs, [tau], DT, method="wiener")
    assert np.std(err(est, truth)) < 0.02


def test_wiener_per_sample_weights_follow_the_noise():
    """Half the samples ten times noisier (in variance): weighting them by 1/variance helps."""
    n = 4000
    t = np.arange(n) * DT
    rng = np.random.default_rng(3)
    truth = THETA(t)
    var = np.where((np.arange(n) // 50) % 2 == 0, 0.05 ** 2, 10 * 0.05 ** 2)
    diffs = [THETA(t + tau) - truth + np.sqrt(var) * rng.standard_normal(n) for tau in TAUS]
    plain = integrate_wiener(diffs, TAUS, DT)
    weighted = integrate_wiener(diffs, TAUS, DT, weights=[1.0 / var] * 3)
    e_plain = np.sqrt(np.mean(err(plain, truth) ** 2))
    e_weighted = np.sqrt(np.mean(err(weighted, truth) ** 2))
    assert e_weighted < 0.85 * e_plain
    # scale-free: weights are relative (to the conjugate-gradient tolerance, 1e-7 relative)
    again = integrate_wiener(diffs, TAUS, DT, weights=[7.0 / var] * 3)
    np.testing.assert_allclose(again, weighted, atol=1e-6 * np.abs(truth).max())
    # equal weights are no weights
    same = integrate_wiener(diffs, TAUS, DT, weights=[np.ones(n)] * 3)
    np.testing.assert_allclose(same, plain, atol=1e-6 * np.abs(truth).max())
    with pytest.raises(ValueError, match="weights"):
        integrate_wiener(diffs, TAUS, DT, weights=[np.ones(n)] * 2)
