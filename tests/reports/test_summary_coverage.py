"""The terminal names the line ranges it did not restore, and why, when they are more than 5 % of the lines."""
import numpy as np
import xarray as xr

from reports.summary import coverage_line, line_ranges


def test_line_ranges_are_the_runs_longest_first():
    m = np.zeros(20, bool)
    m[2:4] = m[10:17] = m[19] = True
    assert line_ranges(m) == [(10, 16), (2, 3), (19, 19)]
    assert line_ranges(np.zeros(5, bool)) == []


def _restoration(n=1000, gaps=(), flagged=()):
    v = np.ones(n)
    f = np.zeros(n, np.int8)
    for a, b in gaps:
        v[a:b] = np.nan
    for a, b in flagged:
        v[a:b] = np.nan
        f[a:b] = 1
    return xr.Dataset({"roll": ("time", v.copy()), "pitch": ("time", v.copy()), "flagged_pitch": ("time", f)})


def test_a_cloudy_record_names_its_unrestored_lines_and_why():
    ds = _restoration(gaps=[(100, 400), (700, 720)], flagged=[(400, 430)])
    line = coverage_line(ds, ["roll", "pitch"])
    assert "35.0 % of the lines" in line
    assert "no usable texture: cloud, water, flat or dark ground" in line and line.endswith("lines 100–429, 700–719")
    assert "30 of them flagged" in line and "max_sigma_px" not in line   # no run is mostly flagged


def test_runs_mostly_flagged_are_named_apart_from_those_without_texture():
    # a transient over half-water ground: its lines flagged for σ; the record's last lines had no differentials
    ds = _restoration(gaps=[(980, 1000), (0, 5)], flagged=[(5, 120), (290, 815)])
    line = coverage_line(ds, ["roll", "pitch"])
    assert "flagged for a predicted σ above restoration.max_sigma_px" in line
    flagged_part, texture_part = line.split("; no differentials")
    assert "lines 0–119, 290–814" in flagged_part and "980" not in flagged_part
    assert texture_part.endswith("lines 980–999")
    assert "640 of them flagged" in line


def test_a_mostly_restored_record_says_nothing():
    assert coverage_line(_restoration(gaps=[(0, 40)]), ["roll", "pitch"]) == ""
    assert coverage_line(None, ["roll"]) == ""


def test_transient_windows_are_named_with_their_axis_and_lines():
    import json

    from reports.summary import transient_line

    info = {"roll": {"options": {"transient_lines": [[0, 749]]}}, "pitch": {"options": {}}}
    ds = xr.Dataset(attrs={"integration": json.dumps(info)})
    assert transient_line(ds, ["roll", "pitch"]).endswith("roll lines 0–748")
    assert transient_line(xr.Dataset(attrs={"integration": json.dumps({"roll": {"options": {}}})}), ["roll"]) is None
    assert transient_line(None, ["roll"]) is None


def test_a_notch_bridged_below_a_continuum_is_said_with_its_axis_band_and_cost():
    from types import SimpleNamespace

    from restore.integration.spectrum import notch_mask
    from reports.summary import NOTCH_CONTINUUM_SHOWN_PX, notch_continuum_line

    dt, taus, sigma, ifov = 0.4e-3, np.array([7.4e-3, 22.2e-3, 14.8e-3]), 2e-7, 4.03e-6
    f = np.fft.rfftfreq(6000, dt)
    poor = notch_mask(f, taus, np.full(3, sigma ** 2 * dt))

    def record(level, bridge):
        s = np.where(poor, bridge, level)
        return SimpleNamespace(spectrum=SimpleNamespace(freq=f, psd=s, noise_std=np.full(3, sigma)), taus=taus,
                               line_period_s=dt, highpass_hz=2.0)

    import re

    from restore.observability import record_notch_continuum

    line = notch_continuum_line({"roll": record(1e-14, 1e-17), "pitch": record(1e-14, 1e-14)}, ["roll", "pitch"],
                                ifov)
    assert line is not None and "pitch" not in line           # pitch's notch holds its continuum: nothing to say
    said = [(float(lo), float(hi), float(px)) for lo, hi, px in
            re.findall(r"roll (\d+\.\d)–(\d+\.\d) Hz \(prior 1\.0e-17 against 1\.0e-14 rad²/Hz beside it\): "
                       r"(\d\.\d{3}) px", line)]
    assert said and said[0][0] < 135.1 < said[0][1]           # the common blind frequency's notch first
    expected = [n.missing_rms_rad / ifov for n in record_notch_continuum(record(1e-14, 1e-17))]
    assert [px for *_, px in said] == [round(v, 3) for v in expected if v >= NOTCH_CONTINUUM_SHOWN_PX]
    # a continuum too weak to cost NOTCH_CONTINUUM_SHOWN_PX is not said; no record, nothing said
    assert notch_continuum_line({"roll": record(1e-19, 0.0)}, ["roll"], ifov) is None
    assert notch_continuum_line({}, ["roll"], ifov) is None
