"""Low frequencies: the high-pass of the estimate follows what the AOCS knowledge covers (recorded in product.nc)."""
import numpy as np
import pytest
from types import SimpleNamespace

from restore.axis_integration import integrate_axis
from restore.stages import HIGHPASS_FRACTION_OF_KNOWLEDGE, highpass_from_product
from restore.synthesis import highpass_nan


def _product(attrs):
    return SimpleNamespace(ds=SimpleNamespace(attrs=attrs))


def test_auto_highpass_is_derived_from_the_recorded_knowledge_cutoff():
    assert highpass_from_product("auto", _product({"knowledge_cutoff_hz": 10.0})) == pytest.approx(2.0)
    assert highpass_from_product("auto", _product({"knowledge_cutoff_hz": 2.0})) == pytest.approx(0.4)
    assert highpass_from_product("auto", _product({})) == 2.0          # an older product: the former default
    assert highpass_from_product(0.7, _product({"knowledge_cutoff_hz": 2.0})) == 0.7   # a number is kept


def test_highpass_gain_is_the_gaussian_complement():
    """highpass_nan subtracts a Gaussian low-pass whose −3 dB point is the cut-off: gain 1 − 2^(−(f/fc)²/2)."""
    dt, n = 4e-4, 20000
    t = np.arange(n) * dt
    for f, fc in ((3.3, 2.0), (3.3, 0.4), (8.0, 2.0)):
        y = highpass_nan(np.sin(2 * np.pi * f * t), dt=dt, cutoff_hz=fc)[2000:-2000]
        expected = 1.0 - 2.0 ** (-(f / fc) ** 2 / 2)   # low-pass exp(−2π²σ²f²), σ = √ln2 / (2π fc)
        assert np.sqrt(2 * np.mean(y ** 2)) == pytest.approx(expected, rel=0.01)


def test_a_line_the_aocs_does_not_know_survives_the_auto_highpass():
    """A 3.3 Hz line under a 2 Hz AOCS: a fixed 2 Hz high-pass removes ~40 % of it, the auto one (0.4 Hz) < 1 %."""
    dt, n = 4e-4, 20000
    taus = [7.4e-3, 14.8e-3, 22.2e-3]
    t = np.arange(n) * dt
    theta = lambda x: 1e-6 * np.sin(2 * np.pi * 3.3 * x + 0.4)  # noqa: E731
    diffs = [theta(t + tau) - theta(t) for tau in taus]
    hp_auto = HIGHPASS_FRACTION_OF_KNOWLEDGE * 2.0
    sl = slice(3000, n - 3000)

    def amplitude(hp):
        est = integrate_axis(diffs, taus, dt, method="wiener", highpass_hz=hp).theta[sl]
        return np.sqrt(2 * np.mean((est - est.mean()) ** 2)) / 1e-6

    assert amplitude(2.0) < 0.7
    assert amplitude(hp_auto) > 0.98


def test_auto_window_widens_only_when_noise_dominates():
    """Contrasted texture keeps the narrow window; the same texture at a tenth of the contrast, same noise, widens it."""
    from reports.synthetic import textured_image
    from restore.stages import WINDOW_COLUMN_CANDIDATES, window_columns_for

    rng = np.random.default_rng(0)
    tex = textured_image((600, 400), rng=rng)
    noise = rng.standard_normal(tex.shape)
    bright = 400.0 + 40.0 * tex + 2.0 * noise
    dim = 400.0 + 4.0 * tex + 2.0 * noise
    assert window_columns_for(bright, window_lines=3) == WINDOW_COLUMN_CANDIDATES[0]
    assert window_columns_for(dim, window_lines=3) > WINDOW_COLUMN_CANDIDATES[0]


