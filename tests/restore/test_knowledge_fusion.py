"""The knowledge's band taken where the images' estimate ran astray (restore.knowledge_fusion), on analytic cases."""
import numpy as np
import pytest
from scipy.fft import irfft

from restore.knowledge_fusion import (FUSION_THRESHOLD, band_part, expected_band_power, fuse_with_knowledge,
                                      fusion_weight, knowledge_band_variance, local_mean_square)
from restore.knowledge_prior import knowledge_noise_floor
from restore.synthesis import highpass_gain

DT = 4e-4
N = 4000
HP = 2.0
CUT = 10.0
NOISE = 0.3e-6
RATE = 64.0
PX = 4e-6


def _target(seed, n=N, extra=None):
    """A stationary draw of the knowledge's error θ − k (its white noise, spline-read at the lines), high-passed
    as the estimate is: what a restoration that holds its band returns there. ``extra(f)``: a two-sided PSD added."""
    rng = np.random.default_rng(seed)
    m = 2 * n
    f = np.fft.rfftfreq(m, DT)
    psd = knowledge_noise_floor(f, rate_hz=RATE, noise_rad=NOISE) + (0.0 if extra is None else extra(f))
    amp = m * np.sqrt(2.0 * psd * highpass_gain(f, HP) ** 2 * (f[1] - f[0]) / 4.0)
    amp[0] = 0.0
    return irfft(amp * (rng.standard_normal(f.size) + 1j * rng.standard_normal(f.size)), m)[:n]


def _fuse(x, **kw):
    return fuse_with_knowledge(x, dt=DT, highpass_hz=HP, cutoff_hz=CUT, noise_rad=NOISE, rate_hz=RATE, **kw)


def test_the_band_variance_is_the_knowledge_noise_through_the_band_and_the_draws_have_it():
    top = 0.7 * CUT
    v = knowledge_band_variance(noise_rad=NOISE, rate_hz=RATE, dt=DT, highpass_hz=HP, top_hz=top)
    # white two-sided σ²/f_k over the band 2-7 Hz (one-sided 2σ²/f_k) within the gains' roll-offs
    f = np.linspace(0, 1250, 200001)
    g = (1 - 2.0 ** (-0.5 * (f / HP) ** 2)) * 2.0 ** (-0.5 * (f / top) ** 2)
    assert v == pytest.approx(np.trapezoid(2 * NOISE ** 2 / RATE * g ** 2, f), rel=0.05)   # spline response ≈ 1 here
    # the draws' band power, in the record's interior, is that variance
    x = np.array([np.mean(band_part(_target(s), dt=DT, top_hz=top)[1000:3000] ** 2) for s in range(40)])
    assert np.mean(x) == pytest.approx(v, rel=0.15)
    e = expected_band_power(np.ones(N, bool), dt=DT, highpass_hz=HP, top_hz=top, window_lines=250,
                            noise_rad=NOISE, rate_hz=RATE)
    assert np.median(e[1000:3000]) == pytest.approx(v, rel=0.25)


def test_fusion_weight_is_the_minimum_variance_share_above_the_threshold_brought_in_without_a_step():
    w = fusion_weight([0.5, 4.9, 7.5, 10.1, 100.0], np.array([1.0, 1.0, 1.0, 1.0, 2.0]))
    assert w.tolist() == [0.0, 0.0, pytest.approx(0.5 * (1 - 1 / 7.5)), pytest.approx(1 - 1 / 10.1),
                          pytest.approx(0.98)]
    assert FUSION_THRESHOLD == 10.0
    # continuous across the ramp's ends (no step in the restored angle where a line crosses them)
    r = np.linspace(0.0, 30.0, 30001)
    assert np.max(np.abs(np.diff(fusion_weight(r, 1.0)))) < 1e-3
    assert np.all(fusion_weight([np.nan, 3.0, 20.0], np.array([1.0, 0.0, -1.0])) == 0.0)
    # the combination's variance (1-w)² (P - v) + w² v is w v, below both estimates' variances
    p, v = 40.0, 1.0
    ww = fusion_weight([p], v)[0]
    assert (1 - ww) ** 2 * (p - v) + ww ** 2 * v == pytest.approx(ww * v)
    assert ww * v < min(v, p - v)


