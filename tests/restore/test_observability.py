"""Observability: the attitude power no pair sees, and the Wiener floor, on analytic spectra."""
import numpy as np
import pytest

from restore.observability import band_power, fused_snr, observability

TAUS = [7.4e-3, 14.8e-3, 22.2e-3]
DT = 4e-4


def _grid(n=3700):
    """A grid holding 1/7.4 ms exactly (3700 × 0.4 ms = 200 × 7.4 ms): the blind frequencies fall on bins."""
    return np.fft.rfftfreq(n, DT)


def _tone_psd(f, freq_hz, amplitude):
    """Two-sided PSD of a sine of ``amplitude`` on the grid: A²/4 per side, in the nearest bin."""
    s = np.zeros(f.size)
    s[np.argmin(np.abs(f - freq_hz))] = amplitude ** 2 / 4 / (f[1] - f[0])
    return s


def test_snr_is_zero_where_every_pair_is_blind():
    f = np.array([1 / 7.4e-3, 2 / 7.4e-3, 60.0])
    snr = fused_snr(f, np.ones(3), 1e-6, TAUS, DT)
    assert snr[0] == pytest.approx(0, abs=1e-20) and snr[1] == pytest.approx(0, abs=1e-20) and snr[2] > 1


def test_a_tone_on_the_common_blind_frequency_is_unobservable_and_a_visible_one_is_not():
    f = _grid()
    a_blind, a_seen = 1e-6, 2e-6
    k = np.argmin(np.abs(f - 1 / 7.4e-3))
    assert f[k] == pytest.approx(1 / 7.4e-3, rel=1e-12)
    s = _tone_psd(f, f[k], a_blind) + _tone_psd(f, 60.0, a_seen)
    obs = observability(f, s, 0.02e-6, TAUS, DT, highpass_hz=2.0)
    assert obs.unobservable_band[k] and not obs.unobservable_band[np.argmin(np.abs(f - 60.0))]
    # the blind tone's variance A²/2 is all in the unobservable band
    assert obs.unobservable_rms_rad == pytest.approx(a_blind / np.sqrt(2), rel=1e-9)
    # the floor: the blind tone almost whole, the visible one reduced by 1 / (1 + SNR)
    snr60 = fused_snr(np.array([f[np.argmin(np.abs(f - 60.0))]]), np.array([s.max()]), 0.02e-6, TAUS, DT)[0]
    expected = np.sqrt(a_blind ** 2 / 2 / (1 + obs.snr[k]) + a_seen ** 2 / 2 / (1 + snr60))
    assert obs.floor_rms_rad == pytest.approx(expected, rel=1e-9)
    assert obs.floor_rms_rad < 1.01 * a_blind / np.sqrt(2)


def test_below_the_highpass_nothing_is_counted():
    f = _grid()
    s = _tone_psd(f, 0.5, 1e-6)
    obs = observability(f, s, 0.02e-6, TAUS, DT, highpass_hz=2.0)
    assert obs.unobservable_rms_rad == 0.0 and obs.floor_rms_rad == 0.0
    assert band_power(f, s, np.ones(f.size, bool)) == pytest.approx(0.5e-12, rel=1e-12)


def test_below_the_scene_offset_band_s_top_a_band_offset_is_an_attitude_to_every_pair():
    # Bands at along-track places x_k (delays τ_AB = (x_A − x_B) / v): an offset c x_k between the bands gives
    # pair AB the differential c v τ_AB, an attitude θ at f gives (e^{2πifτ_AB} − 1) θ. Fitted by the attitude
    # (least squares, written out here), the offset leaves at most OFFSET_MISFIT of itself up to the band's
    # top, and more above it; the top sits near 1 / (2π τ_max).
    from restore.observability import OFFSET_MISFIT, offset_misfit, scene_offset_band

    taus = np.array([0.0074, 0.0222, 0.0148])
    lo, hi = scene_offset_band(taus, 2.0)
    assert lo == 2.0 and 0.8 < hi * 2 * np.pi * taus.max() < 1.2
    offset = taus.astype(complex)                    # c v τ_AB, any scale

    def misfit(f):
        g = np.exp(2j * np.pi * f * taus) - 1
        theta = np.vdot(g, offset) / np.vdot(g, g)
        return np.linalg.norm(offset - theta * g) / np.linalg.norm(offset)

    fs = np.linspace(0.05, hi, 25)
    assert np.allclose(offset_misfit(taus, fs), [misfit(f) for f in fs])
    assert all(misfit(f) <= OFFSET_MISFIT + 1e-9 for f in fs)
    assert misfit(1.05 * hi) > OFFSET_MISFIT and misfit(3 * hi) > 3 * OFFSET_MISFIT
    # one pair: any offset is an attitude at every frequency below its first blind one
    assert np.allclose(offset_misfit([0.01], [1.0, 30.0, 70.0]), 0.0)
    # the knowledge reaches the top: nothing is left to the images alone; unknown cut-off or delays: no band
    assert scene_offset_band(taus, 10.0) is None
    assert scene_offset_band(taus, None) is None and scene_offset_band([], 2.0) is None


