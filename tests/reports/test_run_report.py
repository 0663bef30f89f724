"""Tests of the run report (reports/run_report.py, report_data.py, report_plots.py).

A synthetic run is written into tmp_path with the file formats of the real
pipeline (product.nc, truth.nc, restoration.nc, run.json): analytic jitter
(sinusoids), a smooth knowledge, exact differentials plus noise and a scale
error, and a restoration made with a small joint-Wiener integrator written
here. The numbers the report writes in its CSVs are compared with independent
computations from the analytic truth.
"""
from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from reports import report_data as D
from reports.plotting import read_table_csv
from reports.run_report import make_run_report
from restore.axis_integration import integrate_axis
from restore.integration.methods import register_method

F = 12.905
PITCH = 52e-6
H = 694000.0
TE = 4e-4
V = H * PITCH / F / TE
IFOV = PITCH / F
ALONG = {"B1": 0.962e-3, "B0": 0.0, "B2": -1.924e-3}
BANDS = {"B1": "green", "B0": "blue", "B2": "red"}
PAIRS = [("B1", "B0"), ("B0", "B2"), ("B1", "B2")]
K_WIENER = 0.05
NOISE_URAD = (0.15, 0.2, 0.25)       # per-pair matching σ of the differentials
SCALE_ERR = 0.03                      # model error: differentials 3 % too large
JITTER = {  # axis: [(amplitude rad, frequency Hz, phase)]
    "roll": [(2.0e-6, 51.3, 0.3), (1.0e-6, 77.4, 1.1)],
    "pitch": [(2.0e-6, 57.8, 0.7), (0.8e-6, 115.6, 2.0)],
    "yaw": [(4.0e-6, 66.1, 0.1)],
}
LOWF = {"roll": (3e-6, 3.0), "pitch": (-2e-6, 2.0), "yaw": (1.5e-6, 1.0)}   # known by the AOCS
KERR = {"roll": 0.5e-6, "pitch": 0.4e-6, "yaw": 0.3e-6}                       # knowledge error at 1.5 Hz


def tau_of(a, b):
    return H * (ALONG[a] - ALONG[b]) / (F * V)


def jitter(axis, t):
    t = np.asarray(t, float)
    return sum(A * np.sin(2 * np.pi * f * t + ph) for A, f, ph in JITTER[axis])


def lowf(axis, t):
    A, f = LOWF[axis]
    return A * np.sin(2 * np.pi * f * np.asarray(t, float)) + 1e-6 * np.asarray(t, float)


def true_att(axis, t):
    return lowf(axis, t) + jitter(axis, t)


def knowledge_exact(axis, t):
    return lowf(axis, t) + KERR[axis] * np.sin(2 * np.pi * 1.5 * np.asarray(t, float) + 0.4)


def wiener_integrate(diffs, taus, te, *, method=None, k=K_WIENER, **_):
    """Joint multi-pair Wiener integration by FFT (linear; gaps filled with 0; NaN where no pair measured)."""
    d = [np.asarray(x, float) for x in diffs]
    n = d[0].size
    f = np.fft.fftfreq(n, te)
    num = np.zeros(n, complex)
    den = np.zeros(n)
    for x, tau in zip(d, taus):
        g = np.exp(2j * np.pi * f * tau) - 1.0
        num += np.conj(g) * np.fft.fft(np.nan_to_num(x))
        den += np.abs(g) ** 2
    out = np.real(np.fft.ifft(num / (den + k)))
    none = np.all([~np.isfinite(x) for x in d], axis=0)
    out[none] = np.nan
    return out


@pytest.fixture(scope="module", autouse=True)
def _test_methods():
    """The test's integrators, registered as integration methods for this module only."""
    from restore.integration.methods import INTEGRATION_METHODS

    register_method("test_wiener", wiener_integrate, "joint Wiener by FFT (test oracle)", gain_option="k")
    register_method("adaptive", adaptive_integrate, "data-adaptive Wiener (test)", reports_spectrum=True)
    yield
    INTEGRATION_METHODS.pop("test_wiener")
    INTEGRATION_METHODS.pop("adaptive")


# ----------------------------------------------------------------------------- synthetic run
def _product(run: Path, n_lines: int, n_cols: int):
    from simsat.platform import Platform

    along_mean = np.mean(list(ALONG.values()))
    plat = Platform.straight(altitude_m=H, ground_speed_m_s=V).centred(t_mid_s=0.5 * (n_lines - 1) * TE,
                                                             along_angle_rad=np.arctan(along_mean / F))
    t = np.arange(n_lines) * TE
    dets = list(ALONG)
    rng = np.random.default_rng(3)
    data = {f"image_{d}": (("line", "column"), rng.integers(100, 3000, (n_lines, n_cols)).astype(np.uint16))
            for d in dets}
    kt = np.arange(-0.2, n_lines * TE + 0.2, 1 / 64.0)
    for a in D.AXES:
        data[f"knowledge_{a}"] = ("knowledge_time", knowledge_exact(a, kt))
    data["detector_band"] = ("detector", np.array([BANDS[d] for d in dets]))
    data["detector_along_m"] = ("detector", np.array([ALONG[d] for d in dets]))
    data["detector_across_m"] = ("detector", np.zeros(len(dets)))
    data["detector_pixels"] = ("detector", np.full(len(dets), n_cols, dtype=np.int32))
    data["detector_pitch_m"] = ("detector", np.full(len(dets), PITCH))
    pairs = [f"{a}/{b}" for a in dets for b in dets if ALONG[a] > ALONG[b]]
    data["delay_s"] = ("pair", np.array([tau_of(*p.split("/")) for p in pairs]))
    x = np.arange(-n_lines * 2.8 - 1500, n_lines * 2.8 + 1500, 20.0)
    half_y = n_cols * 2.8 / 2 + 800.0
    y = np.arange(-half_y, half_y, 20.0)
    z = 150 * np.sin(x[None, :] / 700.0) * np.cos(y[:, None] / 400.0) + 100.0
    data["dem"] = (("dem_y", "dem_x"), z)
    ds = xr.Dataset(data, coords={"line": np.arange(n_lines), "time": ("line", t), "detector": np.array(dets),
                                  "knowledge_time": kt, "pair": np.array(pairs), "dem_x": x, "dem_y": y},
                    attrs={"scenario": "synthetic", "t0_s": 0.0, "line_period_s": TE, "focal_length_m": F,
                           "altitude_m": H, "ground_speed_m_s": V, "platform_x_at_t0_m": plat.x_at_t0_m,
                           "platform_y_m": plat.y_m, "off_nadir_roll_rad": 0.0, "off_nadir_pitch_rad": 0.0,
                           "reference_detector": "B0", "pixel_ifov_rad": IFOV, "mtf_nyquist": 0.3, "bits": 12,
                           "dem_dx_m": 20.0, "dem_dy_m": 20.0})
    ds.to_netcdf(run / "product.nc")
    return t


