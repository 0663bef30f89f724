"""The σ's check against the smoothed AOCS knowledge (restore.knowledge_check), on analytic cases."""
import numpy as np
import pytest

from restore.knowledge_check import (KnowledgeCheck, check_band, excess_variance, filter_error_power,
                                     knowledge_check, line_power, smoothed_knowledge_at, tapered_power,
                                     ENBW, MIN_BINS)
from restore.knowledge_prior import knowledge_gain, knowledge_noise_floor
from restore.knowledge_smoothing import knowledge_smoothing, lowband
from restore.synthesis import highpass_gain, highpass_nan
from simsat.attitude import AttitudeSeries

DT = 1e-3          # line period [s]
N = 8000           # 8 s of lines
RATE = 64.0        # knowledge rate [Hz]
CUTOFF, ORDER = 10.0, 4
SIGMA_K = 3e-7     # knowledge noise per sample [rad]
HP = 2.0           # the restoration's high-pass [Hz]


def test_line_power_sums_to_the_mean_square_and_puts_a_sine_in_its_bin():
    t = np.arange(N) * DT
    x = 2.0 * np.sin(2 * np.pi * 5.0 * t) + 0.3
    p = line_power(x)
    f = np.fft.rfftfreq(N, DT)
    assert p.sum() == pytest.approx(np.mean((x - x.mean()) ** 2), rel=1e-12)
    assert p[np.argmin(abs(f - 5.0))] == pytest.approx(2.0, rel=1e-9)   # A² / 2
    # gaps count as zeros: the power of the finite lines scaled by their fraction
    g = x.copy()
    g[1000:3000] = np.nan
    assert line_power(g).sum() == pytest.approx(np.nansum((g - np.nanmean(g)) ** 2) / N, rel=1e-12)
    assert np.all(line_power(np.full(10, np.nan)) == 0)


def test_the_band_runs_from_twice_the_highpass_to_the_filters_flat_part():
    f = np.fft.rfftfreq(N, DT)
    band = check_band(N, DT, 2.0, CUTOFF)
    assert f[band].min() >= 2.5 and f[band].max() <= 7.0
    assert np.count_nonzero(band) == np.count_nonzero((f >= 2.5) & (f <= 7.0))
    # a 1.6 s record: bins every 0.625 Hz, eight of them in 2.5–7 Hz; one in 6.25–7 Hz (high-pass 5 Hz), too few
    assert np.count_nonzero(check_band(1600, DT, 2.0, CUTOFF)) == 8 >= MIN_BINS
    assert check_band(1600, DT, 5.0, CUTOFF) is None
    assert check_band(N, DT, 0.0, CUTOFF) is None          # no high-pass: the images restore every frequency
    assert check_band(N, DT, 2.0, 0.0) is None


def test_the_excess_counts_only_beyond_the_sampling_spread():
    # 150 tapered bins are worth 100 independent ones (ENBW 1.5): threshold 1 + 2/10 = 1.2 × the prediction
    assert excess_variance(1.19, 0.6, 0.4, 150) == 0.0
    assert excess_variance(1.5, 0.6, 0.4, 150) == pytest.approx(0.5)
    assert excess_variance(0.5, 0.6, 0.4, 150) == 0.0
    chk = KnowledgeCheck((4.0, 7.0), 1.5, 0.6, 0.4, 150, excess_variance(1.5, 0.6, 0.4, 150))
    # the high-pass's gain: 1/√2 of its low-pass left at the cut-off, nothing at 0, all far above
    assert highpass_gain(np.array([0.0, 2.0, 20.0]), 2.0) == pytest.approx([0.0, 1 - 2 ** -0.5, 1.0], abs=1e-12)
    assert chk.ratio == pytest.approx(1.5) and chk.threshold == pytest.approx(1.2)
    # σ takes the images' share of the excess: 0.6 / (0.6 + 0.4) of 0.5
    assert chk.images_share == pytest.approx(0.6) and chk.booked_rad2 == pytest.approx(0.3)
    back = KnowledgeCheck.from_dict(chk.as_dict())
    assert back.band_hz == chk.band_hz and back.bins == 150
    assert back.excess_rad2 == pytest.approx(0.5) and back.observed_rad2 == pytest.approx(1.5)
    assert back.booked_rad2 == pytest.approx(0.3)


