"""Drawing for the run report: each ``draw_*`` takes axes and data prepared by
:mod:`reports.report_data` and returns the figure; ``*_figure`` helpers make
the axes in the report style (:mod:`reports.plotting`). No physics here.

The 3-D scene is rendered with PyVista off screen (:func:`render_scene_pyvista`,
run in a child process by the report so that a broken OpenGL stack cannot take
the report down), with :func:`draw_scene_mpl` as the fallback.
"""
from __future__ import annotations

import sys

import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.ticker import FuncFormatter, LogLocator, MaxNLocator, NullFormatter  # noqa: E402

from reports import plotting as P  # noqa: E402
from reports.report_data import AXES, minmax_decimate  # noqa: E402
from simsat.units import URAD_PER_RAD  # noqa: E402

__all__ = ["pair_color", "attitude_figure", "draw_attitude", "spectra_figure", "draw_spectra", "transfer_figure",
           "draw_transfer", "draw_budget", "draw_match_density", "match_density_figure", "draw_misregistration",
           "draw_scene_mpl", "scene_figure_mpl", "render_scene_pyvista", "nice_f_max"]

AXIS_MARKERS = {"roll": "o", "pitch": "s", "yaw": "^"}
C_TRUE, C_KNOW, C_REST, C_ERR, C_MEAS = "#000000", "#E69F00", "#0072B2", "#D55E00", "#8E0152"


def pair_color(j: int) -> str:
    """Colour of the j-th pair (Okabe–Ito, skipping black)."""
    cols = [c for c in P.SERIES_COLORS if c != "#000000"]
    return cols[j % len(cols)]


def nice_f_max(freq, psd, fs: float, *, fraction: float = 0.995, floor_hz: float = 100.0) -> float:
    """Upper frequency for plots: 1.5× the frequency holding ``fraction`` of the power, rounded up to 50 Hz."""
    nyq = 0.5 * fs
    freq = np.asarray(freq, float)
    psd = np.asarray(psd, float)
    if freq.size < 2 or not np.isfinite(psd).any() or np.nansum(psd[1:]) <= 0:
        return nyq
    c = np.nancumsum(psd[1:])
    f99 = freq[1:][np.searchsorted(c, fraction * c[-1])] if c[-1] > 0 else nyq
    f = max(1.5 * f99, floor_hz)
    f = 50.0 * np.ceil(f / 50.0)
    return float(min(f, nyq))


def _px_axis(ax, ifov_rad: float, label: str = "px"):
    """Secondary y axis in pixels for an axis drawn in µrad (``ifov_rad``: the angle of one pixel)."""
    k = ifov_rad * URAD_PER_RAD
    sec = ax.secondary_yaxis("right", functions=(lambda u: u / k, lambda p: p * k))
    sec.set_ylabel(label, fontsize=9)
    sec.tick_params(labelsize=8)
    return sec


# ----------------------------------------------------------------------------- attitude
def attitude_figure():
    """Figure with 2 × 2 axes: (attitudes, error) × (whole record, zoom)."""
    with matplotlib.rc_context(P.STYLE):
        fig = Figure(figsize=(11.0, 6.0), layout="constrained")
        axs = fig.subplots(2, 2, sharex="col", gridspec_kw={"width_ratios": [1.6, 1.0]})
    for ax in axs.ravel():
        P._style_axes(ax)
    return fig, axs