def _truth(run: Path, n_lines: int):
    tt = np.arange(-TE, n_lines * TE + TE + 1e-12, TE / 4)
    ds = xr.Dataset({a: ("time", true_att(a, tt)) for a in D.AXES}, coords={"time": tt},
                    attrs={"pixel_ifov_rad": IFOV})
    ds.to_netcdf(run / "truth.nc")


def exact_differentials(axis, t, remaining=None):
    """δ(t+τ) − δ(t) per pair from the analytic truth (knowledge from the product's series)."""
    from simsat.attitude import AttitudeSeries

    kt = np.arange(-0.2, t.size * TE + 0.2, 1 / 64.0)
    ks = AttitudeSeries(time=kt, **{a: knowledge_exact(a, kt) for a in D.AXES})
    k = D.AXES.index(axis)
    out = []
    for a, b in PAIRS:
        tau = tau_of(a, b)
        d = (true_att(axis, t + tau) - ks.at(t + tau)[k]) - (true_att(axis, t) - ks.at(t)[k])
        if remaining is not None:
            d = d - (remaining(t + tau) - remaining(t))
        out.append(d)
    return np.array(out)


def _record_variables(data: dict, attrs: dict, axis: str, res, *, dmeas, sigma, taus, prev, names, n_lines):
    """The integration record of ``axis`` in restoration.nc's format (what the pipeline writes)."""
    data[f"integrated_diff_{axis}"] = (("pair", "time"), dmeas)
    data[f"integrated_sigma_{axis}"] = (("pair", "time"), sigma)
    data[f"line_lag_{axis}"] = (("pair", "time"), np.zeros((len(taus), n_lines)))
    data[f"line_weight_{axis}"] = (("pair", "time"), np.ones((len(taus), n_lines)))
    data[f"integrated_tau_{axis}"] = ("pair", np.array(taus))
    data[f"increment_{axis}"] = ("time", res.theta)
    data[f"previous_estimate_{axis}"] = ("time", np.zeros(n_lines) if prev is None else np.nan_to_num(prev))
    if res.spectrum is not None:
        data[f"prior_psd_{axis}"] = (f"prior_freq_{axis}", res.spectrum.psd)
        data[f"prior_freq_{axis}"] = (f"prior_freq_{axis}", res.spectrum.freq)
        data[f"prior_noise_std_{axis}"] = ("pair", res.spectrum.noise_std)
    info = json.loads(attrs.get("integration", "{}"))
    info[axis] = {"pairs": names, "method": res.method.name, "options": res.options, "highpass_hz": 0.0,
                  "line_period_s": TE}
    attrs["integration"] = json.dumps(info)


