"""The report of a navigation run (reads ``navigation.nc`` only).

Figures: horizontal error over distance with the filter's ±3σ and the
unaided INS; a map view of the trajectories over the terrain with the
reference map and the segments matched; sample frames with the extracted
segments and the reference map projected into them; filter consistency
(NEES against its χ² bounds) and the per-update counts (segments found,
tracked, reconstructed, matched). An HTML page gathers them with the
requirement check.
"""
from __future__ import annotations

import html
import json
from pathlib import Path

import numpy as np

from navigation.io import read_navigation, summarise
from simsat.product import atomic_write_bytes

from .plotting import SERIES_COLORS, legend_below, new_axes, new_axes_grid, save_figure

__all__ = ["make_navigation_report", "requirement_check"]

BLUE, RED, GREEN, PURPLE, ORANGE = SERIES_COLORS[:5]


def _no_fix_spans(ds):
    """Along-route intervals (km) of updates where no seed got a fix."""
    ok = (ds.update_status.values == "ok").any(axis=0)
    d = ds.update_distance_m.values / 1000.0
    step = float(np.median(np.diff(d))) if len(d) > 1 else 1.0
    return [(x - step, x) for x, good in zip(d, ok) if not good]


def draw_error_over_distance(ds, path):
    truth = ds.true_position.values
    km = ds.distance_m.values / 1000.0
    ea = np.hypot(*(ds.aided_position.values - truth)[..., :2].transpose(2, 0, 1))
    eu = np.hypot(*(ds.unaided_position.values - truth)[..., :2].transpose(2, 0, 1))
    s3 = 3 * np.hypot(ds.aided_sigma.values[..., 0], ds.aided_sigma.values[..., 1])
    fig, ax = new_axes((9.0, 4.8))
    for a, b in _no_fix_spans(ds):
        ax.axvspan(a, b, color="0.85", lw=0)
    for e in eu:
        ax.plot(km, e, color="0.6", lw=0.5, alpha=0.6)
    for e in ea:
        ax.plot(km, e, color=BLUE, lw=0.5, alpha=0.5)
    ax.plot(km, np.median(eu, 0), color="0.3", lw=1.6, ls="--", label=f"unaided INS (median of {len(eu)} seeds)")
    ax.plot(km, np.median(ea, 0), color=BLUE, lw=1.8, label="aided INS (median)")
    ax.plot(km, np.median(s3, 0), color=RED, lw=1.2, label="filter 3σ horizontal (median)")
    ax.set_yscale("log")
    ax.set_ylim(max(min(np.percentile(ea, 1), 1.0), 0.1), None)
    ax.set_xlabel("distance flown (km)")
    ax.set_ylabel("horizontal position error (m)")
    ax.set_title("Horizontal error over the route (grey bands: no fix on any seed)")
    legend_below(ax, ncols=3)
    return save_figure(fig, path)


def draw_map_view(ds, path):
    import matplotlib.pyplot as plt
    from matplotlib.collections import LineCollection

    fig, ax = plt.subplots(figsize=(8.5, 8.0))
    if "terrain_height" in ds:
        t = ds.terrain_height.values
        x, y = ds.terrain_x.values, ds.terrain_y.values
        im = ax.imshow(t, origin="lower", extent=(x[0], x[-1], y[0], y[-1]), cmap="gist_earth", alpha=0.55)
        fig.colorbar(im, ax=ax, shrink=0.6, label="terrain height (m)")
    if "reference_map" in ds:
        seg = ds.reference_map.values
        ax.add_collection(LineCollection(seg.reshape(-1, 2, 2), colors="0.35", linewidths=0.25, alpha=0.5))
    if ds.sizes.get("match", 0):
        seg = ds.matched_reference.values
        ax.add_collection(LineCollection(seg.reshape(-1, 2, 2), colors=ORANGE, linewidths=1.6,
                                         label="reference segments matched (first seed)"))
    p = ds.true_position.values
    ax.plot(p[:, 0], p[:, 1], color="k", lw=1.6, label="true trajectory")
    ax.plot(*ds.unaided_position.values[0, :, :2].T, color="0.45", lw=1.2, ls="--", label="unaided INS (first seed)")
    ax.plot(*ds.aided_position.values[0, :, :2].T, color=BLUE, lw=1.0, label="aided INS (first seed)")
    ax.set_aspect("equal")
    pad = 3000.0
    ax.set_xlim(p[:, 0].min() - pad, p[:, 0].max() + pad)
    ax.set_ylim(p[:, 1].min() - pad, p[:, 1].max() + pad)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title("Map view: trajectories over the terrain and the reference map")
    ax.legend(loc="upper left", fontsize=8)
    return save_figure(fig, path)


