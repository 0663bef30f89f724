"""The MAP Wiener weighing its residual by a coloured noise covariance (``noise_colour=``)."""
import dataclasses

import numpy as np
import pytest

from restore import stages
from restore.axis_integration import integrate_axis
from restore.integration.wiener import _colour_weighting, integrate_wiener
from restore.result import IntegrationRecord

DT = 1e-3
TAUS = np.array([0.0074, 0.0148, 0.0222])
N = 4096
SIGMA = 1e-7
#: the prior: flat (two-sided) up to 60 Hz, at a level where the white-weighted MAP at 1-4 Hz follows the
#: coloured noise (its error there above the prior itself) and the coloured one does not
S0 = 1e-15
F_TOP = 60.0


def _colour(f):
    """Noise power relative to white: 40 × below ~4 Hz (a slow error common to a band's points)."""
    return 1.0 + 39.0 * np.exp(-(np.asarray(f) / 4.0) ** 2)


def _draw(rng, m=4 * N):
    """Attitude on a long grid (so that θ(t + τ) exists), the pairs' differentials with coloured noise."""
    f = np.fft.rfftfreq(m, DT)
    amp = np.where((f > 0) & (f < F_TOP), np.sqrt(S0 / DT / 2), 0.0)
    z = (rng.standard_normal(f.size) + 1j * rng.standard_normal(f.size)) * amp * np.sqrt(m)
    theta = np.fft.irfft(z, n=m)
    t = np.arange(m) * DT
    fn = np.fft.rfftfreq(N, DT)
    diffs = []
    for tau in TAUS:
        w = np.fft.irfft(np.fft.rfft(rng.standard_normal(N)) * np.sqrt(_colour(fn)), n=N) * SIGMA
        diffs.append(np.interp(t[:N] + tau, t, theta) - theta[:N] + w)
    return theta[:N], diffs


def _prior():
    f = np.fft.rfftfreq(8192, DT)
    return f, np.where(f < F_TOP, S0, 0.0)


def _band_error_power(est, truth, lo, hi):
    e = est - truth
    e = e - e.mean()
    p = np.abs(np.fft.rfft(e * np.hanning(N))) ** 2
    f = np.fft.rfftfreq(N, DT)
    sel = (f >= lo) & (f < hi)
    return float(p[sel].mean())


