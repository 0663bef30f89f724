"""The level of each blind notch estimated over its whole width (restore.integration.spectrum.notch_levels) and
the MAP's prior raised to it (restore.axis_integration._notch_prior)."""
import numpy as np
import pytest

import restore.axis_integration as axis_integration
from restore.axis_integration import integrate_axis, notch_residual
from restore.integration.spectrum import notch_levels, notch_mask
from restore.integration.wiener import integrate_wiener

DT = 1 / 2700.0
STEPS = (20, 40, 60)            # delays in lines: every pair is blind at 135 Hz and its multiples
TAUS = np.array(STEPS) * DT
N = 4400
N_FFT = 6600
SD = 1e-8                        # the differentials' white noise [rad]


def _differentials(theta, rng, sd=SD):
    return [theta[k:k + N] - theta[:N] + rng.normal(0.0, sd, N) for k in STEPS]


def _white(level, rng, top_hz=None):
    """An attitude whose two-sided PSD is ``level`` [rad²/Hz] at every frequency (up to ``top_hz``, 0 above)."""
    x = rng.normal(0.0, np.sqrt(level / DT), N + max(STEPS))
    if top_hz is None:
        return x
    spec = np.fft.rfft(x)
    return np.fft.irfft(np.where(np.fft.rfftfreq(x.size, DT) <= top_hz, spec, 0.0), n=x.size)


def test_notch_levels_noise_alone_is_rarely_detected():
    hits = 0
    for seed in range(20):
        rng = np.random.default_rng(seed)
        levels = notch_levels(_differentials(np.zeros(N + 100), rng), TAUS, DT, n_fft=N_FFT, noise_std=SD)
        assert len(levels) >= 8                         # 135, 270, ... 1215 Hz below Nyquist (1350 Hz)
        hits += any(nl.detected for nl in levels)
        # the threshold is the noise's: a few standard deviations of the estimate, never 0
        assert all(nl.threshold > 0 for nl in levels)
    assert hits <= 2                                    # false_alarm = 0.01 per call


def test_notch_levels_of_a_flat_attitude_spectrum_are_its_level():
    """A white attitude (PSD S0 everywhere) seen through the pairs: every notch reads S0 (the estimate is
    unbiased: its mean over seeds within 3 of its own standard errors of S0)."""
    s0 = 1e-16
    rows = []
    for seed in range(24):
        rng = np.random.default_rng(100 + seed)
        levels = notch_levels(_differentials(_white(s0, rng), rng), TAUS, DT, n_fft=N_FFT, noise_std=SD)
        assert all(nl.detected for nl in levels)
        rows.append([nl.level for nl in levels[:4]])
    rows = np.asarray(rows)
    mean, sem = rows.mean(0), rows.std(0) / np.sqrt(rows.shape[0])
    assert np.all(np.abs(mean - s0) < 3 * sem), (mean, sem)
    assert np.all(sem < 0.2 * s0)


def test_notch_levels_band_and_bins_are_the_notch_mask():
    rng = np.random.default_rng(3)
    levels = notch_levels(_differentials(_white(1e-16, rng), rng), TAUS, DT, n_fft=N_FFT, noise_std=SD,
                          low_hz=200.0)
    f = np.fft.rfftfreq(N_FFT, DT)
    poor = notch_mask(f, TAUS, np.full(3, SD**2 * DT))
    assert levels[0].band_hz[0] > 200.0                 # the 135 Hz notch is below low_hz
    for nl in levels:
        a, b = nl.bins
        assert poor[a:b].all() and not poor[a - 1] and (b == poor.size or not poor[b])
        assert nl.band_hz == (f[a], f[b - 1])
        blind = 135.0 * round(0.5 * (nl.band_hz[0] + nl.band_hz[1]) / 135.0)
        assert nl.band_hz[0] < blind <= nl.band_hz[1]


def test_notch_levels_bad_input():
    d = [np.zeros(N)] * 3
    with pytest.raises(ValueError, match="n_fft"):
        notch_levels(d, TAUS, DT, n_fft=N - 1, noise_std=SD)
    with pytest.raises(ValueError, match="noise_std"):
        notch_levels(d, TAUS, DT, n_fft=N_FFT, noise_std=0.0)
    with pytest.raises(ValueError, match="false_alarm"):
        notch_levels(d, TAUS, DT, n_fft=N_FFT, noise_std=SD, false_alarm=1.0)


