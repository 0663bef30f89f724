"""Predicted σ per line (restore.posterior) against analytic cases: the Wiener error formula, gaps, noise checks."""
import numpy as np
import pytest

from restore.axis_integration import PriorSpectrum
from restore.knowledge_prior import spline_response
from restore.observability import observability
from restore.posterior import (
    detrended,
    detrended_rms,
    detrended_rows,
    knowledge_error_moments,
    draw_psd,
    fit_residual_rms,
    knowledge_noise_below,
    noise_per_line,
    posterior_sigma,
    prior_draw,
    simulated_differentials,
)
from restore.result import IntegrationRecord
from restore.stages import flag_uncertain, sigma_limit

TAUS = [7.4e-3, 14.8e-3, 22.2e-3]
DT = 4e-4
N = 3000


def _coloured_psd(f, rms=2e-6, corner=40.0, band=(10.0, 120.0)):
    """Two-sided PSD of a coloured jitter of ``rms`` [rad] (1/(1 + (f/corner)²) shape over ``band`` [Hz]).

    The band stays clear of the pairs' common blind frequency (135 Hz) and of
    the lowest frequencies, where a finite record does worse than the
    infinite-record Wiener formula (the reason σ is computed by Monte Carlo).
    """
    shape = np.where((f >= band[0]) & (f <= band[1]), 1.0 / (1.0 + (f / corner) ** 2), 0.0)
    df = f[1] - f[0]
    return shape * rms ** 2 / (2 * shape.sum() * df)


def _record(valid=None, noise=0.3e-6, seed=1, weights=None, noise_true=None, noise_colour=None, knowledge=None):
    """A record integrated with the frozen Wiener filter of a known prior and noise; diffs drawn from that model
    (the true noise: ``noise_true`` per line, white or with its power shaped by ``noise_colour(f)``). With
    ``knowledge = (noise_rad, rate_hz)`` the remaining error also holds the AOCS knowledge's white noise
    (``noise_rad`` per sample at ``rate_hz``, spline-interpolated), which the filter's prior leaves out."""
    f = np.fft.rfftfreq(8192, DT)
    psd = _coloured_psd(f)
    rng = np.random.default_rng(seed)
    th = prior_draw(f, psd, N + 80, DT, rng)
    if knowledge is not None:
        from scipy.interpolate import CubicSpline

        noise_rad, rate_hz = knowledge
        ts = (np.arange(int((N + 80) * DT * rate_hz) + 6) - 2) / rate_hz
        th = th + CubicSpline(ts, rng.standard_normal(ts.size) * noise_rad)(np.arange(N + 80) * DT)
    lags = np.zeros((3, N))
    valid = np.ones((3, N), bool) if valid is None else valid
    d = simulated_differentials(th, TAUS, lags, valid, DT)
    w = rng.standard_normal(d.shape)
    if noise_colour is not None:
        from scipy.fft import irfft, rfft
        w = irfft(rfft(w, axis=-1) * np.sqrt(noise_colour(np.fft.rfftfreq(N, DT))), n=N, axis=-1)
    d = d + (noise if noise_true is None else noise_true) * w
    spec = PriorSpectrum(f, psd, np.full(3, noise))
    rec = IntegrationRecord(axis="roll", pairs=["a/b", "b/c", "a/c"], diffs=d, sigmas=np.full((3, N), noise),
                            taus=np.array(TAUS), lags_s=lags, weights=np.ones((3, N)) if weights is None else weights,
                            line_period_s=DT, method="wiener", options={}, highpass_hz=0.0, spectrum=spec,
                            increment=np.zeros(N), previous=np.zeros(N))
    rec.increment = rec.rerun()
    return rec, th


def test_prior_draw_has_the_variance_of_its_psd():
    f = np.fft.rfftfreq(4096, DT)
    psd = _coloured_psd(f, rms=3e-6)
    rng = np.random.default_rng(0)
    v = np.mean([np.var(prior_draw(f, psd, 20000, DT, rng)) for _ in range(20)])
    assert np.sqrt(v) == pytest.approx(3e-6, rel=0.05)


def test_simulated_differentials_of_a_sine_are_exact():
    t = np.arange(N + 100) * DT
    th = np.sin(2 * np.pi * 20 * t)
    d = simulated_differentials(th, [7.4e-3], [np.zeros(N)], np.ones((1, N), bool), DT)
    ref = np.sin(2 * np.pi * 20 * (t[:N] + 7.4e-3)) - th[:N]
    assert np.max(np.abs(d[0] - ref)) < 1e-6


