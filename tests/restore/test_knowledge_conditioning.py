"""The integration's prior given the AOCS knowledge (restore.knowledge_conditioning), on analytic cases."""
import numpy as np
import pytest

from restore.axis_integration import integrate_axis
from restore.knowledge_conditioning import (MIN_GAIN, apply_response, attitude_psd, conditional_prior,
                                            knowledge_conditioning, knowledge_signal_response)
from restore.knowledge_prior import knowledge_gain, knowledge_noise_floor, spline_response


@pytest.mark.parametrize("g", [0.9, 0.3 - 0.4j, 0.0])
def test_the_conditional_mean_and_variance_are_the_regression_of_e_on_k(g):
    # per frequency bin: θ ~ CN(0, S), ε ~ CN(0, N), k = G θ + ε, e = θ − k; regressing e on k over many draws
    # gives the slope E[e k*] / E[|k|²] = h and the residual variance V
    rng = np.random.default_rng(1)
    m, s, nk = 400_000, 2.0, 0.5

    def cn(var):
        return np.sqrt(var / 2) * (rng.standard_normal(m) + 1j * rng.standard_normal(m))

    theta, eps = cn(s), cn(nk)
    k = g * theta + eps
    e = theta - k
    slope = np.vdot(k, e) / np.vdot(k, k)
    resid = np.mean(np.abs(e - slope * k) ** 2)
    v, h = conditional_prior(s, g, nk)
    assert complex(h) == pytest.approx(slope, abs=0.01)
    assert float(v) == pytest.approx(resid, rel=0.01)
    # never above the prior of e itself
    assert float(v) <= abs(1 - g) ** 2 * s + nk


def test_the_limits_a_quiet_attitude_a_silent_knowledge_and_a_strong_signal():
    v, h = conditional_prior([0.0, 3.0, 1e6], [1.0, 0.0, 0.5], [1.0, 1.0, 1.0])
    # no attitude: e is −k exactly
    assert v[0] == 0.0 and h[0] == -1.0
    # the knowledge holds only its noise: e = θ − ε, the images restore θ with its own prior
    assert v[1] == pytest.approx(3.0) and h[1] == pytest.approx(-1.0)
    # a strong attitude: the knowledge deconvolved, (1 − G) / G, with its noise over |G|² left
    assert h[2].real == pytest.approx(1.0, rel=1e-5) and v[2] == pytest.approx(4.0, rel=1e-5)
    # no noise and no response: nothing known, the attitude's prior
    v, h = conditional_prior([2.0], [0.0], [0.0])
    assert v[0] == 2.0 and h[0] == 0.0


def test_the_knowledge_counts_as_a_measurement_only_inside_its_band():
    f = np.array([0.0, 2.0, 8.0, 10.0, 12.0, 25.0])
    g = knowledge_signal_response(f, cutoff_hz=10.0, order=2, kind="butterworth_zero_phase", rate_hz=64.0)
    full = knowledge_gain(f, 10.0, 2) * spline_response(f, 64.0)
    inside = full >= MIN_GAIN
    assert inside.tolist() == [True, True, True, False, False, False]   # at the cut-off: ½ × the spline's 0.998
    assert np.allclose(g[inside], full[inside]) and np.all(g[~inside] == 0)


def test_the_attitude_psd_is_the_restored_power_less_the_error_power():
    dt, n = 1e-3, 4000
    t = np.arange(n) * dt
    rng = np.random.default_rng(3)
    sd = 0.05
    theta = 1.0 * np.sin(2 * np.pi * 60.0 * t + 0.3)
    x = theta + sd * rng.standard_normal(n)
    f_bins = np.fft.rfftfreq(n, dt)
    df = f_bins[1] - f_bins[0]
    # white error: sd² spread over the n // 2 + 1 bins of the one-sided record
    err_power = np.full(f_bins.size, sd ** 2 / (f_bins.size - 1))
    freq = np.arange(0, 500.0, df)
    s = attitude_psd(x, err_power, freq, dt)
    # the sine: its power A²/2 (two-sided PSD integrated over ±f) within a few per cent
    line = (freq > 50) & (freq < 70)
    assert 2 * s[line].sum() * df == pytest.approx(0.5, rel=0.05)
    # away from the line the restored power is the error's (sd² × 300 / 500 in 150–450 Hz); what is left is the
    # positive part of a smoothed periodogram's spread (8 bins: ± 35 %, E[max(x, 0)] ≈ 0.14 of the level)
    quiet = (freq > 150) & (freq < 450)
    assert 2 * s[quiet].sum() * df < 0.3 * sd ** 2 * 300 / 500
    with pytest.raises(ValueError, match="bins"):
        attitude_psd(x, err_power[:-1], freq, dt)


