"""Coarse to fine: match again in band B resampled into band A's geometry with a first estimate.

At large amplitude the attitude differential changes by up to a pixel from one
line to the next: band B is sheared and stretched with respect to band A
inside a matching window, the correlation peak blurs, leaves the search area
or is not a peak at all (a third of the matches fail at 7 px peaks, however
the search is centred). A first restoration from the matches that did hold
predicts where B sees the ground of every pixel of A; resampled along that
prediction, B is A's geometry up to the first estimate's error (a few tenths
of a pixel, nearly a translation over a window). Matching A against it with a
small search and mapping the match back through the same prediction gives the
position in B, to be synthesised like any other match.

:func:`geometry_map` and :func:`resample_to_reference` are pure NumPy/SciPy;
:func:`rematch_pair` wires them to a pair.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.ndimage import map_coordinates, maximum_filter

from .matching import match_points
from .result import PairData

__all__ = ["geometry_map", "resample_to_reference", "read_map", "map_back", "rematch_pair", "REMATCH_COLUMN_STEP",
           "RESAMPLE_ORDER"]

#: the prediction is computed every this many columns and interpolated in between (it is smooth across a line)
REMATCH_COLUMN_STEP = 16


def geometry_map(sm, ahead: str, behind: str, n_lines: int, n_cols: int, *, column_step: int = REMATCH_COLUMN_STEP
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Where band ``behind`` sees the ground of every pixel of band ``ahead`` under ``sm``'s attitude.

    Returns
    -------
    (map_line, map_col) : ndarray (n_lines, n_cols), float32
        Position in ``behind`` [px] of pixel (line, column) of ``ahead``; NaN
        where the ground is not seen.
    """
    cols = np.unique(np.r_[np.arange(0, n_cols, max(int(column_step), 1)), n_cols - 1]).astype(np.float64)
    li = np.repeat(np.arange(n_lines, dtype=np.float64), cols.size)
    ci = np.tile(cols, n_lines)
    pl, pc = sm.inverse_location(behind, sm.direct_location(ahead, li, ci))
    full = np.arange(n_cols, dtype=np.float64)
    out = []
    for p in (pl.reshape(n_lines, cols.size), pc.reshape(n_lines, cols.size)):
        # linear interpolation along each line: position of every column between two computed ones
        k = np.clip(np.searchsorted(cols, full, side="right") - 1, 0, cols.size - 2)
        w = (full - cols[k]) / (cols[k + 1] - cols[k])
        out.append(((1 - w) * p[:, k] + w * p[:, k + 1]).astype(np.float32))
    return out[0], out[1]


#: spline order of the resampling of B (:func:`resample_to_reference`)
RESAMPLE_ORDER = 5


def resample_to_reference(image_b: np.ndarray, map_line: np.ndarray, map_col: np.ndarray, *,
                          order: int = RESAMPLE_ORDER) -> np.ndarray:
    """Band B resampled at the mapped positions: B in A's geometry; NaN outside B or near its no-data pixels.

    An interpolating B-spline of ``order`` (SciPy's prefiltered
    :func:`~scipy.ndimage.map_coordinates`), exact for polynomials up to that
    degree. Not OpenCV's bicubic: its kernel (Keys, ``a = −0.75``) does not
    reproduce a linear ramp (at a fractional offset of 0.05 px it samples
    0.071 px), its weights are tabulated in 1/32 px, and the resampled band
    is displaced by up to 0.05 px depending on the map's fractional part: on a
    band-limited texture sheared by 1 px over 40 lines, with the exact map,
    the rematched positions were 0.016 px RMS off (gain 1.012 on the shift);
    quintic 0.0002 px.

    No-data pixels (NaN) are filled with the band's median for the prefilter
    (which reaches the whole image) and every output whose ``order + 1``-pixel
    support touches one is NaN.
    """
    img = np.asarray(image_b, dtype=np.float64)
    ml = np.nan_to_num(np.asarray(map_line, dtype=np.float64), nan=-1e6)
    mc = np.nan_to_num(np.asarray(map_col, dtype=np.float64), nan=-1e6)
    bad = ~np.isfinite(img)
    if bad.any():
        img = np.where(bad, np.median(img[~bad]) if (~bad).any() else 0.0, img)
    out = map_coordinates(img, [ml, mc], order=int(order), mode="mirror")
    inside = (ml >= 1) & (ml <= img.shape[0] - 2) & (mc >= 1) & (mc <= img.shape[1] - 2)
    if bad.any():
        near = maximum_filter(bad.astype(np.uint8), size=int(order) + 2)
        inside &= map_coordinates(near, [np.clip(ml, 0, img.shape[0] - 1), np.clip(mc, 0, img.shape[1] - 1)],
                                  order=0, mode="nearest") == 0
    return np.where(inside, out, np.nan).astype(np.float32)


