"""Instant synthesis, gap filling, window compensation and the least-squares integration."""
import numpy as np
import pytest

from restore.integration.lsq import integrate_lsq, keys_weights
from restore.synthesis import fill_short_gaps, highpass_nan, instant_synthesis, window_compensation


def test_synthesis_recovers_known_differentials_and_rejects_outliers():
    rng = np.random.default_rng(0)
    n_lines, per_line = 50, 20
    lines = np.repeat(np.arange(n_lines), per_line)
    true = np.stack([rng.normal(0, 4e-6, n_lines), rng.normal(0, 4e-6, n_lines), np.zeros(n_lines)], 1)
    s = np.zeros((lines.size, 2, 3))
    s[:, 1, 0] = -2.48e5  # dcol/droll
    s[:, 0, 1] = 2.48e5   # dline/dpitch
    s[:, 0, 0] = rng.normal(0, 50, lines.size)  # small cross terms
    s[:, 1, 1] = rng.normal(0, 50, lines.size)
    rl = np.einsum("nk,nk->n", s[:, 0, :], true[lines]) + rng.normal(0, 0.05, lines.size)
    rc = np.einsum("nk,nk->n", s[:, 1, :], true[lines]) + rng.normal(0, 0.05, lines.size)
    bad = rng.choice(lines.size, 40, replace=False)
    rl[bad] += 3.0
    res = instant_synthesis(lines, rl, rc, s, n_lines=n_lines, axes=("roll", "pitch"))
    assert not res.inlier[bad].any()
    err = (res.diff[:, :2] - true[:, :2]) * 2.48e5  # px
    assert np.sqrt(np.mean(err ** 2)) < 0.05 / np.sqrt(per_line) * 2
    assert np.all(np.isnan(res.diff[:, 2]))  # yaw not fitted


def test_unusable_points_are_left_out_not_fatal():
    """A point with a NaN sensitivity, or on a line off the record, is dropped: the other lines are unchanged."""
    rng = np.random.default_rng(1)
    n_lines = 20
    lines = np.repeat(np.arange(n_lines), 8)
    s = np.zeros((lines.size, 2, 3))
    s[:, 1, 0] = -2.48e5
    s[:, 0, 1] = 2.48e5
    rl = rng.normal(0, 0.05, lines.size)
    rc = rng.normal(0, 0.05, lines.size)
    ref = instant_synthesis(lines, rl, rc, s, n_lines=n_lines, axes=("roll", "pitch"))
    s_bad = np.concatenate([s, np.full((1, 2, 3), np.nan), s[:1]])
    lines_bad = np.concatenate([lines, [3], [n_lines + 5]])
    res = instant_synthesis(lines_bad, np.append(rl, [0.0, 0.0]), np.append(rc, [0.0, 0.0]), s_bad, n_lines=n_lines,
                            axes=("roll", "pitch"))
    np.testing.assert_array_equal(res.diff, ref.diff)
    assert not res.inlier[-2:].any()


def test_lines_without_enough_points_are_gaps_not_zeros():
    lines = np.array([0, 0, 0, 0, 2, 2])
    s = np.zeros((6, 2, 3))
    s[:, 1, 0] = -1e5
    s[:, 0, 1] = 1e5
    res = instant_synthesis(lines, np.full(6, 0.1), np.full(6, -0.2), s, n_lines=3, axes=("roll", "pitch"),
                            min_points=3)
    assert np.isfinite(res.diff[0, :2]).all()
    assert np.isnan(res.diff[1, :2]).all() and np.isnan(res.diff[2, :2]).all()
    assert res.diff[0, 0] == pytest.approx(2e-6) and res.diff[0, 1] == pytest.approx(1e-6)


def test_fill_short_gaps_interpolates_inside_and_never_extrapolates():
    x = np.sin(np.arange(100) * 0.2)
    y = x.copy()
    y[10:14] = np.nan
    y[50:80] = np.nan
    y[:3] = np.nan
    f = fill_short_gaps(y, max_gap=5)
    # cubic interpolation error over a 5-sample span at 0.2 rad/sample: ~(5·0.2)^4/384 ≈ 3e-3
    assert np.allclose(f[10:14], x[10:14], atol=5e-3)
    assert np.isnan(f[50:80]).all() and np.isnan(f[:3]).all()