def test_a_white_colour_weighs_as_the_per_sample_weights_do():
    rng = np.random.default_rng(1)
    w = rng.uniform(0.5, 2.0, (3, 100))
    r = rng.standard_normal((3, 100))
    ones = np.ones((3, 128 // 2 + 1))
    np.testing.assert_allclose(_colour_weighting(w, ones, 128)(r), w * r, rtol=1e-12, atol=1e-12)
    # symmetric positive definite: <a, W b> = <W a, b> and <a, W a> > 0 with a real colour
    col = 1.0 + rng.uniform(0, 5, (3, 128 // 2 + 1))
    op = _colour_weighting(w, col, 128)
    a, b = rng.standard_normal((2, 3, 100))
    assert np.sum(a * op(b)) == pytest.approx(np.sum(op(a) * b), rel=1e-10)
    assert np.sum(a * op(a)) > 0


def test_a_flat_colour_changes_nothing():
    _, diffs = _draw(np.random.default_rng(2))
    psd = _prior()
    fc = np.fft.rfftfreq(N, DT)
    white = integrate_wiener(diffs, TAUS, DT, psd=psd, noise_std=[SIGMA] * 3, tol=1e-12, maxiter=2000)
    flat = integrate_wiener(diffs, TAUS, DT, psd=psd, noise_std=[SIGMA] * 3, tol=1e-12, maxiter=2000,
                            noise_colour=(fc, np.ones((3, fc.size))))
    np.testing.assert_allclose(flat, white, rtol=0, atol=1e-6 * np.nanmax(np.abs(white)))


def test_weighing_with_the_true_colour_reaches_the_coloured_wiener_error():
    """Against the analytic error PSD of the Wiener filter with coloured noise, 1 / (1/S + Σ |G_j|² / N_j):
    the coloured MAP's error at 1-4 Hz matches it; the white MAP's (noise taken white) is larger than the
    prior itself there (worse than no restoration), as on the stress suite's low frequencies."""
    psd = _prior()
    fc = np.fft.rfftfreq(N, DT)
    col = np.tile(_colour(fc), (3, 1))
    coloured, white = [], []
    truth_power = []
    rng = np.random.default_rng(3)
    for _ in range(6):
        theta, diffs = _draw(rng)
        kw = dict(psd=psd, noise_std=[SIGMA] * 3)
        coloured.append(_band_error_power(integrate_wiener(diffs, TAUS, DT, noise_colour=(fc, col), **kw),
                                          theta, 1.0, 4.0))
        white.append(_band_error_power(integrate_wiener(diffs, TAUS, DT, **kw), theta, 1.0, 4.0))
        truth_power.append(_band_error_power(np.zeros(N), theta, 1.0, 4.0))
    # the analytic ratio error / prior at 1-4 Hz, for the coloured Wiener filter
    f = fc[(fc >= 1.0) & (fc < 4.0)]
    g2 = 2 * (1 - np.cos(2 * np.pi * f[None, :] * TAUS[:, None]))
    nu = SIGMA ** 2 * DT * _colour(f)
    ratio = np.mean(1.0 / (1.0 / S0 + (g2 / nu[None, :]).sum(0)) / S0)
    measured = np.mean(coloured) / np.mean(truth_power)
    assert measured == pytest.approx(ratio, rel=0.2)
    assert np.mean(white) > np.mean(truth_power) > np.mean(coloured)
    assert np.mean(coloured) < 0.4 * np.mean(white)


def test_a_noise_colour_of_the_wrong_shape_or_sign_is_refused():
    _, diffs = _draw(np.random.default_rng(4))
    fc = np.fft.rfftfreq(N, DT)
    with pytest.raises(ValueError, match="noise_colour"):
        integrate_wiener(diffs, TAUS, DT, psd=_prior(), noise_std=[SIGMA] * 3, noise_colour=(fc, np.ones((2, fc.size))))
    with pytest.raises(ValueError, match="noise_colour"):
        integrate_wiener(diffs, TAUS, DT, psd=_prior(), noise_std=[SIGMA] * 3,
                         noise_colour=(fc, np.zeros((3, fc.size))))


@pytest.fixture(scope="module")
def wiener_record():
    """One axis's integration record, as the pipeline keeps it, on synthetic differentials."""
    _, diffs = _draw(np.random.default_rng(5))
    n = N
    zeros = [np.zeros(n)] * 3
    res = integrate_axis(diffs, list(TAUS), DT, method="wiener", lags=zeros, weights=[np.ones(n)] * 3)
    assert res.spectrum is not None
    return IntegrationRecord(axis="pitch", pairs=["B1/B0", "B1/B2", "B0/B2"], diffs=np.array(diffs),
                             sigmas=np.full((3, n), SIGMA), taus=TAUS.copy(), lags_s=np.zeros((3, n)),
                             weights=np.ones((3, n)), line_period_s=DT, method="wiener", options=res.options,
                             highpass_hz=0.0, spectrum=res.spectrum, increment=res.theta, previous=np.zeros(n))


def test_colour_weighting_of_a_record_keeps_its_filter_and_only_lowers_weights(wiener_record):
    rec = wiener_record
    n = rec.diffs.shape[1]
    assert stages.colour_weighted(rec, None) is None
    # a colour below 1 is taken as 1: the same filter, the same increment
    below = stages.colour_weighted(rec, np.full((len(rec.taus), n // 2 + 1), 0.5))
    assert below is not None
    # (to the conjugate gradients' tolerance: the weighting goes through an FFT)
    np.testing.assert_allclose(below.increment, rec.rerun(), rtol=0, atol=1e-4 * np.nanmax(np.abs(rec.increment)))
    assert np.all(below.spectrum.noise_colour[1] == 1.0)
    # a colour of the wrong shape is not used
    assert stages.colour_weighted(rec, np.ones((len(rec.taus) + 1, n // 2 + 1))) is None
    # a method that cannot weigh by a colour is left alone
    assert stages.colour_weighted(dataclasses.replace(rec, method="lsq"), np.ones((len(rec.taus), n // 2 + 1))) \
        is None
    # and a real colour changes the increment, and its frozen rerun reproduces it
    colour = np.ones((len(rec.taus), n // 2 + 1))
    colour[:, :40] = 20.0
    weighted = stages.colour_weighted(rec, colour)
    assert np.nanmax(np.abs(weighted.increment - rec.rerun())) > 1e-3 * np.nanmax(np.abs(rec.increment))
    np.testing.assert_allclose(weighted.rerun(), weighted.increment, rtol=0, atol=1e-12)


def test_the_noise_keeps_the_excess_where_it_dominates_and_the_signal_where_it_does():
    """``1 + (c − 1) ν / (ν + |G|² S)``: with no prior the whole excess is the noise's; at the frequencies where
    the attitude seen through the pair is 99 × the noise, 1 % of it; a pair blind at f (|G| = 0) keeps it all."""
    from restore.axis_integration import PriorSpectrum

    dt, tau = 1e-3, 0.01
    f = np.array([10.0, 25.0, 100.0])
    g2 = 2 * (1 - np.cos(2 * np.pi * f * tau))                # |G|² at 10, 25 Hz; 0 at 100 Hz (1 / τ)
    nu = SIGMA ** 2 * dt
    colour = np.full((1, 3), 5.0)
    quiet = PriorSpectrum(f, np.zeros(3), np.array([SIGMA]))
    np.testing.assert_allclose(stages.noise_share_of_excess(colour, f, quiet, [tau], dt), colour)
    loud = PriorSpectrum(f, np.where(g2 > 0, 99 * nu / np.maximum(g2, 1e-300), 1.0), np.array([SIGMA]))
    np.testing.assert_allclose(stages.noise_share_of_excess(colour, f, loud, [tau], dt), [[1.04, 1.04, 5.0]],
                               atol=1e-9)


def test_the_knowledge_proves_noise_only_the_excess_no_underrated_signal_could_make():
    """``1 + max(c − 1 − |G|² (C − S) / ν, 0)``: with the ceiling at the prior (the knowledge leaves no room
    for more signal) the whole excess is noise; with room for k × ν of signal seen through the pair, k less;
    where the knowledge says nothing (infinite ceiling), nothing, except where the pair is blind (|G| = 0)."""
    from restore.axis_integration import PriorSpectrum

    dt, tau = 1e-3, 0.01
    f = np.array([10.0, 25.0, 100.0])
    g2 = 2 * (1 - np.cos(2 * np.pi * f * tau))                # 0 at 100 Hz (1 / τ)
    nu = SIGMA ** 2 * dt
    psd = np.array([3.0, 2.0, 1.0]) * nu
    prior = PriorSpectrum(f, psd, np.array([SIGMA]))
    colour = np.array([[5.0, 5.0, 5.0]])
    tight = (f, psd.copy())
    np.testing.assert_allclose(stages.excess_the_knowledge_proves_noise(colour, f, prior, [tau], dt, tight), colour)
    k = np.array([1.5, 10.0, 7.0])
    room = (f, psd + np.where(g2 > 0, k * nu / np.maximum(g2, 1e-300), 1e3 * nu))
    np.testing.assert_allclose(stages.excess_the_knowledge_proves_noise(colour, f, prior, [tau], dt, room),
                               [[3.5, 1.0, 5.0]], rtol=1e-9)
    unknown = (f, np.full(3, np.inf))
    np.testing.assert_allclose(stages.excess_the_knowledge_proves_noise(colour, f, prior, [tau], dt, unknown),
                               [[1.0, 1.0, 5.0]])
    # a colour below white is white
    np.testing.assert_allclose(stages.excess_the_knowledge_proves_noise(np.full((1, 3), 0.3), f, prior, [tau], dt,
                                                                        tight), 1.0)


def test_a_record_weighs_only_what_its_knowledge_proves_noise(wiener_record):
    rec = wiener_record
    n = rec.diffs.shape[1]
    f = np.fft.rfftfreq(n, rec.line_period_s)
    colour = np.ones((len(rec.taus), n // 2 + 1))
    colour[:, 1:40] = 20.0              # (at 0 Hz every pair is blind: an excess there would be noise)
    # the knowledge knows nothing: not integrated again
    assert stages.colour_weighted(rec, colour, (f, np.full(f.size, np.inf))) is None
    # it bounds the attitude at the prior itself: the excess is all noise, weighed as without a ceiling
    psd = np.interp(f, rec.spectrum.freq, rec.spectrum.psd)
    tight = stages.colour_weighted(rec, colour, (f, psd))
    free = stages.colour_weighted(rec, colour)
    np.testing.assert_array_equal(tight.spectrum.noise_colour[1], free.spectrum.noise_colour[1])
    np.testing.assert_array_equal(tight.increment, free.increment)
    # room for a lot of signal at the coloured frequencies: less of the colour survives
    loose = stages.colour_weighted(rec, colour, (f, psd * 1e3))
    assert loose is None or np.all(loose.spectrum.noise_colour[1] <= free.spectrum.noise_colour[1])
