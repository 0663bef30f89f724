"""Trajectories and scan laws: Kepler by hand, delays by hand, and the renderer against the sensor model.

Every platform kind (straight track, LEO orbit over a round Earth, a cartwheel
spin in LEO, a scan mirror on a geostationary platform) is rendered over a
textured hill: spots at known ground positions must appear where the NumPy
sensor model's inverse location puts them (≤ 0.01 px), and the delay τ of the
one place that computes it must match the hand formula of each geometry.
"""
import math

import numpy as np
import pytest

from simsat.config import ScenarioError
from simsat.instrument import Detector, Instrument, Radiometry
from simsat.platform import Platform
from simsat.scan import MirrorScan, SpinScan, scan_from_attrs
from simsat.sensor_model import SensorModel, constant_attitude
from simsat.terrain.dem import Dem
from simsat.trajectory import (EARTH_MU_M3_S2, EARTH_RADIUS_M, EARTH_ROTATION_RAD_S, GEOSTATIONARY_ALTITUDE_M,
                               CircularOrbit, SampledEphemeris, StraightTrack, trajectory_from_attrs)

from support.geometry import SpotTexture, spot_errors

LEO_H = 694000.0
PITCH = 13e-6
N_LINES = 160
ALONG = (0.962e-3, 0.0)


def _instrument(focal_length_m, line_period_s, pixels=96):
    dets = tuple(Detector(n, b, a, 0.0, pixels, PITCH) for n, b, a in zip(("B1", "B0"), ("green", "blue"), ALONG))
    return Instrument(focal_length_m=focal_length_m, line_period_s=line_period_s, detectors=dets, mtf_nyquist=0.3,
                      time_subsamples=4, radiometry=Radiometry(enabled=False))


def _case(name):
    """(platform before centring, focal length) of each geometry; ground sample ≈ 3 m everywhere."""
    leo_f = LEO_H * PITCH / 3.0
    geo_f = GEOSTATIONARY_ALTITUDE_M * PITCH / 3.0
    if name == "straight":
        return Platform(StraightTrack(LEO_H, 7000.0)), leo_f
    if name == "leo_orbit":
        return Platform(CircularOrbit(LEO_H)), leo_f
    if name == "leo_spin":
        return Platform(CircularOrbit(LEO_H), scan=SpinScan(rate_rad_s=0.05)), leo_f
    if name == "geo_spin":  # claim 17 with the spin: a geostationary spinner sweeping the scene
        return Platform(CircularOrbit(GEOSTATIONARY_ALTITUDE_M, inclination_rad=0.0),
                        scan=SpinScan(rate_rad_s=1e-4)), geo_f
    if name == "geo_mirror":
        return Platform(CircularOrbit(GEOSTATIONARY_ALTITUDE_M, inclination_rad=0.0),
                        scan=MirrorScan(mirror_rate_rad_s=5e-5, scan_frequency_hz=0.5)), geo_f
    raise ValueError(name)


def _centred(name):
    plat, f = _case(name)
    te = 3.0 / plat.ground_speed_m_s  # square pixels
    inst = _instrument(f, te)
    along = np.mean(ALONG)
    plat = plat.centred(t_mid_s=0.5 * (N_LINES - 1) * te, along_angle_rad=math.atan(along / f))
    return plat, inst


def _hill_dem(radius_m=math.inf, half=700.0, step=5.0):
    x = np.arange(-half, half + 0.1, step)
    xx, yy = np.meshgrid(x, x)
    z = 40.0 * np.exp(-(xx ** 2 + yy ** 2) / (2 * 250.0 ** 2)) + 0.01 * xx
    return Dem(x0_m=x[0], y0_m=x[0], dx_m=step, dy_m=step, z=z).on_sphere(radius_m)


# --------------------------------------------------------------------------- trajectories by hand
def test_circular_orbit_is_keplerian():
    orb = CircularOrbit(LEO_H, inclination_rad=math.radians(98.0), theta0_rad=0.01)
    t = np.linspace(-3.0, 3.0, 7)
    p = orb.position(t)
    centre = np.array([0.0, 0.0, -EARTH_RADIUS_M])
    a = EARTH_RADIUS_M + LEO_H
    np.testing.assert_allclose(np.linalg.norm(p - centre, axis=1), a, rtol=1e-14)
    w = math.sqrt(EARTH_MU_M3_S2 / a ** 3) - EARTH_ROTATION_RAD_S * math.cos(math.radians(98.0))
    np.testing.assert_allclose(np.linalg.norm(orb.velocity(t), axis=1), a * w, rtol=1e-12)
    assert orb.ground_speed_m_s == pytest.approx(EARTH_RADIUS_M * w, rel=1e-14)
    assert 6700 < orb.ground_speed_m_s < 7000  # a 694 km sun-synchronous orbit's ground track: ~6.8 km/s
    fr = orb.frame(t)
    radial = (p - centre) / a
    np.testing.assert_allclose(fr[:, :, 2], radial, atol=1e-14)
    np.testing.assert_allclose(fr[:, :, 0], orb.velocity(t) / (a * w), atol=1e-12)