def test_mid_record_sigma_matches_the_stationary_wiener_error():
    """Far from the ends, the posterior σ of a stationary model is the Wiener error ``√(2 ∫ S / (1 + SNR) df)``."""
    rec, _ = _record()
    ps = posterior_sigma(rec, samples=48, seed=3, check_noise=False)
    mid = ps.sigma[N // 4: 3 * N // 4]
    floor = observability(rec.spectrum.freq, rec.spectrum.psd, rec.spectrum.noise_std, TAUS, DT).floor_rms_rad
    assert np.sqrt(np.mean(mid ** 2)) == pytest.approx(floor, rel=0.08)
    assert ps.noise_scale == 1.0 and ps.samples == 48


def test_sigma_is_the_spread_of_actual_errors_over_independent_records():
    """The σ the record predicts is the RMS error of the restoration over records drawn from the same model."""
    rec, _ = _record(seed=5)
    ps = posterior_sigma(rec, samples=24, seed=7, check_noise=False)
    errs = []
    for s in range(12):
        r, th = _record(seed=100 + s)
        e = r.increment - th[:N]
        errs.append(e - np.nanmean(e))
    actual = np.sqrt(np.nanmean(np.array(errs) ** 2))
    assert actual == pytest.approx(np.sqrt(np.nanmean(ps.sigma ** 2)), rel=0.15)
    # and without each record's least-squares line (what no pair sees), the predicted detrended RMS
    assert detrended_rms(np.array(errs)) == pytest.approx(ps.detrended_rms, rel=0.15)
    assert ps.detrended_rms < np.sqrt(np.nanmean(ps.sigma ** 2))


def test_detrended_rms_removes_each_draws_line():
    rng = np.random.default_rng(0)
    x = np.arange(3000)
    noise = rng.standard_normal((4, 3000)) * 0.1
    draws = noise + rng.standard_normal((4, 1)) * 5 + rng.standard_normal((4, 1)) * 1e-2 * x
    draws[1, 200:300] = np.nan
    assert detrended_rms(draws) == pytest.approx(0.1, rel=0.03)
    assert np.isnan(detrended_rms(np.full((2, 2), np.nan)))


def test_sigma_rises_on_a_short_island_between_gaps():
    valid = np.ones((3, N), bool)
    valid[:, 1000:1400] = False
    valid[:, 1460:1900] = False  # a 60-line clear island between two clouds
    rec, _ = _record(valid=valid)
    ps = posterior_sigma(rec, samples=16, seed=2, check_noise=False)
    island = np.nanmean(ps.sigma[1465:1455 + 60 - 5])
    far = np.nanmean(ps.sigma[2300:2700])
    assert island > 1.5 * far
    flagged_corr, flagged = flag_uncertain({"roll": rec.increment}, {"roll": ps}, "auto", 1e-6)
    assert flagged["roll"][1465:1510].any() and not flagged["roll"][2300:2700].any()
    assert np.all(np.isnan(flagged_corr["roll"][flagged["roll"]]))


def test_noise_larger_than_modelled_is_caught_by_the_residual_check():
    rec, _ = _record(noise=0.1e-6, noise_true=0.3e-6)
    ps = posterior_sigma(rec, samples=8, seed=1, check_noise=True)
    assert ps.noise_scale == pytest.approx(3.0, rel=0.15)
    ok, _ = _record(noise=0.1e-6)
    assert posterior_sigma(ok, samples=8, seed=1, check_noise=True).noise_scale == 1.0


def test_weights_lower_the_noise_of_heavy_lines():
    w = np.ones((3, N))
    w[:, : N // 2] = 4.0
    rec, _ = _record(weights=w)
    sig = noise_per_line(rec)
    # mean-1 weights: (4, 1) → (1.6, 0.4); σ ∝ 1/√w
    assert sig[0, 0] / sig[0, -1] == pytest.approx(0.5, rel=1e-9)


def test_lines_of_weight_zero_keep_a_finite_noise_and_a_finite_sigma():
    """Filled lines carry weight 0 (the integration ignores them): the Monte Carlo's noise there is the
    pair's level, not 1/0, and the predicted σ stays finite and close to the all-weights-one one."""
    w = np.ones((3, N))
    w[:, 300:303] = 0.0
    rec, _ = _record(weights=w)
    sig = noise_per_line(rec)
    assert np.all(np.isfinite(sig))
    assert sig[0, 301] == pytest.approx(0.3e-6, rel=1e-12)             # the pair's level
    assert sig[0, 0] == pytest.approx(0.3e-6, rel=1e-3)
    ps = posterior_sigma(rec, samples=8, seed=0)
    ref = posterior_sigma(_record()[0], samples=8, seed=0)
    assert np.all(np.isfinite(ps.sigma))
    assert np.sqrt(np.mean(ps.sigma ** 2)) == pytest.approx(np.sqrt(np.mean(ref.sigma ** 2)), rel=0.15)


def test_fit_residual_of_a_perfect_estimate_is_the_noise():
    t = np.arange(N + 100) * DT
    th = 1e-6 * np.sin(2 * np.pi * 30 * t)
    valid = np.ones((3, N), bool)
    rng = np.random.default_rng(0)
    d = simulated_differentials(th, TAUS, np.zeros((3, N)), valid, DT) + 1e-8 * rng.standard_normal((3, N))
    assert fit_residual_rms(d, th[:N], TAUS, np.zeros((3, N)), DT, highpass_hz=0.0) == pytest.approx(1e-8, rel=0.1)


def test_knowledge_noise_below_the_highpass_is_the_low_band_of_white_noise():
    rng = np.random.default_rng(0)
    n, hp, rate, sig = 200000, 2.0, 50.0, 1e-6
    x = knowledge_noise_below(n, DT, hp, sig, rate, rng)
    # white at 50 Hz, Gaussian low-pass with -3 dB at 2 Hz: ≈ σ² · ∫ |H|² df / (rate / 2)
    sigma_g = np.sqrt(np.log(2)) / (2 * np.pi * hp)
    band = 1 / (4 * np.sqrt(np.pi) * sigma_g)  # ∫_0^∞ exp(-4π²σ²f²) df
    assert np.std(x) == pytest.approx(sig * np.sqrt(band / (rate / 2)), rel=0.15)
    assert not knowledge_noise_below(100, DT, 0.0, sig, rate, rng).any()


def test_sigma_limit_auto_and_in_pixels():
    s = np.array([1.0, 1.0, 1.0, np.nan, 10.0])
    assert sigma_limit(s, "auto", 0.5) == pytest.approx(3.0)
    assert sigma_limit(s, 0.1, 7e-6) == pytest.approx(0.7e-6)


def test_same_seed_same_bytes():
    rec, _ = _record()
    a = posterior_sigma(rec, samples=4, seed=9).sigma
    b = posterior_sigma(rec, samples=4, seed=9).sigma
    assert a.tobytes() == b.tobytes()
    with pytest.raises(ValueError, match="samples"):
        posterior_sigma(rec, samples=1)


def test_noise_rising_in_a_band_is_caught_band_by_band():
    """Matching noise 8× the white level in power over 10–40 Hz: the prediction follows the actual errors."""
    def colour(f):
        return np.where((f >= 10.0) & (f <= 40.0), 8.0, 1.0)

    rec, _ = _record(seed=5, noise_colour=colour)
    ps = posterior_sigma(rec, samples=16, seed=7, check_noise=True)
    white = posterior_sigma(rec, samples=16, seed=7, check_noise=False)
    errs = []
    for s in range(10):
        r, th = _record(seed=200 + s, noise_colour=colour)
        e = r.increment - th[:N]
        errs.append(e - np.nanmean(e))
    actual = np.sqrt(np.nanmean(np.array(errs) ** 2))
    predicted = np.sqrt(np.nanmean(ps.sigma ** 2))
    assert actual == pytest.approx(predicted, rel=0.2)
    assert np.sqrt(np.nanmean(white.sigma ** 2)) < 0.8 * actual      # the white model alone is optimistic
    assert ps.noise_scale > 1.0                                        # (an RMS over all frequencies)


def test_prior_draw_high_pass_is_the_whole_signals():
    """The Monte Carlo's reference: the draw's high-pass on the periodic signal it is cut from — the same as
    the record-only high-pass in the interior, and free of its end effects."""
    from restore.posterior import prior_draw
    from restore.synthesis import highpass_nan

    dt, n = 4e-4, 4000
    freq = np.linspace(0, 1250, 5001)
    psd = np.where((freq > 2.5) & (freq < 9.0), 1e-12, 0.0)           # 3–8 Hz lines' band
    rng = np.random.default_rng(3)
    draw, hp = prior_draw(freq, psd, n, dt, rng, highpass_hz=0.4)
    assert draw.shape == hp.shape == (n,)
    np.testing.assert_allclose(hp - np.mean(hp), draw - np.mean(draw), atol=2e-3 * np.std(draw))   # nothing below 0.4 Hz
    record_only = highpass_nan(draw, dt=dt, cutoff_hz=0.4)
    mid = slice(1500, 2500)
    np.testing.assert_allclose(record_only[mid] - hp[mid], np.mean(record_only[mid] - hp[mid]),
                               atol=0.02 * np.std(draw))
    ends = np.r_[0:100, n - 100:n]
    assert np.std((record_only - hp)[ends]) > 5 * np.std((record_only - hp)[mid])
    # without a high-pass: the draw alone, as before
    assert isinstance(prior_draw(freq, psd, n, dt, np.random.default_rng(3)), np.ndarray)


def test_the_noise_check_resolves_the_lowest_frequencies_bin_by_bin():
    """The integration amplifies noise as 1 / (2π f τ): an excess in the 3 lowest bins must not be diluted in a
    16-bin band, where it would not count."""
    from restore.posterior import CHECK_BAND_BINS, _band_edges, noise_colour_from_check

    n = 4000
    edges = _band_edges(n)
    assert edges[:4] == [1, 2, 3, 4] and edges[-1] == n // 2 + 1
    widths = np.diff(edges)
    assert np.all(widths >= 1) and widths[-2] >= CHECK_BAND_BINS
    sim = np.ones((3, len(edges) - 1))                       # the white model's residual power per band
    real = sim.copy()
    real[:, :3] = 30.0                                       # a slow excess in bins 1-3, 30× the white power
    colour = noise_colour_from_check(real, sim, edges, n)
    np.testing.assert_allclose(colour[:, 1:4], 30.0)          # found where it is, at its level
    assert np.all(colour[:, 8:] < 1.0 + 1e-12)                # and not spread beyond
    # 5× in a one-bin band is within a periodogram's scatter (exponential), 5× over 16 bins is not
    real[:, :3] = 5.0
    assert np.all(noise_colour_from_check(real, sim, edges, n)[:, 1:4] == 1.0)
    wide = [1, 17, n // 2 + 1]
    assert noise_colour_from_check(np.array([[5.0, 1.0]]), np.ones((1, 2)), wide, n)[0, 5] > 4.0


def test_the_check_rarely_raises_a_band_of_a_noise_the_model_describes():
    """Under the white model (real and simulated residuals both white), a pair gets some band raised in about
    CHECK_FALSE_ALARM of the records."""
    from restore.posterior import CHECK_FALSE_ALARM, _band_edges, band_power, noise_colour_from_check

    n, draws, trials = 1000, 8, 400
    edges = _band_edges(n)
    rng = np.random.default_rng(21)
    raised = 0
    for _ in range(trials):
        real = band_power(rng.standard_normal((1, n)), edges)
        sim = np.mean([band_power(rng.standard_normal((1, n)), edges) for _ in range(draws)], axis=0)
        raised += bool(np.any(noise_colour_from_check(real, sim, edges, n, draws=draws) > 1.0))
    assert raised / trials < 3 * CHECK_FALSE_ALARM + 0.01


def test_the_colour_estimate_is_unbiased_where_the_check_drops_a_modest_excess():
    """Under the white model the estimated factors average 1 in every band (one-bin ones included); a 3×
    excess in the three lowest bins, which the significance test keeps at 1 in most records, is estimated at
    3 on average: the predicted σ follows it instead of falling short."""
    from restore.posterior import _band_edges, band_power, noise_colour_estimate, noise_colour_from_check

    n, draws, trials = 1000, 8, 1000
    edges = _band_edges(n)
    rng = np.random.default_rng(22)
    boost = np.ones(n // 2 + 1)
    boost[1:4] = 3.0

    def coloured(k):
        from scipy.fft import irfft, rfft
        return irfft(rfft(rng.standard_normal((k, n)), axis=-1) * np.sqrt(boost), n=n, axis=-1)

    white, excess, tested = [], [], []
    for _ in range(trials):
        sim = np.mean([band_power(rng.standard_normal((1, n)), edges) for _ in range(draws)], axis=0)
        white.append(noise_colour_estimate(band_power(rng.standard_normal((1, n)), edges), sim, edges, n,
                                           draws=draws)[0])
        real = band_power(coloured(1), edges)
        excess.append(noise_colour_estimate(real, sim, edges, n, draws=draws)[0])
        tested.append(noise_colour_from_check(real, sim, edges, n, draws=draws)[0])
    white, excess, tested = map(np.array, (white, excess, tested))
    # unbiased on white noise, bin by bin at the bottom and over the wide bands (up to the 0.25 floor's clip)
    np.testing.assert_allclose(white[:, 1:4].mean(axis=0), 1.0, atol=0.12)
    assert white[:, 40:].mean() == pytest.approx(1.0, abs=0.03)
    # the modest excess: estimated at its level on average, where the test mostly sees nothing
    np.testing.assert_allclose(excess[:, 1:4].mean(axis=0), 3.0, rtol=0.15)
    assert np.mean(tested[:, 1:4] > 1.0) < 0.3


def _band_noise(rng, level):
    """Noise of the pairs a/b, b/c, a/c made of each band's own error, entering every pair that sees the band
    (behind: at the pair's delay, +; ahead: −), plus a small independent part: the pairs' noises correlate."""
    m = N + 80
    e = {b: level * rng.standard_normal(m) for b in "abc"}
    idx = np.arange(N)
    out = []
    for (x, y), tau in zip([("a", "b"), ("b", "c"), ("a", "c")], TAUS):
        k = int(round(tau / DT))
        out.append(e[y][idx + k] - e[x][idx] + 0.2 * level * rng.standard_normal(N))
    return np.array(out)


def _record_with_noise(seed, noise_fn, level=0.25e-6):
    rec, th = _record(seed=seed, noise=level * np.sqrt(2.04))
    rng = np.random.default_rng(1000 + seed)
    d = simulated_differentials(th, TAUS, np.zeros((3, N)), np.ones((3, N), bool), DT)
    n = noise_fn(rng, level)
    rec.diffs = d + n
    rec.increment = rec.rerun()
    return rec, th, n


def test_local_error_sigma_of_white_independent_noise_is_the_models():
    """Given the record's own white noise as the measured local error, the surrogate predicts what the white
    model with that level predicts (mid-record, within the draws' scatter)."""
    from restore.posterior import local_error_sigma
    rec, th = _record(seed=2)
    noise = rec.diffs - simulated_differentials(th, TAUS, np.zeros((3, N)), np.ones((3, N), bool), DT)
    loc = local_error_sigma(rec, noise, samples=32, seed=4)
    model = posterior_sigma(rec, samples=32, seed=4, check_noise=False)
    mid = slice(N // 4, 3 * N // 4)
    assert np.sqrt(np.mean(loc.sigma[mid] ** 2)) == pytest.approx(np.sqrt(np.mean(model.sigma[mid] ** 2)), rel=0.1)
    with pytest.raises(ValueError, match="shape"):
        local_error_sigma(rec, noise[:2], samples=4)


def test_local_error_sigma_of_band_shared_noise_is_the_spread_of_actual_errors():
    """When the pairs share their bands' errors, the surrogate of one record's noise (its cross-spectra kept)
    predicts the RMS error over independent records of that noise; the independent white model of the same
    per-pair level falls short."""
    from restore.posterior import local_error_sigma
    rec, _, n = _record_with_noise(3, _band_noise)
    loc = local_error_sigma(rec, n, samples=24, seed=5)
    errs = []
    for s in range(12):
        r, th, _ = _record_with_noise(200 + s, _band_noise)
        e = r.increment - th[:N]
        errs.append(e - np.mean(e))
    actual = np.sqrt(np.mean(np.array(errs) ** 2))
    assert actual == pytest.approx(np.sqrt(np.nanmean(loc.sigma ** 2)), rel=0.15)
    white = posterior_sigma(rec, samples=24, seed=5, check_noise=False)
    assert np.sqrt(np.nanmean(white.sigma ** 2)) < 0.9 * actual      # 0.84 × measured


def test_larger_sigma_takes_the_larger_per_line_and_keeps_the_models_check():
    from restore.posterior import PosteriorSigma, larger_sigma
    colour = np.ones((3, 5))
    a = PosteriorSigma(sigma=np.array([1.0, 2.0, np.nan, 4.0]), noise_scale=1.3, samples=8, noise_colour=colour,
                       detrended_rms=2.0, detrended_sigma=np.array([1.0, 1.0, np.nan, 1.0]), band_shares={"b": 0.2})
    b = PosteriorSigma(sigma=np.array([3.0, 1.0, 5.0, np.nan]), noise_scale=1.0, samples=8, detrended_rms=2.5,
                       detrended_sigma=np.array([0.5, 2.0, 1.0, 1.0]))
    c = larger_sigma(a, b)
    assert c.sigma.tolist()[:2] == [3.0, 2.0] and np.isnan(c.sigma[2]) and c.sigma[3] == 4.0
    assert c.detrended_sigma.tolist()[:2] == [1.0, 2.0] and c.detrended_rms == 2.5 and c.local_detrended_rms == 2.5
    assert c.noise_colour is colour and c.noise_scale == 1.3 and c.band_shares == {"b": 0.2}
    assert c.model_sigma is a.sigma


def test_auto_flags_follow_the_models_sigma_when_the_local_error_raised_it():
    """"auto" flags where the model's σ rises above 3 × its median; a raised, flat σ does not hide those lines.
    A limit in pixels judges the σ reported."""
    from restore.posterior import PosteriorSigma, larger_sigma
    model_s = np.full(100, 1.0)
    model_s[:5] = 4.0                                   # a record end where the model's σ rises
    model = PosteriorSigma(sigma=model_s, noise_scale=1.0, samples=8)
    local = PosteriorSigma(sigma=np.full(100, 2.0), noise_scale=1.0, samples=8)
    both = larger_sigma(model, local)                   # 4 at the end, 2 elsewhere: under 3 × its median
    _, flagged = flag_uncertain({"roll": np.zeros(100)}, {"roll": both}, "auto", 1.0)
    assert flagged["roll"][:5].all() and not flagged["roll"][5:].any()
    _, flagged = flag_uncertain({"roll": np.zeros(100)}, {"roll": both}, 1.5, 1.0)
    assert flagged["roll"].all()


def test_sigma_counts_the_knowledge_noise_the_prior_left_out():
    """The remaining error holds the knowledge's white noise whatever the prior says: where the prior is below it
    (here 0 below 10 Hz) the filter leaves it, and the draws taken from the prior raised to that floor
    (:func:`restore.posterior.draw_psd`) predict the spread of actual errors; from the prior alone, a fraction."""
    kn, kr = 0.5e-6, 64.0
    rec, _ = _record(seed=5, knowledge=(kn, kr))
    with_k = posterior_sigma(rec, samples=24, seed=7, check_noise=False, knowledge_noise_rad=kn, knowledge_rate_hz=kr)
    without = posterior_sigma(rec, samples=24, seed=7, check_noise=False)
    errs = []
    for s in range(12):
        r, th = _record(seed=100 + s, knowledge=(kn, kr))
        e = r.increment - th[:N]
        errs.append(e - np.mean(e))
    actual = np.sqrt(np.mean(np.array(errs) ** 2))
    assert np.sqrt(np.nanmean(with_k.sigma ** 2)) == pytest.approx(actual, rel=0.15)
    assert np.sqrt(np.nanmean(without.sigma ** 2)) < 0.3 * actual


def test_draw_psd_is_the_prior_raised_to_the_knowledges_white_noise():
    f = np.linspace(0.0, 100.0, 1001)
    prior = np.where(f > 20.0, 1e-13, 0.0)
    out = draw_psd(f, prior, 0.3e-6, 64.0)
    floor = (0.3e-6) ** 2 / 64.0 * spline_response(f, 64.0) ** 2
    below = f <= 32.0
    np.testing.assert_allclose(out[below], np.maximum(prior, floor)[below])
    np.testing.assert_array_equal(out[~below], prior[~below])   # no noise above the knowledge's Nyquist
    assert out[0] == pytest.approx(0.3e-6 ** 2 / 64.0)
    np.testing.assert_array_equal(draw_psd(f, prior, 0.0, 64.0), prior)
    np.testing.assert_array_equal(draw_psd(f, prior, 0.3e-6, None), prior)


def test_extended_lines_hold_the_longest_delay_and_lag_beyond_the_record():
    """A 10 ms delay and lags up to 3 ms at 1 ms a line: 13 lines beyond the record, and the 8-line margin."""
    from restore.posterior import extended_lines

    lags = [np.array([0.002, -0.003]), np.zeros(2)]
    assert extended_lines(100, [0.004, 0.01], lags, 0.001) == 100 + 13 + 8
    assert extended_lines(100, [0.01], [np.zeros(2)], 0.001) == 100 + 10 + 8


def test_the_knowledge_part_of_sigma_does_not_hang_on_the_few_integration_draws():
    """On a short record the smoothing passes a few degrees of freedom of the knowledge's noise whole (the
    polynomial it keeps; every other gain 0 here): the integration's eight draws would estimate their spread to
    ± 25 %. Drawn apart (:func:`knowledge_error_moments`), the knowledge's part of the predicted RMS is within
    12 % of a 4000-draw Monte Carlo of the same error for every seed, however few the integration's draws (two
    here), and adds to the images' part in quadrature."""
    from dataclasses import replace as _replace

    from restore.knowledge_smoothing import KnowledgeSmoothing, lowband_rows

    rec, _ = _record(seed=5)
    rec = _replace(rec, highpass_hz=2.0)
    rec.increment = rec.rerun()
    t = np.arange(int(N * DT * 64.0) + 1) / 64.0
    sm = KnowledgeSmoothing(t, 0.3e-6, 2, np.zeros(t.size))
    rng = np.random.default_rng(99)
    lines = np.arange(N) * DT
    # batched (lowband_rows is lowband row by row: test_knowledge_smoothing) and independent of the prediction's
    ref = np.concatenate([lowband_rows(sm.error_draws(rng, 500), t, lines, line_period_s=DT, highpass_hz=2.0)
                          for _ in range(8)])
    ref = np.sqrt(np.mean(detrended(ref - ref.mean(axis=1, keepdims=True)) ** 2))
    parts = []
    for seed in range(4):
        without = posterior_sigma(rec, samples=2, seed=seed, check_noise=False)
        with_k = posterior_sigma(rec, samples=2, seed=seed, check_noise=False, knowledge_smoothing=sm)
        parts.append(np.sqrt(with_k.detrended_rms ** 2 - without.detrended_rms ** 2))
        assert np.all(with_k.sigma >= without.sigma)
    assert np.array(parts) == pytest.approx(ref, rel=0.12)
    assert knowledge_error_moments(_replace(rec, highpass_hz=0.0), np.ones(N, bool), np.random.default_rng(1),
                                   knowledge_smoothing=sm) is None


def test_the_knowledge_moments_are_the_low_band_of_white_noise_and_the_row_helpers_agree():
    """Raw knowledge noise (white, 0.5 µrad per sample at 50 Hz, 2 Hz high-pass, a 20 s record): the mean square
    the moments give is ``σ² ∫|L|² df / (f_k / 2)`` (L: the Gaussian low-pass), and its detrended figures are
    :func:`detrended` row by row."""
    from types import SimpleNamespace

    sig, rate, hp, n = 0.5e-6, 50.0, 2.0, 50000
    rec = SimpleNamespace(line_period_s=DT, highpass_hz=hp)
    m = np.ones(n, bool)
    mo = knowledge_error_moments(rec, m, np.random.default_rng(3), knowledge_noise_rad=sig, knowledge_rate_hz=rate,
                                 draws=64)
    sigma_g = np.sqrt(np.log(2)) / (2 * np.pi * hp)
    band = 1 / (4 * np.sqrt(np.pi) * sigma_g)            # ∫_0^∞ exp(-4π²σ²f²) df
    assert np.sqrt(np.mean(mo.line_ms[5000:45000])) == pytest.approx(sig * np.sqrt(band / (rate / 2)), rel=0.08)
    assert mo.detrended_ms < np.nanmean(mo.line_ms) and mo.draws == 64
    assert knowledge_error_moments(rec, m, np.random.default_rng(3)) is None      # no noise given: not counted
    x = np.random.default_rng(4).standard_normal((3, N)).cumsum(axis=1)
    mm = np.ones(N, bool)
    mm[:40] = False
    np.testing.assert_allclose(detrended_rows(x, mm), detrended(np.where(mm, x, np.nan)), atol=1e-12,
                               equal_nan=True)
