"""Per-line misregistration statistics against synthetic series with a known signal and noise."""
import numpy as np
import pytest

from restore.correction import per_line_shift_rms


def _points(rng, n_lines, per_line, signal_l, signal_c, std):
    lines = np.repeat(np.arange(n_lines), per_line)
    cols = np.tile(np.linspace(20, 780, per_line), n_lines)
    std = np.broadcast_to(std, lines.shape)
    res_l = signal_l[lines] + rng.normal(0.0, 1.0, lines.size) * std
    res_c = signal_c[lines] + rng.normal(0.0, 1.0, lines.size) * std
    return lines, cols, res_l, res_c


def test_signal_estimate_removes_the_matching_noise():
    rng = np.random.default_rng(1)
    n_lines, per_line = 4000, 20
    t = np.arange(n_lines) * 4e-4
    # known misregistration series: RMS 0.03 px (lines) and 0.02 px (columns)
    sig_l = 0.03 * np.sqrt(2) * np.sin(2 * np.pi * 63.4 * t)
    sig_c = 0.02 * np.sqrt(2) * np.sin(2 * np.pi * 52.7 * t + 1.0)
    lines, cols, rl, rc = _points(rng, n_lines, per_line, sig_l, sig_c, 0.25)
    out = per_line_shift_rms(lines, rl, rc, n_lines, cols=cols)
    noise = 0.25 / np.sqrt(per_line)
    # as measured: signal and noise add in quadrature
    assert out["line_px"] == pytest.approx(np.hypot(0.03, noise), rel=0.05)
    assert out["line_noise_px"] == pytest.approx(noise, rel=0.05)
    # split-half estimate: the signal alone (its sampling error ~ noise² / sqrt(2 n_lines) in variance)
    assert out["line_signal_px"] == pytest.approx(0.03, abs=0.004)
    assert out["col_signal_px"] == pytest.approx(0.02, abs=0.005)
    assert out["total_signal_px"] == pytest.approx(np.hypot(0.03, 0.02), abs=0.004)
    assert out["lines"] == n_lines


def test_no_signal_gives_a_small_signal_estimate():
    rng = np.random.default_rng(2)
    n_lines, per_line = 4000, 20
    zero = np.zeros(n_lines)
    lines, cols, rl, rc = _points(rng, n_lines, per_line, zero, zero, 0.25)
    out = per_line_shift_rms(lines, rl, rc, n_lines, cols=cols)
    assert out["line_px"] > 0.05  # the noise of a per-line mean of 20 points
    assert out["total_signal_px"] < 0.012


def test_inverse_variance_weights_lower_the_noise():
    rng = np.random.default_rng(3)
    n_lines, per_line = 3000, 20
    zero = np.zeros(n_lines)
    # half the points ten times noisier than the others
    std = np.tile(np.where(np.arange(per_line) % 2 == 0, 0.05, 0.5), n_lines)
    lines, cols, rl, rc = _points(rng, n_lines, per_line, zero, zero, std)
    plain = per_line_shift_rms(lines, rl, rc, n_lines, cols=cols)
    w = 1.0 / std ** 2
    weighted = per_line_shift_rms(lines, rl, rc, n_lines, cols=cols, weights_l=w, weights_c=w)
    assert weighted["line_px"] < 0.8 * plain["line_px"]
    # the noise estimate follows the weighting: ~ 0.05 / sqrt(10) for the good half
    assert weighted["line_noise_px"] == pytest.approx(0.05 / np.sqrt(per_line / 2), rel=0.1)


def test_outliers_are_not_misregistration():
    rng = np.random.default_rng(4)
    n_lines, per_line = 2000, 20
    zero = np.zeros(n_lines)
    lines, cols, rl, rc = _points(rng, n_lines, per_line, zero, zero, 0.1)
    bad = rng.random(lines.size) < 0.02
    rl[bad] += 5.0
    out = per_line_shift_rms(lines, rl, rc, n_lines, cols=cols)
    assert out["line_px"] < 0.04


def test_too_few_points_gives_nan_not_zero():
    out = per_line_shift_rms(np.array([0, 0, 1]), np.zeros(3), np.zeros(3), 5)
    assert out["lines"] == 0
    assert np.isnan(out["total_px"]) and np.isnan(out["total_signal_px"])


def test_weights_shape_is_checked():
    with pytest.raises(ValueError, match="weights"):
        per_line_shift_rms(np.zeros(4, int), np.zeros(4), np.zeros(4), 2, weights_l=np.ones(3))


def test_attitude_misregistration_of_a_sinusoidal_error():
    import xarray as xr

    from reports.metrics import attitude_misregistration

    ifov = 4e-6
    te = 4e-4
    t = np.arange(5000) * te
    tt = np.arange(-10, 60000) * 1e-4
    f, a = 63.4, 0.1 * ifov  # error: 0.1 px sinusoid on roll, 0.05 px on pitch
    true_roll = 1e-6 * np.sin(2 * np.pi * 7.0 * tt)
    truth = xr.Dataset({"roll": ("time", true_roll), "pitch": ("time", np.zeros_like(tt))}, coords={"time": tt})
    roll = np.interp(t, tt, true_roll) + a * np.sin(2 * np.pi * f * t)
    pitch = 0.5 * a * np.cos(2 * np.pi * f * t)
    taus = [7.4e-3, 22.2e-3]
    rest = xr.Dataset({"roll": ("time", roll), "pitch": ("time", pitch),
                       "knowledge_roll": ("time", np.zeros_like(t)), "knowledge_pitch": ("time", np.zeros_like(t)),
                       "tau_s": ("pair", taus)},
                      coords={"time": t, "pair": ["A/B", "A/C"]}, attrs={"pixel_ifov_rad": ifov})
    out = attitude_misregistration(rest, truth)
    for name, tau in zip(["A/B", "A/C"], taus):
        g = abs(2 * np.sin(np.pi * f * tau)) / np.sqrt(2)  # RMS of e(t+τ) − e(t) for a unit sinusoid
        assert out[name]["restored"]["col_px"] == pytest.approx(0.1 * g, rel=0.01)
        assert out[name]["restored"]["line_px"] == pytest.approx(0.05 * g, rel=0.01)
        assert out[name]["tau_s"] == tau
        # knowledge = 0: its misregistration is that of the true attitude (a 7 Hz roll of 0.25 px)
        g7 = abs(2 * np.sin(np.pi * 7.0 * tau)) / np.sqrt(2)
        assert out[name]["knowledge"]["col_px"] == pytest.approx(1e-6 / ifov * g7, rel=0.02)
