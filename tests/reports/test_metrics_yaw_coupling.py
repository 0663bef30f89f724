"""Off nadir the pitch error is also given without the yaw the images see as pitch (reports.metrics)."""
import numpy as np
import pytest
import xarray as xr

from reports.metrics import attitude_errors


def _datasets(coupling):
    t = np.arange(2000) * 4e-4
    rng = np.random.default_rng(0)
    yaw_true = 2e-6 * np.sin(2 * np.pi * 60 * t)
    pitch_true = 1e-6 * np.sin(2 * np.pi * 45 * t)
    own = 0.05e-6 * rng.standard_normal(t.size)  # the restoration's own error
    pitch_rest = pitch_true + coupling * yaw_true + own
    rest = xr.Dataset({"pitch": ("time", pitch_rest), "knowledge_pitch": ("time", np.zeros(t.size)),
                       "yaw": ("time", np.zeros(t.size)), "knowledge_yaw": ("time", np.zeros(t.size))},
                      coords={"time": t}, attrs={"pixel_ifov_rad": 1e-6, "yaw_pitch_coupling": coupling})
    truth = xr.Dataset({"pitch": ("time", pitch_true), "yaw": ("time", yaw_true), "roll": ("time", 0 * t)},
                       coords={"time": t})
    return rest, truth, own


def test_the_yaw_seen_as_pitch_is_taken_out_of_the_pitch_error():
    rest, truth, own = _datasets(np.tan(np.radians(20)))
    e = attitude_errors(rest, truth, axes=("pitch",))["pitch"]
    assert e["rms_px"] == pytest.approx(np.tan(np.radians(20)) * 2 / np.sqrt(2), rel=0.02)
    assert e["rms_px_without_yaw_coupling"] == pytest.approx(np.std(own) / 1e-6, rel=1e-6)


def test_looking_ahead_the_yaw_seen_as_roll_is_taken_out_of_the_roll_error():
    t = np.arange(2000) * 4e-4
    yaw_true = 2e-6 * np.sin(2 * np.pi * 60 * t)
    own = 0.05e-6 * np.random.default_rng(1).standard_normal(t.size)
    c = np.sin(np.radians(15))
    z = np.zeros(t.size)
    rest = xr.Dataset({"roll": ("time", c * yaw_true + own), "knowledge_roll": ("time", z),
                       "yaw": ("time", z), "knowledge_yaw": ("time", z)},
                      coords={"time": t}, attrs={"pixel_ifov_rad": 1e-6, "yaw_roll_coupling": c,
                                                 "yaw_pitch_coupling": 0.0})
    truth = xr.Dataset({"pitch": ("time", z), "yaw": ("time", yaw_true), "roll": ("time", z)}, coords={"time": t})
    e = attitude_errors(rest, truth, axes=("roll",))["roll"]
    assert e["rms_px"] == pytest.approx(c * 2 / np.sqrt(2), rel=0.02)
    assert e["rms_px_without_yaw_coupling"] == pytest.approx(np.std(own) / 1e-6, rel=1e-6)
    assert e["yaw_coupling"] == c


def test_at_nadir_there_is_no_split():
    rest, truth, _ = _datasets(0.0)
    assert "rms_px_without_yaw_coupling" not in attitude_errors(rest, truth, axes=("pitch",))["pitch"]