def draw_attitude(axs, att: dict, axis: str, *, ifov_rad: float, zoom: tuple, yaw_half_field_px: float | None = None,
                  max_points: int = 3000,
                  restored: bool = True):
    """True / knowledge / restored ``axis`` over time, and the errors, with a zoom.

    Parameters
    ----------
    axs : 2 × 2 array of Axes
        ``[0, :]`` attitudes, ``[1, :]`` errors; ``[:, 0]`` whole record,
        ``[:, 1]`` zoom on ``zoom = (t0, t1)`` [s].
    att : dict
        :func:`reports.report_data.attitude_table`.
    """
    t = att["time_s"]
    t0 = t[0]
    series_top = [(f"true_{axis}", "true", C_TRUE, 1.0), (f"knowledge_{axis}", "knowledge (AOCS)", C_KNOW, 1.3),
                  (f"restored_{axis}", "restored", C_REST, 1.0)]
    series_err = [(f"knowledge_error_{axis}", "error of knowledge (knowledge − true)", C_KNOW, 1.0),
                  (f"error_{axis}", "error of restored (restored − true)", C_REST, 1.0)]
    z0, z1 = zoom
    zsel = (t >= z0) & (t <= z1)
    for col in (0, 1):
        for row, series in ((0, series_top), (1, series_err)):
            ax = axs[row, col]
            for key, label, color, lw in series:
                if key not in att:
                    continue
                y = att[key] * URAD_PER_RAD
                if col == 0:
                    xs, ys = minmax_decimate((t - t0) * 1e3, y, max_points)
                else:
                    xs, ys = (t[zsel] - t0) * 1e3, y[zsel]
                ls = "--" if key.startswith("restored") else "-"
                ax.plot(xs, ys, color=color, lw=lw, ls=ls, label=label)
            if not ax.lines:
                ax.text(0.5, 0.5, "needs truth" if row == 1 else "no data", transform=ax.transAxes,
                        ha="center", va="center", color="0.4")
    axs[0, 0].set_ylabel(f"{axis} [µrad]")
    axs[1, 0].set_ylabel("error [µrad]")
    axs[1, 0].set_xlabel("time since first line [ms]")
    axs[1, 1].set_xlabel("time since first line [ms]")
    axs[1, 0].axhline(0.0, color="0.5", lw=0.6)
    axs[0, 0].set_title(f"{axis}: whole acquisition" + ("" if restored else " (axis not restored)"))
    axs[0, 1].set_title(f"zoom {1e3 * (z1 - z0):.0f} ms")
    if axs[0, 1].lines:
        axs[0, 0].axvspan((z0 - t0) * 1e3, (z1 - t0) * 1e3, color="0.85", zorder=0, lw=0)
    for ax in (axs[0, 1], axs[1, 1]):
        if axis == "yaw":
            if yaw_half_field_px:  # yaw moves the image by (offset from the field centre) × angle
                _px_axis(ax, 1.0 / yaw_half_field_px, label="image shift at the field edge [px]")
        else:
            _px_axis(ax, ifov_rad)
    handles, labels = [], []
    for ax in (axs[0, 0], axs[1, 0]):
        h, lab = ax.get_legend_handles_labels()
        handles += h
        labels += lab
    if handles:
        axs[0, 0].figure.legend(handles, labels, loc="outside lower center", ncols=min(5, len(handles)),
                                frameon=False)
    return axs[0, 0].figure


# ----------------------------------------------------------------------------- spectra
def spectra_figure(n_axes: int = 3):
    return P.new_axes_grid(n_axes, figsize=(10.0, 2.6 * n_axes + 0.8), sharex=True)


def _mark_pairs(ax, taus, names, f_max):
    for j, (tau, name) in enumerate(zip(taus, names)):
        P.rug_blind_frequencies(ax, tau, f_max_hz=f_max, color=pair_color(j), y_axes=1.0 - 0.035 * j, size=5,
                                label=f"blind n/τ, {name} (τ = {tau * 1e3:.1f} ms)")


def draw_spectra(axs, spec: dict, *, taus, pair_names, f_max: float, axes=AXES):
    """Welch PSDs (µrad²/Hz, log) of true − knowledge, correction and error per axis, blind frequencies marked."""
    f = spec.get("freq_hz", np.zeros(0))
    sel = (f > 0) & (f <= f_max)
    styles = [("delta", "true − knowledge (to restore)", C_TRUE, "-"), ("correction", "restored correction", C_REST, "-"),
              ("error", "error (restored − true)", C_ERR, "-")]
    for ax, a in zip(axs, axes):
        for key, label, color, ls in styles:
            k = f"psd_{key}_{a}"
            if k in spec and np.nanmax(spec[k][sel], initial=0.0) > 0:
                ax.semilogy(f[sel], spec[k][sel] * URAD_PER_RAD ** 2, color=color, ls=ls, lw=1.1, label=label)
        _mark_pairs(ax, taus, pair_names, f_max)
        ax.set_ylabel(f"{a} PSD\n[µrad²/Hz]")
        if f"psd_correction_{a}" in spec and not np.nanmax(spec[f"psd_correction_{a}"], initial=0.0) > 0:
            ax.set_title(f"{a}: not restored (no correction)", fontsize=9, loc="left")
        ax.set_xlim(0, f_max)
        if not ax.lines:
            ax.text(0.5, 0.5, "no data", transform=ax.transAxes, ha="center", va="center")
    axs[-1].set_xlabel("frequency [Hz]")
    if axs[0].get_legend_handles_labels()[0]:
        P.legend_below(axs[0], ncols=3)
    return axs[0].figure


