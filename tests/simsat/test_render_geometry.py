"""The Mitsuba push-broom renderer against the (independent) NumPy sensor model.

Flat textured plane, analytic textures: features at known ground positions must
appear where inverse location says; constant roll / pitch move the image by the
predicted amount; the second band sees a point τ later.
"""
import numpy as np
import pytest

from simsat.render.pushbroom import PushbroomRenderer
from simsat.sensor_model import SensorModel, constant_attitude

from support.geometry import SpotTexture, WaveTexture, centred_platform, flat_dem, small_instrument, spot_centroid, spot_errors

N_LINES = 160


def _render(texture, attitude, *, dem=None, inst=None):
    inst = inst or small_instrument()
    plat = centred_platform(inst, N_LINES)
    dem = dem or flat_dem()
    r = PushbroomRenderer(platform=plat, instrument=inst, dem=dem, texture=texture, attitude=attitude)
    t = np.arange(N_LINES) * inst.line_period_s
    imgs = r.render(t, block_lines=64)
    sm = SensorModel(platform=plat, instrument=inst, dem=dem, attitude=attitude)
    return imgs, sm


@pytest.fixture(scope="module")
def spot_render():
    rng = np.random.default_rng(3)
    xs = np.linspace(-150, 150, 5) + rng.uniform(-2, 2, 5)
    ys = np.linspace(-90, 90, 4) + rng.uniform(-2, 2, 4)
    centres = np.array([(x, y) for x in xs for y in ys])
    tex = SpotTexture(centres)
    imgs, sm = _render(tex, constant_attitude())
    return centres, imgs, sm


def test_features_appear_where_inverse_location_says(spot_render):
    centres, imgs, sm = spot_render
    g = np.c_[centres, np.zeros(len(centres))]
    errs = spot_errors(sm, imgs, ("B1", "B0"), g, N_LINES)
    assert len(errs) >= 20
    assert np.max(np.abs(errs)) <= 0.01, errs


def test_second_band_sees_a_point_tau_later(spot_render):
    centres, imgs, sm = spot_render
    tau_lines = sm.nominal_delay_s("B1", "B0") / sm.line_period_s
    assert tau_lines == pytest.approx(18.5, abs=1e-9)
    g = np.c_[centres, np.zeros(len(centres))]
    l1, c1 = sm.inverse_location("B1", g)
    d = []
    for (la, ca) in zip(l1, c1):
        lb = la + tau_lines
        if 10 < la and lb < N_LINES - 10 and 10 < ca < 86:
            m1 = spot_centroid(imgs["B1"], la, ca)
            m0 = spot_centroid(imgs["B0"], lb, ca)
            d.append(m0[0] - m1[0])
    assert len(d) >= 5
    assert np.max(np.abs(np.array(d) - tau_lines)) <= 0.01


@pytest.mark.parametrize("axis,px", [("roll", 2.3), ("pitch", 1.7)])
def test_constant_attitude_offset_moves_the_image_by_the_predicted_amount(spot_render, axis, px):
    centres, imgs0, sm0 = spot_render
    ifov = sm0.instrument.ifov_rad()
    att = constant_attitude(**{axis: px * ifov})
    imgs1, sm1 = _render(SpotTexture(centres), att)
    g = np.c_[centres, np.zeros(len(centres))]
    l0, c0 = sm0.inverse_location("B0", g)
    l1, c1 = sm1.inverse_location("B0", g)
    # the predicted displacement is of the size asked for
    if axis == "roll":
        assert np.median(c1 - c0) == pytest.approx(-px, rel=2e-3)
    else:
        assert np.median(l1 - l0) == pytest.approx(px, rel=2e-3)
    errs = []
    for a0, b0, a1, b1 in zip(l0, c0, l1, c1):
        if 10 < min(a0, a1) and max(a0, a1) < N_LINES - 10 and 10 < min(b0, b1) and max(b0, b1) < 86:
            m0 = spot_centroid(imgs0["B0"], a0, b0)
            m1 = spot_centroid(imgs1["B0"], a1, b1)
            errs.append(((m1[0] - m0[0]) - (a1 - a0), (m1[1] - m0[1]) - (b1 - b0)))
    errs = np.array(errs)
    assert len(errs) >= 8
    assert np.max(np.abs(errs)) <= 0.01


def test_rendering_is_deterministic_and_textured():
    tex = WaveTexture(seed=1)
    a, _ = _render(tex, constant_attitude())
    b, _ = _render(tex, constant_attitude())
    for k in a:
        assert np.array_equal(a[k], b[k])
        assert a[k].std() > 0.01
