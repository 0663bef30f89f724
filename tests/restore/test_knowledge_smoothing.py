"""The AOCS knowledge's noise below the high-pass, shrunk (restore.knowledge_smoothing)."""
from dataclasses import replace

import numpy as np
import pytest
from scipy.fft import dct

from restore.knowledge_smoothing import (MIN_SAMPLES, knowledge_smoothing, lowband, lowband_correction,
                                         wiener_shrinkage_gain)
from restore.posterior import knowledge_noise_below

RATE = 64.0
T = np.arange(int(1.6 * RATE) + 1) / RATE          # phr_cmg's telemetry: 103 samples over 1.6 s
SIG = 0.3e-6
DT = 0.0004
LINES = np.arange(4000) * DT


def _trend(t):
    return (3.0 * t - 1.5 * t ** 2) * 1e-6


def test_gain_is_one_without_noise_and_zero_on_pure_noise():
    rng = np.random.default_rng(1)
    c = rng.standard_normal(2000)
    assert np.all(wiener_shrinkage_gain(c, 0.0) == 1.0)
    g = wiener_shrinkage_gain(c, 1.0)
    assert np.all((g >= 0) & (g <= 1))
    # pooled power of 5 unit-variance coefficients exceeds 1 about 40 % of the time, and then only a little
    assert g.mean() < 0.15


def test_gain_keeps_coefficients_far_above_the_noise():
    c = np.zeros(50)
    c[10:13] = 20.0
    g = wiener_shrinkage_gain(c, 1.0)
    assert np.all(g[10:13] > 0.99)
    assert np.all(g[20:] == 0.0)


@pytest.mark.parametrize("pool", [0, 2, -1])
def test_gain_refuses_an_even_or_empty_pool(pool):
    with pytest.raises(ValueError, match="pool"):
        wiener_shrinkage_gain(np.ones(10), 1.0, pool=pool)


def test_a_quadratic_is_kept_exactly_and_noise_alone_is_mostly_removed():
    th = _trend(T)
    sm = knowledge_smoothing(T, th, SIG)
    np.testing.assert_allclose(sm.apply(th), th, rtol=0, atol=1e-15)
    rng = np.random.default_rng(2)
    err = []
    for _ in range(200):
        k = th + rng.standard_normal(T.size) * SIG
        err.append(knowledge_smoothing(T, k, SIG).apply(k) - th)
    # the polynomial passes 3 of 103 noise degrees of freedom whole; the shrunk rest about a tenth of its power
    assert np.sqrt(np.mean(np.square(err))) < 0.45 * SIG


def test_a_sine_well_above_the_noise_is_kept():
    th = _trend(T) + 10 * SIG * np.sin(2 * np.pi * 1.3 * T)
    rng = np.random.default_rng(3)
    k = th + rng.standard_normal(T.size) * SIG
    s = knowledge_smoothing(T, k, SIG).apply(k)
    amp = 2 * np.mean((s - _trend(T)) * np.sin(2 * np.pi * 1.3 * T)) / (10 * SIG)
    assert amp == pytest.approx(1.0, abs=0.05)


def test_too_few_samples_or_a_gap_are_not_smoothed():
    assert knowledge_smoothing(T[:MIN_SAMPLES - 1], np.zeros(MIN_SAMPLES - 1), SIG) is None
    v = np.zeros(T.size)
    v[5] = np.nan
    assert knowledge_smoothing(T, v, SIG) is None
    with pytest.raises(ValueError, match="same length"):
        knowledge_smoothing(T, np.zeros(5), SIG)


@pytest.mark.parametrize("extra", [0.0, 0.8e-6])
def test_the_error_draws_match_the_smoothings_actual_error(extra):
    """error_draw's low band has the variance the smoothing's error has over many noise draws (Monte Carlo)."""
    th = _trend(T) + extra * np.sin(2 * np.pi * 1.3 * T)
    rng = np.random.default_rng(4)
    actual, drawn = [], []
    for _ in range(200):
        k = th + rng.standard_normal(T.size) * SIG
        sm = knowledge_smoothing(T, k, SIG)
        actual.append(np.var(lowband(sm.apply(k) - th, T, LINES, line_period_s=DT, highpass_hz=2.0)))
        drawn.append(np.var(lowband(sm.error_draw(rng), T, LINES, line_period_s=DT, highpass_hz=2.0)))
    assert np.sqrt(np.mean(drawn) / np.mean(actual)) == pytest.approx(1.0, abs=0.12)


