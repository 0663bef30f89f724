"""Noise a band shares between the pairs that use it (restore.posterior.shared_band_noise) against known cases."""
import numpy as np
import pytest

from restore.axis_integration import PriorSpectrum
from restore.posterior import (
    correlated_noise,
    detrended_rms,
    fit_residuals,
    pair_bands,
    posterior_sigma,
    prior_draw,
    shared_band_noise,
    simulated_differentials,
)
from restore.result import IntegrationRecord

DT = 4e-4
N = 3000
LAGS = [18, 37, 55]                 # whole lines, so that the reference noise below is built without interpolation
TAUS = [k * DT for k in LAGS]
PAIRS = ["a/b", "b/c", "a/c"]        # a sees the ground first, b 18 lines later, c 55 lines later


def _band_noise(rng, band_sd, pair_sd, n=N, lags=LAGS):
    """Pair noise built the physical way: pair ``A/B`` at line ``l`` compares A's line ``l`` with B's line
    ``l + lag``, each band's lines carrying their own white error, plus white noise of each pair's own."""
    u = {b: rng.standard_normal(n + max(lags)) * band_sd for b in "abc"}
    out = rng.standard_normal((3, n)) * pair_sd
    for j, (p, lag) in enumerate(zip(PAIRS, lags)):
        a, b = p.split("/")
        out[j] += u[b][np.arange(n) + lag] - u[a][np.arange(n)]
    return out


def test_pair_bands_from_the_names():
    assert pair_bands(PAIRS) == [("a", "b"), ("b", "c"), ("a", "c")]
    assert pair_bands([" a / b "]) == [("a", "b")]
    assert pair_bands(["a-b"]) is None and pair_bands(["a/a"]) is None and pair_bands(["a/b/c"]) is None


def test_the_shared_share_of_band_noise_is_recovered():
    """Band errors of 0.2 with a pair's own 0.15: each pair's noise is 2 × 0.04 + 0.0225, of which 0.04 per
    band (39 %); the residual of pure noise is the noise."""
    rng = np.random.default_rng(3)
    sh = shared_band_noise(_band_noise(rng, 0.2, 0.15), PAIRS, TAUS, DT)
    assert [b for b, _ in sh.terms] == ["a", "b", "c"]
    expected = 0.04 / 0.1025
    for x, (_, seen) in enumerate(sh.terms):
        for j, _, _ in seen:
            assert sh.fraction[x, j].mean() == pytest.approx(expected, abs=0.04)
        others = [j for j in range(3) if j not in [s[0] for s in seen]]
        assert np.all(sh.fraction[x, others] == 0.0)
    # the signs and sample times: b is behind in a/b (+, 18 lines on), ahead in b/c (−, its own line)
    seen_b = dict((j, (s, o)) for j, s, o in sh.terms[1][1])
    assert seen_b[0] == (1.0, pytest.approx(18.0)) and seen_b[1] == (-1.0, pytest.approx(0.0))


def test_independent_pair_noise_shares_almost_nothing_down_to_the_lowest_bins():
    """No band shared: the shares stay small everywhere, also in the lowest bins (where the integration
    amplifies noise most) and whatever constant the residuals carry."""
    rng = np.random.default_rng(4)
    shares = []
    for _ in range(10):
        r = rng.standard_normal((3, N)) + rng.standard_normal((3, 1)) * 0.3     # an offset of 0.3 σ per pair
        shares.append(shared_band_noise(r, PAIRS, TAUS, DT).fraction)
    shares = np.array(shares)
    assert shares.mean() < 0.04
    assert shares[..., :4].mean() < 0.06


