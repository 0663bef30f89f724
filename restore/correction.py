"""Image correction with the restored attitude, and band-to-band misregistration.

Each band is resampled to the geometry it would have had under the smooth
*knowledge* attitude: output pixel (l, c) shows the ground point
``G = direct_location(band, l, c, knowledge)``, read in the raw image at
``inverse_location(band, G, restored)``. After correction, bands are related by
the knowledge geometry alone, so matching them at knowledge predictions
measures what misregistration is left.
"""
from __future__ import annotations

import numpy as np

__all__ = ["resampling_grid", "correct_bands", "misregistration", "per_line_shift_rms"]


def resampling_grid(product, band: str, restored, *, column_step: int = 16):
    """Raw-image coordinates (lines, cols) of every pixel of the corrected band.

    The mapping is computed exactly (sensor model) on every line and every
    ``column_step``-th column, and interpolated linearly in between (it is
    smooth across the field).
    """
    det = product.instrument.detector(band)
    n_lines = product.time.size
    cols = np.unique(np.r_[np.arange(0, det.pixels, column_step), det.pixels - 1]).astype(np.float64)
    sm_k = product.sensor_model()
    from simsat.product import clamped_attitude
    sm_r = product.sensor_model(attitude=clamped_attitude(restored))
    L, C = np.meshgrid(np.arange(n_lines, dtype=np.float64), cols, indexing="ij")
    g = sm_k.direct_location(band, L, C)
    rl, rc = sm_r.inverse_location(band, g)
    full_c = np.arange(det.pixels, dtype=np.float64)
    # linear interpolation across columns, vectorised over lines
    idx = np.clip(np.searchsorted(cols, full_c, side="right") - 1, 0, len(cols) - 2)
    w = (full_c - cols[idx]) / (cols[idx + 1] - cols[idx])
    out_l = rl[:, idx] * (1 - w) + rl[:, idx + 1] * w
    out_c = rc[:, idx] * (1 - w) + rc[:, idx + 1] * w
    return out_l, out_c


def correct_bands(product, *, restored, valid=None, column_step: int = 16):
    """All bands resampled to the knowledge geometry (cubic spline interpolation).

    Returns an xarray Dataset with ``image_<band>`` float32 (NaN outside the
    raw image or where the attitude was not restored).
    """
    import xarray as xr
    from scipy.ndimage import map_coordinates

    data = {}
    for name in product.band_names:
        img = product.image(name)
        rl, rc = resampling_grid(product, name, restored, column_step=column_step)
        inside = (rl >= 0) & (rl <= img.shape[0] - 1) & (rc >= 0) & (rc <= img.shape[1] - 1)
        out = map_coordinates(img.astype(np.float64), [np.nan_to_num(rl), np.nan_to_num(rc)], order=3,
                              mode="nearest", prefilter=True).astype(np.float32)
        out[~inside] = np.nan
        if valid is not None:
            out[~np.asarray(valid, bool)] = np.nan
        dims = ("line", "column") if len({d.pixels for d in product.instrument.detectors}) == 1 else ("line", f"column_{name}")
        data[f"image_{name}"] = (dims, out, {"units": "DN", "long_name": f"{name} resampled to the knowledge geometry "
                                                                         "with the restored attitude"})
    return xr.Dataset(data, coords={"time": ("line", product.time, {"units": "s"})},
                      attrs={"title": "simsat corrected images"})