def make_synthetic_run(run: Path, *, n_lines: int = 1200, n_cols: int = 48, truth: bool = True,
                       restoration: bool = True, iterations: int = 1, seed: int = 0, method: str = "test_wiener",
                       options: dict | None = None) -> dict:
    run.mkdir(parents=True, exist_ok=True)
    t = _product(run, n_lines, n_cols)
    _truth(run, n_lines)
    info = {"name": "synthetic", "seed": 7,
            "scenario": {"raw": {"scenario": {"name": "synthetic", "description": "analytic test run",
                                              "requirement": {"max_rms_px": 0.05, "max_p997_px": 0.2}}}}}
    (run / "run.json").write_text(json.dumps(info))
    rng = np.random.default_rng(seed)
    taus = [tau_of(a, b) for a, b in PAIRS]
    names = [f"{a}/{b}" for a, b in PAIRS]
    from simsat.attitude import AttitudeSeries
    kt = np.arange(-0.2, n_lines * TE + 0.2, 1 / 64.0)
    ks = AttitudeSeries(time=kt, **{a: knowledge_exact(a, kt) for a in D.AXES})
    kn = dict(zip(D.AXES, ks.at(t)))
    # gaps: trailing lines that B cannot see, plus a cloud on pair 0
    gap = np.zeros((3, n_lines), bool)
    for j, tau in enumerate(taus):
        gap[j, n_lines - int(np.ceil(tau / TE)) - 1:] = True
    gap[0, 300:340] = True
    data, meta = {}, {"t": t, "taus": taus, "gap": gap}
    options = {"k": K_WIENER} if options is None else options
    rattrs: dict = {}
    for a in D.AXES:
        dtrue = exact_differentials(a, t)
        noise = np.array(NOISE_URAD)[:, None] * 1e-6 * rng.standard_normal(dtrue.shape)
        dmeas = np.where(gap, np.nan, (1 + SCALE_ERR) * dtrue + noise)
        res = integrate_axis(list(dmeas), taus, TE, method=method, options=options)
        est = res.theta
        prev = None
        if iterations == 2:
            # as restore.pipeline: the next iteration predicts with knowledge + nan_to_num(estimate), splined
            # over lines; the estimate's mean is removed only at the end
            prev = est + 0.7e-6
            from scipy.interpolate import CubicSpline
            cs = CubicSpline(t, np.nan_to_num(prev))
            dtrue2 = exact_differentials(a, t, remaining=cs)
            noise2 = np.array(NOISE_URAD)[:, None] * 1e-6 * rng.standard_normal(dtrue.shape)
            dmeas = np.where(gap, np.nan, (1 + SCALE_ERR) * dtrue2 + noise2)
            res = integrate_axis(list(dmeas), taus, TE, method=method, options=options)
            inc = res.theta
            est = np.where(np.isfinite(inc), np.nan_to_num(prev) + inc, np.nan)
        est = est - np.nanmean(est)
        data[a] = ("time", kn[a] + est)
        data[f"knowledge_{a}"] = ("time", kn[a])
        data[f"correction_{a}"] = ("time", est)
        data[f"diff_{a}"] = (("pair", "time"), dmeas)
        data[f"diff_sigma_{a}"] = (("pair", "time"),
                                   np.where(gap, np.nan, np.array(NOISE_URAD)[:, None] * 1e-6 * np.ones((3, n_lines))))
        meta[f"dmeas_{a}"] = dmeas
        meta[f"prev_{a}"] = prev
        meta[f"record_{a}"] = res
        _record_variables(data, rattrs, a, res, dmeas=dmeas, sigma=data[f"diff_sigma_{a}"][1], taus=taus, prev=prev,
                          names=names, n_lines=n_lines)
    data["diff_points"] = (("pair", "time"), np.where(gap, 0, 12).astype(np.int32))
    data["tau_s"] = ("pair", np.array(taus))
    # matches: 12 candidates per line per pair
    mp, la, ca, valid, inl = [], [], [], [], []
    for j in range(3):
        lines = np.repeat(np.arange(n_lines), 12)
        mp.append(np.full(lines.size, j))
        la.append(lines.astype(float))
        ca.append(rng.uniform(5, n_cols - 5, lines.size))
        v = rng.uniform(size=lines.size) < 0.95
        i = v & (rng.uniform(size=lines.size) < 0.9) & ~gap[j][lines]
        valid.append(v)
        inl.append(i)
    mp, la, ca = np.concatenate(mp), np.concatenate(la), np.concatenate(ca)
    valid, inl = np.concatenate(valid), np.concatenate(inl)
    rl = 0.05 * rng.standard_normal(mp.size)
    data["match_pair"] = ("match", mp.astype(np.int16))
    data["match_line_a"] = ("match", la)
    data["match_col_a"] = ("match", ca)
    data["match_pred_line_b"] = ("match", la + 20.0)
    data["match_pred_col_b"] = ("match", ca)
    data["match_meas_line_b"] = ("match", la + 20.0 + rl)
    data["match_meas_col_b"] = ("match", ca + rl)
    data["match_quality"] = ("match", np.full(mp.size, 0.9))
    data["match_valid"] = ("match", valid.astype(np.int8))
    data["match_inlier"] = ("match", inl.astype(np.int8))
    data["match_residual_line"] = ("match", rl)
    data["match_residual_col"] = ("match", rl)
    misreg = {n: {"before_px": 0.8 + 0.1 * j, "after_px": 0.02 + 0.01 * j, "before_line_px": 0.6,
                  "before_col_px": 0.5, "after_line_px": 0.015, "after_col_px": 0.012, "lines": 1000}
              for j, n in enumerate(names)}
    attrs = {"method": method, "pixel_ifov_rad": IFOV, "pairs": ",".join(names), **rattrs,
             "settings": json.dumps({"iterations": iterations, "axes": list(D.AXES), "highpass_hz": 0.0,
                                     "integration_options": options}),
             "timings": json.dumps({"integration_s": 0.01, "total_s": 1.0}),
             "misregistration": json.dumps(misreg), "anchored_on_star_tracker": 0}
    ds = xr.Dataset(data, coords={"time": t, "pair": np.array(names)}, attrs=attrs)
    for a in D.AXES:
        ds.attrs[f"coverage_{a}"] = float(np.isfinite(ds[a].values).mean())
    if restoration:
        ds.to_netcdf(run / "restoration.nc")
    if not truth:
        (run / "truth.nc").unlink()
    meta["restoration"] = ds
    return meta


@pytest.fixture(scope="module")
def synth(tmp_path_factory):
    run = tmp_path_factory.mktemp("synth") / "run"
    meta = make_synthetic_run(run)
    index = make_run_report(run, integrator=wiener_integrate, scene_3d="matplotlib")
    return run, meta, index


def _csv(run, name):
    return read_table_csv(run / "report" / name)


def _stats(e):
    e = np.asarray(e, float)
    e = e[np.isfinite(e)]
    e = e - e.mean()
    return np.sqrt(np.mean(e ** 2)), np.percentile(np.abs(e), 99.7)


