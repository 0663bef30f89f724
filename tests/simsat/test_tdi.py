"""TDI detectors (CNES §3.3.4): rendered as the mean of their stages, dated at the last one.

Under a constant attitude every stage sees the same ground point: the TDI image
is the single-line image. Under an attitude ramp the TDI image sits where the
attitude *averaged over the stages* puts it, (N − 1) / 2 line periods of ramp
away from where the attitude at the line date would.
"""
from dataclasses import replace

import numpy as np
import pytest

from simsat.config import ScenarioError
from simsat.render.pushbroom import PushbroomRenderer
from simsat.sensor_model import SensorModel, constant_attitude, tdi_mean_attitude

from support.geometry import SpotTexture, centred_platform, small_instrument, spot_centroid

N_LINES = 160
STAGES = 9


def _instrument(stages):
    inst = small_instrument()
    b0 = replace(inst.detector("B0"), tdi_stages=stages)
    return replace(inst, detectors=(inst.detector("B1"), b0))


def _centres():
    rng = np.random.default_rng(3)
    xs = np.linspace(-150, 150, 5) + rng.uniform(-2, 2, 5)
    ys = np.linspace(-90, 90, 4) + rng.uniform(-2, 2, 4)
    return np.array([(x, y) for x in xs for y in ys])


def _hill():
    """Relief under the spots: a 40 m hill and a tilt (the TDI rows see it from slightly different angles)."""
    from simsat.terrain.dem import Dem

    x = np.arange(-3000.0, 3000.1, 10.0)
    y = np.arange(-1500.0, 1500.1, 10.0)
    xx, yy = np.meshgrid(x, y)
    z = 40.0 * np.exp(-(xx ** 2 + yy ** 2) / (2 * 150.0 ** 2)) + 0.01 * xx
    return Dem(x0_m=x[0], y0_m=y[0], dx_m=10.0, dy_m=10.0, z=z)


def _render(stages, attitude):
    inst = _instrument(stages)
    plat = centred_platform(inst, N_LINES)
    dem = _hill()
    r = PushbroomRenderer(platform=plat, instrument=inst, dem=dem, texture=SpotTexture(_centres()), attitude=attitude)
    imgs = r.render(np.arange(N_LINES) * inst.line_period_s, block_lines=64)
    return imgs["B0"], SensorModel(platform=plat, instrument=inst, dem=dem, attitude=attitude)


def _measured_minus_predicted(img, sm, attitude):
    c = _centres()
    g = np.c_[c, sm.dem.height(c[:, 0], c[:, 1])]
    lp, cp = sm.inverse_location("B0", g, attitude=attitude)
    out = []
    for l0, c0 in zip(lp, cp):
        if 10 < l0 < N_LINES - 10 and 10 < c0 < 86:
            lm, cm = spot_centroid(img, l0, c0)
            out.append((lm - l0, cm - c0))
    assert len(out) >= 8
    return np.array(out)


def test_tdi_under_a_constant_attitude_is_the_single_line_image():
    att = constant_attitude(2e-6, -3e-6, 0.0)
    one, _ = _render(1, att)
    tdi, sm = _render(STAGES, att)
    assert np.max(np.abs(tdi - one)) <= 1e-4 * np.max(one)
    assert np.max(np.abs(_measured_minus_predicted(tdi, sm, att))) <= 0.01


def test_tdi_under_a_ramp_sits_where_the_stage_mean_attitude_says():
    inst = small_instrument()
    ifov, te = inst.ifov_rad(), inst.line_period_s
    rate = 0.08  # px of pitch per line: the image slides along track while the charge integrates

    def ramp(t):
        t = np.asarray(t, dtype=np.float64)
        return (np.zeros(t.shape), rate * ifov * (t - 0.03) / te, np.zeros(t.shape))

    img, sm = _render(STAGES, ramp)
    mean = tdi_mean_attitude(ramp, STAGES, te)
    err_mean = _measured_minus_predicted(img, sm, mean)
    err_date = _measured_minus_predicted(img, sm, ramp)
    assert np.max(np.abs(err_mean)) <= 0.01
    # at the date the prediction is off by the ramp over (N − 1) / 2 line periods, r (N − 1) / 2 px of pitch;
    # a line l shows the ground at x / v + θ(l), so an attitude offset Δθ moves it by Δθ / (1 − dθ/dl)
    hand = rate * (STAGES - 1) / 2 / (1 - rate)
    shift = np.median(err_date[:, 0] - err_mean[:, 0])
    l_mean, _ = sm.inverse_location("B0", np.array([[0.0, 0.0, 0.0]]), attitude=mean)
    l_date, _ = sm.inverse_location("B0", np.array([[0.0, 0.0, 0.0]]), attitude=ramp)
    assert abs(l_mean[0] - l_date[0]) == pytest.approx(hand, rel=1e-3)
    assert abs(shift) == pytest.approx(hand, abs=0.01)


def test_stage_mean_of_a_sine_is_the_dirichlet_kernel():
    f, te, n = 97.0, 4e-4, 13
    w = 2 * np.pi * f

    def sine(t):
        t = np.asarray(t, dtype=np.float64)
        return (np.sin(w * t), np.zeros(t.shape), np.zeros(t.shape))

    t = np.linspace(0.0, 0.05, 301)
    got = tdi_mean_attitude(sine, n, te)(t)[0]
    gain = np.sin(n * w * te / 2) / (n * np.sin(w * te / 2))
    np.testing.assert_allclose(got, gain * np.sin(w * (t - (n - 1) * te / 2)), atol=1e-12)
    assert tdi_mean_attitude(sine, 1, te) is sine


def test_tdi_rows_must_fit_on_the_focal_plane(tmp_path):
    from simsat.scenario import load_scenario

    p = tmp_path / "s.toml"
    p.write_text('[scenario]\nbase = "tiny"\nname = "t"\n[[instrument.detectors]]\nname = "P"\nband = "pan"\n'
                 'along_track_mm = 9.0\ntdi_stages = 64\n')
    with pytest.raises(ScenarioError, match=r"instrument.detectors\[0\].tdi_stages.*off the focal plane"):
        load_scenario(p)