# ----------------------------------------------------------------------------- transfer
def transfer_figure(n_axes: int = 1):
    """One panel per restored axis (the filter of an adaptive method differs between axes)."""
    n = max(1, n_axes)
    return P.new_axes_grid(n, figsize=(10.0, 2.9 * n + 1.9), sharex=True)


def draw_transfer(ax, *, probe: dict | None, measured: dict | None, taus, pair_names, f_max: float,
                  analytic: dict | None = None, method: str = "", axis: str | None = None, legend: bool = True):
    """|F| of the integration per pair and fused, and the measured chain transfer of ``axis`` (all axes if None)."""
    if probe and probe.get("freq_hz") is not None and probe["freq_hz"].size:
        f = probe["freq_hz"]
        sel = (f > 0) & (f <= f_max)
        for j, name in enumerate(pair_names):
            g = probe.get(f"gain_{name}")
            if g is not None and np.isfinite(g).any():
                ax.plot(f[sel], g[sel], color=pair_color(j), lw=1.0, alpha=0.85,
                        label=f"|F| {name} alone (τ = {taus[j] * 1e3:.1f} ms), probed")
        g = probe.get("gain_fused")
        if g is not None and np.isfinite(g).any():
            ax.plot(f[sel], g[sel], color="k", lw=2.0, label=f"|F| all pairs fused ({method}), probed")
    have_probe = bool(probe and probe.get("freq_hz") is not None and probe["freq_hz"].size)
    if analytic:
        f = analytic["freq_hz"]
        sel = (f > 0) & (f <= f_max)
        for j, name in enumerate(pair_names):
            if f"gain_{name}" in analytic and not have_probe:
                ax.plot(f[sel], analytic[f"gain_{name}"][sel], color=pair_color(j), lw=0.9, ls=":",
                        label=(f"analytic, each pair ({analytic['label']})" if j == 0 else None))
        if "gain_joint" in analytic:
            ax.plot(f[sel], analytic["gain_joint"][sel], color="0.35", lw=1.2, ls="--",
                    label=f"analytic, fused ({analytic['label']})")
    if measured and measured.get("freq_hz") is not None:
        f = measured["freq_hz"]
        for a in AXES if axis is None else (axis,):
            if f"gain_{a}" not in measured:
                continue
            s = measured[f"significant_{a}"] & (f > 0) & (f <= f_max)
            ax.plot(f[s], measured[f"gain_{a}"][s], ls="none", marker=AXIS_MARKERS[a], markersize=4.5,
                    markerfacecolor="white", markeredgecolor=C_MEAS, markeredgewidth=1.1,
                    label=f"measured whole chain, {a}")
    _mark_pairs(ax, taus, pair_names, f_max)
    ax.axhline(1.0, color="0.6", lw=0.8)
    ax.set_xlim(0, f_max)
    vals = [ln.get_ydata() for ln in ax.lines]
    vals = np.concatenate([np.asarray(v, float).ravel() for v in vals]) if vals else np.zeros(0)
    vals = vals[np.isfinite(vals)]
    ymax = float(np.clip(np.max(vals) * 1.08, 1.25, 3.0)) if vals.size else 1.25
    ax.set_ylim(0, ymax)
    ax.set_ylabel(f"{axis + ': ' if axis else ''}|θ̂ / θ|")
    if len(ax.lines) <= 1:
        ax.text(0.5, 0.5, "no transfer available", transform=ax.transAxes, ha="center")
    if legend:
        ax.set_xlabel("frequency [Hz]")
        handles, labels, seen = [], [], set()
        for other in ax.figure.axes:
            for h, lab in zip(*other.get_legend_handles_labels()):
                if lab not in seen:
                    seen.add(lab)
                    handles.append(h)
                    labels.append(lab)
        ax.figure.legend(handles, labels, loc="outside lower center", ncols=2, frameon=False)
    return ax.figure