def test_periodic_highpass_does_not_leak_the_estimates_oscillations_at_the_record_ends():
    """3–8 Hz lines (2.5 px peaks) under a 0.4 Hz high-pass: nothing lies below the cut-off, so the high-pass
    must give them back. On the record alone the truncated low-pass at the ends averages part of a period
    (tenths of a pixel of error); on the MAP's periodic grid, where the estimate goes on, it does not."""
    from restore.axis_integration import periodic_highpass

    dt, n, m = 4e-4, 4000, 6000
    k = np.arange(m)
    # whole numbers of periods over the grid (its padding continues the lines back to the start)
    grid = sum(a * np.sin(2 * np.pi * c * k / m + ph) for a, c, ph in ((1.0, 8, 0.3), (0.8, 12, 1.1), (0.7, 19, 2.0)))
    theta = grid[:n].copy()
    gappy = theta.copy()
    gappy[1500:1600] = np.nan                      # a cloud: a gap stays a gap
    assert np.array_equal(np.isfinite(periodic_highpass(gappy, grid, dt=dt, cutoff_hz=0.4)), np.isfinite(gappy))
    truncated = highpass_nan(theta, dt=dt, cutoff_hz=0.4)
    wrapped = periodic_highpass(theta, grid, dt=dt, cutoff_hz=0.4)

    def err(x):
        e = x - theta
        return float(np.sqrt(np.mean((e - e.mean()) ** 2)))

    assert err(truncated) > 0.03
    assert err(wrapped) < 0.1 * err(truncated)


def test_periodic_highpass_brings_the_padding_to_the_records_level():
    """The record's mean is removed over its estimable samples, the grid's over all of them: with a long gap
    the two levels differ, and the joins must not become steps the wrapped low-pass spreads into the ends."""
    from restore.axis_integration import periodic_highpass

    dt, n, m = 4e-4, 3000, 4500
    k = np.arange(m)
    grid = np.sin(2 * np.pi * 12 * k / m)
    theta = grid[:n].copy()
    theta[1000:1700] = np.nan
    shifted = theta - np.nanmean(theta)                       # as the MAP's _finish leaves it
    a = periodic_highpass(shifted, grid, dt=dt, cutoff_hz=0.4)
    b = periodic_highpass(shifted, grid - np.nanmean(theta), dt=dt, cutoff_hz=0.4)
    np.testing.assert_allclose(a, b, atol=1e-12, equal_nan=True)


def test_periodic_highpass_fills_the_records_unestimated_end_lines_with_the_grids_estimate():
    """Large CMG-like lines (53–123 Hz) under a 2 Hz high-pass: nothing lies below the cut-off, so the
    high-pass gives the record back. The lines the method leaves NaN at the record's ends take the grid's
    estimate in the low-pass, as the padding beyond them does; as missing samples they cut a hole between
    the record and its padding that the normalised convolution averages around, a slow drift beside it.
    A gap inside the record stays missing data."""
    from restore.axis_integration import periodic_highpass

    dt, n, m = 4e-4, 4000, 6000
    k = np.arange(m)
    # whole numbers of periods over the grid: the padding continues the lines back to the start
    grid = sum(a * np.sin(2 * np.pi * c * k / m + ph)
               for a, c, ph in ((3.0, 127, 0.3), (2.0, 141, 1.1), (1.5, 178, 2.0), (1.0, 296, 0.7)))
    theta = grid[:n] - np.mean(grid[12:n - 12])
    theta[:12] = theta[-12:] = np.nan
    ok = np.isfinite(theta)
    hp = periodic_highpass(theta, grid, dt=dt, cutoff_hz=2.0)
    assert np.array_equal(np.isfinite(hp), ok)
    expected = theta - np.nanmean(theta)
    err = np.abs(hp - expected)[ok]
    # the same grid with the record's end lines as missing samples of the wrapped low-pass
    holes = grid - np.mean(grid[:n][ok]) + np.nanmean(theta)
    holes[:n][~ok] = np.nan
    missing = highpass_nan(holes, dt=dt, cutoff_hz=2.0, mode="wrap")[:n]
    missing_err = np.abs(missing - np.nanmean(missing[ok]) - expected)[ok]
    assert np.max(missing_err[-200:]) > 0.01          # the drift the holes make (a 3-unit line)
    assert np.max(err) < 1e-3 * np.max(missing_err)

    gappy = theta.copy()
    gappy[2000:2010] = np.nan                         # a gap inside the record: missing, as highpass_nan has it
    inner = periodic_highpass(gappy, grid, dt=dt, cutoff_hz=2.0)
    assert np.array_equal(np.isfinite(inner), np.isfinite(gappy))
    ref = grid - np.mean(grid[:n][np.isfinite(gappy)]) + np.nanmean(gappy)
    ref[2000:2010] = np.nan
    ref = highpass_nan(ref, dt=dt, cutoff_hz=2.0, mode="wrap")[:n]
    ref[~np.isfinite(gappy)] = np.nan
    np.testing.assert_allclose(inner, ref - np.nanmean(ref), atol=1e-12, equal_nan=True)
