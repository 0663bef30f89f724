"""Run report data: error budget (see :mod:`reports.report_data`)."""
from __future__ import annotations

import json
import time as _time
from dataclasses import replace
from typing import Callable

import numpy as np
from scipy.interpolate import CubicSpline

from restore.observability import record_trend
from reports.metrics import axis_yaw_seen, error_stats, unobservable_split
from restore.stages import local_errors as stages_local_errors
from restore.observability import record_observability
from simsat.units import AXES

from .headline import attitude_table, restored_axes
from .loading import RunData

__all__ = ['integration_record', 'line_lags', 'true_differentials', 'measured_differentials', 'axis_integration', 'error_budget', 'local_errors', 'BUDGET_COMPONENTS']


def _truth_interpolant(truth, axis: str):
    """Cubic interpolant of the finely sampled truth (exact at its samples)."""
    t = np.asarray(truth["time"].values, dtype=np.float64)
    return CubicSpline(t, np.asarray(truth[axis].values, dtype=np.float64), extrapolate=False)


def integration_record(run: RunData, axis: str):
    """The pipeline's record of the last integration of ``axis`` (:class:`restore.result.IntegrationRecord`).

    None without restoration, for an axis that was not restored, or when the
    record does not cover every pair of the restoration.
    """
    if run.result is None:
        return None
    rec = run.result.integration.get(axis)
    if rec is None or list(rec.pairs) != run.pairs:
        return None
    return rec


def line_lags(run: RunData, axis: str | None = None) -> np.ndarray | None:
    """Extra delay of each pair at each line of band A [lines] (time synchronisation), as the pipeline used it.

    Band B sees the ground of line ``l`` of A at ``t + τ + λ(l)·Te`` (pitch
    jitter changes the actual delay): the measured differentials are
    ``δ(t + τ + λ Te) − δ(t)``. Read from the integration record of ``axis``
    (default: the first restored axis); (pair, line) or None.
    """
    axes = restored_axes(run)
    rec = integration_record(run, axis or (axes[0] if axes else "roll"))
    if rec is None:
        return None
    return rec.lags_s / rec.line_period_s


def true_differentials(run: RunData, axis: str, *, previous_estimate=None, lags=None) -> tuple:
    """True differentials ``δ(t+τ_j) − δ(t)`` per pair (pair, line) [rad], NaN where the measured one is NaN.

    ``δ = true − knowledge − previous`` is the remaining error the last
    iteration measured. ``previous`` is the estimate of the earlier iterations
    as the pipeline used it: zero where it was not estimated, and, where it
    was, ``previous_estimate`` (known up to a constant, since the restoration
    removes the mean of its final correction) plus a constant ``c``. Between
    lines it is a cubic spline over the line grid (as the pipeline's attitude
    series). ``c`` cancels except on lines whose τ-partner straddles an
    unestimated stretch; it is fitted there by least squares against the
    measured differentials (0 without a previous estimate or without such lines).
    Truth: cubic interpolation of its fine sampling; knowledge: the product's
    series. ``lags`` (pair, line) [lines], e.g. :func:`line_lags`: the far end
    is taken at ``t + τ_j + lag·Te`` (the delay actually seen by the images)
    instead of the nominal ``t + τ_j``.

    Returns
    -------
    dtrue : ndarray (pair, line)
    previous : ndarray (line,) or None
        The previous estimate at line times, as used (zeros where not estimated).
    """
    t = run.time
    ftrue = _truth_interpolant(run.truth, axis)
    kn_series = run.product.knowledge
    k_idx = AXES.index(axis)

    def delta(tt):
        return ftrue(tt) - kn_series.at(tt, outside="nan")[k_idx]

    meas = np.asarray(measured_differentials(run, axis), dtype=np.float64)
    base = np.full(meas.shape, np.nan)
    slope = np.zeros(meas.shape)
    d0 = delta(t)
    sp_r = sp_m = None
    if previous_estimate is not None:
        pe = np.asarray(previous_estimate, dtype=np.float64)
        m = np.isfinite(pe)
        sp_r = CubicSpline(t, np.where(m, pe, 0.0))
        sp_m = CubicSpline(t, m.astype(np.float64))
    for j, tau in enumerate(run.taus):
        t1 = t + tau + (0.0 if lags is None else np.asarray(lags[j], dtype=np.float64) * run.line_period_s)
        b = delta(t1) - d0
        if sp_r is not None:
            b = b - (sp_r(t1) - sp_r(t))
            slope[j] = -(sp_m(t1) - sp_m(t))
        base[j] = np.where(np.isfinite(meas[j]), b, np.nan)
    c = 0.0
    if sp_r is not None:
        ok = np.isfinite(meas) & np.isfinite(base) & (np.abs(slope) > 1e-9)
        den = float(np.sum(slope[ok] ** 2))
        if den > 0:
            c = float(np.sum(slope[ok] * (meas[ok] - base[ok])) / den)
    dtrue = base + c * slope
    prev = None
    if previous_estimate is not None:
        pe = np.asarray(previous_estimate, dtype=np.float64)
        prev = np.where(np.isfinite(pe), pe + c, 0.0)
    return dtrue, prev