def test_window_compensation_undoes_the_moving_average_to_fourth_order():
    te = 4e-4
    t = np.arange(4000) * te
    for f in (50.0, 155.0):
        x = np.sin(2 * np.pi * f * t)
        ma = np.convolve(x, np.ones(3) / 3, mode="same")
        comp = window_compensation(ma, window_lines=3)
        gain_ma = np.std(ma[10:-10]) / np.std(x[10:-10])
        gain = np.std(comp[10:-10]) / np.std(x[10:-10])
        w = 2 * np.pi * f * te
        assert gain_ma == pytest.approx((1 + 2 * np.cos(w)) / 3, rel=1e-3)
        assert abs(gain - 1) < 0.1 * abs(gain_ma - 1)


def test_highpass_removes_a_drift_and_keeps_jitter():
    te = 4e-4
    t = np.arange(5000) * te
    x = 1e-6 * (3 * t + np.sin(2 * np.pi * 60 * t))
    x[100:120] = np.nan
    y = highpass_nan(x, dt=te, cutoff_hz=2.0)
    core = slice(500, 4500)
    assert np.isnan(y[100:120]).all()
    assert np.nanstd(y[core] - 1e-6 * np.sin(2 * np.pi * 60 * t[core])) < 0.02e-6


def test_keys_weights_sum_to_one_and_interpolate_a_cubic_exactly_at_nodes():
    f = np.linspace(0, 0.99, 7)
    w = keys_weights(f)
    assert np.allclose(w.sum(axis=1), 1.0)
    assert np.allclose(keys_weights(np.array([0.0]))[0], [0, 1, 0, 0])


def test_lsq_integration_with_per_sample_lags_recovers_a_quasi_harmonic_signal():
    dt = 4e-4
    n = 3000
    t = np.arange(n) * dt
    rng = np.random.default_rng(1)
    comps = [(53.0, 1.0), (61.0, 0.7), (118.0, 0.3)]
    def theta(tt):
        return sum(a * np.sin(2 * np.pi * f * tt + f) for f, a in comps)
    taus = [7.4e-3, 14.8e-3, 22.2e-3]
    diffs, lags = [], []
    for tau in taus:
        lag = 0.4 * dt * np.sin(2 * np.pi * 57 * t)  # actual delay wobbles by ±0.4 line
        d = theta(t + tau + lag) - theta(t) + rng.normal(0, 0.01, n)
        d[t + tau > t[-1] - 2 * dt] = np.nan
        d[rng.random(n) < 0.2] = np.nan  # scattered gaps
        diffs.append(d)
        lags.append(lag)
    est = integrate_lsq(diffs, taus, dt, lags=lags)
    ref = theta(t)
    m = np.isfinite(est)
    assert m.mean() > 0.95
    e = (est - ref)[m]
    e -= e.mean()
    assert np.sqrt(np.mean(e ** 2)) < 0.03 * np.std(ref)
    # ignoring the lags is measurably worse: the model matters
    est0 = integrate_lsq(diffs, taus, dt)
    e0 = (est0 - ref)[m]
    e0 -= e0.mean()
    assert np.sqrt(np.mean(e0 ** 2)) > 2 * np.sqrt(np.mean(e ** 2))


def test_drop_sparse_removes_isolated_samples_in_gappy_stretches():
    from restore.synthesis import drop_sparse

    x = np.arange(200, dtype=float)
    x[60:140] = np.nan
    x[[70, 71, 90, 120]] = 1.0          # a scatter of samples inside a long gap
    x[10] = np.nan                      # a single gap in a dense stretch
    out = drop_sparse(x, half_window=8)
    assert np.isnan(out[[70, 71, 90, 120]]).all()
    # dense stretches are untouched, including next to a single gap and at the record ends
    keep = np.isfinite(x) & ~np.isin(np.arange(200), [70, 71, 90, 120])
    np.testing.assert_array_equal(out[keep], x[keep])
    assert np.isfinite(out[:10]).all() and np.isfinite(out[-5:]).all()
    # half_window 0: unchanged
    np.testing.assert_array_equal(drop_sparse(x, half_window=0), x)