def draw_sample_frames(ds, path):
    from matplotlib.collections import LineCollection

    n = ds.sizes.get("sample", 0)
    if not n:
        return None
    fig, axs = new_axes_grid(n, figsize=(7.5, 4.2 * n), sharex=False)
    axs = np.atleast_1d(axs)
    for k, ax in enumerate(axs):
        ax.imshow(ds.sample_frame.values[k], cmap="gray", vmin=0, vmax=255)
        ax.grid(False)
        ref = ds.sample_reference.values[ds.sample_reference_frame.values == k]
        seg = ds.sample_segments.values[ds.sample_segments_frame.values == k]
        ax.add_collection(LineCollection(ref.reshape(-1, 2, 2), colors="cyan", linewidths=0.9, alpha=0.8,
                                         label="reference map, projected"))
        ax.add_collection(LineCollection(seg.reshape(-1, 2, 2), colors=RED, linewidths=1.0,
                                         label="extracted segments"))
        u = int(ds.sample_update.values[k])
        ax.set_title(f"update {u} at {ds.update_distance_m.values[u] / 1000:.1f} km: {len(seg)} segments",
                     fontsize=9)
        h, w = ds.sample_frame.shape[1:]
        ax.set_xlim(0, w)
        ax.set_ylim(h, 0)
        ax.set_xticks([])
        ax.set_yticks([])
    axs[0].legend(loc="upper right", fontsize=7)
    return save_figure(fig, path)


def draw_consistency(ds, path):
    s = summarise(ds)
    km = ds.update_distance_m.values / 1000.0
    fig, (a1, a2) = new_axes_grid(2, figsize=(9.0, 6.8))
    lo, hi = s["nees_bounds"]
    a1.axhspan(lo, hi, color=GREEN, alpha=0.15, label="95 % interval of χ²₃ (one run)")
    for k, row in enumerate(ds.nees.values):
        a1.plot(km, row, ".", color=BLUE, ms=2.5, alpha=0.5, label="position NEES, each seed" if k == 0 else None)
    a1.plot(km, np.nanmean(ds.nees.values, 0), "-", color=RED, lw=1.2, label="mean over seeds")
    a1.axhline(3.0, color="0.4", lw=0.8, ls=":")
    a1.set_yscale("log")
    a1.set_ylabel("NEES (3 dof)")
    a1.set_title(f"Filter consistency: {100 * s['nees_inside_fraction']:.0f} % of (seed, update) inside the "
                 f"χ²₃ 95 % interval, mean NEES {s['nees_mean']:.2f} (ideal 3)")
    a1.legend(fontsize=8)
    for name, c in (("found", "0.5"), ("tracked", PURPLE), ("reconstructed", ORANGE), ("matched", BLUE),
                    ("used", GREEN)):
        a2.plot(km, np.median(ds[name].values, 0), "o-", ms=2.5, color=c, label=name)
    a2.set_yscale("symlog", linthresh=10)
    a2.set_xlabel("distance flown (km)")
    a2.set_ylabel("segments / lines per update (median)")
    legend_below(a2, ncols=5)
    return save_figure(fig, path)