def per_line_shift_rms(lines, res_l, res_c, n_lines: int, *, min_points: int = 5) -> dict:
    """RMS over lines of the per-line mean residual (line and column), in px."""
    lines = np.asarray(lines, dtype=np.int64)
    res_l = np.asarray(res_l, dtype=np.float64)
    res_c = np.asarray(res_c, dtype=np.float64)
    ok = np.isfinite(res_l) & np.isfinite(res_c)
    # mismatches are not misregistration: reject points beyond 3 robust σ of the residuals
    # around their line's median (the same rule as the instant synthesis)
    for r in (res_l, res_c):
        med = _line_median(lines, r, ok, n_lines)
        dev = r - med[np.clip(lines, 0, n_lines - 1)]
        s = 1.4826 * np.nanmedian(np.abs(dev[ok])) if ok.any() else np.nan
        ok &= np.abs(dev) <= 3 * max(s, 1e-3)
    lines, res_l, res_c = lines[ok], res_l[ok], res_c[ok]
    n = np.bincount(lines, minlength=n_lines)
    sl = np.bincount(lines, res_l, minlength=n_lines)
    sc = np.bincount(lines, res_c, minlength=n_lines)
    m = n >= min_points
    if not m.any():
        return {"line_px": float("nan"), "col_px": float("nan"), "total_px": float("nan"), "lines": 0}
    ml = sl[m] / n[m]
    mc = sc[m] / n[m]
    ml = ml - ml.mean()
    mc = mc - mc.mean()
    # matching noise left in a per-line mean: within-line scatter / sqrt(n)
    sl2 = np.bincount(lines, res_l ** 2, minlength=n_lines)
    sc2 = np.bincount(lines, res_c ** 2, minlength=n_lines)
    var_l = (sl2[m] / n[m] - (sl[m] / n[m]) ** 2) / np.maximum(n[m] - 1, 1)
    var_c = (sc2[m] / n[m] - (sc[m] / n[m]) ** 2) / np.maximum(n[m] - 1, 1)
    noise = float(np.sqrt(np.mean(np.clip(var_l, 0, None) + np.clip(var_c, 0, None))))
    total = float(np.sqrt(np.mean(ml ** 2 + mc ** 2)))
    return {"line_px": float(np.sqrt(np.mean(ml ** 2))), "col_px": float(np.sqrt(np.mean(mc ** 2))),
            "total_px": total, "noise_px": noise, "net_px": float(np.sqrt(max(total ** 2 - noise ** 2, 0.0))),
            "lines": int(m.sum())}


def _line_median(lines, values, ok, n_lines):
    """Median of ``values`` per line (NaN where a line has no value)."""
    med = np.full(n_lines, np.nan)
    li = lines[ok]
    v = values[ok]
    if li.size == 0:
        return med
    order = np.lexsort((v, li))
    li, v = li[order], v[order]
    starts = np.flatnonzero(np.r_[True, li[1:] != li[:-1]])
    ends = np.r_[starts[1:], li.size]
    mid_lo = v[(starts + ends - 1) // 2]
    mid_hi = v[(starts + ends) // 2]
    med[li[starts]] = 0.5 * (mid_lo + mid_hi)
    return med


def misregistration(product, corrected, pairs, settings) -> dict:
    """Band-to-band misregistration of each pair before and after correction.

    Both are measured with the same points and the same matcher: raw bands
    against knowledge predictions (before), corrected bands against the same
    predictions (after). The figure is the RMS over lines of the per-line mean
    shift (the jitter-induced misregistration; per-point matching noise is
    averaged out within each line).
    """
    from .matching import match_points

    sm = product.sensor_model()
    out = {}
    n_lines = product.time.size
    for p in pairs:
        v = p.valid & np.isfinite(p.meas_line_b)
        la, ca = p.line_a[v], p.col_a[v]
        if la.size == 0:
            continue
        g = sm.direct_location(p.ahead, la, ca)
        pl, pc = sm.inverse_location(p.behind, g)
        before = per_line_shift_rms(np.rint(la), p.meas_line_b[v] - pl, p.meas_col_b[v] - pc, n_lines)
        ia = np.asarray(corrected[f"image_{p.ahead}"].values)
        ib = np.asarray(corrected[f"image_{p.behind}"].values)
        ok = np.isfinite(ia[np.clip(np.rint(la).astype(int), 0, ia.shape[0] - 1), np.clip(np.rint(ca).astype(int), 0, ia.shape[1] - 1)])
        m = match_points(np.nan_to_num(ia), np.nan_to_num(ib), la[ok], ca[ok], pl[ok], pc[ok], window=settings.window,
                         search=settings.search, method=settings.match_method, min_quality=settings.min_quality)
        good = np.asarray(m.valid, bool)
        after = per_line_shift_rms(np.rint(la[ok][good]), m.line_b[good] - pl[ok][good], m.col_b[good] - pc[ok][good],
                                   n_lines)
        out[p.name] = {"before_px": before["total_px"], "after_px": after["total_px"],
                       "after_noise_px": after["noise_px"], "after_net_px": after["net_px"],
                       "before_line_px": before["line_px"], "before_col_px": before["col_px"],
                       "after_line_px": after["line_px"], "after_col_px": after["col_px"], "lines": after["lines"]}
    return out
