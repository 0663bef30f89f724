"""Summary and report of a run whose product is a matrix detector's frames (:mod:`restore.frames`).

The same accuracy metric as the push-broom runs (docs/design.md): estimate −
truth at the frame times, mean removed, RMS and 99.7 % per restored axis in
pixels, against the AOCS knowledge on the same frames, and the scenario's
requirement.
"""
from __future__ import annotations

import csv
import html
import json
from pathlib import Path

import numpy as np

from .metrics import attitude_errors, truth_at

__all__ = ["is_frames_run", "frames_errors", "frames_headline", "frames_summary", "make_frames_report"]


def is_frames_run(run_dir) -> bool:
    """Whether ``run_dir``'s product is a matrix detector's frames (reads the attributes only)."""
    import netCDF4

    p = Path(run_dir) / "product.nc"
    if not p.is_file():
        return False
    with netCDF4.Dataset(str(p)) as nc:
        return str(getattr(nc, "acquisition", "pushbroom")) == "frames"


def _load(run_dir: Path):
    import xarray as xr

    rest = xr.load_dataset(run_dir / "restoration.nc") if (run_dir / "restoration.nc").is_file() else None
    truth = xr.load_dataset(run_dir / "truth.nc") if (run_dir / "truth.nc").is_file() else None
    info = json.loads((run_dir / "run.json").read_text()) if (run_dir / "run.json").is_file() else {}
    return rest, truth, info


def frames_errors(rest, truth) -> dict:
    """Per-axis error statistics at the frame times (:func:`reports.metrics.attitude_errors`)."""
    return attitude_errors(rest, truth)


def frames_headline(rest, truth, info) -> dict:
    """``{"errors", "axes", "requirement", "worst", "passed", "verdict"}`` of a frames run."""
    from .report_data.headline import _requirement, judge

    req = _requirement(info)
    out = {"errors": {}, "axes": [], "requirement": req, "worst": {}, "passed": None, "verdict": ""}
    if rest is None:
        out["verdict"] = "no restoration: nothing to check"
        return out
    axes = [a for a in str(rest.attrs.get("axes", "roll,pitch")).split(",") if a]
    out["axes"] = axes
    if truth is None:
        out["verdict"] = "requirement cannot be checked without truth" if req else "no requirement; no truth"
        return out
    errs = frames_errors(rest, truth)
    out["errors"] = errs
    return judge(out, errs, req, axes)


def frames_summary(run_dir, *, report_path=None) -> str:
    """The terminal summary of a frames run (same layout as :func:`reports.summary.run_summary`)."""
    rest, truth, info = _load(Path(run_dir))
    hd = frames_headline(rest, truth, info)
    lines = []
    if rest is None:
        lines.append("no restoration in this run (run `simsat restore RUN_DIR`)")
    elif truth is None:
        lines.append("no truth in this run: the restored error cannot be measured")
    else:
        lines.append(f"{'':12s}{'restored error':>18s}  {'AOCS knowledge':>18s}   (at the {rest.time.size} frame times)")
        lines.append(f"{'':12s}{'RMS':>9s}{'99.7 %':>9s}  {'RMS':>9s}{'99.7 %':>9s}")
        for a in hd["axes"]:
            e = hd["errors"][a]
            lines.append(f"  {a:5s}{'[px]':>5s}{e['rms_px']:9.3f}{e['p997_px']:9.3f}  "
                         f"{e['knowledge_rms_px']:9.3f}{e['knowledge_p997_px']:9.3f}")
        lines.append("  (error = estimate − truth, mean removed: the constant is unobservable from images)")
    if hd["passed"] is not None:
        lines.append(f"requirement: {hd['verdict']}")
    elif hd["verdict"]:
        lines.append(f"requirement not checked: {hd['verdict']}")
    if report_path is not None:
        lines.append(f"report: {report_path}")
    return "\n".join(lines)


def _predicted_px(rest, axis: str) -> float:
    """RMS of the predicted 1-σ of ``axis`` [px] (NaN when the restoration has none)."""
    if f"sigma_{axis}" not in rest:
        return float("nan")
    return float(np.sqrt(np.nanmean(rest[f"sigma_{axis}"].values ** 2)) / float(rest.attrs["pixel_ifov_rad"]))


