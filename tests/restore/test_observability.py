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