def requirement_check(summary: dict, requirement: dict) -> list[tuple[str, str, str, bool]]:
    """(what, measured, required, passed) rows."""
    f = summary["final_horizontal_m"]["p95"]
    imp = summary["improvement_median"]
    nees = summary["nees_inside_fraction"]
    rows = [("final horizontal error, 95th percentile over seeds", f"{f:.1f} m",
             f"≤ {requirement['final_horizontal_m']:g} m", f <= requirement["final_horizontal_m"]),
            ("improvement over the unaided INS (median over seeds)", f"{imp:.0f}×",
             f"≥ {requirement['improvement']:g}×", imp >= requirement["improvement"]),
            ("updates whose position NEES lies inside the χ²₃ 95 % interval", f"{100 * nees:.0f} %",
             f"≥ {100 * requirement['nees_inside']:.0f} %", nees >= requirement["nees_inside"])]
    return rows


def make_navigation_report(run_dir, out_dir=None) -> Path:
    """Write the figures and ``index.html`` of a navigation run; returns the HTML path."""
    run_dir = Path(run_dir)
    ds = read_navigation(run_dir)
    out = Path(out_dir) if out_dir else run_dir / "report"
    out.mkdir(parents=True, exist_ok=True)
    figs = [("Horizontal error over distance", draw_error_over_distance(ds, out / "error_over_distance.png")),
            ("Map view", draw_map_view(ds, out / "map_view.png")),
            ("Filter consistency and what each update used", draw_consistency(ds, out / "consistency.png")),
            ("Sample frames", draw_sample_frames(ds, out / "sample_frames.png"))]
    s = summarise(ds)
    req = json.loads(ds.attrs["scenario_toml"]).get("requirement", {})
    req = {"final_horizontal_m": req.get("final_horizontal_m", 30.0), "improvement": req.get("improvement", 10.0),
           "nees_inside": req.get("nees_inside", 0.9)}
    rows = "".join(f"<tr><td>{html.escape(a)}</td><td>{b}</td><td>{html.escape(c)}</td>"
                   f"<td>{'PASS' if ok else 'FAIL'}</td></tr>" for a, b, c, ok in requirement_check(s, req))
    status = ds.update_status.values
    reasons: dict = {}
    for v in status[status != "ok"]:
        key = v.split(":")[0] if "ambiguous" in v else v
        reasons[key] = reasons.get(key, 0) + 1
    why = "".join(f"<li>{html.escape(k)}: {n}</li>" for k, n in sorted(reasons.items(), key=lambda kv: -kv[1]))
    try:
        timings = json.loads((run_dir / "run.json").read_text()).get("timings", {})
    except (OSError, ValueError):
        timings = {}
    body = [f"<h1>Navigation run — {html.escape(ds.attrs['scenario'])}</h1>",
            f"<p>{s['seeds']} Monte Carlo seeds over {s['distance_km']:.0f} km; {s['updates']} aiding sequences; "
            f"{100 * s['fixes_fraction']:.0f} % of (seed, update) gave a fix. "
            f"{html.escape(ds.attrs.get('frames', ''))}.</p>",
            "<table border=1 cellpadding=4><tr><th>requirement</th><th>measured</th><th>required</th><th></th></tr>"
            f"{rows}</table>",
            f"<p>Final horizontal error: median {s['final_horizontal_m']['median']:.1f} m, "
            f"max {s['final_horizontal_m']['max']:.1f} m; unaided median "
            f"{s['unaided_final_horizontal_m']['median']:.0f} m.</p>",
            f"<h3>Updates without a fix (seed × update)</h3><ul>{why or '<li>none</li>'}</ul>",
            "<p>Timings: " + ", ".join(f"{k} {v:.1f}" for k, v in timings.items()) + "</p>"]
    for title, p in figs:
        if p is not None:
            body.append(f"<h2>{html.escape(title)}</h2><img src='{Path(p).name}' style='max-width:100%'>")
    page = "<html><head><meta charset='utf-8'><title>simsat navigation</title></head><body>" + "".join(body) + \
           "</body></html>"
    return atomic_write_bytes(page.encode(), out / "index.html")
