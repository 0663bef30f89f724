"""Lines whose matches are worse for a known cause (stretched windows, gap edges): weighed by how the fit residual
grows with it."""
import numpy as np
import pytest

from restore.axis_integration import integrate_axis
from restore.line_weights import gap_distance, isotonic_increasing, residual_weight_factors, window_stretch
from restore.posterior import fit_residuals

DT = 4e-4
TAUS = (0.0074, 0.0148, 0.0222)
IFOV = 4e-6
N = 4000


def test_isotonic_pools_adjacent_violators_and_keeps_a_monotone_series():
    assert isotonic_increasing([1.0, 3.0, 2.0, 4.0]).tolist() == [1.0, 2.5, 2.5, 4.0]
    assert isotonic_increasing([3.0, 2.0, 1.0]).tolist() == [2.0, 2.0, 2.0]
    np.testing.assert_array_equal(isotonic_increasing([0.0, 1.0, 5.0]), [0.0, 1.0, 5.0])
    # weighted: the heavier value dominates the pooled block
    np.testing.assert_allclose(isotonic_increasing([4.0, 1.0], [3.0, 1.0]), [3.25, 3.25])
    with pytest.raises(ValueError, match="one length"):
        isotonic_increasing([1.0, 2.0], [1.0])


def test_stretch_is_the_lag_change_per_line():
    lag = 0.3 * np.arange(100.0)
    np.testing.assert_allclose(window_stretch(lag), 0.3)
    np.testing.assert_allclose(window_stretch(-lag), 0.3)
    two = window_stretch(np.array([np.sin(np.arange(50.0)), np.full(50, np.nan)]))
    assert two.shape == (2, 50) and np.all(two[1] == 0.0)       # no lag known: no stretch


def test_factors_follow_a_known_growth_of_the_residual_variance():
    """Residual σ² = σ0² (1 + (s / 0.5)²): the factor at s is 1 / (1 + (s / 0.5)²) relative to s ≈ 0."""
    rng = np.random.default_rng(3)
    s = rng.uniform(0.0, 2.0, (2, 20000))
    var = 1.0 + (s / 0.5) ** 2
    r = rng.standard_normal(s.shape) * np.sqrt(var)
    f = residual_weight_factors(r, s)
    expected = 1.0 / var
    # the least stretched bin's variance (its median stretch ≈ 0.05) is the reference
    expected *= 1.0 + (0.05 / 0.5) ** 2
    mid = (s > 0.2) & (s < 1.8)
    np.testing.assert_allclose(f[mid], expected[mid], rtol=0.25)
    assert np.all((f > 0) & (f <= 1.0 + 1e-12))


def test_factors_stay_near_one_where_the_residual_does_not_grow():
    rng = np.random.default_rng(4)
    s = rng.uniform(0.0, 2.0, (3, 4000))
    f = residual_weight_factors(rng.standard_normal(s.shape), s)
    assert np.median(f) > 0.85 and f.min() > 0.6


def test_too_few_lines_or_unusable_lines_keep_the_weights():
    rng = np.random.default_rng(5)
    s = rng.uniform(0.0, 2.0, (1, 80))
    r = rng.standard_normal((1, 80)) * (1 + 10 * s)
    np.testing.assert_array_equal(residual_weight_factors(r, s), 1.0)          # < 10 bins of 50 lines
    s = rng.uniform(0.0, 2.0, (1, 4000))
    r = rng.standard_normal((1, 4000)) * (1 + 10 * s)
    usable = np.zeros((1, 4000), dtype=bool)
    np.testing.assert_array_equal(residual_weight_factors(r, s, usable), 1.0)
    with pytest.raises(ValueError, match="one shape"):
        residual_weight_factors(r, s[:, :10])