def test_delays_that_do_not_add_up_and_gaps_that_do_not_overlap():
    """Each pair's behind band is taken at its own delay (the recorded delays are measured: 18 + 37 ≠ 57 here),
    and a cross-spectrum is normalised by the lines both pairs have at the band's shift (a/b missing its
    first half, b/c its second: no line of theirs holds the same sample of b)."""
    lags = [18, 37, 57]
    rng = np.random.default_rng(8)
    r = _band_noise(rng, 0.2, 0.15, lags=lags)
    sh = shared_band_noise(r, PAIRS, [k * DT for k in lags], DT)
    np.testing.assert_allclose(sh.fraction.max(axis=0).mean(axis=-1), 0.04 / 0.1025, atol=0.04)
    gapped = r.copy()
    gapped[0, : N // 2 + 40] = np.nan
    gapped[1, N // 2 - 40:] = np.nan
    sh = shared_band_noise(gapped, PAIRS, [k * DT for k in lags], DT)
    b = [band for band, _ in sh.terms]
    # a/b and b/c overlap nowhere at b's shift (a/b's line l ↔ b/c's line l + 18): no estimate of b;
    # a (a/b × a/c) and c (b/c × a/c) are estimated on the lines the two pairs share
    assert "b" not in b
    for band, _ in sh.terms:
        x = b.index(band)
        assert sh.fraction[x].max(axis=0).mean() == pytest.approx(0.04 / 0.1025, abs=0.06)


def test_correlated_noise_has_the_modelled_covariance_at_the_bands_lag():
    rng = np.random.default_rng(6)
    sh = shared_band_noise(_band_noise(rng, 0.2, 0.05), PAIRS, TAUS, DT)
    sigma = np.full((3, N), 2.0)
    draws = np.array([correlated_noise(sigma, None, sh, DT, rng) for _ in range(40)])
    assert np.sqrt(np.mean(draws ** 2, axis=(0, 2))) == pytest.approx([2.0] * 3, rel=0.03)
    # a/b and a/c share a at their own lines (both ahead, both −): covariance +ρ σ² at lag 0
    rho = np.sqrt(sh.fraction[0, 0].mean() * sh.fraction[0, 2].mean())
    c0 = np.mean(draws[:, 0] * draws[:, 2]) / 4.0
    assert c0 == pytest.approx(rho, abs=0.04)
    # a/b and b/c share b: a/b's sample 18 lines on is b/c's own line, with opposite signs
    c18 = np.mean(draws[:, 0, :-18] * draws[:, 1, 18:]) / 4.0
    assert c18 < -0.3
    assert abs(np.mean(draws[:, 0] * draws[:, 1]) / 4.0) < 0.05        # not at the wrong lag
    # without a shared part it is the plain white noise
    assert correlated_noise(sigma, None, None, DT, np.random.default_rng(1)).shape == (3, N)


def _record(seed, band_sd, pair_sd):
    """A Wiener record of a known prior on differentials whose noise is ``_band_noise``."""
    f = np.fft.rfftfreq(8192, DT)
    shape = np.where((f >= 10.0) & (f <= 120.0), 1.0 / (1.0 + (f / 40.0) ** 2), 0.0)
    psd = shape * (2e-6) ** 2 / (2 * shape.sum() * (f[1] - f[0]))
    rng = np.random.default_rng(seed)
    th = prior_draw(f, psd, N + 80, DT, rng)
    d = simulated_differentials(th, TAUS, np.zeros((3, N)), np.ones((3, N), bool), DT) \
        + _band_noise(rng, band_sd, pair_sd)
    total = np.sqrt(2 * band_sd ** 2 + pair_sd ** 2)
    rec = IntegrationRecord(axis="pitch", pairs=PAIRS, diffs=d, sigmas=np.full((3, N), total), taus=np.array(TAUS),
                            lags_s=np.zeros((3, N)), weights=np.ones((3, N)), line_period_s=DT, method="wiener",
                            options={}, highpass_hz=0.0, spectrum=PriorSpectrum(f, psd, np.full(3, total)),
                            increment=np.zeros(N), previous=np.zeros(N))
    rec.increment = rec.rerun()
    return rec, th


@pytest.mark.parametrize("band_sd, pair_sd", [(0.2e-6, 0.05e-6), pytest.param(0.0, 0.3e-6, marks=pytest.mark.slow)])
def test_predicted_sigma_is_the_actual_error_when_bands_share_their_noise(band_sd, pair_sd):
    """The actual error over independent records of the model: with band noise the independent-pair model
    under-predicts it; the shared split does not, and it changes nothing much when no band is shared."""
    # the prediction follows its record's own noise (the residual check): averaged over a few records
    recs = [_record(5 + k, band_sd, pair_sd)[0] for k in range(3)]
    shared = np.sqrt(np.mean([posterior_sigma(r, samples=16, seed=7).detrended_rms ** 2 for r in recs]))
    independent = np.sqrt(np.mean([posterior_sigma(r, samples=16, seed=7, shared_bands=False).detrended_rms ** 2
                                   for r in recs]))
    errs = []
    for s in range(10):
        r, th = _record(100 + s, band_sd, pair_sd)
        e = r.increment - th[:N]
        errs.append(e - e.mean())
    actual = detrended_rms(np.array(errs))
    assert shared == pytest.approx(actual, rel=0.1)
    if band_sd > 0:
        assert independent < 0.9 * actual
    else:
        assert independent == pytest.approx(actual, rel=0.1)


def test_the_residual_of_the_fit_carries_the_shared_part():
    """Through the pipeline's own residual (differentials about the fit), not the bare noise."""
    rec, _ = _record(9, 0.2e-6, 0.05e-6)
    r = fit_residuals(rec.diffs, rec.increment, TAUS, rec.lags_s, DT, highpass_hz=0.0)
    sh = shared_band_noise(r, rec.pairs, rec.taus, DT)
    # 2 × 48.5 % of each pair's noise is shared, capped at SHARED_MAX_FRACTION: 45 % per band
    assert sh.fraction.max(axis=0).mean() == pytest.approx(0.45, abs=0.05)


def test_the_posterior_reports_each_bands_share():
    """What the Monte Carlo used is reported: each shared band's share of its pairs' noise (≈ 45 % here)."""
    rec, _ = _record(9, 0.2e-6, 0.05e-6)
    shares = posterior_sigma(rec, samples=4, seed=1).band_shares
    assert set(shares) == {"a", "b", "c"}
    assert all(v == pytest.approx(0.45, abs=0.06) for v in shares.values())
    assert posterior_sigma(rec, samples=4, seed=1, shared_bands=False).band_shares == {}