def test_unit_gains_draw_the_raw_knowledge_noise_below_the_high_pass():
    """With every gain 1 the draw is the knowledge's white noise, as posterior.knowledge_noise_below draws it."""
    sm = replace(knowledge_smoothing(T, _trend(T), SIG), gain=np.ones(T.size))
    rng = np.random.default_rng(5)
    ones = [np.var(lowband(sm.error_draw(rng), T, LINES, line_period_s=DT, highpass_hz=2.0)) for _ in range(300)]
    raw = [np.var(knowledge_noise_below(LINES.size, DT, 2.0, SIG, RATE, rng)) for _ in range(300)]
    assert np.sqrt(np.mean(ones) / np.mean(raw)) == pytest.approx(1.0, abs=0.1)


def test_lowband_passes_slow_and_stops_fast_content():
    slow = np.sin(2 * np.pi * 0.3 * T)
    fast = np.sin(2 * np.pi * 20.0 * T)
    mid = slice(1000, 3000)
    lb = lowband(slow, T, LINES, line_period_s=DT, highpass_hz=2.0)
    np.testing.assert_allclose(lb[mid], np.sin(2 * np.pi * 0.3 * LINES[mid]), atol=0.03)
    assert np.max(np.abs(lowband(fast, T, LINES, line_period_s=DT, highpass_hz=2.0)[mid])) < 1e-3
    assert np.all(lowband(slow, T, LINES, line_period_s=DT, highpass_hz=0.0) == 0.0)


def test_the_correction_replaces_the_knowledges_low_band_by_the_smoothed_one():
    rng = np.random.default_rng(6)
    k = _trend(T) + rng.standard_normal(T.size) * SIG
    sm = knowledge_smoothing(T, k, SIG)
    corr = lowband_correction(sm, k, LINES, line_period_s=DT, highpass_hz=2.0)
    lb = lambda x: lowband(x, T, LINES, line_period_s=DT, highpass_hz=2.0)  # noqa: E731
    np.testing.assert_allclose(lb(k) + corr, lb(sm.apply(k)), rtol=0, atol=1e-15)
    # and the low band of the knowledge's error shrinks (over 50 noise draws: one draw's polynomial may be unlucky)
    before, after = [], []
    for _ in range(50):
        k = _trend(T) + rng.standard_normal(T.size) * SIG
        corr = lowband_correction(knowledge_smoothing(T, k, SIG), k, LINES, line_period_s=DT, highpass_hz=2.0)
        before.append(np.var(lb(k) - lb(_trend(T))))
        after.append(np.var(lb(k) + corr - lb(_trend(T))))
    assert np.sqrt(np.mean(after) / np.mean(before)) < 0.75


def test_dct_noise_stays_white():
    """The premise: an orthonormal DCT-II keeps white noise white with the same variance per coefficient."""
    rng = np.random.default_rng(7)
    c = dct(rng.standard_normal((4000, T.size)), norm="ortho", axis=1)
    np.testing.assert_allclose(c.var(axis=0), 1.0, atol=0.1)


def test_rows_at_once_are_the_one_row_functions():
    """lowband_rows is lowband row by row; error_draws has error_draw's variance per sample (Monte Carlo)."""
    from restore.knowledge_smoothing import lowband_rows

    rng = np.random.default_rng(6)
    rows = rng.standard_normal((4, T.size)) * SIG
    one = np.array([lowband(r, T, LINES, line_period_s=DT, highpass_hz=2.0) for r in rows])
    np.testing.assert_allclose(lowband_rows(rows, T, LINES, line_period_s=DT, highpass_hz=2.0), one,
                               atol=1e-12 * SIG)
    assert not lowband_rows(rows, T, LINES, line_period_s=DT, highpass_hz=0.0).any()
    sm = knowledge_smoothing(T, _trend(T) + rng.standard_normal(T.size) * SIG, SIG)
    many = sm.error_draws(np.random.default_rng(1), 3000)
    single = np.array([sm.error_draw(rng) for _ in range(3000)])
    assert many.shape == (3000, T.size)
    np.testing.assert_allclose(np.mean(many ** 2, axis=0), np.mean(single ** 2, axis=0), rtol=0.15)