def measured_differentials(run: RunData, axis: str) -> list:
    """The run's differentials of ``axis`` per pair as the pipeline integrated them (raw synthesis if unrecorded)."""
    rec = integration_record(run, axis)
    if rec is not None:
        return [d for d in rec.diffs]
    return [m for m in np.asarray(run.restoration[f"diff_{axis}"].values, dtype=np.float64)]


def axis_integration(run: RunData, axis: str) -> dict:
    """The integration the pipeline applied to ``axis``, from its record in ``restoration.nc``.

    Returns
    -------
    dict
        ``options`` (the method's options with a data-estimated prior frozen:
        re-running with them applies the same, fixed filter), ``theta`` (the
        last integration's output), ``frozen`` (bool), ``spectrum`` ({freq,
        psd, noise_std} or None), ``record`` (or None), ``error`` (str).
    """
    rec = integration_record(run, axis)
    if rec is None:
        return {"options": dict(run.settings.get("integration_options") or {}), "theta": None, "frozen": False,
                "spectrum": None, "record": None,
                "error": "restoration.nc has no integration record for this axis (written by an older simsat: "
                         "run `simsat restore` again)"}
    sp = rec.spectrum
    return {"options": rec.frozen_options(), "theta": rec.increment, "frozen": sp is not None,
            "spectrum": None if sp is None else {"freq": sp.freq, "psd": sp.psd, "noise_std": sp.noise_std},
            "record": rec, "error": ""}


def _stats_row(component: str, axis: str, e, ifov: float, note: str = "") -> dict:
    s = error_stats(e, ifov_rad=ifov)
    return {"axis": axis, "component": component, "rms_px": s["rms_px"], "p997_px": s["p997_px"],
            "rms_urad": s["rms_urad"], "p997_urad": s["p997_urad"], "n": s["n"], "note": note}


def _quad_row(component: str, axis: str, total: dict, part: dict, note: str) -> dict:
    row = {"axis": axis, "component": component, "n": total["n"], "note": note}
    for k in ("rms_px", "p997_px", "rms_urad", "p997_urad"):
        a, b = total[k], part[k]
        row[k] = float(np.sqrt(max(a * a - b * b, 0.0))) if np.isfinite(a) and np.isfinite(b) else float("nan")
    return row


BUDGET_COMPONENTS = ("uncorrected knowledge", "unobservable (no pair sees it)", "floor (best linear restoration)",
                     "matching noise", "model / synthesis", "local matching error", "line-common error",
                     "measurement (noise + model)",
                     "integration", "star-tracker anchoring", "total (restored − true)")


def _centred(e):
    e = np.asarray(e, dtype=np.float64)
    m = np.isfinite(e)
    return e - e[m].mean() if m.any() else e