# ----------------------------------------------------------------------------- tests
def test_files_written_and_page_self_contained(synth):
    run, meta, index = synth
    assert index == run / "report" / "index.html"
    page = index.read_text()
    for name in ("attitude.csv", "spectra.csv", "transfer_integration.csv", "transfer_measured.csv", "budget.csv",
                 "budget_differentials.csv", "summary.csv", "misregistration.csv", "footprints.csv", "gaps.csv",
                 "matches_B1-B0.csv", "attitude_roll.png", "spectra.png", "transfer.png", "budget.png",
                 "matches.png", "misregistration.png", "scene3d.png", "report.json"):
        assert (run / "report" / name).stat().st_size > 0, name
    # offline: no external resources, figures embedded
    assert not re.search(r'(src|href)="(https?:)?//', page)
    assert "<script" not in page
    assert page.count("data:image/png;base64,") >= 9
    assert "synthetic" in page and "PASS" in page or "FAIL" in page
    assert "B1/B0 τ = 7.40 ms" in page
    # no temporary files left behind
    assert not [p for p in (run / "report").iterdir() if p.name.startswith(".")]


def test_headline_equals_independent_errors(synth):
    run, meta, _ = synth
    s = _csv(run, "summary.csv")
    rest = meta["restoration"]
    t = meta["t"]
    for i, a in enumerate(D.AXES):
        est = rest[a].values
        m = np.isfinite(est)
        rms, p997 = _stats(np.where(m, est - true_att(a, t), np.nan))
        krms, kp = _stats(np.where(m, rest[f"knowledge_{a}"].values - true_att(a, t), np.nan))
        assert s["rms_px"][i] == pytest.approx(rms / IFOV, rel=1e-9)
        assert s["p997_urad"][i] == pytest.approx(p997 * 1e6, rel=1e-9)
        assert s["knowledge_rms_px"][i] == pytest.approx(krms / IFOV, rel=1e-9)
        assert s["knowledge_p997_px"][i] == pytest.approx(kp / IFOV, rel=1e-9)
        assert s["coverage"][i] == pytest.approx(m.mean())
        assert s["improvement_rms"][i] == pytest.approx(krms / rms, rel=1e-9)
    rep = json.loads((run / "report" / "report.json").read_text())
    worst = max(s["rms_px"])
    assert rep["headline"]["passed"] == bool(worst <= 0.05 and max(s["p997_px"]) <= 0.2)


def test_attitude_csv(synth):
    run, meta, _ = synth
    c = _csv(run, "attitude.csv")
    t = meta["t"]
    np.testing.assert_allclose(c["time_s"], t)
    np.testing.assert_allclose(c["true_pitch_urad"], true_att("pitch", t) * 1e6, atol=1e-9)
    e = meta["restoration"]["yaw"].values - true_att("yaw", t)
    e = e - np.nanmean(e)
    np.testing.assert_allclose(c["error_yaw_urad"], e * 1e6, atol=1e-9)
    np.testing.assert_allclose(c["delta_roll_urad"], (true_att("roll", t) - meta["restoration"]["knowledge_roll"].values)
                               * 1e6, atol=1e-9)


def test_spectra_csv(synth):
    from scipy.signal import welch

    run, meta, _ = synth
    c = _csv(run, "spectra.csv")
    rest = meta["restoration"]
    t = meta["t"]
    # the common fully estimated stretch: all restored finite
    m = np.all([np.isfinite(rest[a].values) for a in D.AXES], axis=0)
    idx = np.flatnonzero(m)
    sl = slice(idx[0], idx[-1] + 1)
    assert m[sl].all()
    delta = true_att("roll", t) - rest["knowledge_roll"].values
    f, p = welch(delta[sl], fs=1 / TE, window="hann", nperseg=256, noverlap=128)
    np.testing.assert_allclose(c["freq_hz"], f)
    np.testing.assert_allclose(c["psd_delta_roll_urad2_per_hz"], p * 1e12, rtol=1e-8)
    # Parseval: the PSD integrates to the variance; the peak sits on the strongest line
    assert np.trapezoid(c["psd_delta_roll_urad2_per_hz"], f) == pytest.approx(np.var(delta[sl]) * 1e12, rel=0.1)
    assert abs(f[np.argmax(c["psd_delta_roll_urad2_per_hz"])] - 51.3) < 1 / (256 * TE)


def test_transfer_matches_analytic_joint_wiener(synth):
    run, meta, _ = synth
    c = _csv(run, "transfer_integration.csv")
    f = c["freq_hz"]
    s = sum(4 * np.sin(np.pi * f * tau) ** 2 for tau in meta["taus"])
    ref = s / (s + K_WIENER)
    sel = (f > 20) & (f < 600)
    for a in D.AXES:
        assert np.median(np.abs(c[f"gain_fused_{a}"][sel] - ref[sel])) < 0.03
        np.testing.assert_allclose(c[f"analytic_gain_fused_{a}"], ref, atol=1e-12)
    # one pair alone is blind at 1/τ = 135 Hz
    g = c["gain_B1-B0_pitch"]
    i = np.argmin(np.abs(f - 1 / meta["taus"][0]))
    ref1 = 4 * np.sin(np.pi * f * meta["taus"][0]) ** 2
    ref1 = ref1 / (ref1 + K_WIENER)
    assert g[i] < 0.5 and np.max(g[(f > 40) & (f < 100)]) > 0.8
    assert np.median(np.abs(g[sel] - ref1[sel])) < 0.03
    # measured chain transfer at the jitter lines ≈ analytic chain gain × (1 + scale error)
    m = _csv(run, "transfer_measured.csv")
    fm = m["freq_hz"]
    for a, (A, f0, _) in (("roll", JITTER["roll"][0]), ("yaw", JITTER["yaw"][0])):
        i = np.argmin(np.abs(fm - f0))
        s0 = sum(4 * np.sin(np.pi * f0 * tau) ** 2 for tau in meta["taus"])
        assert m[f"gain_{a}"][i] == pytest.approx((1 + SCALE_ERR) * s0 / (s0 + K_WIENER), abs=0.05)
        assert m[f"significant_{a}"][i] == 1