def _centre_line_pair(*, roll: float = 0.0, pitch: float = 0.0, dem_half_x: float = 20000.0,
                      dem_step: float = 25.0):
    """A B1/B0 pair of 21 points across the middle line of a 200-pixel instrument over a flat plane, viewed
    with the nominal tilt (roll, pitch) [rad] (the attitude's nominal part), with its sensitivities."""
    from restore.result import PairData
    from simsat.platform import Platform
    from simsat.sensor_model import SensorModel, constant_attitude
    from support.geometry import F, H, TE, V, flat_dem, small_instrument

    inst = small_instrument(pixels=200)
    n = 4000
    along = np.mean([d.along_m for d in inst.detectors])
    plat = Platform.straight(altitude_m=H, ground_speed_m_s=V, off_nadir_roll_rad=roll,
                             off_nadir_pitch_rad=pitch).centred(t_mid_s=0.5 * (n - 1) * TE,
                                                                along_angle_rad=np.arctan(along / F))
    sm = SensorModel(platform=plat, instrument=inst,
                     dem=flat_dem(half_x=dem_half_x, half_y=20000.0, step=dem_step),
                     attitude=constant_attitude(roll, pitch))
    cols = np.linspace(0, 199, 21)
    lines = np.full(cols.size, n / 2)
    sens = sm.sensitivities("B0", sm.direct_location("B1", lines, cols))
    return PairData(name="B1/B0", ahead="B1", behind="B0", tau_s=0.0, line_a=lines, col_a=cols,
                    meas_line_b=lines, meas_col_b=cols, quality=np.ones(cols.size), valid=np.ones(cols.size, bool),
                    sens=sens)


@pytest.mark.parametrize("roll_deg", [0.0, 10.0, 20.0, 35.0])
def test_yaw_moves_a_rolled_line_along_track_by_sin_roll_times_a_pitch(roll_deg):
    """On a flat plane viewed rolled by φ, a small yaw ψ about the vertical turns the ground point of the line's
    centre, (0, H tan φ) from the nadir, along track by H tan φ · ψ; a small pitch δ about the cross-track
    axis moves it by H · δ: the coupling the restoration records is tan φ (0 at nadir)."""
    from restore.stages import yaw_pitch_coupling

    roll = np.radians(roll_deg)
    assert abs(yaw_pitch_coupling([_centre_line_pair(roll=roll)])) == pytest.approx(np.tan(roll), abs=1e-3)


@pytest.mark.parametrize("pitch_deg", [0.0, 15.0, -25.0])
def test_yaw_sweeps_a_line_looking_ahead_across_track_by_sin_tilt_times_a_roll(pitch_deg):
    """Tilted along track by θ₀ (R = Rz(ψ) Ry(θ₀) Rx(φ)) the line's centre looks at (H tan θ₀, 0) from the nadir: a
    small yaw ψ about the vertical moves it across track by H tan θ₀ · ψ, a small roll φ about the tilted body
    axis by H φ / cos θ₀ (over a flat plane, to first order): the coupling the restoration records for roll is
    sin θ₀ in magnitude (0 looking straight down), and the pitch coupling stays 0."""
    from restore.stages import yaw_coupling

    tilt = np.radians(pitch_deg)
    # the line looks up to H tan 25° ≈ 320 km ahead: a coarse flat plane is exact under bilinear interpolation
    pair = _centre_line_pair(pitch=tilt, dem_half_x=400000.0, dem_step=2000.0)
    assert abs(yaw_coupling([pair], "roll")) == pytest.approx(abs(np.sin(tilt)), abs=2e-3)
    assert abs(yaw_coupling([pair], "pitch")) < 2e-3