def test_sigma_books_the_measured_excess_whether_significant_or_not():
    """Below the threshold the two predictions do not significantly disagree (no excess reported), but σ still
    takes the images' share of what was measured beyond them; nothing when the observed power is below them."""
    below = KnowledgeCheck((4.0, 7.0), 1.19, 0.6, 0.4, 150, excess_variance(1.19, 0.6, 0.4, 150))
    assert below.excess_rad2 == 0.0
    assert below.measured_excess_rad2 == pytest.approx(0.19)
    assert below.booked_rad2 == pytest.approx(0.6 * 0.19)
    assert KnowledgeCheck.from_dict(below.as_dict()).booked_rad2 == pytest.approx(0.6 * 0.19)
    under = KnowledgeCheck((4.0, 7.0), 0.5, 0.6, 0.4, 150, 0.0)
    assert under.measured_excess_rad2 == 0.0 and under.booked_rad2 == 0.0


def test_the_filter_error_of_a_tone_is_one_minus_the_gain_times_the_tone():
    """A 6 Hz tone of amplitude A through the zero-phase Butterworth: the knowledge holds G·A, its error (1 − G)·A;
    from the knowledge's own periodogram the filter term is ((1 − G) A)² / 2 in the tone's bin."""
    t = np.arange(N) * DT
    f = np.fft.rfftfreq(N, DT)
    g = knowledge_gain(6.0, CUTOFF, ORDER)
    k = g * 1e-5 * np.sin(2 * np.pi * 6.0 * t)
    pf = filter_error_power(line_power(k), f, cutoff_hz=CUTOFF, order=ORDER, kind="butterworth_zero_phase",
                            noise_rad=0.0, rate_hz=RATE, n=N, dt=DT)
    i = np.argmin(abs(f - 6.0))
    assert pf[i] == pytest.approx(((1 - g) * 1e-5) ** 2 / 2, rel=1e-6)
    # the noise floor is taken out first: knowledge power at the floor leaves no filter error
    floor_only = knowledge_noise_floor(f, rate_hz=RATE, noise_rad=SIGMA_K) * 2 / (N * DT)
    pf0 = filter_error_power(floor_only * 0.99, f, cutoff_hz=CUTOFF, order=ORDER, kind="butterworth_zero_phase",
                             noise_rad=SIGMA_K, rate_hz=RATE, n=N, dt=DT)
    assert np.all(pf0[f < 20] == 0)


def _scene(rng, tone_rad=0.0, tone_hz=5.0):
    """An attitude (a 1.5 Hz and a 6 Hz sine, 20 µrad), its knowledge samples (zero-phase Butterworth, white noise
    at 64 Hz) and their smoothing, and the restored angle built as the pipeline builds it: ``LP(k_s) + H(k + ê)``,
    with the images' estimate ``k + ê`` = attitude + white error (0.2 µrad per line) + an optional tone the images'
    model does not know of. Returns (line times, samples' times, samples, smoothing, restored)."""
    t = np.arange(N) * DT
    th_f = (1.5, 6.0)
    ts = np.arange(int(N * DT * RATE)) / RATE
    k = sum(knowledge_gain(f, CUTOFF, ORDER) * 2e-5 * np.sin(2 * np.pi * f * ts + f) for f in th_f)
    k = k + rng.standard_normal(ts.size) * SIGMA_K
    sm = knowledge_smoothing(ts, k, SIGMA_K)
    theta = sum(2e-5 * np.sin(2 * np.pi * f * t + f) for f in th_f)
    images = theta + rng.standard_normal(N) * 2e-7 + tone_rad * np.sin(2 * np.pi * tone_hz * t + 0.3)
    ks = smoothed_knowledge_at(sm, k, t)
    restored = ks + highpass_nan(images - ks, dt=DT, cutoff_hz=HP)
    return t, ts, k, sm, restored


