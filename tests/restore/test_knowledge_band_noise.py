"""The matching noise read from the pairs' differentials in the AOCS knowledge's band (restore.knowledge_band_noise)."""
import dataclasses
from types import SimpleNamespace

import numpy as np
import pytest

from restore import stages
from restore.axis_integration import PriorSpectrum
from restore.knowledge_band_noise import (COLOUR_LIMIT, MIN_NOISE_SHARE, colour_from_differentials, knowledge_band_colour,
                                          tapered_band_power)
from restore.posterior import _band_edges
from restore.result import IntegrationRecord
from restore.settings import RestorationSettings

DT = 1e-3
TAUS = np.array([0.0074, 0.0148, 0.0222])
N = 4096
SIGMA = 1e-7
#: the prior: flat (two-sided) up to 60 Hz, small enough that at 1-3 Hz the pairs' differentials are mostly noise
S0 = 1e-15
F_TOP = 60.0
BAND = (1.0, 6.0)


def _excess(f):
    """Noise power relative to white: 40 × towards 0 Hz, 1 + 39 e^(−(f/4)²) (a slow error common to a band)."""
    return 1.0 + 39.0 * np.exp(-(np.asarray(f) / 4.0) ** 2)


def _white(f):
    """White matching noise: power 1 × the white level everywhere."""
    return np.ones_like(np.asarray(f, dtype=np.float64))


def _record(rng, colour=_excess, s0=S0):
    """A record as the pipeline keeps it, its prior the true one (flat, ``s0``), its noise white × ``colour``; and
    the truth."""
    m = 4 * N
    f = np.fft.rfftfreq(m, DT)
    amp = np.where((f > 0) & (f < F_TOP), np.sqrt(s0 / DT / 2), 0.0)
    theta = np.fft.irfft((rng.standard_normal(f.size) + 1j * rng.standard_normal(f.size)) * amp * np.sqrt(m), n=m)
    t = np.arange(m) * DT
    fn = np.fft.rfftfreq(N, DT)
    diffs = []
    for tau in TAUS:
        w = np.fft.irfft(np.fft.rfft(rng.standard_normal(N)) * np.sqrt(colour(fn)), n=N) * SIGMA
        diffs.append(np.interp(t[:N] + tau, t, theta) - theta[:N] + w)
    fp = np.fft.rfftfreq(8192, DT)
    spectrum = PriorSpectrum(freq=fp, psd=np.where(fp < F_TOP, s0, 0.0), noise_std=np.full(3, SIGMA))
    rec = IntegrationRecord(axis="pitch", pairs=["B1/B0", "B1/B2", "B0/B2"], diffs=np.array(diffs),
                            sigmas=np.full((3, N), SIGMA), taus=TAUS.copy(), lags_s=np.zeros((3, N)),
                            weights=np.ones((3, N)), line_period_s=DT, method="wiener", options={},
                            highpass_hz=0.0, spectrum=spectrum, increment=np.zeros(N), previous=np.zeros(N),
                            knowledge_conditioned=True)
    return dataclasses.replace(rec, increment=rec.rerun()), theta[:N]


def _band_error(est, truth, lo, hi):
    e = est - truth
    e = e - e.mean()
    p = np.abs(np.fft.rfft(e * np.hanning(N))) ** 2
    f = np.fft.rfftfreq(N, DT)
    return float(p[(f >= lo) & (f < hi)].mean())


def test_a_tapered_sine_lies_in_its_own_band_and_gaps_count_as_the_mean():
    n = 1024
    edges = _band_edges(n)
    k = 100                                           # bin of the sine
    x = np.sin(2 * np.pi * k * np.arange(n) / n)[None, :] + 5.0
    p = tapered_band_power(x, edges)
    own = next(i for i, (a, b) in enumerate(zip(edges[:-1], edges[1:])) if a <= k < b)
    assert np.argmax(p[0]) == own
    # the taper keeps the sine out of bands two of its own widths away (a rectangular window would not)
    far = [i for i, (a, b) in enumerate(zip(edges[:-1], edges[1:])) if b < k - 20 or a > k + 20]
    assert np.max(p[0, far]) < 1e-6 * p[0, own]
    # a NaN sample is the row's mean: the sine's band barely moves
    y = x.copy()
    y[0, 500] = np.nan
    np.testing.assert_allclose(tapered_band_power(y, edges)[0, own], p[0, own], rtol=0.02)