def _line_beside_the_notch(rng):
    """A strong line on the 135 Hz notch's flank (outside it) and a weak white floor, no noise floor issue."""
    t = np.arange(N + max(STEPS)) * DT
    return 2e-6 * np.sin(2 * np.pi * 127.3 * t + 0.4) + _white(1e-19, rng)


def test_notch_residual_takes_out_a_line_beside_the_notch():
    """Raw, the line's skirt leaks into the notch's flanks and reads as a level there; in what the MAP leaves
    (its in-notch part added back) it does not."""
    rng = np.random.default_rng(7)
    d = _differentials(_line_beside_the_notch(rng), rng)
    raw = notch_levels(d, TAUS, DT, n_fft=N_FFT, noise_std=SD)[0]
    assert raw.detected                                # the skirt, not the attitude
    res = integrate_wiener(d, TAUS, DT, noise_std=SD, return_details=True)
    prior = axis_integration._prior_of(res.spectrum, 3)
    assert res.theta_grid.size == N_FFT or 2 * (prior.freq.size - 1) == res.theta_grid.size
    r = notch_residual(res, d, TAUS, DT, None, prior)
    clean = notch_levels(r, TAUS, DT, n_fft=res.theta_grid.size, noise_std=prior.noise_std)[0]
    assert not clean.detected and clean.level < 0.05 * raw.level


def _map_of_a_continuum(s0, seed):
    """Differentials of a flat continuum of level ``s0`` (seed ``40 + seed``), the Wiener MAP of them, its prior
    and the MAP grid's length."""
    rng = np.random.default_rng(40 + seed)
    d = _differentials(_white(s0, rng), rng)
    res = integrate_wiener(d, TAUS, DT, noise_std=SD, return_details=True)
    return d, res, axis_integration._prior_of(res.spectrum, 3), res.theta_grid.size


def test_notch_residual_keeps_what_the_bridge_explained():
    """With a prior in the notch near the true level, the MAP explains part of the notch's flanks: the residual
    alone would read less than the level, the residual with the field's in-notch part added back reads it."""
    s0 = 1e-16
    lv = []
    for seed in range(6):
        d, res, prior, m = _map_of_a_continuum(s0, seed)
        a, b = notch_levels(d, TAUS, DT, n_fft=m, noise_std=SD)[0].bins
        prior.psd[a:b] = s0                          # the bridge at the true level
        res = integrate_wiener(d, TAUS, DT, noise_std=SD, psd=(prior.freq, prior.psd), return_details=True)
        kept = notch_levels(notch_residual(res, d, TAUS, DT, None, prior), TAUS, DT, n_fft=m, noise_std=SD)[0]
        left = notch_levels([x - p for x, p in zip(d, res.predicted)], TAUS, DT, n_fft=m, noise_std=SD)[0]
        lv.append((kept.level, left.level))
    kept, left = np.asarray(lv).mean(0)
    assert 0.7 * s0 < kept < 1.4 * s0
    assert left < 0.6 * s0


def test_integrate_axis_raises_a_notch_bridged_below_a_continuum(monkeypatch):
    """A flat continuum to 400 Hz whose gated estimate bridges the 135 Hz notch at 0 (this seed): the MAP's
    prior in the notch takes the notch's own level, and the error at the notch's flanks falls."""
    s0 = 1e-16
    rng = np.random.default_rng(12)
    theta = _white(s0, rng, top_hz=400.0)
    d = _differentials(theta, rng, sd=3e-8)

    def run(raise_factor):
        monkeypatch.setattr(axis_integration, "NOTCH_RAISE", raise_factor)
        return integrate_axis(d, list(TAUS), DT, method="wiener", sigmas=None, highpass_hz=0.0)

    bridged, raised = run(np.inf), run(2.0)
    f = bridged.spectrum.freq
    inside = (f > 128) & (f < 142)
    assert np.median(bridged.spectrum.psd[inside]) < 0.1 * s0
    assert 0.5 * s0 < np.median(raised.spectrum.psd[inside]) < 2 * s0
    # outside the notches nothing changed
    out = ~notch_mask(f, TAUS, raised.spectrum.noise_std**2 * DT)
    np.testing.assert_array_equal(raised.spectrum.psd[out], bridged.spectrum.psd[out])

    def notch_error(est):
        e = np.nan_to_num(est - (theta[:N] - theta[:N].mean()))
        spec = np.fft.rfft(e - e.mean())
        fe = np.fft.rfftfreq(N, DT)
        flanks = (np.abs(fe - 135.0) > 1.5) & (np.abs(fe - 135.0) < 7.0)
        return np.sqrt(np.sum(np.abs(spec[flanks]) ** 2))

    assert notch_error(raised.theta) < 0.5 * notch_error(bridged.theta)