def test_an_estimate_that_holds_its_band_is_left_bit_for_bit():
    fused_lines = 0
    for seed in range(12):
        x = _target(seed)
        x[1500:1700] = np.nan                                              # a gap: two edges
        out, fu = _fuse(x)
        fused_lines += fu.lines_fused
        if not fu.lines_fused:
            np.testing.assert_array_equal(out, x)
    assert fused_lines < 0.01 * 12 * N                                     # the threshold's false alarms


def test_a_drift_at_the_record_end_takes_the_knowledge_and_sigma_says_so():
    """0.3 px of drift over the last 300 lines (band offsets integrated at a record end): the knowledge's band
    takes over there and the error falls to the knowledge's own band level; the middle is untouched."""
    x0 = _target(3)
    t = np.arange(N)
    drift = np.where(t > N - 300, -0.3 * PX * ((t - (N - 300)) / 300.0) ** 2, 0.0)
    out, fu = _fuse(x0 + drift)
    end = slice(N - 200, N)
    v = knowledge_band_variance(noise_rad=NOISE, rate_hz=RATE, dt=DT, highpass_hz=HP, top_hz=0.7 * CUT)
    before = np.sqrt(np.mean(drift[end] ** 2))
    after = np.sqrt(np.mean((out - x0)[end] ** 2))
    assert fu.lines_fused > 100 and np.all(fu.weight[:N - 700] == 0)
    np.testing.assert_array_equal(out[:N - 700], x0[:N - 700])
    assert after < 0.35 * before and after < 3 * np.sqrt(v)
    assert np.all(fu.added_rad2[fu.weight > 0] > 0) and np.all(fu.added_rad2 <= fu.knowledge_band_rad2)


def test_a_drift_before_a_gap_is_taken_too_and_the_far_side_is_untouched():
    """A cloud from line 2400 to 2900: 0.25 px of drift over the 250 lines before it (a gap edge)."""
    x0 = _target(5)
    x0[2400:2900] = np.nan
    t = np.arange(N)
    drift = np.where((t >= 2150) & (t < 2400), 0.25 * PX * ((t - 2150) / 250.0) ** 2, 0.0)
    out, fu = _fuse(x0 + drift)
    edge = slice(2250, 2400)
    assert np.sqrt(np.mean((out - x0)[edge] ** 2)) < 0.35 * np.sqrt(np.mean(drift[edge] ** 2))
    assert np.all(np.isnan(out[2400:2900])) and np.all(fu.weight[2400:2900] == 0)
    np.testing.assert_array_equal(out[3000:], x0[3000:])


def test_attitude_the_knowledge_filter_misses_is_not_taken_for_a_drift():
    """A 1 px line at 3 Hz above a 2 Hz knowledge: the target itself holds it and the restoration's prior says so;
    the band's filter near the record's ends passes more of it, which the expected power per line holds."""
    cut = 2.0
    hp = 0.4

    def line(f):
        return np.where(np.abs(f - 3.0) < 0.3, (1.0 * PX) ** 2 / 2 / 0.6 / 2, 0.0)   # two-sided: a 1 px sine (0.5 px²) over ±0.3 Hz

    rng = np.random.default_rng(0)
    t = np.arange(N) * DT
    x = 1.0 * PX * np.sin(2 * np.pi * 3.0 * t + rng.uniform(0, 6.28))
    f = np.fft.rfftfreq(8192, DT)
    prior = (f, knowledge_noise_floor(f, rate_hz=RATE, noise_rad=NOISE) + line(f))
    kw = dict(dt=DT, highpass_hz=hp, cutoff_hz=cut, noise_rad=NOISE, rate_hz=RATE)
    out, fu = fuse_with_knowledge(x, prior=prior, **kw)
    assert fu.lines_fused == 0
    np.testing.assert_array_equal(out, x)
    # without the prior too: the line is fitted out of the band's test and kept whole
    out, blind = fuse_with_knowledge(x, **kw)
    assert blind.lines_fused == 0 and blind.lines_kept_hz == (pytest.approx(3.0, abs=1e-3),)
    np.testing.assert_array_equal(out, x)