def test_budget_rows_equal_independent_computations(synth):
    run, meta, _ = synth
    b = _csv(run, "budget.csv")
    rest = meta["restoration"]
    t = meta["t"]
    local = D.local_errors(D.load_run(run))
    assert set(local) == {f"{x}/{y}" for x, y in PAIRS}

    def row(axis, comp):
        i = [k for k in range(len(b["axis"])) if b["axis"][k] == axis and b["component"][k] == comp]
        assert len(i) == 1, (axis, comp)
        return {k: b[k][i[0]] for k in b}

    for a in D.AXES:
        m = np.isfinite(rest[a].values)
        delta = true_att(a, t) - rest[f"knowledge_{a}"].values
        # uncorrected
        r = row(a, "uncorrected knowledge")
        assert r["rms_px"] == pytest.approx(_stats(np.where(m, -delta, np.nan))[0] / IFOV, rel=1e-9)
        # integration: exact differentials (analytic truth), same gaps, integrated, minus the truth
        dtrue = np.where(meta["gap"], np.nan, exact_differentials(a, t))
        eint = np.where(m, wiener_integrate(list(dtrue), meta["taus"], TE) - delta, np.nan)
        rms, p = _stats(eint)
        r = row(a, "integration")
        assert r["rms_urad"] == pytest.approx(rms * 1e6, rel=2e-3)
        assert r["p997_urad"] == pytest.approx(p * 1e6, rel=5e-3)
        # measurement: measured − exact differentials integrated
        emeas = np.where(m, wiener_integrate(list(meta[f"dmeas_{a}"] - dtrue), meta["taus"], TE), np.nan)
        assert row(a, "measurement (noise + model)")["rms_urad"] == pytest.approx(_stats(emeas)[0] * 1e6, rel=2e-3)
        # total = headline, and total = measurement + integration (linear integrator)
        tot = row(a, "total (restored − true)")
        assert tot["rms_urad"] == pytest.approx(_stats(rest[a].values - true_att(a, t))[0] * 1e6, rel=1e-9)
        lin = _stats(emeas + eint)[0]
        assert lin * 1e6 == pytest.approx(tot["rms_urad"], rel=1e-6)
        # matching noise: one seeded draw of the propagated σ — sane magnitude
        n = row(a, "matching noise")
        assert 0.01 < n["rms_urad"] < 0.5
        mod = row(a, "model / synthesis")
        meas = row(a, "measurement (noise + model)")
        assert mod["rms_urad"] == pytest.approx(np.sqrt(max(meas["rms_urad"] ** 2 - n["rms_urad"] ** 2, 0)), rel=1e-9)
        # local matching error: the two interleaved halves' half-difference, integrated on top of the truth
        k = D.AXES.index(a)
        loc = np.array([local[f"{x}/{y}"][:, k] for x, y in PAIRS])
        loc = np.where(np.isfinite(meta[f"dmeas_{a}"]), np.nan_to_num(loc), np.nan)
        el = np.where(m, wiener_integrate(list(dtrue + loc), meta["taus"], TE)
                      - wiener_integrate(list(dtrue), meta["taus"], TE), np.nan)
        r_loc = row(a, "local matching error")
        assert r_loc["rms_urad"] == pytest.approx(_stats(el)[0] * 1e6, rel=5e-3)
        assert row(a, "line-common error")["rms_urad"] == pytest.approx(
            np.sqrt(max(meas["rms_urad"] ** 2 - r_loc["rms_urad"] ** 2, 0)), rel=1e-9)
    d = _csv(run, "budget_differentials.csv")
    for k in range(len(d["pair"])):
        j = [f"{a}/{b}" for a, b in PAIRS].index(d["pair"][k])
        a = d["axis"][k]
        assert d["matching_sigma_urad"][k] == pytest.approx(NOISE_URAD[j], rel=1e-9)
        r = meta[f"dmeas_{a}"][j] - exact_differentials(a, t)[j]
        r = r[np.isfinite(r)]
        assert d["meas_minus_true_rms_urad"][k] == pytest.approx(np.std(r) * 1e6, rel=2e-3)


def test_match_density_and_misregistration_csv(synth):
    run, meta, _ = synth
    rest = meta["restoration"]
    c = _csv(run, "matches_B0-B2.csv")
    sel = (rest["match_pair"].values == 1) & (rest["match_inlier"].values == 1)
    la, ca = rest["match_line_a"].values[sel], rest["match_col_a"].values[sel]
    le = np.unique(np.concatenate([c["line_lo"], c["line_hi"]]))
    ce = np.unique(np.concatenate([c["col_lo"], c["col_hi"]]))
    h, _, _ = np.histogram2d(la, ca, bins=(le, ce))
    np.testing.assert_array_equal(c["inliers"], h.ravel())
    assert c["inliers"].sum() == sel.sum()
    rej = (rest["match_pair"].values == 1) & (rest["match_inlier"].values == 0)
    assert c["rejected"].sum() == rej.sum()
    g = _csv(run, "gaps.csv")
    i = [k for k in range(len(g["pair"])) if g["pair"][k] == "B1/B0"]
    assert [(g["first_line"][k], g["stop_line"][k]) for k in i][0] == (300, 340)
    m = _csv(run, "misregistration.csv")
    assert list(m["pair"]) == ["B1/B0", "B0/B2", "B1/B2"]
    np.testing.assert_allclose(m["after_px"], [0.02, 0.03, 0.04])


