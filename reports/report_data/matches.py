"""Run report data: matches and misregistration (see :mod:`reports.report_data`)."""
from __future__ import annotations

import json

import numpy as np

from reports.matching_lock import matching_lock
from reports.metrics import attitude_misregistration, misregistration_floor
from simsat.product import ProductError, read_product
from simsat.units import AXES

from .headline import restored_axes
from .loading import RunData

__all__ = ['match_density', 'misregistration_rows', 'misregistration_with_true_attitude', 'matching_lock_of_run',
           'matching_lock_sentence']


def match_density(run: RunData, *, line_bins: int = 200, col_bins: int = 16, max_rejected_points: int = 3000,
                  seed: int = 0) -> dict:
    """Where the matches fell, per pair (in band-A image coordinates).

    Returns
    -------
    dict
        ``{pair: {line_edges, col_edges, inliers (2-D counts, line × column),
        rejected (2-D counts: valid but rejected by the synthesis, or invalid
        match), n_total, n_valid, n_inlier, rejected_lines, rejected_cols
        (valid matches rejected by the synthesis) and failed_lines,
        failed_cols (matches that failed, e.g. low correlation) — random
        subsets of at most ``max_rejected_points`` each, for drawing —,
        gap_intervals (list of (first_line, stop_line) where the pair gave no
        differential), points_per_line (inliers per line), n_lines, n_columns,
        ahead, behind}}``.
    """
    rest = run.restoration
    if rest is None or "match_pair" not in rest:
        return {}
    mp = np.asarray(rest["match_pair"].values)
    la = np.asarray(rest["match_line_a"].values, dtype=np.float64)
    ca = np.asarray(rest["match_col_a"].values, dtype=np.float64)
    valid = np.asarray(rest["match_valid"].values).astype(bool)
    inl = np.asarray(rest["match_inlier"].values).astype(bool)
    n_lines = run.time.size
    rng = np.random.default_rng(seed)
    out = {}
    for j, name in enumerate(run.pairs):
        ahead, behind = name.split("/") if "/" in name else (name, "")
        n_cols = run.image_shapes.get(ahead, (n_lines, max(d.pixels for d in run.product.instrument.detectors)))[1]
        le = np.linspace(0, n_lines, min(line_bins, n_lines) + 1)
        ce = np.linspace(0, n_cols, min(col_bins, n_cols) + 1)
        sel = mp == j
        ok = sel & np.isfinite(la) & np.isfinite(ca)
        hi, _, _ = np.histogram2d(la[ok & inl], ca[ok & inl], bins=(le, ce))
        rej = ok & ~inl
        hr, _, _ = np.histogram2d(la[rej], ca[rej], bins=(le, ce))
        idx = np.flatnonzero(rej & valid)
        if idx.size > max_rejected_points:
            idx = np.sort(rng.choice(idx, max_rejected_points, replace=False))
        idf = np.flatnonzero(rej & ~valid)
        if idf.size > max_rejected_points:
            idf = np.sort(rng.choice(idf, max_rejected_points, replace=False))
        if "diff_points" in rest:
            ppl = np.asarray(rest["diff_points"].values)[j].astype(np.int64)
        else:
            ppl = np.bincount(np.rint(la[ok & inl]).astype(np.int64).clip(0, n_lines - 1), minlength=n_lines)
        gap_mask = np.ones(n_lines, dtype=bool)
        for a in restored_axes(run) or AXES:
            if f"diff_{a}" in rest:
                gap_mask &= ~np.isfinite(np.asarray(rest[f"diff_{a}"].values)[j])
        d = np.diff(np.concatenate([[0], gap_mask.astype(np.int8), [0]]))
        gaps = list(zip(np.flatnonzero(d == 1).tolist(), np.flatnonzero(d == -1).tolist()))
        out[name] = {"line_edges": le, "col_edges": ce, "inliers": hi, "rejected": hr,
                     "n_total": int(sel.sum()), "n_valid": int((sel & valid).sum()), "n_inlier": int((sel & inl).sum()),
                     "n_rejected_valid": int((sel & valid & ~inl).sum()), "n_invalid": int((sel & ~valid).sum()),
                     "rejected_lines": la[idx], "rejected_cols": ca[idx],
                     "failed_lines": la[idf], "failed_cols": ca[idf], "gap_intervals": gaps,
                     "points_per_line": ppl, "n_lines": n_lines, "n_columns": int(n_cols),
                     "ahead": ahead, "behind": behind}
    return out