def test_a_band_offset_towards_the_sun_splits_between_pitch_and_roll_by_its_azimuth_from_the_track():
    from restore.observability import sun_offset_shares

    assert sun_offset_shares(0.0) == pytest.approx({"roll": 0.0, "pitch": 1.0})
    assert sun_offset_shares(90.0) == pytest.approx({"roll": 1.0, "pitch": 0.0}, abs=1e-12)
    for az, track in [(150.0, 0.0), (37.0, 12.0), (200.0, -20.0)]:
        s = sun_offset_shares(az, track)
        assert s["roll"] + s["pitch"] == pytest.approx(1.0)
        assert s["pitch"] == pytest.approx(np.cos(np.radians(az - track)) ** 2)
    # the sun behind or ahead is the same line of offset
    assert sun_offset_shares(30.0) == pytest.approx(sun_offset_shares(210.0))


def test_the_wiener_error_of_a_wrong_prior():
    from restore.observability import wiener_error

    st, u = np.array([2.0, 2.0, 2.0, 2.0]), np.array([0.5, 0.5, 3.0, 0.0])
    # the right prior: the floor S / (1 + S u); no prior: the whole attitude; no information: the whole attitude
    np.testing.assert_allclose(wiener_error(st, st, u)[:3], st[:3] / (1 + st[:3] * u[:3]))
    np.testing.assert_allclose(wiener_error(st, np.zeros(4), u), st)
    assert wiener_error(st, st, u)[3] == pytest.approx(2.0)
    # any other prior does worse than the right one: k = Sa u / (1 + Sa u), (1 − k)² S + k² / u
    sa = np.array([0.1, 20.0, 0.5, 1.0])
    k = sa[:3] * u[:3] / (1 + sa[:3] * u[:3])
    np.testing.assert_allclose(wiener_error(st, sa, u)[:3], (1 - k) ** 2 * st[:3] + k ** 2 / u[:3])
    assert np.all(wiener_error(st, sa, u)[:3] > wiener_error(st, st, u)[:3])


def _phr_prior(level, notch_value, line=None):
    """A prior on phr_cmg's pairs: ``level`` everywhere, ``notch_value`` in the notches the spectrum estimate
    bridges (``notch_mask``), optionally a line; noise 0.05 px-ish per line."""
    from restore.integration.spectrum import notch_mask

    dt, taus, sigma = 0.4e-3, np.array([7.4e-3, 22.2e-3, 14.8e-3]), 2e-7
    f = np.fft.rfftfreq(6000, dt)
    s = np.full(f.size, float(level))
    poor = notch_mask(f, taus, np.full(3, sigma ** 2 * dt))
    s[poor] = notch_value
    if line is not None:
        s[np.argmin(abs(f - line))] = 1e-12
    return f, s, sigma, taus, dt, poor


