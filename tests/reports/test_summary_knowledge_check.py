"""The terminal summary says where the restored angle and the AOCS knowledge disagree beyond both predictions, and
how large σ would be if the images' prediction were the short one."""
import json

import numpy as np
import pytest
import xarray as xr

from reports.summary import knowledge_check_line

IFOV = 1e-6


def _ds(checks: dict, sigma_rad: float = 3e-8, ifov: float | None = IFOV):
    data = {}
    for a in ("roll", "pitch"):
        attrs = {"units": "rad", "predicted_detrended_rms_rad": sigma_rad}
        if a in checks:
            attrs["knowledge_check"] = json.dumps(checks[a])
        data[f"sigma_{a}"] = ("line", np.full(4, sigma_rad), attrs)
    return xr.Dataset(data, attrs={} if ifov is None else {"pixel_ifov_rad": ifov})


def _check(excess: float, booked: float, ratio: float = 2.5) -> dict:
    return {"band_hz": [2.5, 6.875], "bins": 8, "observed_rms_rad": 5e-8, "images_rms_rad": 3e-8,
            "knowledge_rms_rad": 3e-8, "excess_rms_rad": excess, "booked_rms_rad": booked, "ratio": ratio,
            "threshold": 1.866}


def test_a_disagreement_names_the_axis_and_the_sigma_if_the_images_are_short():
    # σ 3e-8 rad took 1e-8 of a 2e-8 excess (in quadrature): all of it gives √(9 − 1 + 4) e-8 = 3.4641e-8 rad
    line = knowledge_check_line(_ds({"pitch": _check(2e-8, 1e-8)}), ["roll", "pitch"])
    assert line is not None and "roll" not in line
    assert "pitch at 2.5–6.9 Hz 2.50 × (limit 1.87)" in line
    assert "σ 0.0300 px takes 0.0100 px of the 0.0200 px excess" in line
    worst = float(line.split("excess, ")[1].split(" px")[0])
    assert worst == pytest.approx(np.sqrt(9 - 1 + 4) * 1e-2, abs=5e-5)


def test_no_line_below_the_limit_or_without_a_check():
    # a shortfall under the limit (excess 0) is booked in σ but is no disagreement
    assert knowledge_check_line(_ds({"pitch": _check(0.0, 1e-8, ratio=1.5)}), ["roll", "pitch"]) is None
    assert knowledge_check_line(_ds({"pitch": {}}), ["roll", "pitch"]) is None      # no band: recorded empty
    assert knowledge_check_line(_ds({}), ["roll", "pitch"]) is None
    assert knowledge_check_line(_ds({"pitch": _check(2e-8, 1e-8)}, ifov=None), ["pitch"]) is None
    assert knowledge_check_line(None, ["pitch"]) is None


def test_both_axes_are_listed_in_order():
    line = knowledge_check_line(_ds({"roll": _check(2e-8, 1e-8), "pitch": _check(4e-8, 2e-8, ratio=3.0)}),
                                ["roll", "pitch"])
    assert line.index("roll at") < line.index("pitch at")
    assert "pitch at 2.5–6.9 Hz 3.00 ×" in line


def test_with_the_check_off_sigma_holds_none_of_the_excess():
    """``sigma_knowledge_check = false``: σ took nothing (the check still records its share), so all of the excess
    adds to σ as it is: √(9 + 4) e-8 rad."""
    line = knowledge_check_line(_ds({"pitch": _check(2e-8, 1e-8)}), ["pitch"], took_share=False)
    assert "σ 0.0300 px takes 0.0000 px of the 0.0200 px excess" in line
    worst = float(line.split("excess, ")[1].split(" px")[0])
    assert worst == pytest.approx(np.sqrt(9 + 4) * 1e-2, abs=5e-5)
    on = knowledge_check_line(_ds({"pitch": _check(2e-8, 1e-8)}), ["pitch"], took_share=True)
    assert float(on.split("excess, ")[1].split(" px")[0]) == pytest.approx(np.sqrt(12) * 1e-2, abs=5e-5)
