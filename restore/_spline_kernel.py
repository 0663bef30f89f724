"""Compiled (Numba) cubic B-spline sampling for the image correction.

:func:`cubic_spline_resample` equals ``scipy.ndimage.map_coordinates(image,
[rows, cols], order=3, mode="nearest", prefilter=True)`` (to float rounding):
the image is padded by 12 samples at its edges and spline-filtered by SciPy
exactly as ``map_coordinates`` does, then the 4 × 4 cubic B-spline taps are
evaluated here, one output pixel per iteration, spread over threads by rows
(each pixel's value does not depend on the thread count: same bytes on any
number of cores). It is an implementation detail of
:func:`restore.correction.correct_band_block`; the tests compare it with
SciPy.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

#: samples of edge padding before the spline filter (SciPy's own for mode "nearest")
_PAD = 12


@njit(cache=True, inline="always", error_model="numpy")
def _spline_at(coef, x, y):
    """Cubic B-spline value of the coefficients ``coef`` at (x, y) [padded pixels], edges clamped."""
    n_r, n_c = coef.shape
    fx = math.floor(x)
    fy = math.floor(y)
    tx = x - fx
    ty = y - fy
    wx0 = (1.0 - tx) ** 3 / 6.0
    wx1 = (3.0 * tx ** 3 - 6.0 * tx ** 2 + 4.0) / 6.0
    wx2 = (-3.0 * tx ** 3 + 3.0 * tx ** 2 + 3.0 * tx + 1.0) / 6.0
    wx3 = tx ** 3 / 6.0
    wy0 = (1.0 - ty) ** 3 / 6.0
    wy1 = (3.0 * ty ** 3 - 6.0 * ty ** 2 + 4.0) / 6.0
    wy2 = (-3.0 * ty ** 3 + 3.0 * ty ** 2 + 3.0 * ty + 1.0) / 6.0
    wy3 = ty ** 3 / 6.0
    r0 = int(fx) - 1
    c0 = int(fy) - 1
    acc = 0.0
    for a in range(4):
        r = min(max(r0 + a, 0), n_r - 1)
        wa = wx0 if a == 0 else (wx1 if a == 1 else (wx2 if a == 2 else wx3))
        row = 0.0
        for b in range(4):
            c = min(max(c0 + b, 0), n_c - 1)
            wb = wy0 if b == 0 else (wy1 if b == 1 else (wy2 if b == 2 else wy3))
            row += wb * coef[r, c]
        acc += wa * row
    return acc


@njit(cache=True, parallel=True, error_model="numpy")
def _sample(coef, rows, cols, out):
    for i in prange(rows.shape[0]):
        for j in range(rows.shape[1]):
            out[i, j] = _spline_at(coef, rows[i, j], cols[i, j])


def cubic_spline_resample(image: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """Cubic B-spline interpolation of ``image`` at (``rows``, ``cols``) [px], float64.

    Equal to ``map_coordinates(image, [rows, cols], order=3, mode="nearest",
    prefilter=True)``; coordinates must be finite.
    """
    from scipy.ndimage import spline_filter

    padded = np.pad(np.asarray(image, dtype=np.float64), _PAD, mode="edge")
    coef = spline_filter(padded, order=3, output=np.float64, mode="nearest")
    r = np.ascontiguousarray(rows, dtype=np.float64) + _PAD
    c = np.ascontiguousarray(cols, dtype=np.float64) + _PAD
    out = np.empty(r.shape, np.float64)
    _sample(coef, r.reshape(r.shape[0], -1) if r.ndim > 1 else r.reshape(1, -1),
            c.reshape(c.shape[0], -1) if c.ndim > 1 else c.reshape(1, -1),
            out.reshape(out.shape[0], -1) if out.ndim > 1 else out.reshape(1, -1))
    return out


@njit(cache=True, parallel=True, error_model="numpy")
def _sample_nodes(coef, rl_nodes, rc_nodes, idx, w, row_offset, total, n_cols, out):
    """Like :func:`_sample`, the coordinates interpolated linearly from grid nodes on the fly.

    Output pixel (i, j) reads its raw coordinates ``v[i, idx[j]] (1 - w[j]) + v[i, idx[j] + 1] w[j]``
    (``v`` = ``rl_nodes``, ``rc_nodes``; ``rl`` in lines of the whole band, ``row_offset`` the first
    line held in ``coef`` before padding); NaN where they fall outside ``[0, total - 1] x [0, n_cols - 1]``.
    """
    for i in prange(out.shape[0]):
        for j in range(out.shape[1]):
            k = idx[j]
            wj = w[j]
            rl = rl_nodes[i, k] * (1 - wj) + rl_nodes[i, k + 1] * wj
            rc = rc_nodes[i, k] * (1 - wj) + rc_nodes[i, k + 1] * wj
            if not (rl >= 0 and rl <= total - 1 and rc >= 0 and rc <= n_cols - 1):
                out[i, j] = np.nan
                continue
            out[i, j] = _spline_at(coef, rl - row_offset + _PAD, rc + _PAD)


def column_interpolation(node_cols: np.ndarray, pixels: int) -> tuple[np.ndarray, np.ndarray]:
    """Left node index and weight of every column ``0 .. pixels - 1`` between sorted ``node_cols``."""
    node_cols = np.asarray(node_cols, dtype=np.float64)
    full_c = np.arange(pixels, dtype=np.float64)
    idx = np.clip(np.searchsorted(node_cols, full_c, side="right") - 1, 0, len(node_cols) - 2)
    w = (full_c - node_cols[idx]) / (node_cols[idx + 1] - node_cols[idx])
    return idx.astype(np.int64), w


def cubic_spline_resample_nodes(rows_image: np.ndarray, row_offset: int, total_lines: int, rl_nodes: np.ndarray,
                                rc_nodes: np.ndarray, node_cols: np.ndarray, pixels: int) -> np.ndarray:
    """Cubic B-spline resampling of a block whose coordinates are given at grid columns ``node_cols``.

    ``rows_image`` holds the raw lines ``row_offset ..`` of a band of ``total_lines`` lines;
    ``rl_nodes`` (lines of the whole band), ``rc_nodes`` (columns) have shape (l, len(node_cols)).
    Equal to interpolating them linearly to every column, then :func:`cubic_spline_resample` with
    NaN outside the raw band; float32 (l, pixels). Same spline prefilter as ``map_coordinates``.
    """
    from scipy.ndimage import spline_filter

    padded = np.pad(np.asarray(rows_image, dtype=np.float64), _PAD, mode="edge")
    coef = spline_filter(padded, order=3, output=np.float64, mode="nearest")
    idx, w = column_interpolation(node_cols, pixels)
    out = np.empty((rl_nodes.shape[0], int(pixels)), np.float32)
    _sample_nodes(coef, np.ascontiguousarray(rl_nodes, dtype=np.float64),
                  np.ascontiguousarray(rc_nodes, dtype=np.float64), idx, w, float(row_offset),
                  float(total_lines), float(rows_image.shape[1]), out)
    return out