def error_budget(run: RunData, *, integrate: Callable | None = None, seed: int = 0,
                 max_seconds: float = 120.0) -> dict:
    """Error budget per axis (px and µrad, RMS and 99.7 %).

    Components (each an attitude error over the estimated lines, mean removed):

    * **uncorrected knowledge** — knowledge − true;
    * **integration** — the *true* differentials (θ(t+τ) − θ(t) of the true
      remaining error, same gaps) integrated with the run's method, minus the
      true remaining error: what the integration loses with perfect
      differentials (blind frequencies, regularisation, ends, gaps);
    * **measurement (noise + model)** — total − integration: what the errors of
      the measured differentials cost after integration;
    * **matching noise** — white noise with the per-line formal σ of the
      differentials (``diff_sigma_<axis>``, from the scatter of the inlier
      residuals), same gaps, added to the true differentials: integrate(true +
      noise) − integrate(true) (one seeded draw);
    * **model / synthesis** — the part of the measurement error that matching
      noise does not explain: √(measurement² − noise²), per figure;
    * **local matching error** — the differentials' error that is each matched
      point's own, measured without truth by fitting the differentials again
      from two interleaved halves of the swath
      (:func:`restore.local_noise.local_matching_error`): integrate(true +
      local) − integrate(true) (without truth: integrate(measured + local) −
      integrate(measured));
    * **line-common error** — the measurement error the local one does not
      explain, √(measurement² − local²): an error every point of a line shares
      (a band's bias along the scene's large features), which more points do
      not reduce and, where it moves like an attitude, no residual shows;
    * **total** — restored − true (the headline).

    Every re-run goes through the pipeline's own integration step with the
    inputs ``restoration.nc`` recorded (:meth:`restore.result.IntegrationRecord.rerun`:
    time synchronisation with the recorded per-line lags, weights, the
    method's options, the prior a data-adaptive method estimated, frozen, and
    the high-pass), so every component goes through the filter that was
    actually applied. With several iterations the last one is analysed,
    starting from the recorded previous estimate (see :func:`true_differentials`).

    Returns
    -------
    dict
        ``rows`` (list of dicts: axis, component, rms_px, p997_px, rms_urad,
        p997_urad, n, note); ``differential_rows`` (per pair and axis at the
        differential level: matching σ, measured − true, model, in µrad and
        px); ``notes`` (list of str); ``series`` {axis: {component: array}};
        ``seconds``.
    """
    t0 = _time.perf_counter()
    rows: list = []
    drows: list = []
    notes: list = []
    series: dict = {}
    if run.restoration is None:
        return {"rows": rows, "differential_rows": drows, "notes": ["no restoration"], "series": series,
                "seconds": 0.0}
    integrate = _budget_cost_guard(run, integrate, max_seconds, notes)
    rng = np.random.default_rng(seed)
    local = local_errors(run, notes) if integrate is not None else {}
    for a in restored_axes(run):
        ax = _AxisBudget(run, a, integrate is not None, notes)
        noise = ax.noise_draw(rng)
        drows += ax.differential_rows()
        rows += ax.attitude_rows(noise, series, ax.local_draw(local))
    if integrate is None:
        notes.append("attitude-domain propagation (matching noise, model, integration) needs re-running the "
                     "integration; only the differential-level figures are given")
    if run.truth is None:
        notes.append("no truth: only the matching noise can be budgeted")
    return {"rows": rows, "differential_rows": drows, "notes": notes, "series": series,
            "seconds": _time.perf_counter() - t0}


def local_errors(run: RunData, notes: list | None = None) -> dict:
    """``{pair: (lines, 3) array}``: the local part of each pair's differential error
    (:func:`restore.stages.local_errors`), from the matches ``restoration.nc`` records and the sensitivities of
    the product's sensor model (as the pipeline's first synthesis computed them); {} when the file holds no
    matches."""
    res = getattr(run, "result", None)
    if res is None or not res.pairs or run.product is None:
        return {}
    sm = run.product.sensor_model()
    pairs = []
    for p in res.pairs:
        v = np.asarray(p.valid, dtype=bool)
        if p.pred_line_b is None or not v.any():
            continue
        g = sm.direct_location(p.ahead, np.asarray(p.line_a)[v], np.asarray(p.col_a)[v])
        pairs.append(replace(p, sens=sm.sensitivities(p.behind, g)))
    out = stages_local_errors(pairs, res.settings, int(np.asarray(res.time).size))
    if notes is not None and not out:
        notes.append("restoration.nc holds no matches: the local matching error is not budgeted")
    return out


def _budget_cost_guard(run: RunData, integrate, max_seconds: float, notes: list):
    """``integrate``, or None when re-running it (3 calls per axis) would exceed ``max_seconds``."""
    axes = restored_axes(run)
    iterations = int(run.settings.get("iterations") or 1)
    calls = len(axes) * 3
    try:
        tim = json.loads(str(run.restoration.attrs.get("timings", "{}")))
        per_call = float(tim.get("integration_s", 0.0)) / max(1, iterations * max(1, len(axes)))
    except (json.JSONDecodeError, TypeError, ValueError):
        per_call = 0.0
    if integrate is not None and per_call * calls > max_seconds:
        notes.append(f"integration not re-run for the budget: ~{per_call * calls:.0f} s expected "
                     f"(> {max_seconds:.0f} s allowed)")
        return None
    return integrate