def _correlated_points(seed: int, n_lines: int = 400, per_line: int = 20):
    """Points with line / column errors of known σ and correlation (an edge couples them), on roll (columns) and
    pitch (lines) at 1 px per µrad."""
    rng = np.random.default_rng(seed)
    n = n_lines * per_line
    lines = np.repeat(np.arange(n_lines), per_line)
    sens = np.zeros((n, 2, 3))
    sens[:, 1, 0] = 1e6
    sens[:, 0, 1] = 1e6
    rho = rng.uniform(-0.95, 0.95, n)
    sl, sc = rng.uniform(0.1, 0.5, n), rng.uniform(0.1, 0.5, n)
    z = rng.standard_normal((n, 2))
    el = sl * z[:, 0]
    ec = sc * (rho * z[:, 0] + np.sqrt(1 - rho ** 2) * z[:, 1])
    return lines, el, ec, sens, np.stack([1 / sl ** 2, 1 / sc ** 2], axis=1), rho


def test_correlated_line_and_column_errors_are_weighed_by_their_covariance():
    """Generalised least squares: per line, ``x̂ = (Σ Sᵀ W S)⁻¹ Σ Sᵀ W r`` with ``W`` each point's inverse 2 × 2
    covariance. Its error is the analytic one (the inverse of the summed information) and the formal σ, and
    smaller than the fit's that takes the two coordinates as independent."""
    lines, el, ec, sens, w, rho = _correlated_points(0)
    kw = dict(n_lines=400, weights=w, axes=("roll", "pitch"), n_sigma=10.0)
    indep = instant_synthesis(lines, el, ec, sens, **kw)
    gls = instant_synthesis(lines, el, ec, sens, correlation=rho, **kw)
    rms = lambda r: np.sqrt(np.mean((r.diff[:, :2] * 1e6) ** 2, axis=0))
    formal = lambda r: np.sqrt(np.mean((r.sigma[:, :2] * 1e6) ** 2, axis=0))
    # the analytic GLS variance of each line: the inverse of the summed information
    info = np.zeros((400, 2, 2))
    wl, wc = w[:, 0], w[:, 1]
    k = 1 / (1 - rho ** 2)
    for (i, j), v in {(0, 0): wc * k, (1, 1): wl * k, (0, 1): -rho * np.sqrt(wl * wc) * k}.items():
        info[:, i, j] = np.bincount(lines, v, minlength=400)
    info[:, 1, 0] = info[:, 0, 1]
    expected = np.sqrt(np.mean(np.linalg.inv(info)[:, [0, 1], [0, 1]], axis=0))
    np.testing.assert_allclose(rms(gls), expected, rtol=0.08)
    assert np.all(rms(gls) < 0.85 * rms(indep))
    np.testing.assert_allclose(formal(gls), rms(gls), rtol=0.1)
    # no correlation given: the same fit as before, bit for bit
    same = instant_synthesis(lines, el, ec, sens, correlation=np.zeros(lines.size), **kw)
    np.testing.assert_allclose(same.diff, indep.diff, rtol=1e-12, atol=1e-18)
    with pytest.raises(ValueError, match="correlation"):
        instant_synthesis(lines, el, ec, sens, correlation=rho[:5], **kw)


def test_match_weights_floor_the_variances_not_the_covariance():
    from types import SimpleNamespace

    from restore.synthesis import MATCH_STD_FLOOR_PX, match_weights

    pair = SimpleNamespace(std_line=np.array([0.1, 0.02, 0.3]), std_col=np.array([0.2, 0.02, 0.3]),
                           corr_line_col=np.array([0.9, -0.5, np.nan]), quality=np.ones(3))
    v = np.array([True, True, True])
    w, rho = match_weights(pair, v)
    f2 = MATCH_STD_FLOOR_PX ** 2
    np.testing.assert_allclose(w[:, 0], 1 / (pair.std_line ** 2 + f2))
    np.testing.assert_allclose(rho[0], 0.9 * 0.1 * 0.2 / np.sqrt((0.01 + f2) * (0.04 + f2)))
    np.testing.assert_allclose(rho[1], -0.25)      # σ at the floor: half of each variance is the floor's
    assert rho[2] == 0.0
    assert match_weights(pair, v, covariance=False)[1] is None
    older = SimpleNamespace(std_line=pair.std_line, std_col=pair.std_col, corr_line_col=None, quality=np.ones(3))
    assert match_weights(older, v)[1] is None