def read_map(m: np.ndarray, lines, cols) -> np.ndarray:
    """A map (line, column) read at fractional positions: cubic Lagrange through the four lines around each
    position (exact for a cubic in the line), linear between columns (the map is computed every
    :data:`REMATCH_COLUMN_STEP` columns and linear in between). Positions outside are clamped to the edge;
    a NaN in the support gives NaN.

    Not bilinear: jitter bends the map from line to line (a 148 Hz line of 1 px at 0.4 ms per line turns
    by 0.05 px per line²), and a linear read between lines at the matched fraction was off by up to
    ``t (1 − t) / 2`` of that, coherently with the shift itself: with a map holding 70 % of a 1 px
    shear over 20 lines, the rematched shift came out with a gain of 0.992 (cubic: 0.998).
    """
    m = np.asarray(m, dtype=np.float64)
    n_l, n_c = m.shape
    li = np.clip(np.asarray(lines, dtype=np.float64), 0.0, n_l - 1.0)
    ci = np.clip(np.asarray(cols, dtype=np.float64), 0.0, n_c - 1.0)
    l0 = np.minimum(np.floor(li).astype(np.int64), n_l - 2) if n_l > 1 else np.zeros(li.shape, np.int64)
    c0 = np.minimum(np.floor(ci).astype(np.int64), n_c - 2) if n_c > 1 else np.zeros(ci.shape, np.int64)
    t = li - l0
    u = (ci - c0)[..., None]
    # Lagrange weights of nodes -1, 0, 1, 2 at t
    w = np.stack([-t * (t - 1) * (t - 2) / 6, (t + 1) * (t - 1) * (t - 2) / 2, -(t + 1) * t * (t - 2) / 2,
                  (t + 1) * t * (t - 1) / 6], axis=-1)
    rows = np.clip(l0[..., None] + np.arange(-1, 3), 0, n_l - 1)
    c1 = np.minimum(c0 + 1, n_c - 1)[..., None]
    vals = (1 - u) * m[rows, c0[..., None]] + u * m[rows, c1]
    if n_l > 1:
        # at the edges, the nodes beyond are clamped: extrapolate them linearly instead (the map is smooth)
        lo, hi = l0[..., None] + np.arange(-1, 3) < 0, l0[..., None] + np.arange(-1, 3) > n_l - 1
        vals = np.where(lo, 2 * vals[..., 1:2] - vals[..., 2:3], vals)
        vals = np.where(hi, 2 * vals[..., 2:3] - vals[..., 1:2], vals)
    return np.sum(w * vals, axis=-1)


def map_back(map_line: np.ndarray, map_col: np.ndarray, lines, cols, *, window_lines: int = 1
             ) -> tuple[np.ndarray, np.ndarray]:
    """Positions in B of fractional positions (lines, cols) of the resampled band (:func:`read_map`).

    A match on raw bands measures the displacement averaged over the window's
    ``window_lines`` rows (the restoration deconvolves that average,
    :func:`restore.synthesis.window_compensation`); a match on the resampled
    band measures only the residual, the rest is the map's. The map is
    therefore averaged over the same rows, ``mean_r [map(l + r) − r]``, so
    that a rematched position means what a raw one means.
    """
    lines = np.asarray(lines, dtype=np.float64)
    cols = np.asarray(cols, dtype=np.float64)
    ok = np.isfinite(lines) & np.isfinite(cols)
    li, ci = np.where(ok, lines, 0.0), np.where(ok, cols, 0.0)
    half = (int(window_lines) - 1) // 2
    out = []
    for k, m in enumerate((map_line, map_col)):
        acc = np.zeros(li.size)
        for r in range(-half, half + 1):
            acc += read_map(m, li + r, ci) - (r if k == 0 else 0.0)
        out.append(np.where(ok, acc / (2 * half + 1), np.nan))
    return out[0], out[1]


def rematch_pair(pair: PairData, image_a: np.ndarray, image_b: np.ndarray, sm, *, window, search, method: str,
                 min_quality: float) -> PairData:
    """The pair's candidates matched again in B resampled with ``sm``'s attitude (the first estimate).

    Returns a new :class:`PairData` with the measured positions (in B's own
    pixels), quality, validity and σ of the new matches; the synthesis of the
    first pass is dropped.
    """
    n_lines, n_cols = image_a.shape
    ml, mc = geometry_map(sm, pair.ahead, pair.behind, n_lines, n_cols)
    bp = resample_to_reference(image_b, ml, mc)
    la, ca = pair.line_a, pair.col_a
    m = match_points(image_a, bp, la, ca, la, ca, window=window, search=search, method=method,
                     min_quality=min_quality)
    lb, cb = map_back(ml, mc, m.line_b, m.col_b, window_lines=window[0])
    valid = np.asarray(m.valid, bool) & np.isfinite(lb) & np.isfinite(cb)
    return replace(pair, meas_line_b=lb, meas_col_b=cb, quality=np.asarray(m.quality, float), valid=valid,
                   std_line=np.asarray(m.std_line, float), std_col=np.asarray(m.std_col, float),
                   corr_line_col=np.asarray(m.corr_line_col, float), pred_line_b=None,
                   pred_col_b=None, inlier=None, synthesis=None)
