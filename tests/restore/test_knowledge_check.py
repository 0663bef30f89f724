"""The σ's check against the smoothed AOCS knowledge (restore.knowledge_check), on analytic cases."""
import numpy as np
import pytest

from restore.knowledge_check import (KnowledgeCheck, check_band, excess_variance, filter_error_power,
                                     knowledge_check, line_power, smoothed_knowledge_at, tapered_power,
                                     without_strong_lines, ENBW, MIN_BINS)
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


def test_a_strong_line_outside_the_band_is_taken_out_of_its_power():
    """White noise plus a 20 µrad sine 5.6 bins above a three-bin band (6 Hz over 1.6 s): the taper and the
    trend put the sine's share in the band, several times the noise's power there; without it the band holds the
    noise's power again (within 10 %), and a sine inside the band or beside it stays."""
    dt, n = 4e-4, 4000
    t = np.arange(n) * dt
    f = np.fft.rfftfreq(n, dt)
    band = (f >= 1.2) & (f <= 2.6)
    ok = np.ones(n, bool)
    for seed in range(3):
        noise = np.random.default_rng(seed).standard_normal(n) * 2e-8
        line = 2e-5 * np.sin(2 * np.pi * 6.0 * t + seed)
        alone = tapered_power(noise, ok)[band].sum()
        assert tapered_power(noise + line, ok)[band].sum() > 3 * alone
        clean = without_strong_lines(noise + line, ok, band)
        assert tapered_power(clean, ok)[band].sum() == pytest.approx(alone, rel=0.1)
        assert np.std(clean - noise) < 1e-3 * 2e-5            # the line, and only the line, went
    # a line the band holds, and one within three bins of it, are the band's own content
    for f0 in (1.9, 3.9):
        x = np.random.default_rng(9).standard_normal(n) * 2e-8 + 2e-5 * np.sin(2 * np.pi * f0 * t)
        np.testing.assert_array_equal(without_strong_lines(x, ok, band), x)
    # gaps are zeros, as tapered_power reads them
    g = np.where(t > 0.8, np.random.default_rng(4).standard_normal(n) * 2e-8 + 2e-5 * np.sin(2 * np.pi * 6.0 * t),
                 np.nan)
    out = without_strong_lines(g, np.isfinite(g), band)
    assert np.all(out[t <= 0.8] == 0) and np.std(out[t > 0.8]) < 5e-8


def _short_record_check(rng, tone_rad=0.0):
    """A 1.6 s record under a 4 Hz knowledge (three bins in the band, 1.25–2.5 Hz): a 1.5 Hz and a 6 Hz sine of
    20 µrad, the restored angle as the pipeline builds it, ``k + HP(ê) − LP(k − k_s)``, with the images' high-pass
    on a grid that never meets the record's ends (the MAP's periodic grid: the sines through the high-pass's
    gain) and their estimate ``ê = θ − k`` + white error + an optional 1.9 Hz tone their model does not know."""
    dt, n, cutoff, hp = 4e-4, 4000, 4.0, 0.8
    t = np.arange(n) * dt
    ts = np.arange(int(n * dt * RATE) + 1) / RATE
    sines = [(1.5, 2e-5, rng.uniform(0, 2 * np.pi)), (6.0, 2e-5, rng.uniform(0, 2 * np.pi))]
    k = sum(knowledge_gain(f, cutoff, ORDER) * a * np.sin(2 * np.pi * f * ts + p) for f, a, p in sines)
    k = k + rng.standard_normal(ts.size) * SIGMA_K
    sm = knowledge_smoothing(ts, k, SIGMA_K)
    k_lines = AttitudeSeries(ts, k, k, k).at(np.clip(t, ts[0], ts[-1]))[0]
    ks = smoothed_knowledge_at(sm, k, t)
    noise_k = k_lines - sum(knowledge_gain(f, cutoff, ORDER) * a * np.sin(2 * np.pi * f * t + p) for f, a, p in sines)
    error = rng.standard_normal(n) * 2e-8 + tone_rad * np.sin(2 * np.pi * 1.9 * t + 0.3)
    hp_e = sum((1 - knowledge_gain(f, cutoff, ORDER)) * highpass_gain(f, hp) * a * np.sin(2 * np.pi * f * t + p)
               for f, a, p in sines) + highpass_nan(error - noise_k, dt=dt, cutoff_hz=hp)
    restored = k_lines + hp_e - (k_lines - ks - highpass_nan(k_lines - ks, dt=dt, cutoff_hz=hp))
    draws = np.mean([tapered_power(highpass_nan(rng.standard_normal(n) * 2e-8, dt=dt, cutoff_hz=hp)
                                   + lowband(sm.error_draw(rng), ts, t, line_period_s=dt, highpass_hz=hp),
                                   np.ones(n, bool)) for _ in range(8)], axis=0)
    return knowledge_check(restored, ks, k_lines, draws, sm, line_period_s=dt, highpass_hz=hp, cutoff_hz=cutoff,
                           order=ORDER, kind="butterworth_zero_phase", noise_rad=SIGMA_K, rate_hz=RATE)


def test_three_bins_under_a_strong_line_above_the_cutoff_raise_no_false_alarm_and_find_a_real_error():
    """On 20 seeds with nothing to find the three-bin check stays under its threshold on at least 19 (the 6 Hz
    line's leakage into the band, 3.7–6.1 × the predictions before it was taken out, is gone); with a 0.5 µrad
    tone at 1.9 Hz in the images' estimate, which their prediction does not know, it fires on every seed and the
    excess it reports is the tone's mean square through the high-pass within ± 50 % (the knowledge's error in the
    same bins adds to it or takes from it); σ books the images' share of it."""
    quiet = [_short_record_check(np.random.default_rng(s)) for s in range(20)]
    assert quiet[0].bins == 3 and quiet[0].band_hz == pytest.approx((1.25, 2.5))
    assert sum(c.excess_rad2 > 0 for c in quiet) <= 1
    tone = (highpass_gain(1.9, 0.8) * 5e-7) ** 2 / 2
    for s in range(5):
        c = _short_record_check(np.random.default_rng(50 + s), tone_rad=5e-7)
        assert c.excess_rad2 > 0
        assert 0.5 * tone < c.excess_rad2 < 1.5 * tone
        assert c.booked_rad2 == pytest.approx(c.images_share * c.measured_excess_rad2)
