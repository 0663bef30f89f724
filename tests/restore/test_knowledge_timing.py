"""The AOCS knowledge's latency measured from the pairs' differentials (restore.knowledge_timing), on known
delays."""
from types import SimpleNamespace

import numpy as np
import pytest

from restore.knowledge_prior import knowledge_response
from restore.knowledge_timing import LatencyEstimate, MIN_GAIN, knowledge_latency, latency_band
from restore.method_choice import predicted_differential

DT = 4e-4
N = 4000
TAUS = (0.0074, 0.0148, 0.0222)


def _attitude(t, amp=4e-6):
    """Lines in the band (1.3, 2.2 Hz) and one far above it (9 Hz, which the knowledge does not see)."""
    return amp * (np.sin(2 * np.pi * 2.2 * t + 0.3) + 0.5 * np.sin(2 * np.pi * 1.3 * t + 1.0)), \
        amp * 2.0 * np.sin(2 * np.pi * 9.0 * t + 0.7)


def _records(delay_s, *, noise_rad=4e-8, seed=1, pitch_only=False):
    """Records whose remaining differentials are those of θ − k, k the in-band attitude ``delay_s`` late."""
    rng = np.random.default_rng(seed)
    t = np.arange(N) * DT
    band, high = _attitude(t)
    late, _ = _attitude(t - delay_s)
    theta, k = band + high, late
    recs = {}
    for a in (("pitch",) if pitch_only else ("roll", "pitch")):
        diffs = np.array([predicted_differential(theta - k, tau, DT) + noise_rad * rng.standard_normal(N)
                          for tau in TAUS])
        diffs[1, 1000:1100] = np.nan   # a gap
        # the integration's estimate of θ − k: out of the band whole, in it shrunk to half towards the knowledge
        increment = high + 0.5 * (band - late)
        recs[a] = SimpleNamespace(taus=np.array(TAUS), diffs=diffs, sigmas=np.full((3, N), noise_rad),
                                  lags_s=np.zeros((3, N)), line_period_s=DT, previous=np.zeros(N),
                                  increment=increment)
    return recs, {a: k for a in recs}


@pytest.mark.parametrize("delay_ms", [5.0, 15.0, 30.0, -10.0])
def test_a_known_latency_is_measured_within_its_sigma(delay_ms):
    """Over a gap, under a 9 Hz line twice the band's that the knowledge does not see, with the integration's
    estimate shrunk to half in the band: the latency within 1 ms, its σ at most 3 ms, taken out shrunk by its σ."""
    recs, kn = _records(delay_ms * 1e-3)
    est = knowledge_latency(recs, kn, (0.8, 3.3))
    assert isinstance(est, LatencyEstimate) and est.axes == ("pitch", "roll")
    assert est.delay_s == pytest.approx(delay_ms * 1e-3, abs=1e-3)
    assert abs(est.delay_s - delay_ms * 1e-3) < 2 * est.sigma_s < 6e-3
    assert est.taken and est.applied_s == pytest.approx(est.delay_s * (1 - (est.sigma_s / est.delay_s) ** 2))


def test_no_latency_is_not_significant():
    for seed in (1, 2, 3):
        est = knowledge_latency(*_records(0.0, seed=seed), (0.8, 3.3))
        assert abs(est.delay_s) < 1e-3 and abs(est.delay_s) < est.sigma_s and not est.taken, est


def test_the_estimate_so_far_is_part_of_what_the_knowledge_misses():
    """The records' differentials remain from the knowledge *and* the estimate they started from: with half
    of θ − k already in ``previous``, the same latency is measured."""
    recs, kn = _records(0.015)
    alone = knowledge_latency(recs, kn, (0.8, 3.3))
    t = np.arange(N) * DT
    band, high = _attitude(t)
    late, _ = _attitude(t - 0.015)
    half = 0.5 * (band + high - late)
    for rec in recs.values():
        rec.previous = half
        rec.increment = rec.increment - half
        rec.diffs = rec.diffs - np.array([predicted_differential(half, tau, DT) for tau in TAUS])
    est = knowledge_latency(recs, kn, (0.8, 3.3))
    assert est.delay_s == pytest.approx(alone.delay_s, abs=1e-5)