def _attitude_figure(rest, truth, axis: str, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ifov = float(rest.attrs["pixel_ifov_rad"])
    t = np.asarray(rest.time.values)
    tr = truth_at(truth, axis, t)
    est = np.asarray(rest[axis].values)
    kn = np.asarray(rest[f"knowledge_{axis}"].values)
    fig, (a0, a1) = plt.subplots(2, 1, figsize=(10, 6), sharex=True, constrained_layout=True)
    x = (t - t[0]) * 1e3
    a0.plot(x, (tr - tr.mean()) / ifov, "k.-", lw=1, ms=4, label="true")
    a0.plot(x, (kn - kn.mean()) / ifov, color="#E69F00", lw=1, label="AOCS knowledge")
    a0.plot(x, (est - est.mean()) / ifov, "--", color="#0072B2", lw=1.2, label="restored")
    a0.set_ylabel(f"{axis} [px], mean removed")
    a0.set_title(f"{axis} at the frame times (one point per frame)")
    a0.grid(alpha=0.3)
    a0.legend(loc="upper right", fontsize=8, ncol=3)
    ek = kn - tr
    er = est - tr
    a1.plot(x, (ek - ek.mean()) / ifov, color="#E69F00", lw=1, label="error of the knowledge")
    a1.plot(x, (er - er.mean()) / ifov, color="#0072B2", lw=1.2, label="error of the restored")
    a1.axhline(0, color="0.5", lw=0.5)
    a1.set_xlabel("time since the first frame [ms]")
    a1.set_ylabel("error [px]")
    a1.grid(alpha=0.3)
    a1.legend(loc="upper right", fontsize=8)
    fig.savefig(path, dpi=90)
    plt.close(fig)


def _frames_figure(run_dir: Path, path: Path) -> None:
    """Two successive frames side by side: the overlap the restoration matches."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import xarray as xr

    with xr.open_dataset(run_dir / "product.nc") as ds:
        name = [v for v in ds.data_vars if v.startswith("image_")][0]
        k = ds[name].shape[0] // 2
        a = np.asarray(ds[name][k].values, dtype=np.float32)
        b = np.asarray(ds[name][k + 1].values, dtype=np.float32)
    fig, ax = plt.subplots(1, 2, figsize=(9, 4.6), constrained_layout=True)
    lo, hi = np.percentile(np.r_[a.ravel(), b.ravel()], [1, 99])
    for axx, img, title in ((ax[0], a, f"frame {k}"), (ax[1], b, f"frame {k + 1}")):
        axx.imshow(img, cmap="gray", vmin=lo, vmax=hi)
        axx.set_title(title)
        axx.set_xlabel("column")
    ax[0].set_ylabel("row (row 0 forward)")
    fig.suptitle("successive frames: the ground of frame k reappears lower in frame k + 1", fontsize=10)
    fig.savefig(path, dpi=80)
    plt.close(fig)


def make_frames_report(run_dir, *, out_dir=None) -> Path:
    """``RUN_DIR/report/index.html`` of a frames run: headline, attitude and error plots, the frames."""
    run_dir = Path(run_dir)
    out = Path(out_dir) if out_dir is not None else run_dir / "report"
    out.mkdir(parents=True, exist_ok=True)
    rest, truth, info = _load(run_dir)
    hd = frames_headline(rest, truth, info)
    name = info.get("name", run_dir.name)
    parts = [f"<h1>simsat report — {html.escape(str(name))} (matrix frames)</h1>",
             "<p>A 2-D matrix detector takes successive overlapping frames (EP1843295 fig. 1); the attitude is "
             "restored at the frame times from the overlap of each frame with the next (restore/frames.py). "
             "Error = estimate − truth at the frame times, mean removed.</p>",
             f"<p><b>Requirement</b>: {html.escape(hd['verdict'])}</p>"]
    rows = []
    if rest is not None and truth is not None:
        parts.append("<table border=1 cellpadding=4><tr><th>axis</th><th>restored RMS [px]</th><th>restored 99.7 % "
                     "[px]</th><th>AOCS RMS [px]</th><th>AOCS 99.7 % [px]</th><th>improvement</th>"
                     "<th>predicted 1σ RMS [px]</th></tr>")
        for a in hd["axes"]:
            e = hd["errors"][a]
            imp = e["knowledge_rms_px"] / e["rms_px"] if e["rms_px"] > 0 else float("inf")
            parts.append(f"<tr><td>{a}</td><td>{e['rms_px']:.4f}</td><td>{e['p997_px']:.4f}</td>"
                         f"<td>{e['knowledge_rms_px']:.4f}</td><td>{e['knowledge_p997_px']:.4f}</td><td>{imp:.1f}</td>"
                         f"<td>{_predicted_px(rest, a):.4f}</td></tr>")
            rows.append({"axis": a, **{k: e[k] for k in ("rms_px", "p997_px", "knowledge_rms_px", "knowledge_p997_px")}})
            _attitude_figure(rest, truth, a, out / f"attitude_{a}.png")
        parts.append("</table><p>Predicted 1σ: the least squares' covariance with independent matching errors; "
                     "the windows of neighbouring points overlap, so it is optimistic.</p>")
        for a in hd["axes"]:
            parts.append(f'<h2>{a}</h2><img src="attitude_{a}.png" alt="{a} at the frame times">')
    if rest is not None:
        v, n = rest["pair_valid_matches"].values, rest["pair_points"].values
        r = rest["pair_residual_px"].values
        parts.append(f"<p>Matches kept: {int(v.sum())} of {int(n.sum())} points over {v.size} frame pairs; fit "
                     f"residual {float(np.sqrt(np.nanmean(r ** 2))):.3f} px RMS.</p>")
    _frames_figure(run_dir, out / "frames.png")
    parts.append('<h2>Frames</h2><img src="frames.png" alt="two successive frames">')
    with open(out / "summary.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=["axis", "rms_px", "p997_px", "knowledge_rms_px", "knowledge_p997_px"])
        w.writeheader()
        w.writerows(rows)
    (out / "report.json").write_text(json.dumps({k: v for k, v in hd.items() if k != "errors"} |
                                                {"errors": hd["errors"]}, indent=1, default=float))
    index = out / "index.html"
    index.write_text("<!doctype html><meta charset=utf-8><title>simsat frames report</title>\n" + "\n".join(parts))
    return index
