"""The ceiling the AOCS knowledge puts on the prior (restore.knowledge_prior), on analytic cases."""
import numpy as np
import pytest
from scipy.signal import butter, sosfiltfilt

from restore.integration.wiener import integrate_wiener
from restore.knowledge_prior import knowledge_gain, knowledge_psd_ceiling
from restore.posterior import simulated_differentials

DT = 4e-4


def test_gain_is_that_of_a_zero_phase_butterworth():
    fs = 1 / DT
    sos = butter(4, 10.0, fs=fs, output="sos")
    n = 1 << 16
    x = np.zeros(n)
    x[n // 2] = 1.0
    h = np.abs(np.fft.rfft(sosfiltfilt(sos, x)))
    f = np.fft.rfftfreq(n, DT)
    for fk in (2.0, 10.0, 15.0, 30.0):
        k = np.argmin(np.abs(f - fk))
        assert h[k] == pytest.approx(knowledge_gain(f[k], 10.0, 4), abs=2e-3)
    assert knowledge_gain(10.0, 10.0, 4) == pytest.approx(0.5)
    with pytest.raises(ValueError, match="cutoff_hz"):
        knowledge_gain(1.0, 0.0, 4)


def test_ceiling_of_a_line_well_inside_the_band_is_its_tiny_leakage():
    """A 1 Hz line known through a 10 Hz AOCS: the knowledge's error there is (1 − G) × the line, ~1e-8 of it."""
    n = 8000
    t = np.arange(n) * DT
    a = 4e-6
    k = a * np.sin(2 * np.pi * 1.0 * t) * knowledge_gain(1.0, 10.0, 4)
    f, c = knowledge_psd_ceiling(k, DT, cutoff_hz=10.0, order=4, rate_hz=64.0, noise_rad=0.0)
    band = (f > 0.5) & (f < 1.5)
    var_line = 2 * np.sum(c[band]) * (f[1] - f[0])
    assert var_line == pytest.approx((a * (1 - knowledge_gain(1.0, 10.0, 4))) ** 2 / 2, rel=0.5)
    assert np.all(np.isinf(c[f > 10.0 * 6]))  # far above the cut-off the knowledge says nothing


def test_ceiling_has_the_white_noise_floor():
    f, c = knowledge_psd_ceiling(np.zeros(4000), DT, cutoff_hz=10.0, order=4, rate_hz=50.0, noise_rad=1e-6)
    assert c[5] == pytest.approx(1e-12 / 50.0)


def test_a_differential_drift_no_longer_becomes_a_record_long_drift_of_the_estimate():
    """A slow bias of one pair's differentials (as large as the noise per line) beside a 60 Hz line: without
    the ceiling the estimate books it as a slow attitude drift; with it (AOCS at 10 Hz) it does not."""
    n = 4000
    rng = np.random.default_rng(0)
    taus = [7.4e-3, 14.8e-3, 22.2e-3]
    t = np.arange(n + 100) * DT
    theta = 1e-6 * np.sin(2 * np.pi * 60 * t + 0.3)
    valid = np.ones((3, n), bool)
    d = simulated_differentials(theta, taus, np.zeros((3, n)), valid, DT) + 1e-7 * rng.standard_normal((3, n))
    d[2] += 1e-7 * ((np.arange(n) / n) ** 2 - 1 / 3)  # slow systematic error on the longest pair
    knowledge = 0.3e-6 / 8 * rng.standard_normal(n)  # an AOCS knowledge of no jitter, with its noise
    ceiling = knowledge_psd_ceiling(knowledge, DT, cutoff_hz=10.0, order=4, rate_hz=64.0, noise_rad=0.3e-6 / 8)

    def slow_error(est):
        e = est - theta[:n]
        e -= e.mean()
        return np.std(np.convolve(e, np.ones(400) / 400, mode="valid"))  # what is left below ~6 Hz

    free = integrate_wiener(list(d), taus, DT)
    bounded = integrate_wiener(list(d), taus, DT, psd_ceiling=ceiling)
    assert slow_error(bounded) < 0.1 * slow_error(free)
    e_b, e_f = bounded - theta[:n], free - theta[:n]
    assert np.std(e_b) < np.std(e_f)


def test_ceiling_is_checked():
    with pytest.raises(ValueError, match="psd_ceiling"):
        integrate_wiener([np.random.default_rng(0).standard_normal(100)], [7.4e-3], DT,
                         psd_ceiling=(np.array([2.0, 1.0]), np.array([1.0, 1.0])))


def test_causal_knowledge_response_matches_the_filter_run_forward():
    """The causal Butterworth's complex response against sosfilt measured on sines, and the ceiling uses it."""
    from scipy.signal import butter, sosfilt

    from restore.knowledge_prior import knowledge_response

    fs, fc = 2000.0, 10.0
    sos = butter(4, fc, fs=fs, output="sos")
    t = np.arange(0, 6.0, 1 / fs)
    for f in (2.0, 8.0, 15.0):
        y = sosfilt(sos, np.sin(2 * np.pi * f * t))[t > 3.0]
        tt = t[t > 3.0]
        c = np.linalg.lstsq(np.column_stack([np.sin(2 * np.pi * f * tt), np.cos(2 * np.pi * f * tt)]), y,
                            rcond=None)[0]
        measured = complex(c[0], c[1])
        h = knowledge_response(f, fc, 4, "butterworth_causal")
        assert abs(measured - h) < 0.01, (f, measured, h)
    zp = knowledge_response([2.0, 10.0], fc, 4)
    assert np.allclose(zp, [knowledge_gain(2.0, fc, 4), 0.5]) and np.allclose(zp.imag, 0)
    with pytest.raises(ValueError, match="unknown knowledge filter"):
        knowledge_response(1.0, fc, 4, "kalman")
    # the causal filter's phase lag leaves more error in band than its modulus alone would say
    k = np.sin(2 * np.pi * 3.0 * np.arange(4000) * 1e-3) * 1e-6
    f1, c_zero = knowledge_psd_ceiling(k, 1e-3, cutoff_hz=fc, order=4, rate_hz=50.0, noise_rad=0.0)
    _, c_causal = knowledge_psd_ceiling(k, 1e-3, cutoff_hz=fc, order=4, rate_hz=50.0, noise_rad=0.0,
                                        kind="butterworth_causal")
    i = np.argmin(np.abs(f1 - 3.0))
    assert c_causal[i] > 10 * c_zero[i]


def test_anchoring_removes_an_offset_and_a_drift_the_images_cannot_see():
    from restore.stages import anchor_on_star_tracker
    from simsat.attitude import AttitudeSeries

    t = np.arange(4000) * 4e-4
    truth = 1e-6 * np.sin(2 * np.pi * 60 * t)
    restored = {"roll": truth + 20e-6 + 3e-6 * t, "pitch": truth.copy(), "yaw": np.zeros_like(t)}
    restored["roll"][:100] = np.nan                     # an unrestored stretch stays unrestored
    ts = np.arange(0.0, 1.6, 0.25)
    st = AttitudeSeries(ts, 1e-6 * np.sin(2 * np.pi * 60 * ts), 1e-6 * np.sin(2 * np.pi * 60 * ts), np.zeros_like(ts))
    out, anchored = anchor_on_star_tracker(restored, t, st, ("roll", "pitch"))
    assert anchored
    m = np.isfinite(out["roll"])
    assert not m[:100].any()
    assert np.abs(out["roll"][m] - truth[m]).max() < 1e-9      # offset and slope both gone
    assert np.abs(out["pitch"] - truth).max() < 1e-9
    # one sample only: the offset, not the slope
    one = AttitudeSeries(ts[3:4], st.roll[3:4], st.pitch[3:4], st.yaw[3:4])
    out1, _ = anchor_on_star_tracker(restored, t, one, ("roll",))
    e = out1["roll"][m] - truth[m]
    assert abs(e[np.argmin(np.abs(t[m] - ts[3]))]) < 1e-8 and np.ptp(e) > 3e-6


def test_anchoring_sigma_matches_the_spread_of_the_anchored_slope():
    """The σ the anchoring adds (slope fitted on noisy star-tracker samples) against Monte Carlo."""
    from restore.stages import anchor_on_star_tracker, anchoring_sigma
    from simsat.attitude import AttitudeSeries

    t = np.arange(4000) * 4e-4
    ts = np.arange(-0.05, 1.6, 0.25)
    noise = 1e-6
    restored = {"roll": np.zeros_like(t), "pitch": np.zeros_like(t), "yaw": np.zeros_like(t)}
    rng = np.random.default_rng(1)
    sq = np.zeros_like(t)
    n_draws = 400
    for _ in range(n_draws):
        st = AttitudeSeries(ts, noise * rng.standard_normal(ts.size), np.zeros_like(ts), np.zeros_like(ts))
        out, _ = anchor_on_star_tracker(restored, t, st, ("roll",))
        e = out["roll"] - out["roll"].mean()          # the metric's convention: mean removed
        sq += e ** 2
    actual = np.sqrt(sq / n_draws)
    st = AttitudeSeries(ts, np.zeros_like(ts), np.zeros_like(ts), np.zeros_like(ts))
    pred = anchoring_sigma(restored, t, st, ("roll",), noise_rad=noise)["roll"]
    # analytic: slope σ = noise / √Σ(tᵢ − t̄)² over the samples inside the record, times |t − t̄|
    inside = ts[(ts >= t[0]) & (ts <= t[-1])]
    np.testing.assert_allclose(pred, noise / np.sqrt(np.sum((inside - inside.mean()) ** 2)) * np.abs(t - t.mean()))
    assert abs(np.sqrt(np.mean(pred ** 2)) / np.sqrt(np.mean(actual ** 2)) - 1.0) < 0.1
    # without the noise recorded, the fit's residuals estimate it (here: exact samples, no residual → 0)
    assert np.allclose(anchoring_sigma(restored, t, st, ("roll",), noise_rad=None)["roll"], 0.0)
    # mean-only anchoring (one sample) adds nothing the metric sees
    one = AttitudeSeries(ts[2:3], ts[2:3] * 0, ts[2:3] * 0, ts[2:3] * 0)
    assert np.all(anchoring_sigma(restored, t, one, ("roll",), noise_rad=noise)["roll"] == 0.0)
    assert anchoring_sigma(restored, t, None, ("roll",), noise_rad=noise) == {}


def test_knowledge_crossover_follows_the_formula_and_the_knowledge_noise():
    """f* = 1 / (2π √(E_k Σ τ_j² / N_j)); noisier knowledge → lower crossover; no colour or no spec → None."""
    from types import SimpleNamespace

    from restore.posterior import PosteriorSigma
    from restore.stages import knowledge_crossover_hz

    dt, n = 4e-4, 4000
    taus = np.array([7.4e-3, 14.8e-3, 22.2e-3])
    noise_std = np.array([0.3e-6, 0.4e-6, 0.35e-6])
    rec = SimpleNamespace(line_period_s=dt, diffs=np.zeros((3, n)), taus=taus,
                          spectrum=SimpleNamespace(noise_std=noise_std))
    colour = np.ones((3, n // 2 + 1))
    colour[:, : 100] = 4.0                               # 4× the white power below 62.5 Hz (100 bins)
    ps = PosteriorSigma(sigma=np.zeros(n), noise_scale=1.0, samples=8, noise_colour=colour)

    def product(noise_urad, rate=64.0):
        return SimpleNamespace(knowledge_noise=(noise_urad * 1e-6, rate))

    e_k = (0.3e-6) ** 2 / 64.0
    n_j = noise_std ** 2 * dt * 4.0
    expect = 1.0 / (2 * np.pi * np.sqrt(e_k * np.sum(taus ** 2 / n_j)))
    got = knowledge_crossover_hz({"roll": rec}, {"roll": ps}, product(0.3), 2.0)
    assert got == pytest.approx(expect, rel=1e-12)
    # 4× the knowledge noise (16× its power): the crossover 4× lower
    assert knowledge_crossover_hz({"roll": rec}, {"roll": ps}, product(1.2), 2.0) == pytest.approx(expect / 4)
    # read above the coloured band, the white level: crossover lower by 2
    assert knowledge_crossover_hz({"roll": rec}, {"roll": ps}, product(0.3), 100.0) == pytest.approx(expect / 2)
    no_colour = PosteriorSigma(sigma=np.zeros(n), noise_scale=1.0, samples=8)
    assert knowledge_crossover_hz({"roll": rec}, {"roll": no_colour}, product(0.3), 2.0) is None
    assert knowledge_crossover_hz({"roll": rec}, {"roll": ps}, SimpleNamespace(knowledge_noise=None), 2.0) is None


def test_spline_response_is_the_cardinal_cubic_splines():
    """White samples at 64 Hz, spline-interpolated to the lines: their PSD is σ²/f_s |H|² (+ small aliases)."""
    from scipy.interpolate import CubicSpline

    from restore.knowledge_prior import knowledge_noise_floor, spline_response

    rate, sigma = 64.0, 1.0
    rng = np.random.default_rng(4)
    n_s = 64 * 400
    ts = np.arange(n_s) / rate
    t = np.arange(int(n_s / rate / DT) - 10) * DT
    psd = 0.0
    for _ in range(4):
        x = CubicSpline(ts, sigma * rng.standard_normal(n_s))(t)
        psd = psd + np.abs(np.fft.rfft(x)) ** 2 * DT / t.size / 4
    f = np.fft.rfftfreq(t.size, DT)
    assert spline_response(0.0, rate) == pytest.approx(1.0)
    floor = knowledge_noise_floor(f, rate_hz=rate, noise_rad=sigma)
    for lo, hi in ((1, 4), (8, 12), (14, 18), (24, 30)):
        band = (f >= lo) & (f < hi)
        ratio = psd[band].mean() / floor[band].mean()
        assert 1.0 - 0.05 <= ratio < 1.0 + 0.05 + (0.25 if lo > 20 else 0.02)   # aliases only add, near f_s/2
    assert np.all(floor[f > rate / 2] == 0.0)
    with pytest.raises(ValueError, match="rate_hz"):
        spline_response(1.0, 0.0)


def test_the_knowledge_noise_floor_lifts_a_prior_the_differentials_left_too_low():
    """Differentials of an attitude that is the knowledge's white noise alone: the estimate from them puts
    (near) nothing at low frequencies; with the floor the prior holds at least σ_k²/f_k there (what it does
    to the accuracy is the benches' business: on this synthetic case it is within the seeds' scatter)."""
    from scipy.interpolate import CubicSpline

    from restore.knowledge_prior import knowledge_noise_floor

    n, rate, sk = 4000, 64.0, 0.3e-6
    rng = np.random.default_rng(7)
    taus = [7.4e-3, 14.8e-3, 22.2e-3]
    ts = np.arange(-8, int((n + 100) * DT * rate) + 8) / rate
    theta = CubicSpline(ts, sk * rng.standard_normal(ts.size))(np.arange(n + 100) * DT)
    valid = np.ones((3, n), bool)
    d = simulated_differentials(theta, taus, np.zeros((3, n)), valid, DT) + 0.2e-6 * rng.standard_normal((3, n))
    f, c = knowledge_psd_ceiling(np.zeros(n), DT, cutoff_hz=10.0, order=4, rate_hz=rate, noise_rad=sk)
    floor = knowledge_noise_floor(f, rate_hz=rate, noise_rad=sk)
    plain = integrate_wiener(list(d), taus, DT, psd_ceiling=(f, c), return_details=True)
    lifted = integrate_wiener(list(d), taus, DT, psd_ceiling=(f, c, floor), return_details=True)
    fg = lifted.spectrum.freq
    low = (fg > 1.0) & (fg < 10.0)
    assert np.all(lifted.spectrum.psd[low] >= np.interp(fg[low], f, floor) * (1 - 1e-9))
    assert np.mean(plain.spectrum.psd[low]) < np.mean(lifted.spectrum.psd[low])

    # a malformed floor is refused
    with pytest.raises(ValueError, match="floor"):
        integrate_wiener(list(d), taus, DT, psd_ceiling=(f, c, -floor))


def test_above_ceiling_marks_where_the_differentials_show_more_than_the_attitude_can_have():
    """A slow error on every pair (a band's error common to a line) under a 10 Hz AOCS: the estimate
    reaches the ceiling at low frequencies, and knowledge_proves_excess says so; white noise alone does not."""
    from types import SimpleNamespace

    from restore.stages import knowledge_proves_excess

    n = 4000
    rng = np.random.default_rng(2)
    taus = [7.4e-3, 14.8e-3, 22.2e-3]
    t = np.arange(n) * DT
    noise = 0.1e-6 * rng.standard_normal((3, n))
    drift = 0.2e-6 * np.sin(2 * np.pi * 1.3 * t + 0.4)        # the band error: 0.05 px at 1.3 Hz
    f, c = knowledge_psd_ceiling(np.zeros(n), DT, cutoff_hz=10.0, order=4, rate_hz=64.0, noise_rad=0.3e-6)
    seen = integrate_wiener(list(noise + drift), taus, DT, psd_ceiling=(f, c), return_details=True)
    clean = integrate_wiener(list(noise), taus, DT, psd_ceiling=(f, c), return_details=True)

    def rec(res):
        return SimpleNamespace(spectrum=SimpleNamespace(freq=res.spectrum.freq,
                                                        above_ceiling=res.spectrum.above_ceiling))

    assert knowledge_proves_excess(rec(seen), 0.9, 2.0)
    assert not knowledge_proves_excess(rec(clean), 0.9, 2.0)
    # nothing known: not lowered on that evidence
    assert knowledge_proves_excess(SimpleNamespace(spectrum=None), 0.9, 2.0)
    no_ceiling = integrate_wiener(list(noise), taus, DT, return_details=True)
    assert knowledge_proves_excess(rec(no_ceiling), 0.9, 2.0)


def test_an_axis_takes_its_crossover_unless_the_knowledge_proves_its_differentials_wrong_there():
    """Two axes with the same noise: the one whose prior reached the ceiling between the crossover and the
    high-pass keeps the high-pass; the other is lowered to its crossover; none above the high-pass."""
    from types import SimpleNamespace

    from restore.posterior import PosteriorSigma
    from restore.restorer import Restorer
    from restore.settings import RestorationSettings
    from restore.stages import knowledge_crossover_hz

    dt, n = 4e-4, 4000
    taus = np.array([7.4e-3, 14.8e-3, 22.2e-3])
    freq = np.fft.rfftfreq(n, dt)

    def rec(excess_at):
        above = np.zeros(freq.size, bool)
        if excess_at is not None:
            above[np.argmin(np.abs(freq - excess_at))] = True
        return SimpleNamespace(line_period_s=dt, diffs=np.zeros((3, n)), taus=taus,
                               spectrum=SimpleNamespace(noise_std=np.full(3, 0.3e-6), freq=freq, above_ceiling=above))

    ps = PosteriorSigma(sigma=np.zeros(n), noise_scale=1.0, samples=8, noise_colour=np.full((3, n // 2 + 1), 3.0))
    product = SimpleNamespace(knowledge_noise=(0.3e-6, 64.0))
    r = Restorer(RestorationSettings(highpass_hz=2.0))
    records = {"roll": rec(None), "pitch": rec(1.8), "yaw": rec(2.5)}
    fx = knowledge_crossover_hz({"roll": records["roll"]}, {"roll": ps}, product, 2.0)
    assert 0 < fx < 2.0
    got = r._axes_to_lower(records, {"roll": ps, "pitch": ps, "yaw": ps}, product)
    assert got == {"roll": pytest.approx(fx), "yaw": pytest.approx(fx)}   # yaw's excess is above the high-pass
    # a knowledge so good that the crossover lies above the high-pass: nothing lowered
    assert r._axes_to_lower(records, {"roll": ps}, SimpleNamespace(knowledge_noise=(0.3e-9, 64.0))) == {}
