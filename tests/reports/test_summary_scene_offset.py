"""The terminal summary says where the images alone restore the attitude and the scene's band offset passes."""
import numpy as np
import pytest

from reports.summary import scene_offset_line

TAUS = [0.0074, 0.0222, 0.0148]


def _attrs(**kw):
    a = {"acquisition": "pushbroom", "knowledge_cutoff_hz": 2.0, "sun_elevation_deg": 45.0, "sun_azimuth_deg": 150.0}
    a.update(kw)
    return a


def test_a_knowledge_below_the_band_leaves_it_to_the_images_and_the_sun_names_the_axis():
    line = scene_offset_line(_attrs(), TAUS, ["roll", "pitch"])
    assert line is not None
    assert "2.0–6.8 Hz" in line and "150° from the track" in line
    assert "75 % on pitch" in line and "25 % on roll" in line


def test_the_track_s_direction_comes_from_the_ephemeris():
    # a track heading along +y: a sun at 100° from +x is 10° from the track, mostly along it (pitch)
    eph = np.column_stack([np.zeros(5), np.linspace(0.0, 1e4, 5), np.full(5, 7e5)])
    line = scene_offset_line(_attrs(sun_azimuth_deg=100.0), TAUS, ["roll", "pitch"], eph)
    assert "10° from the track" in line and "97 % on pitch" in line


@pytest.mark.parametrize("attrs", [_attrs(knowledge_cutoff_hz=10.0),       # the knowledge covers the band
                                   {"acquisition": "pushbroom", "knowledge_cutoff_hz": 2.0},   # no sun
                                   _attrs(acquisition="frames"),
                                   {k: v for k, v in _attrs().items() if k != "knowledge_cutoff_hz"}])
def test_no_band_no_sun_or_no_push_broom_no_line(attrs):
    assert scene_offset_line(attrs, TAUS, ["roll", "pitch"]) is None


def test_only_the_restored_axes_are_named():
    line = scene_offset_line(_attrs(), TAUS, ["roll"])
    assert "on roll" in line and "pitch" not in line
    assert scene_offset_line(_attrs(), TAUS, ["yaw"]) is None


def test_a_run_without_a_restoration_has_no_line():
    from reports.summary import scene_offset_line_of_run

    class _Run:
        restoration = None

    assert scene_offset_line_of_run(_Run(), ["roll", "pitch"]) is None