def test_a_notch_bridged_below_its_sides_continuum_is_found_with_the_error_it_adds():
    from restore.observability import notch_continuum, wiener_error

    f, s, sigma, taus, dt, poor = _phr_prior(1e-14, 1e-17)
    found = notch_continuum(f, s, sigma, taus, dt, highpass_hz=2.0)
    assert found and all(n.sides == pytest.approx(1e-14) and n.bridged == pytest.approx(1e-17) for n in found)
    first = found[0]
    assert 129.0 < first.band_hz[0] < 135.1 < first.band_hz[1] < 141.0     # the common blind frequency's notch
    # the error the bridge adds, written out: Wiener on the bridge minus Wiener on the continuum, over the notch
    inside = (f >= first.band_hz[0]) & (f <= first.band_hz[1])
    u = fused_snr(f, np.ones(f.size), sigma, taus, dt)
    full = np.full(f.size, 1e-14)
    extra = wiener_error(full, s, u) - wiener_error(full, full, u)
    assert first.missing_rms_rad == pytest.approx(np.sqrt(band_power(f, extra, inside)), rel=1e-9)
    assert first.missing_rms_rad > 0
    # bridged at the continuum: nothing found; a line-only spectrum (zero beside the notch): nothing found
    f, s, sigma, taus, dt, _ = _phr_prior(1e-14, 1e-14)
    assert notch_continuum(f, s, sigma, taus, dt) == []
    f, s, sigma, taus, dt, _ = _phr_prior(0.0, 0.0, line=126.8)
    assert notch_continuum(f, s, sigma, taus, dt) == []
    # below the high-pass a notch is the AOCS knowledge's
    f, s, sigma, taus, dt, _ = _phr_prior(1e-14, 1e-17)
    assert notch_continuum(f, s, sigma, taus, dt, highpass_hz=f[-1] + 1.0) == []


def _lagged_knowledge(f0, kind, amp=4e-6, n=4000, dt=4e-4, cutoff=4.0):
    """The knowledge of a sine attitude through the recorded filter (its gain and phase at ``f0``), and the
    restored angle's error below a 0.8 Hz high-pass were the knowledge taken for the attitude there: the low-pass
    complement of ``(1 − F) θ``, its linear trend removed."""
    from restore.knowledge_prior import knowledge_response
    from restore.synthesis import highpass_gain

    t = np.arange(n) * dt
    u = np.linspace(-1, 1, n)
    g = complex(np.atleast_1d(knowledge_response(np.array([f0]), cutoff, 4, kind))[0])
    k = amp * abs(g) * np.sin(2 * np.pi * f0 * t + np.angle(g) + 0.3)
    h = 1 - g
    e = float(1 - highpass_gain(f0, 0.8)) * abs(h) * amp * np.sin(2 * np.pi * f0 * t + np.angle(h) + 0.3)
    e = e - np.polyval(np.polyfit(u, e, 1), u)
    return k, float(np.sqrt(np.mean(e ** 2)))


@pytest.mark.parametrize("f0", [0.6, 1.0, 1.6, 2.2])
def test_a_causal_filters_lag_below_the_highpass_is_estimated_from_the_knowledge(f0):
    """A 4 Hz causal 4th-order Butterworth lags a sine at 0.6–2.2 Hz by 0.10 s: below a 0.8 Hz high-pass the
    knowledge, taken for the attitude, errs by the low-pass complement of ``(1 − F) θ``; estimated from the
    knowledge alone within 40 % (the record holds 1–3.5 cycles). A zero-phase filter's error there is nothing."""
    from restore.observability import knowledge_filter_error_below

    k, truth = _lagged_knowledge(f0, "butterworth_causal")
    est = knowledge_filter_error_below(k, 4e-4, highpass_hz=0.8, cutoff_hz=4.0, order=4, kind="butterworth_causal")
    assert est == pytest.approx(truth, rel=0.4)
    kz, _ = _lagged_knowledge(f0, "butterworth_zero_phase")
    assert knowledge_filter_error_below(kz, 4e-4, highpass_hz=0.8, cutoff_hz=4.0, order=4,
                                        kind="butterworth_zero_phase") < 1e-3 * 4e-6
    assert knowledge_filter_error_below(k, 4e-4, highpass_hz=0.0, cutoff_hz=4.0, order=4,
                                        kind="butterworth_causal") == 0.0