def _stretched_record(seed=0):
    """CMG-like attitude seen at t + τ + λ; the lag λ oscillates (its change per line up to ~1.2 lines) and
    the matching noise grows with the stretch as on large_amplitude (0.09 px, × 4 where most stretched)."""
    rng = np.random.default_rng(seed)
    t = np.arange(N) * DT

    def theta(x):
        return 2e-6 * sum(np.sin(2 * np.pi * f * x + k) for k, f in enumerate((52.7, 58.9, 63.4, 74.1)))

    diffs, lags, stretch = [], [], []
    for j, tau in enumerate(TAUS):
        lag = 8.0 * np.sin(2 * np.pi * (61.0 + 3 * j) * t + j) * DT           # up to 8 lines: ≤ 1.2-1.3 lines/line
        st = window_stretch(lag / DT)
        noise = 0.09 * IFOV * (1.0 + 3.0 * np.clip(st - 0.8, 0.0, None) / 0.4) * rng.standard_normal(N)
        diffs.append(theta(t + tau + lag) - theta(t) + noise)
        lags.append(lag)
        stretch.append(st)
    return t, theta(t), diffs, lags, np.array(stretch)


def _rms_px(e):
    e = e[np.isfinite(e)]
    return float(np.sqrt(np.mean((e - e.mean()) ** 2))) / IFOV


def test_weighing_the_stretched_lines_restores_with_less_error():
    t, truth, diffs, lags, stretch = _stretched_record()
    first = integrate_axis(diffs, TAUS, DT, method="wiener", lags=lags, transient_factor=0.0)
    res = fit_residuals(np.array(diffs), first.theta, TAUS, lags, DT, highpass_hz=2.0)
    f = residual_weight_factors(res, stretch)
    assert f[stretch > 1.1].mean() < 0.3 * f[stretch < 0.5].mean()
    again = integrate_axis(diffs, TAUS, DT, method="wiener", lags=lags, weights=list(f), transient_factor=0.0)
    from restore.synthesis import highpass_nan
    ref = highpass_nan(truth, dt=DT, cutoff_hz=2.0)
    e0, e1 = _rms_px(first.theta - ref), _rms_px(again.theta - ref)
    assert e1 < 0.85 * e0, (e0, e1)


def test_the_pipeline_step_gives_each_pair_and_axis_its_factors_and_can_be_switched_off():
    from types import SimpleNamespace

    from restore import stages
    from restore.settings import RestorationSettings

    t, truth, diffs, lags, stretch = _stretched_record(seed=1)
    first = integrate_axis(diffs, TAUS, DT, method="wiener", lags=lags, transient_factor=0.0)
    rec = SimpleNamespace(diffs=np.array(diffs), increment=first.theta, taus=np.array(TAUS), lags_s=np.array(lags),
                          highpass_hz=2.0, method="wiener", weights=np.full((3, N), 24.0))
    pds = [stages.PairDifferentials(tau_s=tau, diffs={"roll": d}, sigmas={"roll": np.full(N, IFOV)}, lag_s=lag,
                                    weight=np.full(N, 24.0)) for tau, d, lag in zip(TAUS, diffs, lags)]
    factors = stages.line_weight_factors(pds, {"roll": rec}, RestorationSettings(), DT)
    assert len(factors) == 3 and all(set(f) == {"roll"} for f in factors)
    pds[0].axis_factor = factors[0]
    np.testing.assert_allclose(pds[0].weight_for("roll"), 24.0 * factors[0]["roll"])
    np.testing.assert_array_equal(pds[0].weight_for("pitch"), 24.0)          # no factor for that axis
    assert factors[0]["roll"][stretch[0] > 1.1].mean() < 0.3
    off = stages.line_weight_factors(pds, {"roll": rec}, RestorationSettings(line_weighting=False), DT)
    assert off == [{}, {}, {}]
    # one pair: the fit absorbs its noise, its residual measures nothing — no weighting
    one = SimpleNamespace(diffs=rec.diffs[:1], increment=first.theta, taus=rec.taus[:1], lags_s=rec.lags_s[:1],
                          highpass_hz=2.0, method="wiener", weights=rec.weights[:1])
    # a method that ignores line weights gets none
    lsq = SimpleNamespace(**{**vars(rec), "method": "lsq"})
    assert stages.line_weight_factors(pds, {"roll": lsq}, RestorationSettings(), DT) == [{}, {}, {}]
    assert stages.line_weight_factors(pds[:1], {"roll": one}, RestorationSettings(), DT) == [{}]


def test_gap_distance_counts_lines_to_the_nearest_unusable_one():
    u = np.ones(12, dtype=bool)
    u[4:6] = False
    np.testing.assert_array_equal(gap_distance(u), [4, 3, 2, 1, 0, 0, 1, 2, 3, 4, 5, 6])
    assert np.all(gap_distance(np.ones((2, 7), dtype=bool)) == 7)          # the record's ends are not gaps