# ----------------------------------------------------------------------------- budget
def draw_budget(ax, rows: list, *, unit: str = "px"):
    """Horizontal bars of RMS and 99.7 % per component, grouped by axis.

    The predicted parts (what no pair sees, the best linear restoration's floor) have an RMS only: one
    solid bar, beside the measured components.
    """
    comps = [c for c in ("uncorrected knowledge", "unobservable (no pair sees it)", "floor (best linear restoration)",
                         "matching noise", "model / synthesis", "local matching error", "line-common error",
                         "integration", "star-tracker anchoring",
                         "total (restored − true)") if any(r["component"] == c for r in rows)]
    axes = [a for a in AXES if any(r["axis"] == a for r in rows)]
    colors = {"uncorrected knowledge": C_KNOW, "unobservable (no pair sees it)": "#444444",
              "floor (best linear restoration)": "#0072B2", "matching noise": "#56B4E9",
              "model / synthesis": "#CC79A7", "local matching error": "#F0E442", "line-common error": "#882255",
              "integration": "#009E73", "star-tracker anchoring": "#999999",
              "total (restored − true)": C_ERR}
    h = 0.8 / max(1, len(comps))
    yt, yl = [], []
    for i, a in enumerate(axes):
        for k, c in enumerate(comps):
            r = next((r for r in rows if r["axis"] == a and r["component"] == c), None)
            if r is None:
                continue
            y = i + k * h
            p997 = r.get(f"p997_{unit}")
            if p997 is not None and np.isfinite(p997):
                ax.barh(y, p997, height=h * 0.9, color=colors[c], alpha=0.35,
                        label=f"{c} (99.7 %)" if i == 0 else None)
            ax.barh(y, r[f"rms_{unit}"], height=h * 0.9, color=colors[c], label=f"{c} (RMS)" if i == 0 else None)
        yt.append(i + 0.4 - h / 2)
        yl.append(a)
    ax.set_yticks(yt, yl)
    ax.invert_yaxis()
    ax.set_xscale("log")
    ax.set_xlabel(f"error [{unit}]  (solid: RMS, light: 99.7 % of |error|)")
    handles, labels = ax.get_legend_handles_labels()
    keep = [(hh, ll) for hh, ll in zip(handles, labels) if ll.endswith("(RMS)")]
    if keep:
        ax.legend([k[0] for k in keep], [k[1].replace(" (RMS)", "") for k in keep], loc="center left",
                  bbox_to_anchor=(1.01, 0.5), frameon=False)
    return ax.figure


# ----------------------------------------------------------------------------- uncertainty
def uncertainty_figure():
    """Figure with 1 × 2 axes: (σ and |error| over time, actual against predicted)."""
    with matplotlib.rc_context(P.STYLE):
        fig = Figure(figsize=(11.0, 3.6), layout="constrained")
        axs = fig.subplots(1, 2, gridspec_kw={"width_ratios": [1.8, 1.0]})
    for ax in axs:
        P._style_axes(ax)
    return fig, axs