def test_no_band_or_no_knowledge_noise_changes_nothing():
    x = _target(1)
    out, fu = fuse_with_knowledge(x, dt=DT, highpass_hz=6.0, cutoff_hz=CUT, noise_rad=NOISE, rate_hz=RATE)
    assert fu is None and out is x or np.array_equal(out, x)
    out, fu = fuse_with_knowledge(x, dt=DT, highpass_hz=HP, cutoff_hz=CUT, noise_rad=0.0, rate_hz=RATE)
    assert fu is None and np.array_equal(out, x)


def test_local_mean_square_skips_missing_lines():
    x = np.array([1.0, np.nan, 3.0, np.nan, np.nan, np.nan, np.nan])
    m = local_mean_square(x, 3)
    assert m[1] == pytest.approx(5.0) and np.isnan(m[5])


def test_a_causal_knowledges_error_in_its_own_band_is_not_taken_for_the_estimate_running_astray():
    """A 4 Hz causal AOCS filter lags a 2.2 Hz line by 86°: the knowledge's error θ − k there is the line's own
    size, and a restoration that holds its band returns it. Against the knowledge's error PSD the product gives
    (``stages.knowledge_error_prior``: its filter's error from its own periodogram, plus its noise) no line is
    fused; against the variance of that error given the knowledge (its noise alone, what a conditioned record's
    prior holds there) every line is."""
    from types import SimpleNamespace

    from restore.knowledge_prior import knowledge_response
    from restore.stages import knowledge_error_prior

    cut, hp, f0, amp = 4.0, 0.8, 2.2, 3e-6
    t = np.arange(N) * DT
    theta = amp * np.sin(2 * np.pi * f0 * t + 0.4)
    g = knowledge_response(f0, cut, 4, "butterworth_causal")
    k = amp * abs(g) * np.sin(2 * np.pi * f0 * t + 0.4 + np.angle(g))
    k = k + np.random.default_rng(3).standard_normal(N) * 0.02e-6
    e = theta - k
    assert np.std(e) > 0.9 * np.std(theta)
    product = SimpleNamespace(ds=SimpleNamespace(attrs={"knowledge_cutoff_hz": cut, "knowledge_filter_order": 4,
                                                        "knowledge_filter": "butterworth_causal"}),
                              knowledge_noise=(NOISE, RATE))
    fr = np.fft.rfftfreq(N, DT)
    floor = knowledge_noise_floor(fr, rate_hz=RATE, noise_rad=NOISE)
    record = SimpleNamespace(spectrum=SimpleNamespace(freq=fr, psd=floor), line_period_s=DT)
    prior = knowledge_error_prior(product, k, record)
    i = np.argmin(abs(prior[0] - f0))
    assert prior[1][i] > 1e3 * floor[i]
    kw = dict(dt=DT, highpass_hz=hp, cutoff_hz=cut, noise_rad=NOISE, rate_hz=RATE)
    _, fu = fuse_with_knowledge(e, prior=prior, **kw)
    assert fu is not None and fu.lines_fused == 0
    _, fu_given = fuse_with_knowledge(e, prior=(fr, floor), **kw)
    assert fu_given.lines_fused > 0.9 * N
    # where the filter passes less than half the attitude (above ~1.15 × the cut-off) the ceiling would divide
    # the knowledge's noise by |F|²: the record's prior stands there
    weak = np.abs(knowledge_response(prior[0], cut, 4, "butterworth_causal")) < 0.5
    assert weak.any() and prior[0][weak].min() > cut
    np.testing.assert_array_equal(prior[1][weak], np.interp(prior[0][weak], fr, floor))
    # without the filter in the product, the record's prior stands
    bare = SimpleNamespace(ds=SimpleNamespace(attrs={"knowledge_cutoff_hz": cut}), knowledge_noise=(NOISE, RATE))
    np.testing.assert_array_equal(knowledge_error_prior(bare, k, record)[1], floor)