def test_geostationary_orbit_stands_still_over_the_ground():
    geo = CircularOrbit(GEOSTATIONARY_ALTITUDE_M, inclination_rad=0.0)
    assert GEOSTATIONARY_ALTITUDE_M + EARTH_RADIUS_M == pytest.approx(42_164.17e3, abs=0.1e3)  # the GEO radius
    assert abs(geo.ground_speed_m_s) < 1e-6
    assert np.ptp(geo.position(np.array([0.0, 100.0])), axis=0).max() < 1e-3


def test_sampled_ephemeris_reproduces_the_orbit_it_samples():
    orb = CircularOrbit(LEO_H, theta0_rad=-2e-4)
    t = np.arange(0.0, 0.5, 1e-3)
    eph = SampledEphemeris(t, orb.position(t), earth_radius_m=EARTH_RADIUS_M)
    tq = t[:-1] + 0.37e-3
    np.testing.assert_allclose(eph.position(tq), orb.position(tq), atol=1e-6)
    np.testing.assert_allclose(eph.frame(tq), orb.frame(tq), atol=1e-12)
    assert eph.altitude_m == pytest.approx(LEO_H, abs=1e-6)
    assert eph.ground_speed_m_s == pytest.approx(orb.ground_speed_m_s, rel=1e-9)
    back = trajectory_from_attrs(eph.attrs(), ephemeris_time=t, ephemeris=orb.position(t))
    np.testing.assert_allclose(back.position(tq), eph.position(tq), atol=1e-9)


@pytest.mark.parametrize("name", ["straight", "leo_orbit", "leo_spin", "geo_mirror", "geo_spin"])
def test_platform_attributes_round_trip(name):
    plat, _ = _centred(name)
    a = plat.attrs()
    back = Platform(trajectory_from_attrs(a), scan=scan_from_attrs(a))
    t = np.linspace(0.0, 0.02, 5)
    np.testing.assert_allclose(back.position(t), plat.position(t), atol=1e-9)
    np.testing.assert_allclose(back.pointing(t, 1e-5, -2e-5, 3e-5), plat.pointing(t, 1e-5, -2e-5, 3e-5), atol=1e-15)
    assert back.ground_speed_m_s == pytest.approx(plat.ground_speed_m_s, rel=1e-12)


# --------------------------------------------------------------------------- delays by hand
def _ground_angle(alpha, h, radius=EARTH_RADIUS_M):
    """Central angle from the sub-satellite point where a ray at off-nadir angle α meets the sphere."""
    return math.asin((radius + h) * math.sin(alpha) / radius) - alpha


@pytest.mark.parametrize("name", ["straight", "leo_orbit", "leo_spin", "geo_mirror", "geo_spin"])
def test_delay_matches_the_hand_formula_of_each_geometry(name):
    plat, inst = _centred(name)
    f = inst.focal_length_m
    aa, ab = (math.atan(a / f) for a in ALONG)
    sm = SensorModel(platform=plat, instrument=inst, dem=_hill_dem(), attitude=constant_attitude())
    tau = sm.nominal_delay_s("B1", "B0")
    if name == "straight":
        hand = LEO_H * (math.tan(aa) - math.tan(ab)) / 7000.0
    elif name == "leo_orbit":  # the ground track turns at ω; a ray at α meets the sphere φ(α) ahead
        orb = plat.trajectory
        hand = (_ground_angle(aa, LEO_H) - _ground_angle(ab, LEO_H)) / orb.angular_rate_rad_s
    elif name == "leo_spin":  # small angles: the ground point advances at ω R + (H / R) ω_s R
        orb = plat.trajectory
        hand = (LEO_H / EARTH_RADIUS_M) * (aa - ab) / (orb.angular_rate_rad_s + LEO_H / EARTH_RADIUS_M * 0.05)
    elif name == "geo_spin":  # a fixed point: the spin turns the line of sight by ω t
        hand = (aa - ab) / 1e-4
    else:  # a fixed point: the mirror turns the line of sight by 2 ω_m t
        hand = (aa - ab) / (2 * 5e-5)
    assert tau == pytest.approx(hand, rel=2e-6 if name == "leo_spin" else 1e-7)
    # the same delay the product stores and restore reads
    assert tau / inst.line_period_s == pytest.approx((ALONG[0] - ALONG[1]) / PITCH, rel=0.02)