def test_the_raised_notches_are_recorded_and_said(monkeypatch):
    """The options record each notch raised (band, level); the terminal's line gives the RMS the level holds
    over the notch; a frozen rerun with those options is the same filter (the record's key is not the method's)."""
    import json

    import xarray as xr

    from reports.summary import notch_level_line

    s0 = 1e-16
    rng = np.random.default_rng(12)
    theta = _white(s0, rng, top_hz=400.0)
    d = _differentials(theta, rng, sd=3e-8)
    monkeypatch.setattr(axis_integration, "NOTCH_RAISE", 2.0)
    res = integrate_axis(d, list(TAUS), DT, method="wiener", highpass_hz=0.0)
    raised = res.options["notch_levels"]
    lo, hi, level = raised[0]
    assert lo < 135.0 < hi and level == pytest.approx(float(np.median(
        res.spectrum.psd[(res.spectrum.freq >= lo) & (res.spectrum.freq <= hi)])))
    again = integrate_axis(d, list(TAUS), DT, method="wiener", options=res.frozen_options(), highpass_hz=0.0)
    np.testing.assert_allclose(again.theta, res.theta, rtol=0, atol=1e-6 * np.nanstd(res.theta))
    ifov = 4e-6
    ds = xr.Dataset(attrs={"pixel_ifov_rad": ifov,
                           "integration": json.dumps({"roll": {"options": {"notch_levels": raised}}})})
    line = notch_level_line(ds, ["roll", "pitch"])
    assert f"roll {lo:.1f}–{hi:.1f} Hz ({np.sqrt(2 * level * (hi - lo)) / ifov:.3f} px)" in line
    assert notch_level_line(xr.Dataset(attrs={"integration": "{}"}), ["roll"]) is None


def test_a_notch_is_raised_with_per_line_lags_too(monkeypatch):
    """With per-line lags the MAP's grid is padded for the longest of them and the prior, estimated without
    lags, is read onto it: the two grids differ (a record length chosen so), and the notch's level is still
    found and taken (before: nothing was raised, the residual's grid did not match the prior's)."""
    from scipy.interpolate import CubicSpline

    from restore.integration.wiener import _grid

    n = 4392
    amp = 1.5 * DT
    assert _grid(n, TAUS, DT, 0.5, 0.0) != _grid(n, TAUS, DT, 0.5, amp + 2 * DT)
    s0 = 1e-16
    rng = np.random.default_rng(12)
    theta = _white(s0, rng, top_hz=400.0)
    spline = CubicSpline(np.arange(theta.size) * DT, theta)
    t = np.arange(n) * DT
    lags = [amp * np.sin(2 * np.pi * t / (0.6 + 0.2 * j)) for j in range(3)]
    d = [spline(t + tau + lag) - spline(t) + rng.normal(0.0, 3e-8, n) for tau, lag in zip(TAUS, lags)]
    monkeypatch.setattr(axis_integration, "NOTCH_RAISE", 2.0)
    # no tone search (it would try 127 candidates here: seconds each, and nothing to find)
    res = integrate_axis(d, list(TAUS), DT, method="wiener", options={"tones": None}, lags=lags, highpass_hz=0.0,
                         first_stage_gcv=False)
    f = res.spectrum.freq
    lo, hi, level = res.options["notch_levels"][0]
    assert lo < 135.0 < hi
    inside = (f > lo) & (f < hi)
    assert np.all(res.spectrum.psd[inside] >= level)
    # one realisation's level spreads by about half of it (test above)
    assert 0.25 * s0 < level < 4 * s0


