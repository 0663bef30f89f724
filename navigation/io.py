"""The navigation product: ``navigation.nc`` (trajectories, covariance, per-update diagnostics, sample frames).

Dimensions: ``seed``, ``time`` (1 Hz records), ``update`` (aiding sequences),
``axis`` (x, y, z). Written atomically (temporary file, then rename) into a
run directory beside a ``run.json`` that says which files simsat wrote.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import xarray as xr

from .world import KINDS

__all__ = ["navigation_dataset", "write_navigation", "read_navigation", "summarise", "NAV_FILES"]

NAV_FILES = ("navigation.nc", "run.json", "report")
_COUNTS = ("found", "tracked", "reconstructed", "matched", "used", "nis_dof")


def summarise(ds: xr.Dataset) -> dict:
    """Headline figures of a run: final horizontal errors, improvement, NEES consistency, no-aiding stretches."""
    from scipy.stats import chi2

    truth = ds.true_position.values
    ea = np.hypot(*(ds.aided_position.values - truth)[..., :2].transpose(2, 0, 1))
    eu = np.hypot(*(ds.unaided_position.values - truth)[..., :2].transpose(2, 0, 1))
    fa, fu = ea[:, -1], eu[:, -1]
    nees = ds.nees.values                                   # (seed, update)
    m = nees.shape[0]
    # per run: each (seed, update) against the χ²₃ 95 % interval (what a single flight can check)
    r_lo, r_hi = chi2.ppf(0.025, 3), chi2.ppf(0.975, 3)
    inside = float(np.mean((nees >= r_lo) & (nees <= r_hi)))
    # averaged over seeds (Bar-Shalom): stricter, and it assumes independent runs, which seeds sharing the
    # flight's frames and reference map are not
    lo, hi = chi2.ppf(0.025, 3 * m) / m, chi2.ppf(0.975, 3 * m) / m
    mean_nees = np.nanmean(nees, axis=0)
    inside_mean = float(np.mean((mean_nees >= lo) & (mean_nees <= hi)))
    status = ds.update_status.values
    ok = status == "ok"
    return {"seeds": int(m), "distance_km": float(ds.distance_m.values[-1] / 1000.0),
            "final_horizontal_m": {"median": float(np.median(fa)), "p95": float(np.percentile(fa, 95)),
                                   "max": float(fa.max()), "rms": float(np.sqrt(np.mean(fa ** 2)))},
            "unaided_final_horizontal_m": {"median": float(np.median(fu)), "rms": float(np.sqrt(np.mean(fu ** 2)))},
            "improvement_median": float(np.median(fu / np.maximum(fa, 1e-6))),
            "improvement_of_rms": float(np.sqrt(np.mean(fu ** 2)) / max(np.sqrt(np.mean(fa ** 2)), 1e-6)),
            "nees_bounds": [float(r_lo), float(r_hi)], "nees_inside_fraction": inside,
            "nees_above_fraction": float(np.mean(nees > r_hi)), "nees_mean": float(np.nanmean(nees)),
            "nees_mean_bounds": [float(lo), float(hi)], "nees_mean_inside_fraction": inside_mean,
            "updates": int(status.shape[1]), "fixes_fraction": float(ok.mean()),
            "no_aiding_updates": int((~ok).all(axis=0).sum())}


def navigation_dataset(result) -> xr.Dataset:
    """Long: one place lays out every variable of the product (names, dims, units)."""
    f = result.flight
    runs = result.runs
    step = max(int(round(1.0 / f.dt)), 1)
    idx = np.arange(0, len(f.t), step)
    n_up = max(len(r.updates) for r in runs)
    ups = runs[0].updates
    axis = ["x", "y", "z"]
    ds = xr.Dataset(coords={"seed": np.array(result.seeds, dtype=np.int64), "time": f.t[idx], "axis": axis,
                            "update": np.arange(n_up)})
    ds["true_position"] = (("time", "axis"), f.p[idx], {"units": "m"})
    ds["distance_m"] = (("time",), f.distance_m[idx], {"units": "m"})
    ds["height_above_ground_m"] = (("time",), f.agl[idx], {"units": "m"})
    ds["unaided_position"] = (("seed", "time", "axis"), np.stack([r.unaided for r in runs]), {"units": "m"})
    ds["aided_position"] = (("seed", "time", "axis"), np.stack([r.aided for r in runs]), {"units": "m"})
    ds["aided_sigma"] = (("seed", "time", "axis"), np.stack([r.sigma for r in runs]),
                         {"units": "m", "long_name": "filter 1-sigma of the aided position"})
    ds["update_time"] = (("update",), np.array([u["t"] for u in ups]), {"units": "s"})
    ds["update_distance_m"] = (("update",), np.array([u["distance_m"] for u in ups]), {"units": "m"})
    ds["update_fog"] = (("update",), np.array([bool(u["fog"]) for u in ups]))
    ds["update_status"] = (("seed", "update"), np.array([[u.get("status", "not aided") for u in r.updates]
                                                           for r in runs], dtype=str))
    for k in _COUNTS:
        ds[k] = (("seed", "update"), np.array([[int(u.get(k, 0)) for u in r.updates] for r in runs], np.int32))
    for k in ("nis", "nees"):
        ds[k] = (("seed", "update"), np.array([[float(u.get(k, np.nan)) for u in r.updates] for r in runs]))
    ds["update_error"] = (("seed", "update", "axis"), np.array([[u["error_m"] for u in r.updates] for r in runs]),
                          {"units": "m", "long_name": "INS minus truth after the update"})
    ds["update_sigma"] = (("seed", "update", "axis"), np.array([[u["sigma_m"] for u in r.updates] for r in runs]),
                          {"units": "m"})
    mr = [(i, s) for i, u in enumerate(runs[0].updates) for s in u.get("matched_ref", np.zeros((0, 4)))]
    ds["matched_reference"] = (("match", "xyxy"), np.array([s for _, s in mr]).reshape(-1, 4),
                               {"long_name": "reference segments matched (first seed)", "units": "m"})
    ds["matched_update"] = (("match",), np.array([i for i, _ in mr], dtype=np.int32))
    if result.sample_frames:
        imgs = np.stack([s[1] for s in result.sample_frames])
        lo, hi = np.percentile(imgs, [0.5, 99.5])
        ds["sample_frame"] = (("sample", "row", "col"), np.clip((imgs - lo) / (hi - lo) * 255, 0, 255).astype(np.uint8))
        ds["sample_update"] = (("sample",), np.array([s[0] for s in result.sample_frames], dtype=np.int32))
        for name, pos, dim in (("sample_segments", 2, "segment"), ("sample_reference", 3, "projected")):
            segs = [(k, seg) for k, s in enumerate(result.sample_frames) for seg in s[pos]]
            ds[name] = ((dim, "xyxy"), np.array([s for _, s in segs]).reshape(-1, 4), {"units": "px"})
            ds[name + "_frame"] = ((dim,), np.array([k for k, _ in segs], dtype=np.int32))
    if result.reference is not None:
        ds["reference_map"] = (("reference", "xyxy"), result.reference.segments, {"units": "m"})
        ds["reference_kind"] = (("reference",), result.reference.kinds.astype(np.int8))
        ds.attrs["reference_kinds"] = ",".join(KINDS)
    if result.dem is not None:
        dem = result.dem
        k = max(int(round(200.0 / dem.dx_m)), 1)
        ds = ds.assign_coords(terrain_x=dem.x[::k], terrain_y=dem.y[::k])
        ds["terrain_height"] = (("terrain_y", "terrain_x"), np.asarray(dem.z)[::k, ::k].astype(np.float32),
                                {"units": "m", "long_name": "DEM, decimated to ~200 m"})
    sc = result.scenario
    ds.attrs.update(scenario=sc.name, scenario_toml=json.dumps(sc.source, sort_keys=True),
                    camera=json.dumps({"width": sc.camera.width, "height": sc.camera.height,
                                       "hfov_deg": sc.camera.hfov_deg, "depression_deg": sc.camera.depression_deg}),
                    frames="reduced-frame mode: only the frames of each aiding sequence are rendered")
    ds.attrs["summary"] = json.dumps(summarise(ds))
    return ds


def write_navigation(result, out_dir) -> Path:
    """Write ``navigation.nc`` and ``run.json`` atomically into ``out_dir`` (created if needed)."""
    from simsat.product import atomic_write_dataset, atomic_write_json

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    ds = navigation_dataset(result)
    atomic_write_dataset(ds, out / "navigation.nc")
    atomic_write_json({"scenario": result.scenario.name, "kind": "navigation",
                       "files": {"navigation.nc": "trajectories, covariance, per-update diagnostics"},
                       "summary": json.loads(ds.attrs["summary"]),
                       "timings": {k: float(v) for k, v in result.timings.items()}},
                      out / "run.json")
    return out / "navigation.nc"


def read_navigation(path) -> xr.Dataset:
    p = Path(path)
    if p.is_dir():
        p = p / "navigation.nc"
    if not p.exists():
        from simsat.product import ProductError

        raise ProductError(f"{p}: file not found (run `simsat navigate SCENARIO --out DIR` first)")
    with xr.open_dataset(p) as ds:
        return ds.load()