def test_sigma_takes_the_knowledge_filters_error_below_the_highpass_and_the_report_says_it():
    """stages.raise_by_knowledge_filter adds the estimate in quadrature on every line (model_sigma keeps the σ
    before it); a zero-phase knowledge adds nothing worth a digit; a product without its filter, nothing. The
    report's line names the lag and the figure when it reaches 0.01 px."""
    from types import SimpleNamespace

    import xarray as xr

    from reports.summary import knowledge_filter_line
    from restore.observability import knowledge_filter_error_below
    from restore.posterior import PosteriorSigma
    from restore.stages import raise_by_knowledge_filter
    from simsat.attitude import AttitudeSeries

    n, dt = 4000, 4e-4
    t = np.arange(n) * dt
    k, _ = _lagged_knowledge(1.0, "butterworth_causal")
    attrs = {"knowledge_cutoff_hz": 4.0, "knowledge_filter_order": 4, "knowledge_filter": "butterworth_causal"}
    product = SimpleNamespace(ds=SimpleNamespace(attrs=attrs), time=t,
                              knowledge=AttitudeSeries(t, np.zeros(n), k, np.zeros(n)))
    records = {"pitch": SimpleNamespace(line_period_s=dt, highpass_hz=0.8)}
    sig = np.full(n, 1e-8)
    ps = PosteriorSigma(sigma=sig, noise_scale=1.0, samples=2, detrended_rms=1e-8, detrended_sigma=sig,
                        error_power=np.zeros(n // 2 + 1))
    out = raise_by_knowledge_filter({"pitch": ps}, records, product)
    e = knowledge_filter_error_below(k, dt, highpass_hz=0.8, cutoff_hz=4.0, order=4, kind="butterworth_causal")
    assert e > 1e-7
    np.testing.assert_allclose(out["pitch"].sigma, np.sqrt(sig ** 2 + e ** 2), rtol=1e-12)
    assert out["pitch"].detrended_rms == pytest.approx(np.sqrt(1e-16 + e ** 2))
    np.testing.assert_array_equal(out["pitch"].model_sigma, sig)
    kz, _ = _lagged_knowledge(1.0, "butterworth_zero_phase")
    zero = SimpleNamespace(ds=SimpleNamespace(attrs={**attrs, "knowledge_filter": "butterworth_zero_phase"}), time=t,
                           knowledge=AttitudeSeries(t, np.zeros(n), kz, np.zeros(n)))
    assert raise_by_knowledge_filter({"pitch": ps}, records, zero)["pitch"].detrended_rms == pytest.approx(1e-8, rel=1e-3)
    bare = SimpleNamespace(ds=SimpleNamespace(attrs={"knowledge_cutoff_hz": 4.0}), time=t, knowledge=product.knowledge)
    assert raise_by_knowledge_filter({"pitch": ps}, records, bare)["pitch"] is ps
    # the report's line, from restoration.nc's knowledge and high-pass (a 4 µrad pixel)
    import json
    rs = xr.Dataset({"knowledge_pitch": ("time", k)}, coords={"time": t},
                    attrs={"pixel_ifov_rad": 4e-6,
                           "integration": json.dumps({"pitch": {"line_period_s": dt, "highpass_hz": 0.8}})})
    line = knowledge_filter_line(attrs, rs, ["pitch"])
    assert line is not None and "0.10 s" in line and f"pitch {e / 4e-6:.3f} px" in line
    rz = rs.assign(knowledge_pitch=("time", kz))
    assert knowledge_filter_line({**attrs, "knowledge_filter": "butterworth_zero_phase"}, rz, ["pitch"]) is None
    # a restoration that took the causal phase out first (restore.knowledge_dephasing): the line reads the
    # knowledge it used, as the zero-phase filter of gain |F| it became; the lag is gone from it
    from restore.knowledge_dephasing import dephase_samples

    kd = dephase_samples(k, dt, cutoff_hz=4.0, order=4)
    rd = rs.assign(knowledge_dephasing_pitch=("time", kd - k))
    ed = knowledge_filter_error_below(kd, dt, highpass_hz=0.8, cutoff_hz=4.0, order=4, kind="butterworth_dephased")
    assert ed < 0.2 * e
    line_d = knowledge_filter_line(attrs, rd, ["pitch"])
    assert line_d is None if ed / 4e-6 < 0.01 else ("lags" not in line_d and f"pitch {ed / 4e-6:.3f} px" in line_d)