def draw_uncertainty(axs, d: dict, axis: str, *, ifov_rad: float):
    """Left: ±σ and ±2σ bands with the actual error per line (if known), flagged lines marked.
    Right: actual RMS error against predicted σ per σ-quantile bin, with the 1:1 line and the × 1.5 band."""
    ax, cal = axs
    t, sg = d["time_s"], d["sigma"] / ifov_rad
    ax.fill_between(t, -2 * sg, 2 * sg, color=C_REST, alpha=0.15, lw=0, label="±2σ predicted")
    ax.fill_between(t, -sg, sg, color=C_REST, alpha=0.3, lw=0, label="±1σ predicted")
    if "error" in d:
        x, y = minmax_decimate(t, d["error"] / ifov_rad, 6000)
        ax.plot(x, y, color=C_ERR, lw=0.5, label="actual error (restored − true)" if "yaw_seen_removed" not in d
                else f"actual error less the yaw seen as {axis} ({d['yaw_seen_removed']:+.3f} × yaw)")
    if d["flagged"].any():
        tf = t[d["flagged"]]
        ax.plot(tf, np.zeros(tf.size), ls="none", marker="|", color="#000000", ms=8,
                label=f"flagged ({int(d['flagged'].sum())} lines, "
                      f"{'model σ' if d.get('flag_judged_on') == 'model' else 'σ'} > {d['flag_limit'] / ifov_rad:.3f} px)")
    ax.set_xlabel("time [s]")
    ax.set_ylabel(f"{axis} [px]")
    ax.legend(loc="upper right", fontsize=8, frameon=False, ncol=2)
    if "calibration" in d and d["calibration"]["predicted"].size:
        c = d["calibration"]
        p, a = c["predicted"] / ifov_rad, c["actual"] / ifov_rad
        lo, hi = 0.8 * min(p.min(), a.min()), 1.25 * max(p.max(), a.max())
        xx = np.array([lo, hi])
        cal.fill_between(xx, xx / 1.5, xx * 1.5, color="#999999", alpha=0.2, lw=0, label="within × 1.5")
        cal.plot(xx, xx, color="#666666", lw=1, label="actual = predicted")
        cal.plot(p, a, marker="o", color=C_ERR, lw=1, label="lines binned by predicted σ")
        cal.set_xscale("log")
        cal.set_yscale("log")
        cal.set_xlim(lo, hi)
        cal.set_ylim(lo, hi)
        for axis_ in (cal.xaxis, cal.yaxis):
            # less than a decade wide: the minor ticks' own labels (2×10⁻², 3×10⁻²…) ran into each other
            axis_.set_minor_formatter(NullFormatter())
            # under a factor 4 wide the log locator falls back to evenly spaced ticks, crowded at the top of a log
            # axis (0.0225, 0.025, 0.0275 ran into each other): a few round values instead
            axis_.set_major_locator(MaxNLocator(nbins=4) if hi / lo < 4.0 else
                                    LogLocator(base=10.0, subs=(1.0, 2.0, 5.0)))
            axis_.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
        cal.set_xlabel("predicted σ (RMS in bin) [px]")
        cal.set_ylabel("actual RMS error [px]")
        cal.legend(loc="upper left", fontsize=8, frameon=False)
    else:
        cal.text(0.5, 0.5, "actual error needs truth.nc", ha="center", va="center", transform=cal.transAxes)
        cal.set_axis_off()
    return ax.figure


# ----------------------------------------------------------------------------- matches
def match_density_figure(n_pairs: int):
    return P.new_axes_grid(max(1, n_pairs), figsize=(11.0, 2.3 * max(1, n_pairs) + 0.9), sharex=True)


def draw_match_density(ax, d: dict, name: str, *, show_rejected: bool = True, colorbar: bool = True):
    """Density of inlier matches (line × column of band A), rejected points and gap lines."""
    le, ce = d["line_edges"], d["col_edges"]
    cell = (le[1] - le[0]) * (ce[1] - ce[0])
    dens = d["inliers"].T / cell  # points per px², rows = columns
    m = ax.pcolormesh(le, ce, np.where(dens > 0, dens, np.nan), cmap="viridis", shading="flat", rasterized=True)
    for k, (g0, g1) in enumerate(d["gap_intervals"]):
        ax.axvspan(g0, g1, color="0.6", alpha=0.45, lw=0, label="lines without differential" if k == 0 else None)
    if show_rejected and d.get("failed_lines") is not None and d["failed_lines"].size:
        ax.plot(d["failed_lines"], d["failed_cols"], ls="none", marker=".", markersize=1.6, color="0.55",
                alpha=0.6, label=f"failed matching ({d['n_invalid']:,})")
    if show_rejected and d["rejected_lines"].size:
        ax.plot(d["rejected_lines"], d["rejected_cols"], ls="none", marker=".", markersize=2.2, color=C_ERR,
                alpha=0.85, label=f"rejected by synthesis ({d['n_rejected_valid']:,})")
    ax.set_xlim(0, d["n_lines"])
    ax.set_ylim(0, d["n_columns"])
    ax.set_ylabel(f"{name}\ncolumn of {d['ahead']}")
    ax.set_title(f"{name}: {d['n_inlier']:,} inliers / {d['n_valid']:,} valid / {d['n_total']:,} candidates",
                 fontsize=9.5, loc="left")
    if colorbar:
        cb = ax.figure.colorbar(m, ax=ax, pad=0.01, fraction=0.04)
        cb.set_label("inliers / px²", fontsize=8)
        cb.ax.tick_params(labelsize=7)
    h, lab = ax.get_legend_handles_labels()
    if h:
        ax.legend(loc="upper right", fontsize=7.5, markerscale=4, framealpha=0.9)
    return ax.figure