def test_the_band_ends_where_the_knowledge_stops_seeing_the_attitude():
    def gain(f):
        return np.abs(knowledge_response(f, 4.0, 4, "butterworth_dephased"))
    lo, hi = latency_band(0.8, gain, top_hz=1250.0)
    assert lo == 0.8 and gain(np.array([hi]))[0] == pytest.approx(MIN_GAIN, abs=0.01)
    assert hi == pytest.approx(4.0 * (1 / MIN_GAIN ** 2 - 1) ** (1 / 8), rel=0.01)
    assert latency_band(3.0, gain, top_hz=1250.0) is None   # the high-pass above the knowledge's band
    assert knowledge_latency({}, {}, (0.8, 3.3)) is None
    recs, kn = _records(0.01)
    assert knowledge_latency(recs, kn, None) is None


def test_the_summary_says_a_latency_taken_out_and_nothing_otherwise():
    import json

    import xarray as xr

    from reports.summary import knowledge_timing_line

    est = LatencyEstimate(delay_s=0.0151, sigma_s=0.0021, band_hz=(0.8, 3.44), axes=("pitch", "roll"))
    ds = xr.Dataset(attrs={"knowledge_latency": json.dumps(est.to_dict())})
    line = knowledge_timing_line(ds)
    assert line is not None and "15.1 ± 2.1 ms late" in line and "pitch, roll at 0.80–3.44 Hz" in line
    assert f"advanced by {15.1 * (1 - (2.1 / 15.1) ** 2):.1f} ms" in line
    weak = LatencyEstimate(delay_s=0.002, sigma_s=0.0021, band_hz=(0.8, 3.44), axes=("pitch", "roll"))
    assert knowledge_timing_line(ds.assign_attrs(knowledge_latency=json.dumps(weak.to_dict()))) is None
    assert knowledge_timing_line(xr.Dataset()) is None and knowledge_timing_line(None) is None
    # a restoration.nc written before the shrinkage took a "significant" latency whole
    old = {k: v for k, v in est.to_dict().items() if k not in ("shrinkage", "applied_s", "taken")}
    line = knowledge_timing_line(ds.assign_attrs(knowledge_latency=json.dumps({**old, "significant": True})))
    assert line is not None and "advanced by that" in line
    assert knowledge_timing_line(ds.assign_attrs(knowledge_latency=json.dumps({**old, "significant": False}))) is None


def test_a_knowledge_whose_band_holds_only_its_noise_measures_no_latency():
    """No attitude in the band (phr_cmg's case): the knowledge's derivative there is its white noise's, so
    whatever the regression says is not a latency."""
    from scipy.interpolate import CubicSpline

    from restore.knowledge_prior import knowledge_noise_floor

    rng = np.random.default_rng(5)
    rate, noise = 64.0, 0.3e-6
    tk = np.arange(0, N * DT + 0.1, 1 / rate)
    t = np.arange(N) * DT
    k = CubicSpline(tk, noise * rng.standard_normal(tk.size))(t)
    diffs = np.array([predicted_differential(-k, tau, DT) + 4e-8 * rng.standard_normal(N) for tau in TAUS])
    recs = {"pitch": SimpleNamespace(taus=np.array(TAUS), diffs=diffs, sigmas=np.full((3, N), 4e-8),
                                     lags_s=np.zeros((3, N)), line_period_s=DT, previous=np.zeros(N),
                                     increment=np.zeros(N))}

    def psd(f):
        return knowledge_noise_floor(f, rate_hz=rate, noise_rad=noise)
    est = knowledge_latency(recs, {"pitch": k}, (2.0, 7.6), noise_psd=psd)
    assert est.signal_to_noise < 2.0 and not est.taken
    # the same regression with an attitude in the band: thousands of times the noise
    recs2, kn2 = _records(0.015, pitch_only=True)
    est2 = knowledge_latency(recs2, kn2, (0.8, 3.3), noise_psd=psd)
    assert est2.signal_to_noise > 100 and est2.taken