def test_closeness_to_a_gap_is_weighed_down_when_the_residual_says_so():
    rng = np.random.default_rng(8)
    usable = np.ones((2, 6000), dtype=bool)
    for start in range(300, 6000, 700):
        usable[:, start:start + 60] = False                                # clouds
    dist = gap_distance(usable)
    sigma = 1.0 + 2.0 * np.exp(-dist / 15.0)                               # 3 × next to a gap, 1 × far
    r = np.where(usable, rng.standard_normal(usable.shape) * sigma, np.nan)
    f = residual_weight_factors(r, dist, usable, increasing=False)
    near, far = usable & (dist <= 2), usable & (dist > 100)
    assert 0.08 < np.median(f[near]) < 0.2                                  # ≈ 1 / 3² … 1 / 2.5²
    assert np.median(f[far]) > 0.85


def test_a_cause_the_weights_already_model_is_not_counted_twice():
    """Residual variance ∝ 1 / weight, the weight falling with the stretch: normalised, nothing is left."""
    rng = np.random.default_rng(9)
    s = rng.uniform(0.0, 2.0, (2, 8000))
    w = 24.0 / (1.0 + (s / 0.5) ** 2)
    r = rng.standard_normal(s.shape) / np.sqrt(w)
    raw = residual_weight_factors(r, s)
    normalised = residual_weight_factors(r, s, weights=w)
    assert np.median(raw[s > 1.5]) < 0.2
    # (the integration normalises the weights to a mean of 1: only the spread between lines matters)
    assert np.median(normalised[s > 1.5]) > 0.8 * np.median(normalised[s < 0.3])


def test_the_reweighted_integration_skips_the_tone_search_only_where_none_was_found(monkeypatch):
    from restore import axis_integration, stages
    from restore.settings import RestorationSettings

    t, truth, diffs, lags, stretch = _stretched_record(seed=2)
    pds = [stages.PairDifferentials(tau_s=tau, diffs={"roll": d}, sigmas={"roll": np.full(N, IFOV)}, lag_s=lag,
                                    weight=np.full(N, 24.0)) for tau, d, lag in zip(TAUS, diffs, lags)]
    settings = RestorationSettings(highpass_hz=2.0)          # "auto" is resolved from the product upstream
    first = stages.integrate_differentials("roll", [], pds, np.zeros(N), settings, DT)
    assert first.spectrum.tones is None

    def searched(*args, **kwargs):
        raise AssertionError("the blind-tone search ran")

    monkeypatch.setattr(axis_integration, "blind_tones", searched)
    again = stages.integrate_differentials("roll", [], pds, np.zeros(N), settings, DT, no_blind_tone=True)
    np.testing.assert_array_equal(again.increment, first.increment)
    with pytest.raises(AssertionError, match="search ran"):
        stages.integrate_differentials("roll", [], pds, np.zeros(N), settings, DT)


def test_a_few_gross_lines_do_not_weigh_down_the_record():
    """A cluster of 10 lines at 6 σ (the despiker keeps such runs: their neighbours are off too) must not raise a
    bin's mean square and, through the pooling, every bin above it."""
    rng = np.random.default_rng(12)
    s = rng.uniform(0.0, 2.0, (1, 6000))
    r = rng.standard_normal(s.shape)
    r[0, np.argsort(s[0])[1000:1010]] = 6.0
    f = residual_weight_factors(r, s)
    assert np.mean(f < 0.8 * np.median(f)) < 0.05


def test_stretch_ignores_the_missing_lags_of_a_gap_and_the_ends_are_no_gap():
    lag = np.linspace(0.0, 3.0, 40)
    lag[10:20] = np.nan
    st = window_stretch(lag)
    np.testing.assert_allclose(st[np.isfinite(lag)], 3.0 / 39, rtol=1e-9)     # no jump into the gap
    usable = np.ones(30, dtype=bool)
    usable[:5] = usable[-5:] = False                  # unusable runs that reach the record's ends
    d = gap_distance(usable)
    assert np.all(d[5:-5] == 30) and np.all(d[:5] == 0)