def _check(rng, tone_rad=0.0, tone_hz=5.0):
    """The check of :func:`_scene`, the images' prediction from draws made as the posterior makes them: the
    images' white error through the high-pass plus the smoothing's noise below it."""
    t, ts, k, sm, restored = _scene(rng, tone_rad, tone_hz)
    draws = np.mean([tapered_power(highpass_nan(rng.standard_normal(N) * 2e-7, dt=DT, cutoff_hz=HP)
                                   + lowband(sm.error_draw(rng), ts, t, line_period_s=DT, highpass_hz=HP),
                                   np.ones(N, bool)) for _ in range(8)], axis=0)
    k_lines = AttitudeSeries(ts, k, k, k).at(np.clip(t, ts[0], ts[-1]))[0]   # read as product.nc's knowledge is
    return knowledge_check(restored, smoothed_knowledge_at(sm, k, t), k_lines, draws, sm, line_period_s=DT,
                           highpass_hz=HP, cutoff_hz=CUTOFF, order=ORDER, kind="butterworth_zero_phase",
                           noise_rad=SIGMA_K, rate_hz=RATE)


def test_restored_and_knowledge_agreeing_within_their_predictions_raise_nothing():
    """The images' error and the knowledge's are what both predictions say: over 20 seeds the ratio stays near
    1 (the knowledge's filter error on the 6 Hz sine is part of its prediction) and the excess is 0 in at least
    19 (the threshold is two sampling spreads)."""
    checks = [_check(np.random.default_rng(s)) for s in range(20)]
    ratios = np.array([c.ratio for c in checks])
    assert 0.7 < np.median(ratios) < 1.2
    assert sum(c.excess_rad2 == 0 for c in checks) >= 19
    # what σ books then is the positive part of the band power's sampling scatter: with the band's power a
    # χ² of 2 m / ENBW degrees of freedom about the prediction, E[(X − 1)⁺] of it (the prediction, an upper
    # bound, makes it less); twice that bounds the mean of 20 checks
    k = 2 * checks[0].bins / ENBW
    from scipy.stats import chi2
    x = np.linspace(1, 12, 20001)
    mean_positive = np.trapezoid((x - 1) * chi2.pdf(x * k, k) * k, x)
    booked = np.mean([c.booked_rad2 / (c.images_share * (c.images_rad2 + c.knowledge_rad2)) for c in checks])
    assert 0 < booked < 2 * mean_positive
    c = checks[0]
    assert c.band_hz[0] >= 2.5 and c.band_hz[1] <= 7.0 and c.bins >= MIN_BINS


def test_an_error_both_predictions_miss_is_what_the_sigma_takes():
    """A 5 Hz tone of 0.4 µrad in the images' estimate, unknown to their prediction: the restored angle holds it
    through the high-pass, H(5 Hz) · 0.4 µrad, and the excess the check books is that tone's mean square, within
    two sampling spreads of the band's power (2 / √(bins / ENBW))."""
    for s in range(3):
        c = _check(np.random.default_rng(100 + s), tone_rad=4e-7)
        tone = (highpass_gain(5.0, HP) * 4e-7) ** 2 / 2
        assert c.excess_rad2 == pytest.approx(tone, rel=2 / np.sqrt(c.bins / ENBW))
    # a tone half as large stays under the threshold (no excess reported) and is still what the measured
    # excess, which σ books its share of, holds: within two spreads of the band's predicted power
    for s in range(3):
        c = _check(np.random.default_rng(100 + s), tone_rad=2e-7)
        tone = (highpass_gain(5.0, HP) * 2e-7) ** 2 / 2
        assert c.excess_rad2 == 0.0 and c.ratio > 1.0
        spread = 2 / np.sqrt(c.bins / ENBW) * (c.images_rad2 + c.knowledge_rad2)
        assert abs(c.measured_excess_rad2 - tone) < spread
        assert c.booked_rad2 == pytest.approx(c.images_share * c.measured_excess_rad2)
    # and the check ignores what lies outside its band: the same tone at 9 Hz (above 0.7 × 10 Hz)
    assert _check(np.random.default_rng(7), tone_rad=4e-7, tone_hz=9.0).excess_rad2 == 0.0


def test_tapered_power_of_rows_is_the_sum_of_each_rows():
    from restore.knowledge_check import tapered_power, tapered_power_rows

    x = np.random.default_rng(2).standard_normal((4, 900)).cumsum(axis=1)
    m = np.ones(900, bool)
    m[300:360] = False
    one_by_one = sum(tapered_power(r, m) for r in x)
    np.testing.assert_allclose(tapered_power_rows(x, m), one_by_one, rtol=1e-9, atol=1e-12 * one_by_one.max())
    assert not tapered_power_rows(x, np.zeros(900, bool)).any()
