"""The noise colour read in the part of a residual no attitude can make (restore.integration.spectrum.null_space_colour),
the spectrum estimate that takes it (estimate_spectrum's noise_colour) and the prior pass that uses it
(restore.axis_integration.significant_colour)."""
import numpy as np
import pytest

from restore.integration.spectrum import estimate_spectrum, null_space_colour

DT = 1 / 2700.0
STEPS = (20, 40, 60)
TAUS = np.array(STEPS) * DT
N = 4000
SD = np.array([1.0e-8, 1.5e-8, 2.0e-8])


def _noise(rng, boost_band=None, boost=1.0):
    """Each pair's white noise of σ ``SD``, its power × ``boost`` inside ``boost_band`` [Hz]."""
    out = []
    f = np.fft.rfftfreq(N, DT)
    for s in SD:
        w = np.fft.rfft(rng.normal(0.0, s, N))
        if boost_band is not None:
            w[(f > boost_band[0]) & (f < boost_band[1])] *= np.sqrt(boost)
        out.append(np.fft.irfft(w, n=N))
    return np.array(out)


def _attitude(rng, level):
    """A white attitude of two-sided PSD ``level`` [rad²/Hz], long enough for the longest delay."""
    return rng.normal(0.0, np.sqrt(level / DT), N + max(STEPS))


def _differentials(theta, noise):
    return np.array([theta[k:k + N] - theta[:N] for k in STEPS]) + noise


def _band_mean(f, c, lo, hi):
    m = (f > lo) & (f < hi)
    return float(np.mean(c[m]))


#: a white attitude whose differentials are a few times the noise, as what a fit leaves of a record can be (on raw
#: differentials hundreds of times the noise the taper's edges, which a delay moves, leak ~1e-4 of their power
#: outside the attitude's direction: the function reads a fit's residual)
LEVEL = 2e-19


def test_white_noise_reads_one_whatever_the_attitude():
    """A broadband attitude (its differentials 3 × the noise) adds nothing: what it does lies along
    ``(G_j / √ν_j)``; the white noise reads 1 in every band (within 20 %: a 100 Hz band holds five of the
    running median's 20 Hz windows)."""
    rng = np.random.default_rng(1)
    d = _differentials(_attitude(rng, LEVEL), _noise(rng))
    assert np.std(d[0]) > 2.5 * SD[0]
    f, c = null_space_colour(d, TAUS, DT, SD)
    for lo in (20, 200, 500, 900):
        assert _band_mean(f, c, lo, lo + 100) == pytest.approx(1.0, rel=0.2)


def test_a_coloured_band_reads_its_factor():
    """Noise 3 × its white level in power at 300-500 Hz, under the same attitude: ≈ 3 there, ≈ 1 well away from
    it (within 20 %)."""
    rng = np.random.default_rng(2)
    d = _differentials(_attitude(rng, LEVEL), _noise(rng, (300.0, 500.0), 3.0))
    f, c = null_space_colour(d, TAUS, DT, SD)
    assert _band_mean(f, c, 340, 460) == pytest.approx(3.0, rel=0.2)
    assert _band_mean(f, c, 50, 200) == pytest.approx(1.0, rel=0.2)
    assert _band_mean(f, c, 700, 1000) == pytest.approx(1.0, rel=0.2)


def test_null_space_colour_needs_two_pairs_and_lines():
    rng = np.random.default_rng(3)
    d = _noise(rng)
    assert null_space_colour(d[:1], TAUS[:1], DT, SD[:1]) is None
    assert null_space_colour(d[:, :40], TAUS, DT, SD) is None
    gaps = d.copy()
    gaps[1, 1000:1500] = np.nan                   # lines a pair lacks are left out for every pair
    f, c = null_space_colour(gaps, TAUS, DT, SD)
    assert np.all(np.isfinite(c)) and _band_mean(f, c, 200, 600) == pytest.approx(1.0, rel=0.2)