def test_a_drift_under_strong_lines_above_the_band_is_taken_and_the_lines_kept_whole():
    """Under a 2 Hz knowledge the estimate holds the 1 px lines at 3.3 and 5.1 Hz it misses (and the restoration's
    prior says so), plus 0.3 px of quadratic drift over the first 1200 lines, high-passed as the estimate is. A
    1.4 Hz band filter passes 15 % of the 3.3 Hz line, and near the start, where it sees one side only, more:
    counted as the knowledge's error, that blinded the test. With the lines fitted out first, the knowledge's
    expected band error is its noise's, the band's share of the drift is taken (what is left is the drift above
    the band's top), and the lines are left whole."""
    from restore.synthesis import highpass_nan

    cut, hp = 2.0, 0.4
    t = np.arange(N) * DT
    lines = PX * (np.sin(2 * np.pi * 3.3 * t + 1.0) + np.sin(2 * np.pi * 5.1 * t + 2.5))

    def line_psd(f):
        return sum(np.where(np.abs(f - f0) < 0.3, PX ** 2 / 2 / 0.6 / 2, 0.0) for f0 in (3.3, 5.1))

    x0 = _target(7) + lines
    idx = np.arange(N)
    drift = highpass_nan(np.where(idx < 1200, -0.3 * PX * ((1200 - idx) / 1200.0) ** 2, 0.0), dt=DT, cutoff_hz=hp)
    f = np.fft.rfftfreq(8192, DT)
    prior = (f, knowledge_noise_floor(f, rate_hz=RATE, noise_rad=NOISE) + line_psd(f))
    out, fu = fuse_with_knowledge(x0 + drift, dt=DT, highpass_hz=hp, cutoff_hz=cut, noise_rad=NOISE, rate_hz=RATE,
                                  prior=prior)
    assert sorted(round(v, 2) for v in fu.lines_kept_hz) == [3.3, 5.1]
    v = knowledge_band_variance(noise_rad=NOISE, rate_hz=RATE, dt=DT, highpass_hz=hp, top_hz=0.7 * cut)
    assert np.all(fu.knowledge_band_rad2 < 10 * v)               # the lines' leakage is not the knowledge's error
    start = slice(0, 250)

    def rms(y):
        return np.sqrt(np.mean(y[start] ** 2))

    above = drift - band_part(drift, dt=DT, top_hz=0.7 * cut)   # what a band fusion cannot take
    assert np.all(fu.weight[:250] > 0.9)
    assert rms(out - x0) < 0.4 * rms(drift) and rms(out - x0) < rms(above) + 3 * np.sqrt(v)
    # the lines are whole: past the drift the fused estimate is the estimate
    np.testing.assert_array_equal(out[2000:], (x0 + drift)[2000:])


def test_lines_far_above_the_band_are_left_to_the_prior():
    """Only lines up to LINES_UP_TO × the band's top are fitted out: beyond, the band's filter passes nothing of
    them inside the record, and near an end the prior's draws hold what it passes (a fit would trade that for
    its misfit). Under a 2 Hz knowledge (top 1.4 Hz, lines up to 8.4 Hz) a 3.3 Hz line is kept whole, a 20 Hz one
    is not fitted (the band holding only the knowledge's noise, a residual peak may be: harmless), and the estimate, holding both and nothing else, is left bit for bit."""
    from restore.knowledge_fusion import LINES_UP_TO

    cut, hp = 2.0, 0.4
    assert LINES_UP_TO * 0.7 * cut < 20.0
    t = np.arange(N) * DT
    x = _target(2) + PX * (np.sin(2 * np.pi * 3.3 * t + 0.3) + np.sin(2 * np.pi * 20.0 * t + 1.1))

    def line_psd(f):
        return sum(np.where(np.abs(f - f0) < 0.3, PX ** 2 / 2 / 0.6 / 2, 0.0) for f0 in (3.3, 20.0))

    f = np.fft.rfftfreq(8192, DT)
    prior = (f, knowledge_noise_floor(f, rate_hz=RATE, noise_rad=NOISE) + line_psd(f))
    out, fu = fuse_with_knowledge(x, dt=DT, highpass_hz=hp, cutoff_hz=cut, noise_rad=NOISE, rate_hz=RATE,
                                  prior=prior)
    assert 3.3 in [round(v, 1) for v in fu.lines_kept_hz]
    assert max(fu.lines_kept_hz) <= LINES_UP_TO * 0.7 * cut      # the 20 Hz line is not among them
    assert fu.lines_fused == 0
    np.testing.assert_array_equal(out, x)