class _AxisBudget:
    """The budget of one restored axis: its measured and true differentials and the integration record."""

    def __init__(self, run: RunData, axis: str, rerun: bool, notes: list):
        self.run, self.a, self.notes = run, axis, notes
        rest = run.restoration
        self.att = attitude_table(run)
        self.ifov = run.ifov
        self.mask = np.isfinite(self.att[f"restored_{axis}"])
        self.meas = np.asarray(measured_differentials(run, axis), dtype=np.float64)
        self.sig = (np.asarray(rest[f"diff_sigma_{axis}"].values, dtype=np.float64)
                    if f"diff_sigma_{axis}" in rest else None)
        fz = axis_integration(run, axis)
        if fz["error"]:
            notes.append(f"{axis}: {fz['error']}; budget at the differential level only")
        rec = fz["record"]
        prev = rec.previous if rec is not None and np.any(rec.previous) else None
        self.rec = rec if rerun else None
        if self.rec is not None:
            self._check_reproduced()
        self.dtrue = self.prev_used = self.dlag = None
        if run.truth is not None:
            self.dtrue, self.prev_used = true_differentials(run, axis, previous_estimate=prev)
            lags = line_lags(run)
            if lags is not None:
                self.dlag = true_differentials(run, axis, previous_estimate=prev, lags=lags)[0]

    def _check_reproduced(self) -> None:
        """The recorded inputs must reproduce what the pipeline's integration returned (else: say so)."""
        c = _centred(np.where(self.mask, self.rec.increment, np.nan))
        r = _centred(np.where(self.mask, self.rec.rerun(), np.nan))
        d = (c - r)[np.isfinite(c - r)]
        cc = c[np.isfinite(c)]
        if d.size and cc.size and np.sqrt(np.mean(d ** 2)) > 0.02 * np.sqrt(np.mean(cc ** 2)):
            self.notes.append(f"{self.a}: re-running the integration differs from the restoration's by "
                              f"{np.sqrt(np.mean(d ** 2)) / np.sqrt(np.mean(cc ** 2)) * 100:.0f} % RMS; the split "
                              "between measurement and integration is approximate")

    def noise_draw(self, rng) -> np.ndarray | None:
        """White noise with the per-line formal σ of the differentials (gaps: the median σ), one draw."""
        if self.sig is None:
            return None
        s_ = np.where(np.isfinite(self.meas), self.sig, np.nan)
        fill = np.nanmedian(s_) if np.isfinite(s_).any() else 0.0
        s_ = np.where(np.isfinite(self.meas) & ~np.isfinite(s_), fill, s_)
        return s_ * rng.standard_normal(s_.shape)

    def local_draw(self, local: dict) -> np.ndarray | None:
        """The local matching error of this axis's pairs (record's order; 0 on lines a half does not cover)."""
        if not local or self.rec is None or any(p not in local for p in self.rec.pairs):
            return None
        k = AXES.index(self.a)
        e = np.array([local[p][:, k] for p in self.rec.pairs])
        return np.where(np.isfinite(self.meas), np.nan_to_num(e), np.nan)

    def differential_rows(self) -> list:
        """Per pair: matching σ, measured − true (at the delay the images saw), time sync, model."""
        out = []
        for j, pname in enumerate(self.run.pairs):
            meas = self.meas[j]
            row = {"pair": pname, "axis": self.a, "tau_s": self.run.taus[j], "lines": int(np.isfinite(meas).sum())}
            if self.sig is not None:
                sj = self.sig[j][np.isfinite(meas) & np.isfinite(self.sig[j])]
                row["matching_sigma_urad"] = float(np.sqrt(np.mean(sj ** 2)) * 1e6) if sj.size else float("nan")
            if self.dtrue is not None:
                row.update(self._measurement_error(j))
            for k in list(row):
                if k.endswith("_urad"):
                    row[k.replace("_urad", "_px")] = row[k] * 1e-6 / self.ifov
            out.append(row)
        return out

    def _measurement_error(self, j: int) -> dict:
        """Measured − true differential of pair ``j`` [µrad]: the truth at the delay the images actually saw."""
        meas, dtrue, dlag = self.meas[j], self.dtrue, self.dlag
        ref = dlag if dlag is not None else dtrue
        r = meas - ref[j]
        r = r[np.isfinite(r)]
        row = {}
        if dlag is not None:
            ts = (dlag[j] - dtrue[j])[np.isfinite(meas)]
            ts = ts[np.isfinite(ts)]
            row["time_sync_rms_urad"] = float(np.sqrt(np.mean((ts - ts.mean()) ** 2)) * 1e6) if ts.size \
                else float("nan")
        mm = float(np.sqrt(np.mean((r - r.mean()) ** 2)) * 1e6) if r.size else float("nan")
        row["meas_minus_true_rms_urad"] = mm
        row["meas_minus_true_mean_urad"] = float(r.mean() * 1e6) if r.size else float("nan")
        sig = self.sig
        ms = 0.0
        if sig is not None:
            sj = sig[j][np.isfinite(meas) & np.isfinite(sig[j])]
            ms = float(np.sqrt(np.mean(sj ** 2)) * 1e6) if sj.size else float("nan")
        row["model_rms_urad"] = float(np.sqrt(max(mm * mm - ms * ms, 0.0))) if np.isfinite(mm) else float("nan")
        return row

    def attitude_rows(self, noise, series: dict, local=None) -> list:
        """The attitude-domain rows of this axis (and its series into ``series``). Long: one row after the other,
        with and without truth."""
        a, att, ifov, mask, rec = self.a, self.att, self.ifov, self.mask, self.rec
        rows: list = []
        ser: dict = {}
        series[a] = ser
        have_truth = self.run.truth is not None
        if have_truth:
            rows.append(_stats_row("uncorrected knowledge", a, np.where(mask, att[f"knowledge_{a}"] - att[f"true_{a}"],
                                                                        np.nan), ifov))
        rows += self.observability_rows()
        if rec is None or not have_truth:
            if have_truth:
                rows.append(_stats_row("total (restored − true)", a, att[f"restored_{a}"] - att[f"true_{a}"], ifov))
            elif rec is not None and noise is not None:
                # no truth: integrate(measured + σ·noise) − integrate(measured)
                en = np.where(mask, rec.rerun(self.meas + noise) - rec.rerun(), np.nan)
                rows.append(_stats_row("matching noise", a, en, ifov,
                                       "integrate(measured + σ·noise) − integrate(measured), 1 draw"))
                ser["matching noise"] = en
            if rec is not None and local is not None:
                el = np.where(mask, rec.rerun(self.meas + local) - rec.rerun(), np.nan)
                rows.append(_stats_row("local matching error", a, el, ifov,
                                       "integrate(measured + local) − integrate(measured); local: the scaled "
                                       "difference of two interleaved halves of the swath"))
                ser["local matching error"] = el
            return rows
        # perfect differentials as the images saw them (at t + τ + λ), through the same integration
        dperfect = self.dlag if self.dlag is not None else self.dtrue
        th_true = rec.rerun(dperfect)
        remaining = att[f"delta_{a}"] - (self.prev_used if self.prev_used is not None else 0.0)
        # the smoothing of the knowledge's noise below the high-pass is part of what the integration step gives
        smooth_name = f"knowledge_smoothing_{a}"
        smoothed = smooth_name in self.run.restoration.variables
        given = th_true + (np.asarray(self.run.restoration[smooth_name].values, dtype=np.float64) if smoothed else 0.0)
        # and so is the causal filter's phase taken out of the knowledge (restore.knowledge_dephasing)
        dephase_name = f"knowledge_dephasing_{a}"
        if dephase_name in self.run.restoration.variables:
            given = given + np.asarray(self.run.restoration[dephase_name].values, dtype=np.float64)
        eint = _centred(np.where(mask, given - remaining, np.nan))
        anchored = bool(int(self.run.restoration.attrs.get("anchored_on_star_tracker", 0)))
        total = _centred(att[f"restored_{a}"] - att[f"true_{a}"])
        eanc = None
        if anchored:
            # the star tracker sets the record's trend after the integration (no pair sees it): the integration
            # and the measurement are judged without it, and the trend left is the anchoring's own error
            eint = _centred(eint - record_trend(eint))
            eanc = _centred(record_trend(total - eint))
        emeas = total - eint if eanc is None else total - eint - eanc
        r_noise = None
        if noise is not None:
            en = np.where(mask, rec.rerun(dperfect + noise) - th_true, np.nan)
            if anchored:  # judged like the measurement it is part of: without the trend the anchoring sets
                en = en - record_trend(en)
            r_noise = _stats_row("matching noise", a, en, ifov, "integrate(true + σ·noise) − integrate(true), 1 draw")
            rows.append(r_noise)
            ser["matching noise"] = en
        r_meas = _stats_row("measurement (noise + model)", a, emeas, ifov,
                            "total − integration" + (" − anchoring" if anchored else ""))
        if r_noise is not None:
            rows.append(_quad_row("model / synthesis", a, r_meas, r_noise, "√(measurement² − noise²)"))
        if local is not None:
            el = np.where(mask, rec.rerun(dperfect + local) - th_true, np.nan)
            if anchored:
                el = el - record_trend(el)
            r_local = _stats_row("local matching error", a, el, ifov,
                                 "integrate(true + local) − integrate(true); local: the scaled difference of two "
                                 "interleaved halves of the swath")
            rows.append(r_local)
            rows.append(_quad_row("line-common error", a, r_meas, r_local, "√(measurement² − local²)"))
            ser["local matching error"] = el
        rows.append(r_meas)
        rows.append(_stats_row("integration", a, eint, ifov, "integrate(true differentials) − truth"
                               + (" (the knowledge's noise below the high-pass smoothed)" if smoothed else "")
                               + (", its trend removed (the star-tracker anchoring sets it)" if anchored else "")))
        if eanc is not None:
            rows.append(_stats_row("star-tracker anchoring", a, eanc, ifov,
                                   "the record's trend left by the star-tracker samples' noise"))
            ser["star-tracker anchoring"] = eanc
        rows.append(_stats_row("total (restored − true)", a, total, ifov, "= measurement + integration"
                               + (" + anchoring" if anchored else "")))
        rows += self.band_split_rows(total)
        rows += self.yaw_coupling_rows(total)
        ser.update({"measurement": emeas, "integration": eint, "total": total})
        return rows

    def observability_rows(self) -> list:
        """What no method recovers with these pairs, and the best linear restoration's error, from the product."""
        rec = axis_integration(self.run, self.a)["record"]
        out = []
        if rec is None or not np.isfinite(rec.floor_rms_rad):
            return out
        for comp, v, note in (("unobservable (no pair sees it)", rec.unobservable_rms_rad,
                               "attitude power where the pairs' fused SNR < 1, predicted from the product"),
                              ("floor (best linear restoration)", rec.floor_rms_rad,
                               "Wiener / Cramér-Rao error with the estimated prior and noise")):
            out.append({"axis": self.a, "component": comp, "rms_px": v / self.ifov, "p997_px": float("nan"),
                        "rms_urad": v * 1e6, "p997_urad": float("nan"), "n": 0, "note": note})
        return out

    def _yaw_seen(self):
        """With truth and a material coupling: (coupling, yaw seen as this axis per line [rad]); else (c, None)."""
        return axis_yaw_seen(self.run.restoration.attrs, self.att, self.a)

    def yaw_coupling_rows(self, total) -> list:
        """Tilted, with truth: the part of the pitch (roll) error that is yaw seen as pitch (roll), and the rest."""
        c, yaw_seen = self._yaw_seen()
        if yaw_seen is None:
            return []
        seen = _centred(np.where(np.isfinite(total), yaw_seen, np.nan))
        how = ("off nadir a yaw moves the line along track like a pitch" if self.a == "pitch" else
               "tilted along track a yaw sweeps the line across track like a roll")
        return [_stats_row(f"yaw seen as {self.a}", self.a, seen, self.ifov,
                           f"{c:.3f} × (true − knowledge yaw): {how}; the images cannot tell them apart"),
                _stats_row("total without it", self.a, total - seen, self.ifov, f"total − yaw seen as {self.a}")]

    def band_split_rows(self, total) -> list:
        """With truth: what of the measured total no pair can see (the record's trend, the yaw seen as the axis,
        the blind band up to its predicted power: :func:`reports.metrics.unobservable_split`) and the rest."""
        rec = axis_integration(self.run, self.a)["record"]
        if rec is None:
            return []
        obs = record_observability(rec)
        _, yaw_seen = self._yaw_seen()
        sp = unobservable_split(total, rec.line_period_s, obs.freq, obs.unobservable_band,
                                predicted_band_rms=rec.unobservable_rms_rad, yaw_seen=yaw_seen)
        if not np.isfinite(sp["outside_rms"]):
            return []
        n = int(np.isfinite(total).sum())
        out = []
        for comp, v, note in (
                ("total, record trend", sp["trend_rms"],
                 "offset + slope over the record: constant differentials, like a static band misregistration"),
                ("total, in the unobservable band", sp["band_rms"],
                 "the error's power in the band, at most the predicted unobservable power"),
                ("total, outside the unobservable parts", sp["outside_rms"],
                 f"total − trend − yaw seen as {self.a} − blind band")):
            out.append({"axis": self.a, "component": comp, "rms_px": v / self.ifov, "p997_px": float("nan"),
                        "rms_urad": v * 1e6, "p997_urad": float("nan"), "n": n, "note": note})
        return out