def test_apply_response_filters_a_tone_and_takes_what_lies_beyond_the_record_as_zero():
    dt, n = 1e-3, 3000
    t = np.arange(n) * dt
    freq = np.linspace(0, 500, 2001)
    band = np.where((freq > 4) & (freq < 30), -1.0, 0.0)
    # a tone inside the band comes out negated in the record's middle (the quadratic trend taken out first
    # removes its small projection on a quadratic)
    y = apply_response(np.sin(2 * np.pi * 10.0 * t), band, freq, dt)
    mid = slice(500, n - 500)
    assert np.max(np.abs(y[mid] + np.sin(2 * np.pi * 10.0 * t[mid]))) < 0.05
    # white noise: its band part, known from a record five times as long, is estimated near the ends as well
    # as zero beyond the record allows — the error stays a fraction of the band part, mostly near the ends
    rng = np.random.default_rng(5)
    long = rng.standard_normal(5 * n)
    f_long = np.fft.rfftfreq(long.size, dt)
    truth = np.fft.irfft(np.fft.rfft(long) * np.interp(f_long, freq, band), long.size)[2 * n:3 * n]
    est = apply_response(long[2 * n:3 * n], band, freq, dt)
    err = est - truth
    assert np.sqrt(np.mean(err ** 2)) < 0.25 * np.std(truth)
    assert np.sqrt(np.mean(err[mid] ** 2)) < 0.05 * np.std(truth)


def test_conditioning_on_the_knowledge_removes_its_noise_where_the_attitude_is_quiet():
    # An attitude with a line at 60 Hz and nothing between 2 and 40 Hz; knowledge = the attitude through a
    # zero-phase Butterworth (10 Hz) plus white noise at 64 Hz, spline-interpolated; three pairs measure the
    # differentials of e = θ − k with white noise. Integrating e with its own prior passes the pairs' noise at
    # 2–30 Hz (the knowledge's noise makes e's prior large there); with the prior given k, the restored
    # θ̂ = k + μ + ê' keeps far less of it, and the draws' own prediction agrees with what it does.
    from scipy.interpolate import CubicSpline
    from scipy.signal import butter, sosfiltfilt

    from restore.posterior import simulated_differentials
    from restore.synthesis import highpass_nan

    dt, n, rate, sk, sd = 4e-4, 4000, 64.0, 3e-7, 4e-7
    taus = [0.0074, 0.0222, 0.0148]
    rng = np.random.default_rng(7)
    ext = n + 80
    t = np.arange(ext) * dt
    theta = 2e-6 * np.sin(2 * np.pi * 60.0 * t + 0.4) + 1e-6 * (t / t[-1]) ** 2
    sos = butter(2, 10.0, fs=1 / dt, output="sos")
    filtered = sosfiltfilt(sos, theta)
    ts = np.arange(-2, int(t[-1] * rate) + 4) / rate
    k = CubicSpline(ts, np.interp(ts, t, filtered) + sk * rng.standard_normal(ts.size))(t)
    e = theta - k
    valid = np.ones((3, n), bool)
    lags = [np.zeros(n)] * 3
    diffs = simulated_differentials(e, taus, lags, valid, dt) + sd * rng.standard_normal((3, n))
    hp = 2.0
    common = dict(method="wiener", lags=lags, sigmas=[np.full(n, sd)] * 3, weights=[np.ones(n)] * 3,
                  highpass_hz=hp)
    res = integrate_axis(list(diffs), taus, dt, options={}, **common)
    plain = k[:n] + res.theta

    def err(x):
        d = highpass_nan(x - theta[:n], dt=dt, cutoff_hz=hp)[200:-200]
        return np.sqrt(np.mean(d ** 2))

    # the error power of the plain estimate, as the draws would predict it: use its actual error here (the
    # prediction itself is the posterior module's business); the conditioning must not need it exact
    e_plain = plain - theta[:n]
    w = np.hanning(n)
    p_err = np.abs(np.fft.rfft((e_plain - e_plain.mean()) * w)) ** 2 / (np.sum(w ** 2) * n) * 2
    p_err[0] = 0
    cond = knowledge_conditioning(res.spectrum.freq, res.spectrum.psd, plain, p_err, dt, cutoff_hz=10.0, order=2,
                                  kind="butterworth_zero_phase", rate_hz=rate, noise_rad=sk)
    mu = highpass_nan(cond.mean(k, dt), dt=dt, cutoff_hz=hp)
    d2 = diffs - simulated_differentials(mu, taus, lags, valid, dt)
    res2 = integrate_axis(list(d2), taus, dt, options={"psd": (res.spectrum.freq, cond.variance),
                                                       "noise_std": res.spectrum.noise_std}, **common)
    conditioned = k[:n] + mu[:n] + res2.theta
    quiet = (cond.freq > 3) & (cond.freq < 30)
    nk = knowledge_noise_floor(cond.freq, rate_hz=rate, noise_rad=sk)
    # in the quiet band the prior given k is a small fraction of e's own (the knowledge's noise)
    assert np.mean(cond.variance[quiet]) < 0.2 * np.mean(nk[quiet])
    # measured: 0.066 → 0.036 µrad (the pairs' noise 0.4 µrad per line)
    assert err(conditioned) < 0.7 * err(plain)
