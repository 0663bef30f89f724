"""The terminal summary says when a line on the pairs' common blind frequency was found through the lags."""
import numpy as np
import xarray as xr

from reports.summary import blind_tone_line


def _ds(**attrs_by_axis):
    data = {}
    for a in ("roll", "pitch"):
        data[f"prior_noise_std_{a}"] = ("pair", np.ones(3), dict(attrs_by_axis.get(a, {}), units="rad"))
    return xr.Dataset(data)


def test_a_found_tone_is_named_with_its_axis_and_frequency():
    ds = _ds(pitch={"blind_tone_hz": np.array([135.1672]), "blind_tone_prior_sd_rad": 6e-6, "blind_tone_order": 2})
    line = blind_tone_line(ds, ["roll", "pitch"])
    assert line is not None and "pitch 135.17 Hz" in line and "roll" not in line


def test_no_tone_no_line():
    assert blind_tone_line(_ds(), ["roll", "pitch"]) is None
    assert blind_tone_line(None, ["roll"]) is None