def test_the_colour_is_the_factor_on_the_noise_that_matches_the_real_power():
    """real = A + c N, simulated = A + N: c in the bands wholly inside the band, 1 elsewhere, never below 1."""
    n = 512
    edges = _band_edges(n)
    nb = len(edges) - 1
    f_idx = np.arange(n // 2 + 1)
    in_band = (f_idx >= 20) & (f_idx < 120)
    inside = np.array([in_band[a:b].all() for a, b in zip(edges[:-1], edges[1:])])
    att = np.full((2, nb), 3.0)
    noise = np.full((2, nb), 1.0)
    c_true = np.array([[6.0] * nb, [0.5] * nb])       # the second pair's real power is below the draws'
    col = colour_from_differentials(att + c_true * noise, att + noise, noise, edges, n, in_band, confidence=None)
    assert col.shape == (2, n // 2 + 1)
    # read at the lower end of its scatter (the default) the factor is smaller, never larger, and still > 1
    low = colour_from_differentials(att + c_true * noise, att + noise, noise, edges, n, in_band)
    assert np.all(low <= col + 1e-12) and np.all(low[0, in_band] > 1.0) and np.all(low[1] == 1.0)
    # every bin of the band takes the factor, up to its ends (the bands that straddle them are not read)
    assert inside.sum() >= 3
    np.testing.assert_allclose(col[0, in_band], 6.0, rtol=1e-9)
    between = in_band
    assert np.all(col[1] == 1.0)
    assert np.all(col[:, ~in_band] == 1.0)
    # an excess where the draws hold no noise at all is bounded (its share taken as MIN_NOISE_SHARE) and capped
    half = colour_from_differentials(att * 1.5, att, np.zeros((2, nb)), edges, n, in_band, confidence=None)
    np.testing.assert_allclose(half[0, between], 1.0 + 0.5 / MIN_NOISE_SHARE, rtol=1e-9)
    huge = colour_from_differentials(att * 100, att, np.zeros((2, nb)), edges, n, in_band, confidence=None)
    assert np.max(huge) == pytest.approx(COLOUR_LIMIT, rel=1e-12)


@pytest.mark.parametrize("seed", [3, 4, 5])
def test_a_slow_noise_the_draws_lack_is_read_from_the_differentials(seed):
    """Under a prior as small as a knowledge-conditioned one the factor is read as a lower bound: a good part of
    the true one (37 × at 1 Hz, 5 × at 6 Hz) and not above it beyond the scatter; white noise reads as white."""
    rec, _ = _record(np.random.default_rng(seed), s0=1e-16)
    col = knowledge_band_colour(rec, BAND, samples=8, seed=0)
    f = np.fft.rfftfreq(N, DT)
    inb = (f >= BAND[0]) & (f <= BAND[1])
    assert np.all(col[:, ~inb] == 1.0)
    ratio = col[:, inb] / _excess(f[inb])[None, :]
    assert 0.2 < np.exp(np.mean(np.log(ratio))) < 1.0
    white, _ = _record(np.random.default_rng(seed), colour=_white, s0=1e-16)
    w = knowledge_band_colour(white, BAND, samples=8, seed=0)[:, inb]
    assert np.mean(w) < 1.1 and np.max(w) < 2.0
    # a band no band of the record lies wholly in: nothing measured
    assert knowledge_band_colour(rec, (1.0, 1.1), samples=4, seed=0) is None


def test_the_pooled_read_is_one_colour_for_every_pair_and_scatters_less_than_each_pair_s():
    """Every pair under the same slow noise: each pair's own read scatters between the pairs (which would weigh
    them against each other by chance) and between records; the pooled read, one per record, scatters less and
    stays a lower bound."""
    f = np.fft.rfftfreq(N, DT)
    inb = (f >= BAND[0]) & (f <= BAND[1])
    own, pooled = [], []
    for seed in range(3, 9):
        rec, _ = _record(np.random.default_rng(seed), s0=1e-16)
        per = knowledge_band_colour(rec, BAND, samples=8, seed=0, pooled=False)[:, inb]
        one = knowledge_band_colour(rec, BAND, samples=8, seed=0)[:, inb]
        assert np.all(one == one[0])
        own.append(np.log(per / _excess(f[inb])))
        pooled.append(np.log(one[0] / _excess(f[inb])))
        assert 0.3 < np.exp(np.mean(pooled[-1])) < 1.0
    own, pooled = np.concatenate([x.ravel() for x in own]), np.concatenate(pooled)
    assert np.std(pooled) < 0.8 * np.std(own)
    assert np.mean(pooled) > np.mean(own)        # more degrees of freedom: a lower bound nearer the truth


def test_weighing_by_it_lowers_the_error_in_the_band_and_the_rerun_reproduces_it():
    rec, truth = _record(np.random.default_rng(7))
    product = SimpleNamespace(ds=SimpleNamespace(attrs={"knowledge_cutoff_hz": BAND[1] / 0.9}))
    s = RestorationSettings()
    out = stages.knowledge_band_weighted(rec, product, s)
    assert out is not None
    new, largest = out
    assert 10.0 < largest <= COLOUR_LIMIT
    before = _band_error(rec.increment, truth, *BAND)
    after = _band_error(new.increment, truth, *BAND)
    assert after < 0.7 * before
    np.testing.assert_allclose(new.rerun(), new.increment, rtol=0, atol=1e-12)
    # off, not conditioned on the knowledge, a method that cannot weigh, no cut-off: nothing
    assert stages.knowledge_band_weighted(rec, product, dataclasses.replace(s, knowledge_band_noise=False)) is None
    assert stages.knowledge_band_weighted(dataclasses.replace(rec, knowledge_conditioned=False), product, s) is None
    assert stages.knowledge_band_weighted(dataclasses.replace(rec, method="lsq"), product, s) is None
    assert stages.knowledge_band_weighted(rec, SimpleNamespace(ds=SimpleNamespace(attrs={})), s) is None


def test_the_record_s_own_colour_is_kept_where_larger():
    rec, _ = _record(np.random.default_rng(8))
    f = np.fft.rfftfreq(N, DT)
    own = np.full((3, f.size), 100.0)               # larger than anything measured: the weighting is the same
    with_own = dataclasses.replace(rec, spectrum=dataclasses.replace(rec.spectrum, noise_colour=(f, own)))
    product = SimpleNamespace(ds=SimpleNamespace(attrs={"knowledge_cutoff_hz": BAND[1] / 0.9}))
    new, _ = stages.knowledge_band_weighted(with_own, product, RestorationSettings())
    np.testing.assert_array_equal(new.spectrum.noise_colour[1], own)


def test_the_sigma_of_a_weighted_record_follows_its_filter():
    """σ predicted through the weighted filter: pooled over six records within × 1.5 of the weighted estimate's
    actual error (which the weighting lowers on every record, to ≈ 0.55 × pooled)."""
    from restore.posterior import posterior_sigma

    product = SimpleNamespace(ds=SimpleNamespace(attrs={"knowledge_cutoff_hz": BAND[1] / 0.9}))
    actual, before, predicted = [], [], []
    for seed in range(3, 9):
        rec, truth = _record(np.random.default_rng(seed), s0=1e-16)
        new, _ = stages.knowledge_band_weighted(rec, product, RestorationSettings())
        assert new.knowledge_band_hz == pytest.approx((0.0, BAND[1]))
        e0, e = rec.increment - truth, new.increment - truth
        assert np.std(e) < np.std(e0)
        actual.append(np.mean((e - e.mean()) ** 2))
        before.append(np.mean((e0 - e0.mean()) ** 2))
        predicted.append(posterior_sigma(new, samples=8, seed=0).detrended_rms ** 2)
    assert np.sqrt(np.mean(actual) / np.mean(before)) < 0.7
    assert 1 / 1.5 < np.sqrt(np.mean(actual) / np.mean(predicted)) < 1.5


#: an attitude-like offset over 1-6 Hz (two-sided rad²/Hz): through the pairs, 10-60 × their white noise there
S_OFF = 4e-15


def _record_with_offset(rng, s0=1e-16):
    """White matching noise plus an offset every pair sees as it would an attitude (the scene's band offset), which
    the truth does not hold."""
    from restore.posterior import prior_draw

    rec, theta = _record(rng, colour=_white, s0=s0)
    m = 4 * N
    fo = np.fft.rfftfreq(8192, DT)
    off = prior_draw(fo, np.where((fo >= 1.0) & (fo <= 6.0), S_OFF, 0.0), m, DT, rng)
    t = np.arange(m) * DT
    d = np.array(rec.diffs) + np.array([np.interp(t[:N] + tau, t, off) - off[:N] for tau in TAUS])
    rec = dataclasses.replace(rec, diffs=d)
    return dataclasses.replace(rec, increment=rec.rerun()), theta


def test_sigma_draws_the_attitude_like_offset_the_knowledge_band_shows():
    """The offset's PSD read back from the weighted record (≈ the truth, ~0 on white noise), and σ drawing it:
    pooled over four records the actual error within × 1.2 of σ, where σ without it falls × 1.15 short."""
    from restore.knowledge_band_noise import knowledge_band_offset_psd
    from restore.posterior import posterior_sigma

    product = SimpleNamespace(ds=SimpleNamespace(attrs={"knowledge_cutoff_hz": BAND[1] / 0.9}))
    actual, drawn, without, read = [], [], [], []
    for seed in range(3, 7):
        rec, truth = _record_with_offset(np.random.default_rng(seed))
        assert knowledge_band_offset_psd(rec) is None            # not weighed: no band
        new, _ = stages.knowledge_band_weighted(rec, product, RestorationSettings())
        f, psd = knowledge_band_offset_psd(new, samples=8, seed=0)
        mid = (f >= 1.5) & (f <= 5.5)
        assert np.all(psd[f > BAND[1]] == 0.0)
        read.append(np.exp(np.mean(np.log(np.maximum(psd[mid], 1e-300) / S_OFF))))
        e = new.increment - truth
        actual.append(np.mean((e - e.mean()) ** 2))
        drawn.append(posterior_sigma(new, samples=8, seed=0).detrended_rms ** 2)
        without.append(posterior_sigma(dataclasses.replace(new, knowledge_band_hz=None), samples=8,
                                       seed=0).detrended_rms ** 2)
    assert 0.4 < np.exp(np.mean(np.log(read))) < 1.5
    with_offset = np.sqrt(np.mean(actual) / np.mean(drawn))
    assert 1 / 1.2 < with_offset < 1.2
    assert np.sqrt(np.mean(actual) / np.mean(without)) > 1.15
    # white noise alone: next to nothing is read
    white, _ = _record(np.random.default_rng(3), colour=_white, s0=1e-16)
    f, psd = knowledge_band_offset_psd(dataclasses.replace(white, knowledge_band_hz=(0.0, BAND[1])))
    assert np.mean(psd[(f >= 1.5) & (f <= 5.5)]) < 0.05 * S_OFF


def test_the_summary_says_which_axes_and_how_much():
    import json

    import xarray as xr

    from reports.summary import knowledge_band_noise_line

    f = np.linspace(0.0, 20.0, 41)
    col = np.ones((3, f.size))
    col[1, (f >= 2.0) & (f <= 3.0)] = 12.5
    col[0, f > 10.0] = 99.0                             # outside the band: not the band's
    info = {"pitch": {"knowledge_band_hz": [0.8, 3.6]}, "roll": {"knowledge_band_hz": None}}
    ds = xr.Dataset({"prior_noise_colour_pitch": (("pair", "colour_freq_pitch"), col),
                     "prior_noise_colour_roll": (("pair", "colour_freq_roll"), col)},
                    coords={"colour_freq_pitch": f, "colour_freq_roll": f},
                    attrs={"integration": json.dumps(info)})
    line = knowledge_band_noise_line(ds, ["roll", "pitch"])
    assert line is not None and "pitch up to 12.5 × the white noise at 0.80–3.60 Hz" in line and "roll" not in line
    assert knowledge_band_noise_line(ds, ["roll"]) is None
    assert knowledge_band_noise_line(xr.Dataset(attrs={"integration": "not json"}), ["pitch"]) is None