def test_report_without_truth(tmp_path, monkeypatch):
    import reports.run_report as RR

    def no_opengl(*args, **kwargs):
        raise RuntimeError("no OpenGL context (test)")
    monkeypatch.setattr(RR, "_render_pyvista_subprocess", no_opengl)
    run = tmp_path / "real"
    make_synthetic_run(run, n_lines=600, truth=False)
    index = make_run_report(run, integrator=wiener_integrate)
    page = index.read_text()
    assert "no OpenGL context (test)" in page and "drawn with matplotlib instead" in page
    assert (run / "report" / "scene3d.png").stat().st_size > 5000
    assert "No truth.nc" in page
    assert "cannot be checked without truth" in page
    out = run / "report"
    assert not (out / "transfer_measured.csv").exists()
    att = _csv(run, "attitude.csv")
    assert "error_roll_urad" not in att and "restored_roll_urad" in att
    b = _csv(run, "budget.csv")
    assert set(b["component"]) == {"matching noise", "local matching error"}
    spec = _csv(run, "spectra.csv")
    assert "psd_correction_pitch_urad2_per_hz" in spec and "psd_error_pitch_urad2_per_hz" not in spec
    rep = json.loads((out / "report.json").read_text())
    assert rep["headline"]["passed"] is None


def test_report_product_only_and_no_integrator(tmp_path, monkeypatch):
    run = tmp_path / "p"
    make_synthetic_run(run, n_lines=400, restoration=False)
    index = make_run_report(run, scene_3d="none", out_dir=tmp_path / "rep")
    assert index == tmp_path / "rep" / "index.html"
    assert "No restoration.nc" in index.read_text()
    c = read_table_csv(tmp_path / "rep" / "attitude.csv")
    assert "knowledge_error_roll_urad" in c
    # restoration present but the integrator not importable: analytic transfer, differential-level budget
    run2 = tmp_path / "q"
    make_synthetic_run(run2, n_lines=400)
    monkeypatch.setattr(D, "get_integrator", lambda integrator=None: (None, "not importable (test)"))
    index = make_run_report(run2, scene_3d="none")
    page = index.read_text()
    assert "not importable (test)" in page
    b = _csv(run2, "budget.csv")
    assert set(b["component"]) == {"uncorrected knowledge", "total (restored − true)"}
    assert (run2 / "report" / "budget_differentials.csv").exists()


def test_two_iterations_budget_uses_previous_estimate(tmp_path):
    run = tmp_path / "it2"
    meta = make_synthetic_run(run, n_lines=1000, iterations=2)
    bud = D.error_budget(D.load_run(run), integrate=wiener_integrate)
    b = {k: np.array([r.get(k) for r in bud["rows"]], dtype=object if k in ("axis", "component", "note") else float)
         for k in bud["rows"][0]}
    d = {k: np.array([r.get(k) for r in bud["differential_rows"]],
                     dtype=object if k in ("axis", "pair") else float) for k in bud["differential_rows"][0]}
    rest = meta["restoration"]
    t = meta["t"]
    a = "pitch"
    from scipy.interpolate import CubicSpline
    prev = np.nan_to_num(meta[f"prev_{a}"])
    cs = CubicSpline(t, prev)
    dtrue = np.where(meta["gap"], np.nan, exact_differentials(a, t, remaining=cs))
    m = np.isfinite(rest[a].values)
    remaining = true_att(a, t) - rest[f"knowledge_{a}"].values - prev
    eint = np.where(m, wiener_integrate(list(dtrue), meta["taus"], TE) - remaining, np.nan)
    i = [k for k in range(len(b["axis"])) if b["axis"][k] == a and b["component"][k] == "integration"][0]
    assert b["rms_urad"][i] == pytest.approx(_stats(eint)[0] * 1e6, rel=5e-3)
    k = [k for k in range(len(d["pair"])) if d["axis"][k] == a and d["pair"][k] == "B1/B0"][0]
    r = meta[f"dmeas_{a}"][0] - dtrue[0]
    assert d["meas_minus_true_rms_urad"][k] == pytest.approx(np.nanstd(r) * 1e6, rel=5e-3)


def test_product_image_shapes_without_reading_images(synth):
    from simsat.product import read_product

    run, _, _ = synth
    full = read_product(run)
    assert full.image_shapes == {b: full.image(b).shape for b in full.band_names} == \
        {b: (1200, 48) for b in full.band_names}


def test_footprints_csv_from_sensor_model(synth):
    from simsat.product import read_product

    run, _, _ = synth
    c = _csv(run, "footprints.csv")
    sm = read_product(run).sensor_model()
    sel = c["band"] == "B2"
    first = np.array([c["x_m"][sel][0], c["y_m"][sel][0], c["z_m"][sel][0]])
    np.testing.assert_allclose(first, sm.direct_location("B2", 0.0, 0.0), atol=1e-6)
    # B1 (ahead) sees line 0 further along-track than B2 (behind)
    s1 = c["band"] == "B1"
    assert c["x_m"][s1][0] - c["x_m"][sel][0] == pytest.approx(V * (tau_of("B1", "B2")), rel=0.05)


def test_minmax_decimate_keeps_envelope():
    x = np.arange(100000.0)
    y = np.sin(x / 50.0)
    y[5000] = 7.0
    y[70000:70100] = np.nan
    xs, ys = D.minmax_decimate(x, y, 2000)
    assert xs.size <= 2000
    assert np.nanmax(ys) == 7.0
    assert np.all(np.diff(xs) >= 0)
    assert np.isnan(ys).any()


def test_pyvista_scene_renders_off_screen(synth, tmp_path):
    """PyVista in a child process; where no OpenGL context exists the report falls back (tested in synth)."""
    from reports.run_report import _render_pyvista_subprocess

    run, _, _ = synth
    scene = D.scene_geometry(D.load_run(run))
    png = tmp_path / "scene.png"
    try:
        _render_pyvista_subprocess(scene, png, timeout_s=90)
    except RuntimeError as e:  # no OpenGL here: the report would draw with matplotlib
        pytest.skip(f"PyVista cannot render here: {e}")
    assert png.stat().st_size > 5000
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_bad_scene_option(tmp_path):
    with pytest.raises(ValueError, match="scene_3d"):
        make_run_report(tmp_path, scene_3d="opengl")


