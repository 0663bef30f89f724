"""The run report: ``simsat report RUN_DIR`` → ``RUN_DIR/report/index.html``.

One self-contained HTML page (PNG figures embedded as base64, no external
JS/CSS) with the CSVs of the plotted data and the PNGs beside it. It reads the
product, the restoration and the truth of a run — it never re-runs the
simulation; it may re-run the *integration* (``restore.integration.integrate``)
on differentials to measure its transfer function and to split the error
budget. A run without ``truth.nc`` (a real product) or without
``restoration.nc`` gets the sections that do not need them, and the page says
what was left out.

Data preparation lives in :mod:`reports.report_data`, drawing in
:mod:`reports.report_plots`; this module lays the page out and writes the
files, each atomically (temporary file + ``os.replace``), ``index.html`` last.
"""
from __future__ import annotations

import base64
import html
import io
import json
import os
import subprocess
import sys
import tempfile
import time as _time
from datetime import datetime, timezone
from pathlib import Path
from typing import Callable

import numpy as np

from reports import plotting as P
from reports import report_data as D
from reports import report_plots as RP
from reports.frames_report import is_frames_run, make_frames_report
from reports.summary import sigma_if_images_short
from simsat.product import atomic_write_bytes, atomic_write_json
from simsat.units import URAD_PER_RAD

__all__ = ["make_run_report"]

DPI = 100
#: widest embedded thumbnail (px); the full-resolution PNG is linked beside the page
THUMB_WIDTH = 900


def _thumbnail(png: bytes, *, max_width: int = THUMB_WIDTH, colors: int = 128) -> bytes:
    """A smaller PNG to embed in the page: at most ``max_width`` wide, adaptive palette.

    Keeps the HTML small (a few hundred kB) whatever the run length; the
    full PNG is the link target. Falls back to the original bytes if Pillow
    cannot read them.
    """
    try:
        from PIL import Image

        im = Image.open(io.BytesIO(png)).convert("RGB")
        w, h = im.size
        if w > max_width:
            im = im.resize((max_width, max(1, round(h * max_width / w))), Image.LANCZOS)
        q = im.quantize(colors=colors, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE)
        out = io.BytesIO()
        q.save(out, format="PNG", optimize=True)
        data = out.getvalue()
        return data if len(data) < len(png) else png
    except Exception:  # pragma: no cover - an unreadable PNG is embedded as it is
        return png


# ----------------------------------------------------------------------------- small helpers
def _fmt(v, digits: int = 4) -> str:
    if v is None:
        return "—"
    if isinstance(v, (bool, np.bool_)):
        return "yes" if v else "no"
    if isinstance(v, (int, np.integer)):
        return f"{int(v):,}"
    try:
        x = float(v)
    except (TypeError, ValueError):
        return html.escape(str(v))
    if not np.isfinite(x):
        return "∞" if x == np.inf else "—"
    if x == 0:
        return "0"
    if abs(x) >= 1000 or abs(x) < 10 ** (-digits + 1):
        return f"{x:.{max(digits - 1, 1)}g}" if abs(x) < 1e5 else f"{x:.3g}"
    return f"{x:.{digits}g}"


def _e(s) -> str:
    return html.escape(str(s))


class _Page:
    """Accumulates sections, figures (written as PNG + embedded) and CSVs."""

    def __init__(self, out_dir: Path):
        self.out_dir = out_dir
        self.parts: list[str] = []
        self.files: list[str] = []
        self.toc: list[tuple[str, str]] = []

    def section(self, anchor: str, title: str):
        self.toc.append((anchor, title))
        self.parts.append(f'<h2 id="{anchor}">{_e(title)}</h2>')

    def html(self, s: str):
        self.parts.append(s)

    def para(self, text: str, cls: str = ""):
        self.parts.append(f'<p class="{cls}">{text}</p>' if cls else f"<p>{text}</p>")

    def note(self, text: str):
        self.parts.append(f'<p class="note">{text}</p>')

    def figure(self, fig, name: str, caption: str, *, width: int | None = None):
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=DPI)
        data = buf.getvalue()
        atomic_write_bytes(data, self.out_dir / name)
        self.files.append(name)
        b64 = base64.b64encode(_thumbnail(data)).decode("ascii")
        style = f' style="max-width:{width}px"' if width else ""
        self.parts.append(f'<figure><a href="{_e(name)}"><img alt="{_e(name)}" src="data:image/png;base64,{b64}"{style}>'
                          f'</a><figcaption>{caption}</figcaption></figure>')

    def png_file(self, path: Path, caption: str):
        data = path.read_bytes()
        self.files.append(path.name)
        b64 = base64.b64encode(_thumbnail(data)).decode("ascii")
        self.parts.append(f'<figure><a href="{_e(path.name)}"><img alt="{_e(path.name)}" '
                          f'src="data:image/png;base64,{b64}"></a><figcaption>{caption}</figcaption></figure>')

    def csv(self, name: str, table: dict) -> str:
        P.write_table_csv(self.out_dir / name, table)
        self.files.append(name)
        return f'<a href="{_e(name)}">{_e(name)}</a>'

    def table(self, header: list, rows: list, cls: str = "") -> None:
        h = "".join(f"<th>{c}</th>" for c in header)
        body = "".join("<tr>" + "".join(f"<td>{c}</td>" for c in r) + "</tr>" for r in rows)
        self.parts.append(f'<table class="{cls}"><thead><tr>{h}</tr></thead><tbody>{body}</tbody></table>')


CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Helvetica,Arial,sans-serif;margin:1.5em auto;max-width:1180px;
color:#222;line-height:1.4;padding:0 1em}
h1{font-size:1.5em;margin-bottom:.2em} h2{font-size:1.2em;border-bottom:1px solid #ccc;margin-top:2em;padding-bottom:.2em}
table{border-collapse:collapse;margin:.6em 0;font-size:.88em} th,td{border:1px solid #ccc;padding:.25em .55em;text-align:right}
th{background:#f1f3f5} td:first-child,th:first-child{text-align:left}
figure{margin:1em 0} figure img{max-width:100%;border:1px solid #ddd} figcaption{font-size:.86em;color:#444;margin-top:.3em}
.meta{color:#666;font-size:.85em} .note{background:#fff8e1;border-left:4px solid #f0b400;padding:.4em .7em;font-size:.88em}
.summary{background:#f6f8fa;border:1px solid #dde;padding:.6em 1em;border-radius:4px}
.pass{color:#fff;background:#1a7f37;padding:.1em .5em;border-radius:3px;font-weight:bold}
.fail{color:#fff;background:#cf222e;padding:.1em .5em;border-radius:3px;font-weight:bold}
.na{color:#fff;background:#6e7781;padding:.1em .5em;border-radius:3px;font-weight:bold}
nav a{margin-right:.8em;font-size:.88em} .files{font-size:.82em;color:#555}
"""


# ----------------------------------------------------------------------------- sections
def _summary_section(pg: _Page, run: D.RunData, sc: dict, hd: dict, report_notes: list):
    ifov = sc["ifov_rad"]
    pg.html('<div class="summary">')
    bands = ", ".join(f"{b['name']} ({b['band']}, {b['along_mm']:+.3f} mm)" for b in sc["bands"])
    pairs = ", ".join(f"{p['name']} τ = {p['tau_s'] * 1e3:.2f} ms ({p['tau_lines']:.1f} lines)" for p in sc["pairs"])
    desc = f" — {_e(sc['description'])}" if sc.get("description") else ""
    pg.para(f"<b>Scenario</b> <code>{_e(sc['name'])}</code>{desc}<br>"
            f"{sc['lines']:,} lines × {sc['columns']:,} columns, line period {sc['line_period_s'] * 1e3:.3f} ms "
            f"({sc['duration_s']:.3f} s); reference band {_e(sc['reference_band'])}, 1 px = {ifov * URAD_PER_RAD:.3f} µrad."
            f"<br><b>Bands</b> (along-track position): {_e(bands)}"
            f"<br><b>Pairs</b> {'used by the restoration' if run.restoration is not None else '(nominal delays)'}: "
            f"{_e(pairs) or '—'}")
    if run.restoration is not None:
        opts = sc.get("integration_options") or {}
        pg.para(f"<b>Restoration</b>: integration <code>{_e(sc['method'])}</code>"
                f"{(' (' + _e(json.dumps(opts)) + ')') if opts else ''}, {sc.get('iterations') or '?'} iteration(s), "
                f"axes {', '.join(sc['restored_axes']) or '—'}"
                f"{'; anchored on star tracker' if sc.get('anchored') else ''}.")
    # verdict
    if hd["passed"] is True:
        badge = '<span class="pass">PASS</span>'
    elif hd["passed"] is False:
        badge = '<span class="fail">FAIL</span>'
    else:
        badge = '<span class="na">N/A</span>'
    req = hd["requirement"]
    req_txt = ", ".join(f"{k.replace('max_', '').replace('_px', '').replace('p997', '99.7 %').upper()} ≤ {v:g} px"
                        for k, v in req.items()) or "none"
    verdict = hd["verdict"]
    if hd["passed"] is not None and verdict.split(":", 1)[0] in ("PASS", "FAIL"):
        verdict = verdict.split(":", 1)[1].strip()  # the badge already says it
    pg.para(f"<b>Requirement</b> (scenario.requirement): {_e(req_txt)} — {badge} {_e(verdict)}")
    # headline table
    rows = []
    have_truth = run.truth is not None
    for a in D.AXES:
        d = hd["axes"][a]
        if a == "yaw":  # yaw does not move the image by its line-of-sight angle: show it in µrad only
            d = {k: (float("nan") if k.endswith("_px") else v) for k, v in d.items()}
        tag = "" if d.get("restored", True) or run.restoration is None else " (not restored)"
        if have_truth and run.restoration is not None:
            rows.append([f"{a}{tag}", _fmt(d.get("rms_px")), _fmt(d.get("p997_px")), _fmt(d.get("rms_urad")),
                         _fmt(d.get("p997_urad")), _fmt(d.get("knowledge_rms_px")), _fmt(d.get("knowledge_p997_px")),
                         _fmt(d.get("knowledge_rms_urad")), _fmt(d.get("knowledge_p997_urad")),
                         _fmt(d.get("improvement_rms"), 3), f"{d.get('coverage', float('nan')) * 100:.1f} %"])
        elif have_truth:
            rows.append([a, _fmt(d.get("knowledge_rms_px")), _fmt(d.get("knowledge_p997_px")),
                         _fmt(d.get("knowledge_rms_urad")), _fmt(d.get("knowledge_p997_urad"))])
        elif run.restoration is not None:
            rows.append([f"{a}{tag}", _fmt(d.get("correction_rms_px")), _fmt(d.get("correction_rms_urad")),
                         f"{d.get('coverage', float('nan')) * 100:.1f} %"])
    if have_truth and run.restoration is not None:
        pg.table(["axis", "restored RMS [px]", "restored 99.7 % [px]", "RMS [µrad]", "99.7 % [µrad]",
                  "AOCS RMS [px]", "AOCS 99.7 % [px]", "AOCS RMS [µrad]", "AOCS 99.7 % [µrad]",
                  "improvement (RMS)", "coverage"], rows)
        pg.para("Error = estimate − truth over the estimated lines, mean removed (the metric of docs/design.md); AOCS = the uncorrected "
                "knowledge on the same lines; improvement = AOCS RMS / restored RMS.", "meta")
    elif have_truth:
        pg.table(["axis", "AOCS RMS [px]", "AOCS 99.7 % [px]", "AOCS RMS [µrad]", "AOCS 99.7 % [µrad]"], rows)
    elif rows:
        pg.table(["axis", "correction RMS [px]", "correction RMS [µrad]", "coverage"], rows)
        pg.para("No truth: accuracy cannot be measured; the table gives the size of the applied correction.", "meta")
    if rows:
        ref = run.product.reference_detector
        det = next((x for x in run.product.instrument.detectors if x.name == ref), run.product.instrument.detectors[0])
        half = det.pixels / 2.0
        pg.para(f"Yaw is given in µrad only (its px columns are empty): it rotates the image about the line of "
                f"sight, moving a point along track by (its column offset from the field centre) × yaw; at the "
                f"field edge ({half:.0f} px from the centre of {det.name}) 1 µrad of yaw moves the image by "
                f"{half * 1e-6:.2g} px.", "meta")
    for n in run.notes + report_notes:
        pg.note(_e(n))
    pg.html("</div>")


def _attitude_section(pg: _Page, run: D.RunData, sc: dict, hd: dict):
    att = D.attitude_table(run)
    pg.section("attitude", "Attitude over time")
    valid = None
    if run.restoration is not None:
        valid = np.all([np.isfinite(att[f"restored_{a}"]) for a in (sc["restored_axes"] or D.AXES)], axis=0)
    zoom = D.zoom_window(att["time_s"], valid, duration_s=0.05)
    table = {"line": att["line"], "time_s": att["time_s"]}
    for a in D.AXES:
        for k in ("true", "knowledge", "restored", "correction", "delta", "error", "knowledge_error"):
            key = f"{k}_{a}"
            if key in att:
                table[f"{key}_urad"] = att[key] * URAD_PER_RAD
    link = pg.csv("attitude.csv", table)
    for a in D.AXES:
        fig, axs = RP.attitude_figure()
        ref = run.product.reference_detector
        half = next((d.pixels for d in run.product.instrument.detectors if d.name == ref),
                    run.product.instrument.detectors[0].pixels) / 2.0
        RP.draw_attitude(axs, att, a, ifov_rad=sc["ifov_rad"], zoom=zoom, yaw_half_field_px=half,
                         restored=(a in sc["restored_axes"]) or run.restoration is None)
        extra = ""
        d = hd["axes"][a]
        if "rms_px" in d:
            extra = (f" Restored error RMS {d['rms_px']:.4f} px / 99.7 % {d['p997_px']:.4f} px; "
                     f"AOCS {d['knowledge_rms_px']:.4f} / {d['knowledge_p997_px']:.4f} px.")
        what = ", ".join(x for x, ok in (("true", run.truth is not None), ("AOCS knowledge", True),
                                          ("restored", run.restoration is not None)) if ok)
        errs = " and errors (mean removed)" if run.truth is not None else " (errors need truth)"
        pg.figure(fig, f"attitude_{a}.png",
                  f"{a}: {what} (left: whole record, envelope-decimated; right: "
                  f"{1e3 * (zoom[1] - zoom[0]):.0f} ms zoom, every line){errs}; µrad, px on the right axis.{extra}")
    pg.para(f"Data (every line, µrad): {link}", "files")


def _spectra_section(pg: _Page, run: D.RunData, sc: dict) -> float:
    spec = D.spectra(run)
    pg.section("spectra", "Power spectra")
    fs = 1.0 / run.line_period_s
    taus = [p["tau_s"] for p in sc["pairs"]]
    names = [p["name"] for p in sc["pairs"]]
    if not spec.get("freq_hz", np.zeros(0)).size:
        pg.note("Not enough estimated lines for spectra.")
        return 0.5 * fs
    ref = next((spec[k] for k in (f"psd_delta_{a}" for a in D.AXES) if k in spec), None)
    if ref is None:
        ref = next((spec[k] for k in (f"psd_correction_{a}" for a in D.AXES) if k in spec), None)
    tot = sum(spec[k] for k in spec if k.startswith("psd_delta_")) if run.truth is not None else ref
    f_max = RP.nice_f_max(spec["freq_hz"], tot, fs)
    fig, axs = RP.spectra_figure(3)
    RP.draw_spectra(axs, spec, taus=taus, pair_names=names, f_max=f_max)
    table = {"freq_hz": spec["freq_hz"]}
    for k in sorted(k for k in spec if k.startswith("psd_")):
        table[f"{k}_urad2_per_hz"] = spec[k] * URAD_PER_RAD ** 2
    link = pg.csv("spectra.csv", table)
    nps = spec["nperseg"]
    span = spec.get("span_roll", (0, 0))
    pg.figure(fig, "spectra.png",
              f"Welch PSDs (Hann, {nps} lines per segment = {nps * run.line_period_s * 1e3:.0f} ms, "
              f"{fs / nps:.2f} Hz resolution, 50 % overlap) over the longest fully estimated stretch "
              f"(lines {span[0]}–{span[1]}). Triangles: blind frequencies n/τ of each pair "
              f"(a pair alone cannot see them).")
    pg.para(f"Data (full frequency range up to {fs / 2:.0f} Hz): {link}", "files")
    return f_max


def _transfer_section(pg: _Page, run: D.RunData, sc: dict, f_max: float, integrate, why_not: str,
                      max_integration_s: float, report_notes: list):
    pg.section("transfer", "Transfer function of the integration")
    taus = [p["tau_s"] for p in sc["pairs"]]
    names = [p["name"] for p in sc["pairs"]]
    if run.restoration is None:
        pg.note("No restoration: no integration to show.")
        return
    method = sc["method"] or ""
    axes = sc["restored_axes"] or list(D.AXES)
    if integrate is not None:
        expected = _integration_call_s(run) * (len(taus) + 2) * len(axes)
        if expected > max_integration_s:
            report_notes.append(f"integration transfer not probed: ~{expected:.0f} s expected")
            integrate = None
            why_not = f"re-running it would take ~{expected:.0f} s"
    if integrate is None:
        pg.note(_e(f"The integration cannot be re-run ({why_not}); only an analytic Wiener reference is drawn."))
    tc = D.transfer_curves(run, taus, names, axes, method=method, options=dict(sc.get("integration_options") or {}),
                           integrate=integrate, f_max=f_max)
    for msg in tc["notes"]:
        pg.note(_e(msg))
    probes, analytic, frozen_any, gaps_txt = tc["probes"], tc["analytic"], tc["frozen"], tc["gaps"]
    measured = D.measured_transfer(run)
    fig, axs = RP.transfer_figure(len(axes))
    for i, (ax, a) in enumerate(zip(axs, axes)):
        RP.draw_transfer(ax, probe=probes.get(a), measured=measured, taus=taus, pair_names=names, f_max=f_max,
                         analytic=analytic.get(a), method=method, axis=a, legend=(i == len(axes) - 1))
    links = []
    f0 = next((p["freq_hz"] for p in probes.values() if p["freq_hz"].size), None)
    if f0 is None:
        f0 = next(iter(analytic.values()))["freq_hz"] if analytic else np.zeros(0)
    t1 = {"freq_hz": f0}
    for a in axes:
        if a in probes and probes[a]["freq_hz"].size == f0.size:
            t1[f"gain_fused_{a}"] = probes[a]["gain_fused"]
            t1[f"phase_fused_{a}_deg"] = probes[a]["phase_fused_deg"]
            for nm in names:
                t1[f"gain_{D.pair_file_tag(nm)}_{a}"] = probes[a][f"gain_{nm}"]
        if a in analytic and analytic[a]["freq_hz"].size == f0.size:
            t1[f"analytic_gain_fused_{a}"] = analytic[a]["gain_joint"]
            for nm in names:
                t1[f"analytic_gain_{D.pair_file_tag(nm)}_{a}"] = analytic[a][f"gain_{nm}"]
    links.append(pg.csv("transfer_integration.csv", t1))
    if measured:
        t2 = {"freq_hz": measured["freq_hz"]}
        for a in D.AXES:
            if f"gain_{a}" in measured:
                t2[f"gain_{a}"] = measured[f"gain_{a}"]
                t2[f"phase_{a}_deg"] = measured[f"phase_{a}_deg"]
                t2[f"coherence_{a}"] = measured[f"coherence_{a}"]
                t2[f"psd_delta_{a}_urad2_per_hz"] = measured[f"psd_delta_{a}"] * URAD_PER_RAD ** 2
                t2[f"significant_{a}"] = measured[f"significant_{a}"].astype(int)
        links.append(pg.csv("transfer_measured.csv", t2))
    ran = {a: getattr(D.integration_record(run, a), "method", None) for a in axes}
    used = ", ".join(f"{a} {m}" for a, m in ran.items() if m and m != method)
    cap = ("Chain gain |θ̂/θ| per restored axis. Solid lines: the integration actually used "
           f"(<code>{_e(method)}</code>{_e(' — ' + used) if used else ''}), probed by re-running it on a band-limited random attitude with exact "
           "differentials (each pair alone, thin; all pairs fused, thick)")
    if frozen_any:
        cap += (". The method adapts its prior to the data, so it was first run on the measured differentials of "
                "each axis and its PSD prior and noise levels frozen: the curves are the filter that was applied, "
                "hence one panel per axis; dotted/dashed: the same Wiener filter computed analytically "
                "(the stationary formula F = Σ|G_j|²S/N_j / (1 + Σ|G_j|²S/N_j), averaged over the probe's Hann "
                "spectral window: the data's prior has lines narrower than the probe's resolution, and the point "
                "formula would jump between 0 and 1 where the probe cannot)")
        if gaps_txt:
            cap += (f"; |analytic − probed| gain from 1 to {f_max or 0:.0f} Hz, fused: " + "; ".join(gaps_txt) +
                    " — what remains is the finite record: the probe runs the MAP solution on N lines with "
                    "padding, which is not the stationary filter, most of all beside the prior's narrow lines")
    elif analytic:
        cap += "; dotted/dashed: analytic Wiener chain gain F_k = 2(1−cos ωτ)/(2(1−cos ωτ)+k)"
    if measured:
        cap += ("; markers: measured transfer of the whole chain (Welch cross-spectrum of the restored correction "
                "with true − knowledge, over the PSD of true − knowledge), where the truth has power above the "
                "uncorrelated part of the correction")
    elif run.truth is None:
        cap += "; the measured chain transfer needs truth"
    pg.figure(fig, "transfer.png", cap + ". Triangles: blind frequencies n/τ.")
    pg.para("Data: " + ", ".join(links), "files")


def _integration_call_s(run: D.RunData) -> float:
    try:
        tim = json.loads(str(run.restoration.attrs.get("timings", "{}")))
        it = int(run.settings.get("iterations") or 1)
        nax = max(1, len(D.restored_axes(run)))
        return float(tim.get("integration_s", 0.0)) / (it * nax)
    except (ValueError, TypeError, AttributeError):
        return 0.0


def _budget_section(pg: _Page, run: D.RunData, integrate, max_integration_s: float) -> dict:
    pg.section("budget", "Error budget")
    if run.restoration is None:
        pg.note("No restoration: no budget.")
        return {}
    bud = D.error_budget(run, integrate=integrate, max_seconds=max_integration_s)
    rows = bud["rows"]
    if rows:
        trs = []
        for r in rows:
            strong = r["component"].startswith("total")
            b = (lambda s: f"<b>{s}</b>") if strong else (lambda s: s)
            trs.append([b(_e(r["axis"])), b(_e(r["component"])), b(_fmt(r["rms_px"])), b(_fmt(r["p997_px"])),
                        b(_fmt(r["rms_urad"])), b(_fmt(r["p997_urad"])), _e(r.get("note", ""))])
        pg.table(["axis", "component", "RMS [px]", "99.7 % [px]", "RMS [µrad]", "99.7 % [µrad]", "how"], trs)
        fig, ax = P.new_axes(figsize=(10.0, 1.3 + 1.2 * len({r['axis'] for r in rows})))
        RP.draw_budget(ax, rows)
        pg.figure(fig, "budget.png", "Error budget per axis (log scale).")
    txt = ("<b>Matching noise</b>: white noise with the per-line formal σ of the differentials (from the scatter "
           "of the inlier match residuals) added to the differentials and integrated with the run's method: "
           "integrate(d + noise) − integrate(d), one seeded draw. ")
    if run.truth is not None:
        txt += ("<b>Integration</b>: the true differentials θ(t+τ) − θ(t) of the true remaining error (true − "
                "knowledge − earlier iterations' estimate), with the same gaps, integrated, minus the truth: blind "
                "frequencies, regularisation, ends. <b>Measurement</b> = total − integration: the cost of the errors "
                "of the measured differentials; <b>model / synthesis</b> = the part of it matching noise does not "
                "explain, √(measurement² − noise²) (the 99.7 % figures combine this way only approximately). ")
        if int(run.restoration.attrs.get("anchored_on_star_tracker", 0)):
            txt += ("<b>Star-tracker anchoring</b>: the record's trend (offset and slope, which no pair sees) is set "
                    "by the star-tracker samples after the integration; the integration and the measurement are "
                    "given without it, and the trend left (the samples' noise through the fitted slope) is this "
                    "row: total = measurement + integration + anchoring. ")
    txt += ("Methods that adapt to their data (wiener) are frozen on the measured differentials first, so every row "
            "goes through the filter actually applied. All errors over the estimated lines, mean removed.")
    pg.para(txt, "meta")
    for n in bud["notes"]:
        pg.note(_e(n))
    table = {k: [r.get(k, "") for r in rows] for k in ("axis", "component", "rms_px", "p997_px", "rms_urad",
                                                        "p997_urad", "n", "note")}
    links = [pg.csv("budget.csv", table)] if rows else []
    drows = bud["differential_rows"]
    if drows:
        keys = ["pair", "axis", "tau_s", "lines", "matching_sigma_urad", "meas_minus_true_rms_urad",
                "model_rms_urad", "meas_minus_true_mean_urad", "matching_sigma_px", "meas_minus_true_rms_px",
                "model_rms_px", "time_sync_rms_urad", "time_sync_rms_px"]
        keys = [k for k in keys if any(k in r for r in drows)]
        trs = [[_e(r["pair"]), _e(r["axis"]), _fmt(r["tau_s"] * 1e3), _fmt(r["lines"])] +
               [_fmt(r.get(k, float("nan"))) for k in keys[4:]] for r in drows]
        hdr = ["pair", "axis", "τ [ms]", "lines"] + [k.replace("_urad", " [µrad]").replace("_px", " [px]")
                                                     .replace("_", " ") for k in keys[4:]]
        pg.html("<p><b>Differential level</b> (per pair, before integration): measured differentials against "
                "the true ones at the delay the images actually saw, τ + λ(t) with λ the per-line line residual of "
                "the matches (pitch jitter changes the delay; the restoration models it, see time synchronisation); "
                "<i>time sync</i> is the size of that effect, true(τ + λ) − true(τ).</p>")
        pg.table(hdr, trs)
        links.append(pg.csv("budget_differentials.csv", {k: [r.get(k, float("nan")) for r in drows] for k in keys}))
    if links:
        pg.para("Data: " + ", ".join(links), "files")
    return bud


def _knowledge_check_text(chk: dict, ifov: float, sigma_rad: float | None = None, took_share: bool = True) -> str:
    """One cell: the band, observed / predicted power of restored − smoothed knowledge, and the excess beyond it
    (with ``sigma_rad``, the axis's predicted σ, also σ if the images' prediction is the short one; ``took_share``:
    whether σ holds its share of the excess: the setting ``sigma_knowledge_check``)."""
    if not chk:
        return "—"
    lo, hi = chk["band_hz"]
    txt = f"{lo:.1f}–{hi:.1f} Hz: {chk['ratio']:.2f} × (limit {chk['threshold']:.2f})"
    booked = chk.get("booked_rms_rad", chk["excess_rms_rad"])
    if chk["excess_rms_rad"] > 0:
        txt += f"; excess {chk['excess_rms_rad'] / ifov:.4f} px, σ takes {booked / ifov:.4f} px of it"
        if sigma_rad is not None and np.isfinite(sigma_rad):
            worst = sigma_if_images_short(sigma_rad, chk, took_share=took_share)
            txt += f" ({worst / ifov:.4f} px if the images' prediction is the short one)"
        return txt
    # below the limit the two do not significantly disagree, but σ still takes its share of what was measured
    return txt + (f"; σ takes {booked / ifov:.4f} px of the excess" if booked > 0 else "")


def _explained_lines(run, unc) -> tuple:
    """``(line or None, why)`` for each part of the error the restoration names and does not restore (the
    knowledge's dephasing and latency, its filter's own error, the scene's band offset, a notch's continuum and
    level)."""
    from .summary import (knowledge_dephasing_line, knowledge_filter_line_of_run, knowledge_timing_line,
                          notch_continuum_line_of_run, notch_level_line, scene_offset_line_of_run)

    product_ds = getattr(getattr(run, "product", None), "ds", None)
    explained = (
        (knowledge_dephasing_line(product_ds.attrs if product_ds is not None else {}, run.restoration),
         ". The high-pass, the low band, the prior's ceiling, the conditioning and the fusion all read the knowledge "
         "as a zero-phase one; the phase of its recorded filter is known, so it was taken out by an all-pass on the "
         "samples (no noise amplified; the lag stays over the record's last group delay, where the knowledge of the "
         "next instants does not exist) and the knowledge read as a zero-phase filter of gain |F| "
         "(restore.knowledge_dephasing)."),
        (knowledge_timing_line(run.restoration),
         ". Where both the images and the knowledge see the attitude (above the high-pass, where the knowledge's "
         "filter passes 90 % or more), the attitude the knowledge misses is, to first order, its latency times "
         "its rate: each pair's differentials of it were regressed on those of the knowledge's derivative, the "
         "σ from the residuals' spectrum (or a jackknife over eight stretches of the record, if larger), and the "
         "knowledge advanced by the estimate shrunk by its σ, δ (1 − σ²/δ²), nothing within one σ of zero "
         "(restore.knowledge_timing)."),
        (knowledge_filter_line_of_run(run, list(unc)),
         ". Below the high-pass the images' estimate is discarded (the differentials see little there and a band's "
         "slow bias would pass for attitude) and the restored angle is the knowledge: its noise is smoothed and "
         "in σ, and so is its filter's own error, estimated from the knowledge through (1 − F)/F "
         "(restore.observability.knowledge_filter_error_below) — nothing for a zero-phase filter well below its "
         "cut-off, the lag of a causal one. Nothing restores it."),
        (scene_offset_line_of_run(run, list(unc)),
         ": each band is a different blend of the scene's sunlit and shaded features, offset towards the sun by "
         "amounts that follow the scene's large features, and where the pairs see the attitude through about "
         "2π f τ such an offset is an attitude to every pair (restore.observability.scene_offset_band). Its size "
         "depends on the scene, not on the product; an AOCS knowledge whose band reaches the top of this one "
         "would hold it."),
        (notch_continuum_line_of_run(run, list(unc)),
         ". The spectrum estimate does not estimate the prior round a frequency every pair is blind to; it "
         "bridges it from the notch's edge bins, the smaller one, so that a line's skirt does not raise it. "
         "Under a broadband continuum that bridge can fall to nothing while the pairs' flanks still see the "
         "jitter: the figure is the error the filter built on the bridge adds to the best the pairs allow were "
         "the continuum at its sides' level (restore.observability.notch_continuum)."),
        (notch_level_line(run.restoration, list(unc)),
         ". Over its whole width a notch's flanks still see the attitude: its level, fitted there on what the MAP "
         "left (restore.integration.spectrum.notch_levels), was detected above the bridge, and the prior took it "
         "(restore.axis_integration._notch_prior). The filter gives back what the flanks see; the notch's middle, "
         "which no pair sees, is in the unobservable part and in σ."))
    return explained


def _uncertainty_section(pg: _Page, run: D.RunData, sc: dict):
    unc = D.uncertainty(run)
    if not unc:
        return
    pg.section("uncertainty", "Predicted uncertainty")
    ifov = sc["ifov_rad"]
    took = bool(run.settings.get("sigma_knowledge_check", True))
    rows = []
    for a, d in unc.items():
        rows.append([_e(a), _fmt(d["predicted_rms"] / ifov), _fmt(d.get("actual_rms", np.nan) / ifov),
                     _fmt(d.get("ratio", np.nan), 3), _fmt(d.get("within_2sigma", np.nan) * 100, 3),
                     str(int(d["flagged"].sum())), _fmt(d["noise_scale"], 3),
                     _e(", ".join(f"{b} {v:.2f}" for b, v in d.get("band_shares", {}).items()) or "—"),
                     _e(_knowledge_check_text(d.get("knowledge_check", {}), ifov, d["predicted_rms"], took))])
    pg.table(["axis", "predicted RMS σ [px]", "actual RMS [px]", "actual / predicted", "lines within 2σ [%]",
              "flagged lines", "noise inflation", "band's share of its pairs' noise",
              "against the smoothed knowledge"], rows)
    for a, d in unc.items():
        fig, axs = RP.uncertainty_figure()
        RP.draw_uncertainty(axs, d, a, ifov_rad=ifov)
        pg.figure(fig, f"uncertainty_{a}.png",
                  f"{a}: the restoration's predicted 1-σ per line (Monte Carlo through its own integration: prior "
                  f"and noise as it estimated them, the record's gaps, lags and weights)"
                  + (" against the actual error" + (f", less the yaw seen as {a} (× {d['yaw_seen_removed']:+.3f}: no "
                                                     "pair tells it apart off nadir; the error budget gives it)"
                                                     if "yaw_seen_removed" in d else "")
                     + "; right, lines binned by predicted σ." if "error" in d else "."))
    pg.para("Lines whose predicted σ exceeds restoration.max_sigma_px (\"auto\": 3 × the axis's median) are not "
            "restored and are counted as flagged, not as valid. A ratio near 1 says the error model holds; well "
            "above 1, the error comes from something the model does not hold (a blind frequency, an unmodelled "
            "axis, a bias): see the error budget. The last column checks the prediction against the AOCS "
            "knowledge, which sees the same attitude independently: between 1.25 × the high-pass and 0.7 × the "
            "knowledge's cut-off, the power of restored − smoothed knowledge over the sum of both predicted errors "
            "(images: the draws above; knowledge: the noise its smoothing leaves and its filter's error). Beyond "
            "the limit (two sampling spreads) one of the two predictions is short by at least the excess, and the "
            "data cannot tell which; σ takes the images' share of it (restoration.sigma_knowledge_check), and the "
            "cell gives, in brackets, σ if the images' prediction is the short one.")
    fused = {a: d["fused_lines"] for a, d in unc.items() if d.get("fused_lines")}
    if fused:
        from restore.knowledge_fusion import FUSION_HIGH_FRACTION, FUSION_THRESHOLD

        pg.para("Knowledge fusion: " + ", ".join(f"{a} {n} lines" for a, n in fused.items()) + " took the AOCS "
                f"knowledge's band below {FUSION_HIGH_FRACTION:g} × its cut-off, where the restored angle's own band, "
                "its strong lines above the band kept whole, held more than "
                f"{FUSION_THRESHOLD / 2:g} times the power the knowledge's error has there (the minimum-variance "
                f"weight from {FUSION_THRESHOLD:g} times, brought in linearly from {FUSION_THRESHOLD / 2:g}: a drift "
                "at a record end or a gap edge, or band offsets "
                "that move like an attitude); σ holds the combination's error on those lines "
                "(restoration.knowledge_fusion).")
    explained = _explained_lines(run, unc)
    for line, why in explained:
        if line:
            text = line.strip()
            pg.note(text[0].upper() + text[1:] + why)


def _matches_section(pg: _Page, run: D.RunData):
    pg.section("matches", "Matches on the image and misregistration")
    dens = D.match_density(run)
    if not dens:
        pg.note("No matches in the restoration.")
    else:
        fig, axs = RP.match_density_figure(len(dens))
        for ax, (name, d) in zip(axs, dens.items()):
            RP.draw_match_density(ax, d, name)
        axs[-1].set_xlabel("line of the ahead band (time →)")
        pg.figure(fig, "matches.png",
                  "Density of inlier matches per pair over the image of the ahead band (line horizontal); "
                  "red dots: matches rejected by the 3σ synthesis, grey dots: candidates whose matching failed "
                  "(low correlation; at most 3000 of each drawn); grey bands: lines without differential (gaps).")
        links = []
        for name, d in dens.items():
            le, ce = d["line_edges"], d["col_edges"]
            L0, C0 = np.meshgrid(le[:-1], ce[:-1], indexing="ij")
            L1, C1 = np.meshgrid(le[1:], ce[1:], indexing="ij")
            links.append(pg.csv(f"matches_{D.pair_file_tag(name)}.csv",
                                {"line_lo": L0.ravel(), "line_hi": L1.ravel(), "col_lo": C0.ravel(),
                                 "col_hi": C1.ravel(), "inliers": d["inliers"].ravel().astype(int),
                                 "rejected": d["rejected"].ravel().astype(int)}))
        gp, g0, g1 = [], [], []
        for name, d in dens.items():
            for a, b in d["gap_intervals"]:
                gp.append(name)
                g0.append(a)
                g1.append(b)
        links.append(pg.csv("gaps.csv", {"pair": gp, "first_line": g0, "stop_line": g1}))
        rows = [[_e(n), _fmt(d["n_total"]), _fmt(d["n_valid"]), _fmt(d["n_inlier"]), _fmt(d["n_rejected_valid"]),
                 _fmt(d["n_invalid"]), _fmt(sum(b - a for a, b in d["gap_intervals"]))] for n, d in dens.items()]
        pg.table(["pair", "candidates", "valid", "inliers", "rejected by synthesis", "failed matching",
                  "gap lines"], rows)
        pg.para("Data (counts per bin): " + ", ".join(links), "files")
        lock = D.matching_lock_sentence(D.matching_lock_of_run(run))
        if lock:
            pg.note(lock)
    _misregistration_part(pg, run)


def _misregistration_part(pg: _Page, run: D.RunData):
    """The misregistration figure, table and notes of the matches section."""
    mis = D.misregistration_rows(run)
    if mis:
        fig, ax = P.new_axes(figsize=(8.0, 3.8))
        RP.draw_misregistration(ax, mis)
        pg.figure(fig, "misregistration.png",
                  "Band-to-band misregistration: RMS over lines of the per-line mean shift between bands, before "
                  "correction (raw images) and after (images resampled with the restored attitude), from "
                  "restoration.nc. After correction the per-line mean of cross-band 3-line windows carries a "
                  "matching noise of the same order as the misregistration left; the grey bar removes it "
                  "(two interleaved halves of each line's points, whose noises are independent). With truth, the light "
                  "grey bar repeats the measurement on bands corrected with the true attitude: the floor of the "
                  "measurement, what a perfect restoration would show.", width=800)
        pg.table(["pair", "before [px]", "after, measured [px]", "matching noise [px]", "after, noise removed [px]",
                  "before line/col [px]", "after line/col [px]", "noise removed line/col [px]", "lines",
                  "improvement"],
                 [[_e(r["pair"]), _fmt(r["before_px"]), _fmt(r["after_px"]), _fmt(r["after_noise_px"]),
                   _fmt(r["after_signal_px"]),
                   f"{_fmt(r['before_line_px'])} / {_fmt(r['before_col_px'])}",
                   f"{_fmt(r['after_line_px'])} / {_fmt(r['after_col_px'])}",
                   f"{_fmt(r['after_line_signal_px'])} / {_fmt(r['after_col_signal_px'])}", _fmt(r["lines"]),
                   _fmt(r["improvement"], 3)] for r in mis])
        weak = [r for r in mis if r.get("weakly_correlated")]
        if weak:
            pg.para("Weakly correlated bands (EP1843295 claims 9–11): "
                    + "; ".join(f"{_e(r['pair'])} was not used to restore the line of sight (its radiometry "
                                f"correlates poorly with the visible bands); it is corrected with the attitude "
                                f"restored from the visible pairs and measured against {_e(r['reference_band'])} on "
                                f"gradient-magnitude images (edges coincide where the radiometry is inverted): "
                                f"{_fmt(r['before_px'])} px before, {_fmt(r['after_px'])} px after as measured "
                                f"(matching noise {_fmt(r['after_noise_px'])} px), {_fmt(r['after_signal_px'])} px "
                                f"with the noise removed" for r in weak) + ".")
        if any(np.isfinite(r["attitude_total_px"]) for r in mis):
            pg.para("With truth, the misregistration that the restored attitude's error leaves, e(t + τ) − e(t) "
                    "(pitch error along track, roll error across): "
                    + "; ".join(f"{_e(r['pair'])} {_fmt(r['attitude_line_px'])} / {_fmt(r['attitude_col_px'])} px "
                                f"(line / column), {_fmt(r['attitude_total_px'])} px 2-D" for r in mis) + ".")
        if any(np.isfinite(r.get("true_attitude_px", np.nan)) for r in mis):
            pg.para("Control, with truth: the same measurement (same points, same matcher) on bands corrected with "
                    "the true attitude, i.e. what a perfect restoration would measure: "
                    + "; ".join(f"{_e(r['pair'])} {_fmt(r['true_attitude_px'])} px against {_fmt(r['after_px'])} px "
                                f"with the restored attitude" for r in mis)
                    + ". Where the two agree, what the image measurement shows after correction is its own floor "
                      "(cross-band matching noise, resampling), not misregistration left by the attitude.")
        link = pg.csv("misregistration.csv", {k: [r[k] for r in mis] for k in mis[0]})
        pg.para(f"Data: {link}", "files")
    elif run.restoration is not None:
        why = (" (image correction disabled: restoration.correct_images = false)"
               if run.settings.get("correct_images") is False else "")
        pg.note(_e(f"No band-to-band misregistration in restoration.nc{why}."))


def _scene_section(pg: _Page, run: D.RunData, mode: str, timeout_s: float, report_notes: list):
    pg.section("scene", "3-D scene: terrain and band footprints")
    try:
        scene = D.scene_geometry(run)
    except Exception as e:  # geometry failure must not sink the report
        pg.note(_e(f"Footprints could not be computed ({type(e).__name__}: {e})."))
        return
    names = list(scene["footprints"])
    rows = {"band": [], "x_m": [], "y_m": [], "z_m": []}
    for b, g in scene["footprints"].items():
        rows["band"] += [b] * len(g)
        rows["x_m"] += list(g[:, 0])
        rows["y_m"] += list(g[:, 1])
        rows["z_m"] += list(g[:, 2])
    link = pg.csv("footprints.csv", rows)
    why = ""
    done = False
    if mode in ("auto", "pyvista"):
        png = pg.out_dir / "scene3d.png"
        try:
            _render_pyvista_subprocess(scene, png, timeout_s=timeout_s)
            pg.png_file(png, f"Terrain ({scene['dem_source']}, vertical ×{scene['z_exaggeration']:.1f}) and the "
                             f"ground footprints of {', '.join(names)} by the product's sensor model (knowledge "
                             "attitude), rendered with PyVista off screen.")
            done = True
        except Exception as e:
            why = f"PyVista rendering failed ({type(e).__name__}: {str(e).strip().splitlines()[-1] if str(e).strip() else ''})"
    elif mode == "matplotlib":
        why = "matplotlib requested"
    if not done and mode != "none":
        fig, ax = RP.scene_figure_mpl()
        RP.draw_scene_mpl(ax, scene, note="matplotlib fallback")
        if why and mode != "matplotlib":
            pg.note(_e(why + "; drawn with matplotlib instead."))
            report_notes.append(why)
        pg.figure(fig, "scene3d.png", f"Terrain ({scene['dem_source']}, vertical ×{scene['z_exaggeration']:.1f}) "
                                      f"and the ground footprints of {', '.join(names)} (matplotlib 3-D"
                                      f"{'' if mode == 'matplotlib' else ', fallback'}).", width=900)
    pg.para(f"Footprint outlines (m, local frame): {link}", "files")


def _render_pyvista_subprocess(scene: dict, png: Path, *, timeout_s: float):
    """Render with PyVista in a child process (a VTK crash or hang cannot take the report down)."""
    root = Path(__file__).resolve().parents[1]
    with tempfile.TemporaryDirectory(prefix="simsat_scene_") as tmp:
        npz = Path(tmp) / "scene.npz"
        arrays = {"x": scene["x"], "y": scene["y"], "z": scene["z"],
                  "z_exaggeration": np.array(scene["z_exaggeration"])}
        arrays.update({f"fp_{b}": g for b, g in scene["footprints"].items()})
        np.savez(npz, **arrays)
        out = Path(tmp) / "scene.png"
        env = dict(os.environ)
        env["PYTHONPATH"] = str(root) + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
        r = subprocess.run([sys.executable, "-m", "reports.report_plots", str(npz), str(out)], cwd=str(root),
                           env=env, capture_output=True, text=True, timeout=timeout_s)
        if r.returncode != 0 or not out.exists() or out.stat().st_size == 0:
            msg = (r.stderr or r.stdout or "").strip().splitlines()
            msg = [m for m in msg if m.strip()]
            raise RuntimeError(msg[-1] if msg else f"exit status {r.returncode}")
        atomic_write_bytes(out.read_bytes(), png)


# ----------------------------------------------------------------------------- entry point
def make_run_report(run_dir, *, out_dir=None, integrator: Callable | None = None, scene_3d: str = "auto",
                    max_integration_s: float = 120.0, pyvista_timeout_s: float = 90.0,
                    progress: bool = False) -> Path:
    """Write the HTML report of a run.

    Parameters
    ----------
    run_dir : path
        Run directory (``product.nc`` required; ``restoration.nc``, ``truth.nc``,
        ``run.json`` used when present).
    out_dir : path, optional
        Report directory (default ``RUN_DIR/report``); receives ``index.html``,
        the PNGs, the CSVs of the plotted data and ``report.json``.
    integrator : callable, optional
        Integration function with the signature of
        ``restore.integration.integrate`` (default: that function when
        importable). Re-run to probe the transfer function and split the error
        budget; without one those parts are reduced (the page says so).
    scene_3d : {"auto", "pyvista", "matplotlib", "none"}
        3-D view renderer; ``auto`` tries PyVista off screen (child process)
        and falls back on matplotlib.
    max_integration_s : float
        Skip re-running the integration when the run's own timings predict it
        would take longer than this [s].
    pyvista_timeout_s : float
        Time limit of the PyVista child process [s].
    progress : bool
        Say each stage on stderr as it starts (the report takes tens of seconds on full products).

    Returns
    -------
    Path
        Path of ``index.html``.
    """
    if scene_3d not in ("auto", "pyvista", "matplotlib", "none"):
        raise ValueError(f"scene_3d: must be auto, pyvista, matplotlib or none; got {scene_3d!r}")
    if is_frames_run(run_dir):  # a matrix detector's frames: their own, shorter report
        return make_frames_report(run_dir, out_dir=out_dir)
    t_start = _time.perf_counter()
    run_dir = Path(run_dir)
    out = Path(out_dir) if out_dir is not None else run_dir / "report"
    timings = {}

    def stage(name: str) -> None:
        if progress:
            print(f"report: {name} ({_time.perf_counter() - t_start:.1f} s)", file=sys.stderr, flush=True)

    stage("reading the run")
    t = _time.perf_counter()
    run = D.load_run(run_dir)  # refuses an invalid run before anything is written
    timings["load_s"] = _time.perf_counter() - t
    out.mkdir(parents=True, exist_ok=True)
    integrate, why_not = D.get_integrator(integrator)
    if run.restoration is not None and integrate is None:
        run.notes.append(f"The integration cannot be re-run ({why_not}): the transfer is analytic and the budget "
                         "is given at the differential level.")
    sc = D.scenario_summary(run)
    hd = D.headline(run)
    pg = _Page(out)
    report_notes: list = []

    stage("attitude and headline")
    t = _time.perf_counter()
    _attitude_section(pg, run, sc, hd)
    timings["attitude_s"] = _time.perf_counter() - t
    stage("spectra")
    t = _time.perf_counter()
    f_max = _spectra_section(pg, run, sc)
    timings["spectra_s"] = _time.perf_counter() - t
    stage("transfer functions (re-runs the integration)")
    t = _time.perf_counter()
    _transfer_section(pg, run, sc, f_max, integrate, why_not, max_integration_s, report_notes)
    timings["transfer_s"] = _time.perf_counter() - t
    stage("error budget")
    t = _time.perf_counter()
    bud = _budget_section(pg, run, integrate, max_integration_s)
    timings["budget_s"] = _time.perf_counter() - t
    stage("predicted uncertainty")
    _uncertainty_section(pg, run, sc)
    stage("matches")
    t = _time.perf_counter()
    _matches_section(pg, run)
    timings["matches_s"] = _time.perf_counter() - t
    stage("3-D scene")
    t = _time.perf_counter()
    _scene_section(pg, run, scene_3d, pyvista_timeout_s, report_notes)
    timings["scene_s"] = _time.perf_counter() - t
    body = pg.parts
    # summary goes first: build it separately
    top = _Page(out)
    _summary_section(top, run, sc, hd, report_notes)
    timings["total_s"] = _time.perf_counter() - t_start

    summary_tab = {"axis": list(D.AXES)}
    keys = sorted({k for a in D.AXES for k in hd["axes"][a] if k != "restored"})
    for k in keys:
        summary_tab[k] = [hd["axes"][a].get(k, float("nan")) for a in D.AXES]
    summary_tab["restored"] = [int(hd["axes"][a].get("restored", False)) for a in D.AXES]
    link = top.csv("summary.csv", summary_tab)
    report_json = {"run_dir": str(run_dir), "scenario": sc, "headline": hd,
                   "budget": bud.get("rows", []) if bud else [], "timings": timings,
                   "notes": run.notes + report_notes,
                   "generated": datetime.now(timezone.utc).isoformat(timespec="seconds")}
    atomic_write_json(report_json, out / "report.json", sort_keys=False)
    nav = " ".join(f'<a href="#{a}">{_e(ti)}</a>' for a, ti in pg.toc)
    gen = datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    page = ["<!DOCTYPE html>", '<html lang="en"><head><meta charset="utf-8">',
            f"<title>simsat report — {_e(sc['name'])}</title>", f"<style>{CSS}</style></head><body>",
            f"<h1>simsat run report — {_e(sc['name'])}</h1>",
            f'<p class="meta">Run <code>{_e(run_dir.resolve())}</code> · generated {gen} in '
            f"{timings['total_s']:.1f} s · files: product.nc{', restoration.nc' if run.restoration is not None else ''}"
            f"{', truth.nc' if run.truth is not None else ''} · summary data: {link}, "
            f'<a href="report.json">report.json</a></p>',
            f"<nav>{nav}</nav>"] + top.parts + body + [
            '<p class="meta">Report timings: ' + ", ".join(f"{k} {v:.2f} s" for k, v in timings.items()) + "</p>",
            "</body></html>"]
    index = out / "index.html"
    atomic_write_bytes("\n".join(page).encode("utf-8"), index)
    return index