def test_estimate_spectrum_with_the_colour_does_not_take_the_noise_for_attitude():
    """No attitude above 250 Hz and noise 3 × its white level at 300-500 Hz: against the white level the
    estimate finds a prior on a third of that band's bins; with the colour on a few at most."""
    rng = np.random.default_rng(4)
    theta = _attitude(rng, 1e-15)
    spec = np.fft.rfft(theta)
    spec[np.fft.rfftfreq(theta.size, DT) > 250.0] = 0.0
    theta = np.fft.irfft(spec, n=theta.size)
    noise = _noise(rng, (300.0, 500.0), 3.0)
    d = _differentials(theta, noise)
    f, c = null_space_colour(noise, TAUS, DT, SD)    # the noise alone stands for a fit's residual
    white = estimate_spectrum(list(d), TAUS, DT, noise_std=SD)
    coloured = estimate_spectrum(list(d), TAUS, DT, noise_std=SD, noise_colour=(f, np.where(c > 2.0, c, 1.0)))
    band = (white.freq > 340) & (white.freq < 460)        # the colour's 20 Hz median blurs the band's edges
    assert white.detected[band].mean() > 0.2
    # a few bins may still pass where the colour's median dips (seeds 4-6: 5.6, 0 and 0 % against 35, 16 and 29 %)
    assert coloured.detected[band].mean() < min(0.1, 0.25 * white.detected[band].mean())
    low = (white.freq > 20) & (white.freq < 240)          # the attitude below stays
    assert coloured.detected[low].mean() > 0.9
    np.testing.assert_allclose(coloured.psd[low], white.psd[low], rtol=1e-12)


def test_significant_colour_takes_only_a_doubled_noise():
    """The prior pass's colour: None when the residual's noise is white; where it is 3 × at 300-500 Hz, that
    band's factor and 1 elsewhere."""
    from types import SimpleNamespace

    from restore.axis_integration import COLOUR_PRIOR_MIN, significant_colour

    rng = np.random.default_rng(5)
    white = _noise(rng)
    res = SimpleNamespace(predicted=np.zeros_like(white))
    assert significant_colour(res, white, TAUS, DT, SD) is None
    coloured = _noise(rng, (300.0, 500.0), 3.0)
    f, c = significant_colour(res, coloured, TAUS, DT, SD)
    assert _band_mean(f, c, 340, 460) > COLOUR_PRIOR_MIN
    assert np.all((c == 1.0) | (c > COLOUR_PRIOR_MIN))
    assert np.all(c[(f > 50) & (f < 250)] == 1.0)
    assert significant_colour(SimpleNamespace(), coloured, TAUS, DT, SD) is None


def test_the_prior_pass_takes_the_colour(monkeypatch):
    """Lines at 50-61 Hz seen through per-line lags, and matching noise 4 × its white level at 200-350 Hz: with
    the colour off (its threshold infinite) the prior holds power at 200-350 Hz, where the attitude has
    nothing; with it, a tenth of that at most, and the lines' prior is unchanged (to 10 %)."""
    import restore.axis_integration as axis_integration
    from restore.axis_integration import integrate_axis

    rng = np.random.default_rng(21)
    t = np.arange(N + max(STEPS) + 8) * DT
    theta = sum(a * np.sin(2 * np.pi * f0 * t + ph) for a, f0, ph in ((3e-6, 50.3, 0.1), (2e-6, 57.9, 1.3),
                                                                      (1.5e-6, 61.1, 2.2)))
    lag = 0.2 * DT * np.sin(2 * np.pi * 0.7 * t[:N])
    lags = [lag] * 3
    d = []
    for k, noise in zip(STEPS, _noise(rng, (200.0, 350.0), 4.0)):
        seen = np.interp(t[:N] + k * DT + lag, t, theta) - theta[:N]
        d.append(seen + noise)

    def prior_power(colour_min):
        monkeypatch.setattr(axis_integration, "COLOUR_PRIOR_MIN", colour_min)
        res = integrate_axis(d, list(TAUS), DT, method="wiener", lags=lags, highpass_hz=0.0)
        f, psd = res.spectrum.freq, res.spectrum.psd
        return psd[(f > 210) & (f < 340)].sum(), psd[(f > 45) & (f < 66)].sum()

    white_band, white_lines = prior_power(np.inf)
    band, lines = prior_power(2.0)
    assert white_band > 0
    assert band <= 0.1 * white_band
    assert lines == pytest.approx(white_lines, rel=0.1)
