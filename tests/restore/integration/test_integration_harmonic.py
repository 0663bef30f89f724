"""Harmonic-model integration and polynomial integration against analytic references."""
import numpy as np
import pytest

from restore.integration import integrate
from restore.integration.harmonic import HarmonicModel
from restore.integration.polynomial import polynomial_design, polynomial_gain
from restore.integration.transfer import pair_transfer

DT = 0.4e-3
TAUS = [7.4e-3, 14.8e-3, 22.2e-3]


def chirp(t, f0=53.0, rate=0.2, a=1.0, ph=0.3):      # drifting line: f = f0 + rate t
    return a * np.sin(ph + 2 * np.pi * (f0 * t + 0.5 * rate * t**2))


def theta(t):
    return chirp(t) + chirp(t, 108.0, -0.3, 0.4, 2.0)


def make(fun, n, sigma=0.0, seed=0, taus=TAUS):
    t = np.arange(n) * DT
    rng = np.random.default_rng(seed)
    return [fun(t + tau) - fun(t) + sigma * rng.standard_normal(n) for tau in taus], fun(t)


def test_harmonic_model_is_linear_and_evaluates_lines():
    m = HarmonicModel([50.0], 0.0, 1.0, 0.1)
    coef = np.zeros(m.n_coef)
    coef[0::2] = 2.0                                   # all cos coefficients: B-splines sum to 1
    t = np.linspace(0.05, 0.95, 200)
    np.testing.assert_allclose(m.evaluate(coef, t), 2 * np.cos(2 * np.pi * 50 * t), atol=1e-12)


def test_harmonic_drifting_lines_noise_free():
    diffs, truth = make(theta, 5000)
    est = integrate(diffs, TAUS, DT, method="harmonic")
    e = est - truth
    assert np.std(e) < 2e-3


def test_harmonic_noisy_near_cramer_rao():
    sigma, n = 0.04, 5000
    f = [53.0, 108.0]
    fun = lambda t: np.sin(2 * np.pi * 53.0 * t + 0.3) + 0.4 * np.sin(2 * np.pi * 108.0 * t + 2)
    diffs, truth = make(fun, n, sigma=sigma, seed=1)
    est = integrate(diffs, TAUS, DT, method="harmonic", knot_spacing_s=1.0)
    crb = np.sqrt(sum(2 * sigma**2 / (n * sum(abs(pair_transfer(fi, tau)) ** 2 for tau in TAUS))
                      for fi in f))
    rms = np.std(est - truth)
    # one carrier per line with (duration / knot + 3) B-spline amplitudes: ~sqrt(5) x CRB
    assert rms < 4 * crb


def test_harmonic_given_frequencies_and_residual():
    diffs, truth = make(theta, 3000, sigma=0.01, seed=2)
    est = integrate(diffs, TAUS, DT, method="harmonic", frequencies_hz=[53.1, 107.8],
                    residual="wiener")
    assert np.std(est - truth) < 0.01
    with pytest.raises(ValueError, match="^frequencies_hz"):
        integrate(diffs, TAUS, DT, method="harmonic", frequencies_hz=[-3.0])
    with pytest.raises(ValueError, match="^knot_spacing_s"):
        integrate(diffs, TAUS, DT, method="harmonic", knot_spacing_s=0)


# --- polynomial ---------------------------------------------------------------------
def test_polynomial_recovers_a_cubic_up_to_the_constant():
    fun = lambda t: 3e-6 + 2e-6 * t - 4e-6 * t**2 + 1e-6 * t**3
    diffs, truth = make(fun, 2000, taus=[0.05, 0.12])
    est = integrate(diffs, [0.05, 0.12], DT, method="polynomial", degree=3, noise_std=1e-9)
    np.testing.assert_allclose(est, truth - truth.mean(), atol=1e-12)


def test_polynomial_design_rows():
    rows = polynomial_design(np.array([0.0, 1.0]), 0.5, 3)
    np.testing.assert_allclose(rows, [[0.5, 0.25, 0.125], [0.5, 1.25, 2.375]])
    with pytest.raises(ValueError, match="^degree"):
        polynomial_design(np.zeros(2), 0.5, 6)


def test_polynomial_gain_falls_as_one_over_tau():
    # patent fig. 14: 0.5 ms lines, one measurement every 10 lines, 6 s
    g = {tau: polynomial_gain(tau, duration_s=6.0, step_s=5e-3, degree=4)[1].mean()
         for tau in (0.01, 0.02, 0.05, 0.1)}
    for tau in (0.02, 0.05, 0.1):
        assert g[tau] * tau == pytest.approx(g[0.01] * 0.01, rel=0.03)
    t, gain = polynomial_gain(0.1, duration_s=6.0, step_s=5e-3)
    assert gain[0] == 0.0 and t[-1] == pytest.approx(6.0)