# --------------------------------------------------------------------------- renderer against sensor model
@pytest.mark.parametrize("name", ["straight", "leo_orbit", "leo_spin", "geo_mirror", "geo_spin"])
def test_renderer_agrees_with_the_sensor_model_over_relief(name):
    from simsat.render.pushbroom import PushbroomRenderer

    plat, inst = _centred(name)
    dem = _hill_dem(plat.earth_radius_m)
    rng = np.random.default_rng(5)
    xs = np.linspace(-180, 180, 5) + rng.uniform(-2, 2, 5)
    ys = np.linspace(-100, 100, 4) + rng.uniform(-2, 2, 4)
    centres = np.array([(x, y) for x in xs for y in ys])
    ifov = PITCH / inst.focal_length_m
    att = constant_attitude(0.3 * ifov, -0.2 * ifov, 1e-4)
    r = PushbroomRenderer(platform=plat, instrument=inst, dem=dem, texture=SpotTexture(centres, sigma_m=4.0),
                          attitude=att)
    t = np.arange(N_LINES) * inst.line_period_s
    imgs = r.render(t, block_lines=64)
    sm = SensorModel(platform=plat, instrument=inst, dem=dem, attitude=att)
    g = np.c_[centres, dem.height(centres[:, 0], centres[:, 1])]
    errs = spot_errors(sm, imgs, ("B1", "B0"), g, N_LINES)
    assert len(errs) >= 20
    assert np.max(np.abs(errs)) <= 0.01, errs


# --------------------------------------------------------------------------- scenario keys
def _scenario(tmp_path, platform_toml, lines=400):
    from simsat.scenario import load_scenario

    p = tmp_path / "s.toml"
    p.write_text(f'[scenario]\nbase = "tiny"\nname = "t"\n[platform]\n{platform_toml}\n'
                 f"[acquisition]\nlines = {lines}\n")
    return load_scenario(p)


def test_orbit_refuses_a_ground_speed(tmp_path):
    with pytest.raises(ScenarioError, match="platform.ground_speed_m_s"):
        _scenario(tmp_path, 'trajectory = "orbit"\naltitude_m = 694000.0\nground_speed_m_s = 7000.0')


def test_geostationary_platform_needs_a_scan(tmp_path):
    with pytest.raises(ScenarioError, match="platform.scan.*geostationary.*spin.*mirror"):
        _scenario(tmp_path, f'trajectory = "orbit"\naltitude_m = {GEOSTATIONARY_ALTITUDE_M}\ninclination_deg = 0.0')


def test_mirror_sweep_must_hold_the_acquisition(tmp_path):
    with pytest.raises(ScenarioError, match="platform.scan.*one mirror sweep"):
        _scenario(tmp_path, 'trajectory = "orbit"\naltitude_m = 35786000.0\ninclination_deg = 0.0\n'
                            '[platform.scan]\nkind = "mirror"\nmirror_rate_deg_s = 0.01\nscan_frequency_hz = 50.0')


# --------------------------------------------------------------------------- products
@pytest.mark.parametrize("name,pan", [("leo_spin", False), ("geo_mirror", True)])
def test_product_reads_back_the_trajectory_scan_tdi_and_delays(tmp_path, name, pan):
    """A rendered product of each variant gives the ground segment the scenario's geometry back."""
    from simsat.product import read_product
    from simsat.scenario import load_scenario
    from simsat.simulate import simulate

    ov = {"acquisition": {"lines": 40}, "instrument": {"pixels": 48},
          "scene": {"dem": {"resolution_m": 50.0}}}
    if pan:  # a TDI band in front
        ov["instrument"]["detectors"] = {0: {"tdi_stages": 5}}
    sc = load_scenario(name, overrides=ov)
    simulate(sc, tmp_path / "r", progress=False)
    p = read_product(tmp_path / "r")
    assert type(p.platform.trajectory) is type(sc.platform.trajectory)
    assert type(p.platform.scan) is type(sc.platform.scan)
    t = sc.line_times[::7]
    np.testing.assert_allclose(p.platform.position(t), sc.platform.position(t), atol=1e-6)
    np.testing.assert_allclose(p.platform.pointing(t, 1e-5, 2e-5, 0.0), sc.platform.pointing(t, 1e-5, 2e-5, 0.0),
                               atol=1e-14)
    assert [d.tdi_stages for d in p.instrument.detectors] == [d.tdi_stages for d in sc.instrument.detectors]
    assert p.instrument.detectors[0].tdi_stages == (5 if pan else 1)
    for a, b in (("B1", "B0"), ("B0", "B2")):
        assert p.delay_s(a, b) == pytest.approx(sc.delay_s(a, b), rel=1e-12)  # read back from the file
        assert p.sensor_model().nominal_delay_s(a, b) == pytest.approx(sc.delay_s(a, b), rel=1e-12)  # recomputed
    stored = dict(zip([str(s) for s in p.ds["pair"].values], p.ds["delay_s"].values))
    assert stored["B1/B0"] == pytest.approx(7.4e-3, rel=2e-4)
    # the ground segment's ephemeris is the platform's
    np.testing.assert_allclose(p.ds["ephemeris"].values, sc.platform.position(sc.line_times), atol=1e-6)