def misregistration_rows(run: RunData) -> list:
    """Band-to-band misregistration before/after correction (restoration attr ``misregistration``).

    Returns a list of ``{pair, before_px, after_px, before_line_px, before_col_px,
    after_line_px, after_col_px, after_noise_px, after_signal_px,
    after_line_signal_px, after_col_signal_px, lines, improvement}`` (missing
    keys NaN). ``after_px`` is as measured (matching noise of a per-line mean
    included, ``after_noise_px``); ``after_signal_px`` is the split-half
    estimate without that noise (see :func:`restore.correction.per_line_shift_rms`).
    """
    rest = run.restoration
    if rest is None:
        return []
    try:
        mis = json.loads(str(rest.attrs.get("misregistration", "{}")) or "{}")
    except json.JSONDecodeError:
        return []
    rows = []
    keys = ("before_px", "after_px", "before_line_px", "before_col_px", "after_line_px", "after_col_px",
            "after_noise_px", "after_signal_px", "after_line_signal_px", "after_col_signal_px")
    for pair, v in mis.items():
        if not isinstance(v, dict):
            continue
        r = {"pair": pair}
        for k in keys:
            x = v.get(k)
            r[k] = float(x) if isinstance(x, (int, float)) and x is not None else float("nan")
        r["lines"] = int(v.get("lines", 0) or 0)
        r["weakly_correlated"] = bool(v.get("weakly_correlated", False))
        r["reference_band"] = str(v.get("reference_band", ""))
        r["tau_s"] = float(v.get("tau_s", float("nan")) or float("nan"))
        r["improvement"] = r["before_px"] / r["after_px"] if r["after_px"] and r["after_px"] > 0 else float("nan")
        rows.append(r)
    # with truth: the misregistration the restored attitude's error leaves (geometric, noise-free)
    geo = {}
    if run.truth is not None:
        try:
            geo = attitude_misregistration(rest, run.truth, extra_pairs={
                r["pair"]: r["tau_s"] for r in rows if r["weakly_correlated"]})
        except (KeyError, ValueError):
            geo = {}
    for r in rows:
        g = geo.get(r["pair"], {}).get("restored", {})
        for k in ("line_px", "col_px", "total_px"):
            r[f"attitude_{k}"] = float(g.get(k, float("nan")))
    floor = misregistration_with_true_attitude(run) if rows else {}
    for r in rows:
        f = floor.get(r["pair"], {})
        for k in ("px", "line_px", "col_px"):
            r[f"true_attitude_{k}"] = float(f.get(f"after_{k}", float("nan")))
    return rows


def misregistration_with_true_attitude(run: RunData) -> dict:
    """The "after" measurement repeated on bands corrected with the *true* attitude (needs truth).

    Same points (the restoration's valid matches, from ``restoration.nc``),
    same matcher settings: what a perfect restoration would measure, i.e. the
    floor of the image-based measurement. ``{}`` without truth, without
    corrected images, or when it cannot be computed (said in ``run.notes``).
    See :func:`reports.metrics.misregistration_floor`.
    """
    rest = run.restoration
    if run.truth is None or rest is None or not run.has_corrected or "match_pair" not in rest:
        return {}
    if "true_attitude_floor" in run._cache:
        return run._cache["true_attitude_floor"]
    out = {}
    try:
        product = read_product(run.run_dir)
        pairs, settings = run.result.pairs, run.result.settings
        out = misregistration_floor(product, run.truth, pairs, settings)
    except (ProductError, KeyError, ValueError, OSError) as ex:
        run.notes.append(f"misregistration with the true attitude not computed: {ex}")
    run._cache["true_attitude_floor"] = out
    return out


def matching_lock_of_run(run: RunData):
    """The worst pair matched again under the restored and the true attitude
    (:func:`reports.matching_lock.matching_lock`); None without truth or a restoration with matches, or when it
    cannot be computed (said in ``run.notes``)."""
    if run.truth is None or run.result is None or not any(np.size(p.line_a) for p in run.result.pairs):
        return None
    if "matching_lock" in run._cache:
        return run._cache["matching_lock"]
    out = None
    try:
        out = matching_lock(run.product, run.result, run.truth)   # the run's product: no second handle on the file
    except (ProductError, KeyError, ValueError, OSError) as ex:
        run.notes.append(f"matching under the true attitude not computed: {ex}")
    run._cache["matching_lock"] = out
    return out


def matching_lock_sentence(lock) -> str | None:
    """The report's sentence on a :class:`reports.matching_lock.MatchingLock` (None: nothing to say)."""
    if lock is None or not lock.valid_true > 0:
        return None
    verdict = ("the restoration finds what the images allow" if lock.lock >= 0.98 else
               "the restoration loses matches the true geometry keeps: its geometry is off by more than the "
               "search absorbs (a wider restoration.rematch_search_lines / _columns, or another restoration.rematch pass, may find them)")
    return (f"With truth: the worst pair, {lock.pair}, matched again as the last pass matches (band B resampled "
            f"into band A's geometry) finds {lock.valid_restored * 100:.1f} % of its {lock.points} points valid "
            f"under the restored attitude and {lock.valid_true * 100:.1f} % under the true one (lock "
            f"{lock.lock * 100:.1f} %, {lock.lost * 100:.1f} % of the points lost): {verdict}. The points that fail "
            f"under the true attitude fail on the images themselves (the bands' textures differ, weak texture, "
            f"noise); their valid ones are off by {lock.shift_rms_true_px:.2f} px RMS, the matching's own error "
            f"({lock.shift_rms_restored_px:.2f} px under the restored attitude).")