def draw_misregistration(ax, rows: list):
    """Grouped bars per pair: misregistration before correction, after (as measured, matching noise
    included), after with the matching noise removed (when known) and, with truth, the same measurement
    on bands corrected with the true attitude (its floor), px (2-D RMS of the per-line shift)."""
    if not rows:
        ax.text(0.5, 0.5, "no misregistration data", transform=ax.transAxes, ha="center")
        return ax.figure
    comps = [("before_px", "before correction", C_KNOW), ("after_px", "after, as measured", C_REST)]
    if any(np.isfinite(r.get("after_signal_px", np.nan)) for r in rows):
        comps.append(("after_signal_px", "after, matching noise removed", "0.45"))
    if any(np.isfinite(r.get("true_attitude_px", np.nan)) for r in rows):
        comps.append(("true_attitude_px", "after, with the true attitude (floor)", "0.75"))
    x = np.arange(len(rows))
    w = 0.8 / len(comps)
    for k, (key, label, color) in enumerate(comps):
        v = [r.get(key, np.nan) for r in rows]
        bars = ax.bar(x + (k - (len(comps) - 1) / 2) * w, v, width=w * 0.95, color=color, label=label)
        for b, val in zip(bars, v):
            if np.isfinite(val) and val > 0:
                ax.text(b.get_x() + b.get_width() / 2, val, f"{val:.3f}", ha="center", va="bottom", fontsize=7.5)
    ax.set_xticks(x, [r["pair"] + ("\n(in no pair)" if r.get("weakly_correlated") else "") for r in rows])
    ax.set_ylabel("RMS of per-line shift [px]")
    ax.set_yscale("log")
    vals = [r.get(k, np.nan) for r in rows for k, _, _ in comps[1:]]
    lo = min([v for v in vals if np.isfinite(v) and v > 0] or [1e-3])
    hi = max([r["before_px"] for r in rows if np.isfinite(r["before_px"])] or [1.0])
    ax.set_ylim(lo / 2.5, hi * 25.0)  # room above the bars for a two-column legend
    ax.legend(loc="upper center", fontsize=8, ncol=2)
    return ax.figure


# ----------------------------------------------------------------------------- 3-D scene
def scene_figure_mpl():
    with matplotlib.rc_context(P.STYLE):
        fig = Figure(figsize=(9.0, 6.5), layout="constrained")
        ax = fig.add_subplot(1, 1, 1, projection="3d")
    return fig, ax


def draw_scene_mpl(ax, scene: dict, *, note: str = ""):
    """Matplotlib 3-D fallback: DEM surface and band footprints (km, vertical exaggeration applied)."""
    ex = scene["z_exaggeration"]
    X, Y = np.meshgrid(scene["x"] / 1e3, scene["y"] / 1e3)
    ax.plot_surface(X, Y, scene["z"] * ex / 1e3, cmap="terrain", linewidth=0, antialiased=False, alpha=0.85,
                    rcount=80, ccount=80)
    lift = 0.01 * max(np.ptp(scene["z"]) * ex, 1.0) / 1e3
    styles = ("-", "--", "-.", ":")
    n = len(scene["footprints"])
    for j, (band, g) in enumerate(scene["footprints"].items()):
        ok = np.all(np.isfinite(g), axis=1)
        # the bands see nearly the same strip: widest line first, dashed thinner ones on top, so all show
        ax.plot(g[ok, 0] / 1e3, g[ok, 1] / 1e3, g[ok, 2] * ex / 1e3 + lift * (1 + j), color=pair_color(j),
                lw=1.2 + 1.6 * (n - 1 - j), ls=styles[j % len(styles)], label=f"footprint {band}")
    ax.set_xlabel("x along-track [km]")
    ax.set_ylabel("y across-track [km]")
    ax.set_zlabel(f"z [km] (×{ex:.1f})")
    sep = footprint_separation_m(scene["footprints"])
    sep_txt = f"; footprints coincide within {sep:.0f} m" if np.isfinite(sep) else ""
    ax.set_title(("DEM and band footprints" + sep_txt + (f" — {note}" if note else "")), fontsize=10)
    ax.legend(loc="upper left", fontsize=8)
    ax.view_init(elev=35, azim=-60)
    return ax.figure


