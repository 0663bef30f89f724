"""Accuracy of every integration method on analytic cases (not only shapes).

θ(t) is known (a sum of sines away from the pairs' blind frequencies k/τ_j;
a cubic for the polynomial method and a damped chirp over a cubic for the
parametric one, whose models they are), its differentials are
exact ``θ(t + τ_j) − θ(t)`` for the PHR-like delays 7.4 / 14.8 / 22.2 ms, with
or without white noise. Errors are RMS, mean removed (θ's constant is
unobservable), away from the record's ends (edge effects are documented for
the FFT methods), relative to θ's RMS.

Bounds:

* noise-free: a method whose model holds recovers θ to < 1 % (measured:
  ≤ 0.4 %); ``wiener_fft`` is a circular one-shot filter (3 %, measured
  1.4 %); ``inverse`` is the fixed-k pseudo-inverse, whose error is set by its
  chain gain: it must equal the stationary prediction
  ``RMS((1 − F_k(f)) θ(f))`` of :func:`restore.integration.transfer.fused_chain_gain`;
* with noise σ_D per sample: a Wiener-like fused estimate passes noise with
  a gain ≤ 1 outside the blind bands, so its error stays below σ_D / RMS(θ)
  (2.2 % here); ``wiener_fft`` 8 %;
* a broken method — differentials negated, or integrated with the wrong τ —
  must be clearly worse (> 25 %), so the bounds do not pass by accident.
"""
import numpy as np
import pytest

from restore.integration import METHODS, integrate
from restore.integration.transfer import fused_chain_gain

DT = 4e-4
N = 4000
TAUS = [7.4e-3, 14.8e-3, 22.2e-3]
LINES = [(11.3, 1.0, 0.3), (27.9, 0.6, 1.1), (52.7, 0.4, 2.0), (97.1, 0.25, 0.7)]  # Hz, µrad, rad
NOISE = 0.02e-6
TRIM = 100
NOISE_FREE_BOUND = {"wiener_fft": 0.03}
NOISY_BOUND = {"wiener_fft": 0.08}


def sines(t):
    return 1e-6 * sum(a * np.sin(2 * np.pi * f * t + p) for f, a, p in LINES)


def cubic(t):
    x = t - 0.8
    return 1e-6 * (0.8 * x + 0.5 * x ** 2 - 0.9 * x ** 3)


def damped_chirp_over_cubic(t):
    x = np.maximum(t - 0.35, 0.0)
    chirp = np.where(t >= 0.35, np.exp(-x / 0.6) * np.sin(2 * np.pi * (31.0 * x - 4.0 * x ** 2)), 0.0)
    return 1e-6 * 1.5 * chirp + cubic(t)


def _signal(method):
    return {"polynomial": cubic, "parametric": damped_chirp_over_cubic}.get(method, sines)


def _rms(e):
    e = np.asarray(e, float)
    e = e[np.isfinite(e)]
    return float(np.sqrt(np.mean((e - e.mean()) ** 2)))


def _relative_error(method, *, noise=0.0, sign=1.0, taus_used=TAUS, trim=TRIM):
    t = np.arange(N) * DT
    sig = _signal(method)
    rng = np.random.default_rng(0)
    diffs = [sign * (sig(t + tau) - sig(t)) + noise * rng.standard_normal(N) for tau in TAUS]
    theta = integrate(diffs, taus_used, DT, method=method)
    assert theta.shape == (N,) and np.isfinite(theta[trim:-trim]).all()
    sl = slice(trim, N - trim)
    return _rms((theta - sig(t))[sl]) / _rms(sig(t)[sl])


@pytest.mark.parametrize("method", sorted(set(METHODS) - {"inverse"}))
def test_exact_differentials_give_the_attitude(method):
    assert _relative_error(method) < NOISE_FREE_BOUND.get(method, 0.01)


@pytest.mark.parametrize("method", sorted(set(METHODS) - {"inverse"}))
def test_noise_passes_with_a_gain_below_one(method):
    t = np.arange(N) * DT
    bound = NOISE / _rms(_signal(method)(t)[TRIM:-TRIM])
    assert _relative_error(method, noise=NOISE) < NOISY_BOUND.get(method, bound)


def test_inverse_error_is_its_chain_gain():
    """The fixed-k pseudo-inverse loses (1 − F_k) of each line: its error is the stationary formula's."""
    f = np.array([x[0] for x in LINES])
    gain = fused_chain_gain(f, TAUS, k=0.1)
    predicted = np.sqrt(sum(((1 - g) * a) ** 2 / 2 for g, (_, a, _) in zip(gain, LINES)))  # µrad
    t = np.arange(N) * DT
    theta_rms = _rms(sines(t)[1000:-1000]) * 1e6
    measured = _relative_error("inverse", trim=1000) * theta_rms
    assert measured == pytest.approx(predicted, rel=0.03)


# the local integration's case takes 45 s on 2 cores: slow; the other methods run by default
@pytest.mark.parametrize("method", [pytest.param(m, marks=pytest.mark.slow) if m == "local" else m for m in sorted(METHODS)])
def test_a_broken_integration_fails_the_bounds(method):
    assert _relative_error(method, sign=-1.0) > 0.25
    assert _relative_error(method, taus_used=[1.5 * x for x in TAUS]) > 0.25