def test_sigma_holds_what_is_still_unknown_of_the_latency():
    """A 2.2 Hz line of amplitude A: a latency known to σ_δ leaves σ_δ · 2π · 2.2 · A / √2 of error (to the 5 %
    the band-pass of 3.5 cycles loses to its own leakage) where the
    restoration leans on the knowledge; one not taken out leaves its own size too; σ takes it in quadrature."""
    from restore.posterior import PosteriorSigma
    from restore.stages import knowledge_latency_errors, raise_by_knowledge_filter
    from simsat.attitude import AttitudeSeries

    t = np.arange(N) * DT
    amp = 4e-6
    k = amp * np.sin(2 * np.pi * 2.2 * t)
    product = SimpleNamespace(time=t, knowledge=AttitudeSeries(t, k, k, np.zeros(N)),
                              ds=SimpleNamespace(attrs={}))
    records = {"roll": SimpleNamespace(line_period_s=DT, highpass_hz=0.8)}
    rate = 2 * np.pi * 2.2 * amp / np.sqrt(2)
    taken = LatencyEstimate(delay_s=0.015, sigma_s=0.002, band_hz=(0.8, 3.3), axes=("roll",))
    assert knowledge_latency_errors(records, product, taken)["roll"] == pytest.approx(0.002 * rate, rel=0.08)
    # 1.5 σ: taken out shrunk to 1 − 1/1.5² of it, the rest left
    left = LatencyEstimate(delay_s=0.003, sigma_s=0.002, band_hz=(0.8, 3.3), axes=("roll",))
    assert left.taken and left.applied_s == pytest.approx(0.003 * (1 - 1 / 1.5 ** 2))
    assert knowledge_latency_errors(records, product, left)["roll"] == pytest.approx(
        np.hypot(0.003 / 1.5 ** 2, 0.002) * rate, rel=0.08)
    within = LatencyEstimate(delay_s=0.0015, sigma_s=0.002, band_hz=(0.8, 3.3), axes=("roll",))
    assert not within.taken
    assert knowledge_latency_errors(records, product, within)["roll"] == pytest.approx(
        np.hypot(0.0015, 0.002) * rate, rel=0.08)
    noise_only = LatencyEstimate(delay_s=0.003, sigma_s=0.002, band_hz=(0.8, 3.3), axes=("roll",),
                                 signal_to_noise=1.0)
    assert not noise_only.measured and knowledge_latency_errors(records, product, noise_only) == {}
    far = LatencyEstimate(delay_s=0.3, sigma_s=0.05, band_hz=(0.8, 3.3), axes=("roll",))
    assert not far.measured and knowledge_latency_errors(records, product, far) == {}
    assert knowledge_latency_errors(records, product, None) == {}
    sig = np.full(N, 1e-8)
    ps = PosteriorSigma(sigma=sig, noise_scale=1.0, samples=2, detrended_rms=1e-8, detrended_sigma=sig,
                        error_power=np.zeros(N // 2 + 1))
    out = raise_by_knowledge_filter({"roll": ps}, records, product, taken)["roll"]
    np.testing.assert_allclose(out.sigma, np.hypot(sig, knowledge_latency_errors(records, product, taken)["roll"]))
    np.testing.assert_array_equal(out.model_sigma, sig)


def test_a_latency_beyond_the_models_reach_or_not_common_to_the_axes_is_not_taken():
    """Beyond 1 rad at the band's top the estimate is not a latency the model measures; a latency on one axis
    only is not a time tag's."""
    far = LatencyEstimate(delay_s=0.765, sigma_s=0.143, band_hz=(0.4, 1.6), axes=("pitch", "roll"),
                          signal_to_noise=11.8)
    assert far.max_delay_s == pytest.approx(1.0 / (2 * np.pi * 1.6)) and not far.taken
    recs, kn = _records(0.015)
    est = knowledge_latency(recs, kn, (0.8, 3.3))
    assert est.axes_agree and set(est.axis_delays_s) == {"roll", "pitch"}
    for d, sg in est.axis_delays_s.values():
        assert d == pytest.approx(0.015, abs=1e-3) and sg > 0
    # roll's knowledge on time, pitch's 15 ms late: the joint estimate falls between, the axes disagree
    t = np.arange(N) * DT
    on_time, _ = _attitude(t)
    recs["roll"].diffs = recs["roll"].diffs + np.array(
        [predicted_differential(kn["roll"] - on_time, tau, DT) for tau in TAUS])
    recs["roll"].increment = recs["roll"].increment + (kn["roll"] - on_time)
    split = knowledge_latency(recs, {"roll": on_time, "pitch": kn["pitch"]}, (0.8, 3.3))
    # (each axis's own estimate is one linear step from the joint one: 2 ms of the first-order model's error)
    assert split.axis_delays_s["roll"][0] == pytest.approx(0.0, abs=2e-3)
    assert split.axis_delays_s["pitch"][0] == pytest.approx(0.015, abs=2e-3)
    assert not split.axes_agree and not split.taken, split


def _band_noise(rng, lo, hi, rms, n=N):
    """Gaussian noise band-limited to [lo, hi] Hz over ``n`` lines (not periodic over them), RMS ``rms``."""
    f = np.fft.rfftfreq(2 * n, DT)
    x = np.fft.irfft((rng.standard_normal(f.size) + 1j * rng.standard_normal(f.size)) * ((f >= lo) & (f <= hi)),
                     2 * n)[:n]
    return x / x.std() * rms


def test_the_spectral_sigma_is_the_estimates_spread_under_no_latency():
    """A regressor (an attitude a few hertz wide) and residuals independent of it: over 300 draws the RMS of
    :func:`spectral_sigma` is within ×1.3 of the spread of ``Σ w x y / Σ w x²`` itself."""
    from scipy.signal.windows import tukey

    from restore.knowledge_timing import spectral_sigma

    rng = np.random.default_rng(0)
    band = (0.8, 3.3)
    w = tukey(N, 0.2)
    x = _band_noise(rng, *band, 1.0)
    est, sig = [], []
    for _ in range(300):
        y = _band_noise(rng, *band, 1.0)
        d = float(np.sum(w * x * y) / np.sum(w * x * x))
        est.append(d)
        sig.append(spectral_sigma([y], [x], [w], d, DT, band))
    ratio = float(np.sqrt(np.mean(np.square(sig))) / np.std(est))
    assert 1 / 1.3 < ratio < 1.3, ratio


def test_a_knowledge_with_an_independent_error_and_no_latency_takes_little():
    """No latency; the knowledge's error in the band (the images' low-frequency error looks the same to the
    regression) independent of the attitude, both random and a few hertz wide. Blocks of 0.2 s of such series
    are not independent, and the jackknife alone was ~2.8 × too small there (5 seeds of 40 past 4 of it); with
    the spectral σ the estimates still spread 1.5 × their σ over these 60 seeds. The advance taken is, in RMS,
    under 0.8 of the raw estimates' (0.58 for an exact σ, 0.76 for estimates spread 1.5 × it; 1 for taking the
    estimate whole) and at most 1.25 of the σ (1.14 at a 1.5 × spread)."""
    applied, sigma, raw = [], [], []
    for seed in range(60):
        rng = np.random.default_rng(seed)
        recs, kn = {}, {}
        for a in ("roll", "pitch"):
            band_part, high = _band_noise(rng, 0.8, 3.3, 4e-6), _band_noise(rng, 6.0, 40.0, 4e-6)
            k = band_part + _band_noise(rng, 0.5, 8.0, 2e-7)
            theta = band_part + high
            diffs = np.array([predicted_differential(theta - k, tau, DT) + 4e-8 * rng.standard_normal(N)
                              for tau in TAUS])
            recs[a] = SimpleNamespace(taus=np.array(TAUS), diffs=diffs, sigmas=np.full((3, N), 4e-8),
                                      lags_s=np.zeros((3, N)), line_period_s=DT, previous=np.zeros(N),
                                      increment=high + 0.5 * (band_part - k))
            kn[a] = k
        est = knowledge_latency(recs, kn, (0.8, 3.3))
        applied.append(est.applied_s)
        sigma.append(est.sigma_s)
        raw.append(est.delay_s if est.measured else 0.0)
    applied, sigma, raw = np.array(applied), np.array(sigma), np.array(raw)
    rms = float(np.sqrt(np.mean(applied ** 2)))
    assert rms < 0.8 * np.sqrt(np.mean(raw ** 2)), (applied, raw)
    assert rms < 1.25 * np.sqrt(np.mean(sigma ** 2)), (applied, sigma)


@pytest.mark.parametrize("true_sigmas", [0.0, 1.0, 2.0, 2.5, 3.0, 3.5, 5.0, 10.0])
def test_the_shrunk_latency_errs_less_than_a_threshold_where_it_matters(true_sigmas):
    """Estimates drawn about a known latency with their σ (an exact σ): the advance taken errs, in mean square,
    by at most 1.6 σ² at any latency (the posterior mean's risk; a 3 σ all-or-nothing rule's reaches 5 σ² at
    3 σ), by no more than the threshold's plus 0.35 σ² anywhere, and by less than it from 1 σ to 4 σ."""
    rng = np.random.default_rng(7)
    sigma = 2e-3
    delays = true_sigmas * sigma + sigma * rng.standard_normal(4000)
    applied = np.array([LatencyEstimate(delay_s=float(d), sigma_s=sigma, band_hz=(0.8, 3.3), axes=("roll",)).applied_s
                        for d in delays])
    threshold = np.where(np.abs(delays) >= 3 * sigma, delays, 0.0)
    risk = np.mean((applied - true_sigmas * sigma) ** 2) / sigma ** 2
    risk_threshold = np.mean((threshold - true_sigmas * sigma) ** 2) / sigma ** 2
    assert risk < 1.6 and risk < risk_threshold + 0.35, (risk, risk_threshold)
    if 1.0 <= true_sigmas <= 4.0:
        assert risk < risk_threshold, (risk, risk_threshold)