def footprint_separation_m(footprints: dict) -> float:
    """Largest horizontal distance between corresponding points of the bands' footprints [m]."""
    gs = [np.asarray(g, float) for g in footprints.values()]
    if len(gs) < 2 or any(g.shape != gs[0].shape for g in gs):
        return float("nan")
    d = [np.hypot(g[:, 0] - gs[0][:, 0], g[:, 1] - gs[0][:, 1]) for g in gs[1:]]
    d = np.concatenate(d)
    return float(np.nanmax(d)) if np.isfinite(d).any() else float("nan")


def render_scene_pyvista(scene: dict, png_path, *, window_size=(1000, 680)) -> str:
    """Render DEM + footprints with PyVista off screen into ``png_path``; returns the path.

    Raises whatever VTK raises when no OpenGL context can be made (the caller
    falls back on :func:`draw_scene_mpl`).
    """
    import pyvista as pv

    pv.OFF_SCREEN = True
    ex = float(scene["z_exaggeration"])
    x = np.asarray(scene["x"], float)
    y = np.asarray(scene["y"], float)
    X, Y = np.meshgrid(x, y)
    Z = np.asarray(scene["z"], float)
    grid = pv.StructuredGrid(X, Y, Z * ex)
    grid["elevation [m]"] = Z.ravel(order="F")
    pl = pv.Plotter(off_screen=True, window_size=list(window_size))
    pl.set_background("white")
    pl.add_mesh(grid, scalars="elevation [m]", cmap="gist_earth", smooth_shading=True, show_scalar_bar=True,
                scalar_bar_args={"title": "elevation [m]", "color": "black", "vertical": True, "title_font_size": 14,
                                 "label_font_size": 12, "position_x": 0.9, "position_y": 0.2, "height": 0.55,
                                 "width": 0.05, "fmt": "%.0f"})
    span = max(np.ptp(X), np.ptp(Y))
    lift = 0.002 * span
    texts = []
    for j, (band, g) in enumerate(scene["footprints"].items()):
        g = np.asarray(g, float)
        g = g[np.all(np.isfinite(g), axis=1)]
        if len(g) < 2:
            continue
        pts = g.copy()
        pts[:, 2] = pts[:, 2] * ex + lift * (1 + j)
        col = pair_color(j)
        # nearly coincident strips: widest line first, thinner ones on top, so every band shows
        pl.add_mesh(pv.lines_from_points(pts), color=col, line_width=3 + 3 * (len(scene["footprints"]) - 1 - j))
        texts.append((band, col))
    for j, (band, col) in enumerate(texts):
        pl.add_text(f"footprint {band}", position=(12, window_size[1] - 60 - 22 * j), font_size=11, color=col)
    sep = footprint_separation_m(scene["footprints"])
    sep_txt = (f"; the band footprints coincide within {sep:.0f} m (widest line drawn first)"
               if np.isfinite(sep) else "")
    pl.add_text(f"DEM and band ground footprints (vertical x{ex:.1f})", position="upper_edge", font_size=12,
                color="black")
    pl.add_text(f"x along-track: {np.ptp(x) / 1e3:.1f} km, y across-track: {np.ptp(y) / 1e3:.1f} km, "
                f"relief {np.ptp(Z):.0f} m{sep_txt}", position="lower_left", font_size=9, color="black")
    # look from the south-west, above, along-track axis running left to right
    c = np.array([x.mean(), y.mean(), float(np.mean(Z)) * ex])
    d = 1.25 * span
    pl.camera_position = [tuple(c + np.array([-0.25 * d, -0.9 * d, 0.75 * d])), tuple(c), (0.0, 0.0, 1.0)]
    pl.reset_camera_clipping_range()
    pl.screenshot(str(png_path))
    pl.close()
    return str(png_path)


def _pyvista_main(argv=None) -> int:
    """Child-process entry: ``python -m reports.report_plots SCENE.npz OUT.png``."""
    argv = sys.argv[1:] if argv is None else argv
    data = np.load(argv[0], allow_pickle=False)
    fps = {}
    for k in data.files:
        if k.startswith("fp_"):
            fps[k[3:]] = data[k]
    scene = {"x": data["x"], "y": data["y"], "z": data["z"], "footprints": fps,
             "z_exaggeration": float(data["z_exaggeration"])}
    render_scene_pyvista(scene, argv[1])
    return 0


if __name__ == "__main__":  # pragma: no cover - exercised through a subprocess
    sys.exit(_pyvista_main())