class _Details:
    def __init__(self, theta, spectrum):
        self.theta = theta
        self.spectrum = spectrum


class _Spectrum:
    def __init__(self, freq, psd, noise_std):
        self.freq, self.psd, self.noise_std = freq, psd, noise_std


def adaptive_integrate(diffs, taus, te, *, method=None, psd=None, noise_std=None, return_details=False):
    """A data-adaptive Wiener integrator (its prior is a flat PSD set from the data) that can be frozen.

    The prior PSD level is the variance of the first pair's differentials (data dependent: not linear);
    with ``psd`` and ``noise_std`` given it is the fixed linear filter
    ``Θ = Σ conj(G_j) D_j S/N_j / (1 + Σ |G_j|² S/N_j)``, N_j = σ_j² Δt.
    """
    d = [np.asarray(x, float) for x in diffs]
    n = d[0].size
    f = np.fft.fftfreq(n, te)
    if noise_std is None:
        noise_std = np.full(len(d), 0.2e-6)
    sig = np.broadcast_to(np.asarray(noise_std, float), (len(d),))
    if psd is None:
        fr = np.abs(np.fft.rfftfreq(n, te))
        level = np.nanvar(d[0]) * te * 0.5
        psd = (fr, np.full(fr.size, level))
        spec = _Spectrum(fr, psd[1], sig.copy())
    else:
        spec = _Spectrum(np.asarray(psd[0]), np.asarray(psd[1]), sig.copy())
    S = np.interp(np.abs(f), psd[0], psd[1])
    num = np.zeros(n, complex)
    den = np.ones(n)
    for x, tau, sj in zip(d, taus, sig):
        g = np.exp(2j * np.pi * f * tau) - 1.0
        snr = S / (sj * sj * te)
        num += np.conj(g) * snr * np.fft.fft(np.nan_to_num(x))
        den += np.abs(g) ** 2 * snr
    out = np.real(np.fft.ifft(num / den))
    out[np.all([~np.isfinite(x) for x in d], axis=0)] = np.nan
    out = out - np.nanmean(out)
    return _Details(out, spec) if return_details else out


def test_adaptive_integrator_is_frozen_for_budget_and_transfer(tmp_path):
    run_dir = tmp_path / "adaptive"
    # restored with the adaptive integrator through the pipeline's integration step, which records its prior
    meta = make_synthetic_run(run_dir, n_lines=800, method="adaptive", options={})
    run = D.load_run(run_dir)
    fz = D.axis_integration(run, "roll")
    assert fz["frozen"] and "psd" in fz["options"]
    ds = meta["restoration"]
    # the frozen filter reproduces the adaptive run on the measured data, and is linear
    again = adaptive_integrate(list(meta["dmeas_roll"]), meta["taus"], TE, **fz["options"])
    np.testing.assert_allclose(again, fz["theta"], atol=1e-15)
    x = list(meta["dmeas_roll"] * 3.0)
    np.testing.assert_allclose(adaptive_integrate(x, meta["taus"], TE, **fz["options"]), 3 * again, atol=1e-15)
    bud = D.error_budget(run, integrate=adaptive_integrate)
    t = meta["t"]
    row = {(r["axis"], r["component"]): r for r in bud["rows"]}
    # integration row: exact differentials through the *frozen* filter, minus the truth
    dtrue = np.where(meta["gap"], np.nan, exact_differentials("roll", t))
    delta = true_att("roll", t) - ds["knowledge_roll"].values
    m = np.isfinite(ds["roll"].values)
    eint = np.where(m, adaptive_integrate(list(dtrue), meta["taus"], TE, **fz["options"]) - delta, np.nan)
    assert row[("roll", "integration")]["rms_urad"] == pytest.approx(_stats(eint)[0] * 1e6, rel=2e-3)
    assert not any("differs from the restoration" in n for n in bud["notes"])
    # probed transfer of the frozen filter = its analytic chain gain
    pr = D.integration_probe(meta["taus"], TE, 800, integrate=adaptive_integrate, method="adaptive",
                             options=fz["options"], pair_names=["B1/B0", "B0/B2", "B1/B2"])
    f = pr["freq_hz"]
    an = D.frozen_chain_gain(f, meta["taus"], fz["spectrum"], TE)
    sel = (f > 20) & (f < 600)
    assert np.median(np.abs(pr["gain_fused"][sel] - an[sel])) < 0.03


def test_true_differentials_at_the_delay_the_images_saw(synth):
    """Truth taken at t + τ + λ Te; the lags are the ones the pipeline recorded (zero in this synthetic run)."""
    from simsat.attitude import AttitudeSeries

    run_dir, meta, _ = synth
    run = D.load_run(run_dir)
    n = run.time.size
    lags = D.line_lags(run)
    assert lags.shape == (3, n) and not lags.any()
    # exaggerate the lags so that the effect is large, and check against the analytic truth
    big = 3.0 * np.sin(np.arange(n) / 40.0)[None, :].repeat(3, axis=0)
    t = run.time
    kt = np.arange(-0.2, n * TE + 0.2, 1 / 64.0)
    ks = AttitudeSeries(time=kt, **{a: knowledge_exact(a, kt) for a in D.AXES})
    got = D.true_differentials(run, "pitch", lags=big)[0]
    k = D.AXES.index("pitch")
    for j, (a, b) in enumerate(PAIRS):
        t1 = t + tau_of(a, b) + big[j] * TE
        exp = (true_att("pitch", t1) - ks.at(t1)[k]) - (true_att("pitch", t) - ks.at(t)[k])
        ok = np.isfinite(got[j]) & (t1 <= t[-1])
        np.testing.assert_allclose(got[j][ok], exp[ok], atol=2e-10)