def _zero_prior(n_fft=N_FFT):
    return np.fft.rfftfreq(n_fft, DT), np.zeros(n_fft // 2 + 1)


def test_a_noise_floor_above_the_white_level_is_not_read_as_a_level():
    """Matching noise is coloured: here 3 × the white level the pairs' blind frequencies gave, flat over the
    band. Read against the white level every record shows a notch "level"; read against each pair's level on
    the notch's two sides (``residual_of``: the differentials are a residual, here of a fit with a zero prior,
    which leaves all of the noise) noise alone is detected about as rarely as white noise (false_alarm 0.01)."""
    white, local = 0, 0
    for seed in range(30):
        rng = np.random.default_rng(200 + seed)
        d = _differentials(np.zeros(N + 100), rng, sd=np.sqrt(3.0) * SD)
        white += any(nl.detected for nl in notch_levels(d, TAUS, DT, n_fft=N_FFT, noise_std=SD))
        local += any(nl.detected for nl in notch_levels(d, TAUS, DT, n_fft=N_FFT, noise_std=SD,
                                                        residual_of=_zero_prior()))
    assert white == 30
    assert local <= 3


def test_the_flank_level_keeps_a_continuum_seen_through_the_notch():
    """Under a flat continuum the MAP's residual on a notch's sides is the noise its leverage leaves,
    ``ν (1 − h)``: read with the MAP's prior, the flank level is the white one and the notch's level is found
    as without it (every notch of six records detected, the levels 10 % lower at most on average: the flank
    level of a pair is a mean over some hundred correlated bins, and it is never taken below the white one)."""
    s0 = 1e-17
    ratios = []
    for seed in range(6):
        d, res, prior, m = _map_of_a_continuum(s0, seed)
        r = notch_residual(res, d, TAUS, DT, None, prior)
        plain = notch_levels(r, TAUS, DT, n_fft=m, noise_std=SD)
        flank = notch_levels(r, TAUS, DT, n_fft=m, noise_std=SD, residual_of=(prior.freq, prior.psd))
        assert all(nl.detected for nl in flank)
        ratios += [a.level / b.level for a, b in zip(flank, plain)]
    assert 0.9 < np.mean(ratios) <= 1.0 + 1e-12


def test_flank_levels_scale_the_white_level_by_what_the_sides_show():
    """Noise 4 × the white level in power on one pair only: that pair's level is ≈ 4 (at each notch the mean over
    some hundred correlated bins, within 40 %; over the ten notches within 10 %), the others' stay near 1
    (never below it)."""
    from restore.integration.spectrum import _flank_levels, _periodograms, _min_segment

    rng = np.random.default_rng(5)
    d = np.array(_differentials(np.zeros(N + 100), rng))
    d[1] *= 2.0
    f = np.fft.rfftfreq(N_FFT, DT)
    nu = np.full(3, SD**2 * DT)
    poor = notch_mask(f, TAUS, nu)
    edges = np.diff(np.r_[0, poor.astype(np.int8), 0])
    spans = list(zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)))
    P, _ = _periodograms(d, np.isfinite(d), DT, N_FFT, min_segment=_min_segment(TAUS, DT), smooth_bins=(1,))
    levels = np.array(_flank_levels(P, f, TAUS, nu, poor, spans, _zero_prior()))
    assert levels.shape == (len(spans), 3)
    assert np.all(levels >= 1.0)
    np.testing.assert_allclose(levels[:, 1], 4.0, rtol=0.4)
    assert abs(levels[:, 1].mean() - 4.0) < 0.4
    assert levels[:, [0, 2]].mean() < 1.2


def test_coloured_noise_beside_a_notch_does_not_raise_it(monkeypatch):
    """Lines at 50-60 Hz and matching noise 4 × the white level (in power) at 200-350 Hz in every pair, as at 12 px
    peak jitter: read against the white level the 270 Hz notch shows a level and its prior is raised (the filter
    would then pass that noise through the notch); read against the notch's sides, nothing is raised."""
    import restore.integration.spectrum as spectrum

    rng = np.random.default_rng(21)
    t = np.arange(N + max(STEPS)) * DT
    theta = sum(a * np.sin(2 * np.pi * f0 * t + ph) for a, f0, ph in ((3e-6, 50.3, 0.1), (2e-6, 57.9, 1.3),
                                                                      (1.5e-6, 61.1, 2.2)))
    d = []
    f = np.fft.rfftfreq(N, DT)
    band = (f > 200) & (f < 350)
    for k in STEPS:
        w = np.fft.rfft(rng.normal(0.0, SD, N))
        w[band] *= 2.0
        d.append(theta[k:k + N] - theta[:N] + np.fft.irfft(w, n=N))

    def run():
        return integrate_axis(d, list(TAUS), DT, method="wiener", highpass_hz=0.0)

    res = run()
    assert not res.options.get("notch_levels")
    plain = spectrum.notch_levels

    def white_only(*args, residual_of=None, **kw):
        return plain(*args, **kw)

    monkeypatch.setattr(spectrum, "notch_levels", white_only)
    raised = run().options.get("notch_levels")
    assert raised and any(lo < 270.0 < hi for lo, hi, _ in raised)