def test_an_anchored_run_judges_the_integration_without_the_trend_the_star_tracker_sets(synth, tmp_path):
    """Anchored on a star tracker, the record's trend is set after the integration: the budget's integration row
    is the exact differentials' integration error less its least-squares line, and the identity total =
    measurement + integration still holds."""
    import shutil

    import xarray as xr

    run0, meta, _ = synth
    run = tmp_path / "anchored"
    shutil.copytree(run0, run)
    ds = xr.load_dataset(run / "restoration.nc")
    ds.attrs["anchored_on_star_tracker"] = 1
    ds.to_netcdf(run / "restoration.nc")
    bud = D.error_budget(D.load_run(run), integrate=wiener_integrate)
    t = meta["t"]
    for a in ("roll", "pitch"):
        m = np.isfinite(meta["restoration"][a].values)
        delta = true_att(a, t) - meta["restoration"][f"knowledge_{a}"].values
        dtrue = np.where(meta["gap"], np.nan, exact_differentials(a, t))
        eint = np.where(m, wiener_integrate(list(dtrue), meta["taus"], TE) - delta, np.nan)
        x = np.arange(eint.size)
        ok = np.isfinite(eint)
        eint = np.where(ok, eint - np.polyval(np.polyfit(x[ok], eint[ok], 1), x), np.nan)
        rows = {r["component"]: r for r in bud["rows"] if r["axis"] == a}
        assert rows["integration"]["rms_urad"] == pytest.approx(_stats(eint)[0] * 1e6, rel=2e-3)
        assert "star-tracker anchoring" in rows["integration"]["note"]
        # the trend left, apart: measurement + integration + anchoring = total, line by line
        ser = bud["series"][a]
        tot = np.where(m, meta["restoration"][a].values - true_att(a, t), np.nan)
        tot = tot - np.nanmean(tot)
        np.testing.assert_allclose(ser["measurement"] + ser["integration"] + ser["star-tracker anchoring"], tot,
                                   atol=1e-12, equal_nan=True)
        anc = ser["star-tracker anchoring"]
        ok = np.isfinite(anc)
        assert np.allclose(np.diff(anc[ok], 2), 0.0, atol=1e-15) if ok.sum() > 2 else True   # a straight line
        total = rows["total (restored − true)"]["rms_urad"]
        assert total == pytest.approx(_stats(meta["restoration"][a].values - true_att(a, t))[0] * 1e6, rel=1e-9)


def test_the_budget_figure_draws_the_predicted_parts_beside_the_measured_ones():
    """What no pair sees and the floor (an RMS each, no 99.7 %) get one solid bar each, drawn at their value;
    a measured component gets its RMS and its 99.7 % bar."""
    from matplotlib.figure import Figure

    from reports.report_plots import draw_budget

    rows = [{"axis": "roll", "component": "uncorrected knowledge", "rms_px": 0.7, "p997_px": 1.8},
            {"axis": "roll", "component": "unobservable (no pair sees it)", "rms_px": 0.002, "p997_px": None},
            {"axis": "roll", "component": "floor (best linear restoration)", "rms_px": 0.01, "p997_px": None},
            {"axis": "roll", "component": "total (restored − true)", "rms_px": 0.03, "p997_px": 0.1}]
    ax = Figure().subplots()
    draw_budget(ax, rows)
    widths = sorted(round(p.get_width(), 6) for p in ax.patches)
    assert widths == [0.002, 0.01, 0.03, 0.1, 0.7, 1.8]
    assert [t.get_text() for t in ax.get_legend().get_texts()] == [r["component"] for r in rows]


def test_knowledge_check_cell_says_what_sigma_takes_below_the_limit_too():
    """Beyond the limit the cell states the excess and σ's share of it; below it no excess is claimed, but what σ
    takes of the measured one is still said; nothing when the observed power is within the predictions."""
    from reports.run_report import _knowledge_check_text

    base = {"band_hz": [2.5, 6.9], "threshold": 1.87}
    below = _knowledge_check_text({**base, "ratio": 1.79, "excess_rms_rad": 0.0, "booked_rms_rad": 1.05e-8}, 1e-6)
    assert "excess 0" not in below and below.endswith("σ takes 0.0105 px of the excess")
    beyond = _knowledge_check_text({**base, "ratio": 2.5, "excess_rms_rad": 2e-8, "booked_rms_rad": 1e-8}, 1e-6)
    assert "excess 0.0200 px, σ takes 0.0100 px of it" in beyond and "short one" not in beyond
    # with the axis's σ (3e-8 rad): all of the excess instead of its share, √(9 − 1 + 4) × 0.01 px
    with_sigma = _knowledge_check_text({**base, "ratio": 2.5, "excess_rms_rad": 2e-8, "booked_rms_rad": 1e-8}, 1e-6,
                                       3e-8)
    assert with_sigma.endswith(f"({np.sqrt(12) * 0.01:.4f} px if the images' prediction is the short one)")
    assert "short one" not in _knowledge_check_text({**base, "ratio": 1.79, "excess_rms_rad": 0.0,
                                                     "booked_rms_rad": 1.05e-8}, 1e-6, 3e-8)
    assert _knowledge_check_text({**base, "ratio": 0.5, "excess_rms_rad": 0.0, "booked_rms_rad": 0.0},
                                 1e-6) == "2.5–6.9 Hz: 0.50 × (limit 1.87)"
