"""Deterministic, tile-consistent lattice noise (internal).

Everything here is a pure function of *absolute* ground coordinates, quantised to
``1 / QUANTA_PER_M`` m (integers), so that a texel gets bit-identical values whether
it is computed alone, in a big block or in tiles, and whether the coordinates come
as a regular grid (separable fast path) or as scattered points (gather path).

Only IEEE-exact operations (``+ - * /``, ``floor``, comparisons, ``sqrt``) are used
on per-texel data: transcendental functions may differ between SIMD lanes and the
scalar tail of a loop, which would break bitwise tile consistency.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

QUANTA_PER_M = 1024  # coordinate quantum: 1/1024 m (~1 mm)

_F32 = np.float32
_U32 = np.uint32
_INV24 = _F32(2.0 ** -24)


def quantise(x_m: np.ndarray) -> np.ndarray:
    """Coordinates in m → int64 quanta (round half to even)."""
    return np.rint(np.asarray(x_m, dtype=np.float64) * QUANTA_PER_M).astype(np.int64)


def _mix32(h: np.ndarray) -> np.ndarray:
    """'lowbias32' integer finaliser (Wellons); uint32 in, uint32 out."""
    h = h ^ (h >> _U32(16))
    h = h * _U32(0x7FEB352D)
    h = h ^ (h >> _U32(15))
    h = h * _U32(0x846CA68B)
    h = h ^ (h >> _U32(16))
    return h


def hash2(ix, iy, salt: int) -> np.ndarray:
    """Hash of two integer lattice coordinates (any broadcastable int arrays) → uint32."""
    a = np.asarray(ix).astype(np.int64).astype(_U32)
    b = np.asarray(iy).astype(np.int64).astype(_U32)
    h = _mix32(a ^ _U32(salt & 0xFFFFFFFF))
    h = _mix32(h + b * _U32(0x9E3779B9))
    return h


def hash3(ix, iy, iz, salt: int) -> np.ndarray:
    """Hash of three integer coordinates → uint32."""
    h = hash2(ix, iy, salt)
    c = np.asarray(iz).astype(np.int64).astype(_U32)
    return _mix32(h ^ (c * _U32(0x85EBCA77)))


def unit(h: np.ndarray) -> np.ndarray:
    """uint32 hash → float32 uniform in [0, 1) (24 bits)."""
    return (h >> _U32(8)).astype(_F32) * _INV24


def rehash(h: np.ndarray, k: int) -> np.ndarray:
    """A further independent uint32 draw from a hash."""
    return _mix32(h ^ _U32((0x27D4EB2F * (k + 1)) & 0xFFFFFFFF))


def signed_lattice(salt: int) -> Callable:
    """Lattice value function (ix, iy) → float32 uniform in [-1, 1)."""
    def fn(ix, iy):
        return unit(hash2(ix, iy, salt)) * _F32(2.0) - _F32(1.0)
    return fn


def _weights(q: np.ndarray, cell_q: int, smooth: bool):
    i = q // cell_q
    f = ((q - i * cell_q).astype(np.float64) / cell_q).astype(_F32)
    if smooth:
        f = f * f * (_F32(3.0) - _F32(2.0) * f)
    return i, f


@dataclass
class Coords:
    """Quantised coordinates, either a regular grid or scattered points.

    ``grid=True``: ``qx`` has shape (1, nx), ``qy`` (ny, 1).  ``grid=False``:
    ``qx`` and ``qy`` have the same shape (any).
    """

    qx: np.ndarray
    qy: np.ndarray
    grid: bool

    @property
    def shape(self):
        return np.broadcast_shapes(self.qx.shape, self.qy.shape)

    @property
    def x(self) -> np.ndarray:
        """Coordinates in m (float32; exact for |x| < 16384 m)."""
        return (self.qx.astype(np.float64) / QUANTA_PER_M).astype(_F32)

    @property
    def y(self) -> np.ndarray:
        return (self.qy.astype(np.float64) / QUANTA_PER_M).astype(_F32)

    def shifted(self, dx_m: float, dy_m: float) -> "Coords":
        dqx = int(round(dx_m * QUANTA_PER_M))
        dqy = int(round(dy_m * QUANTA_PER_M))
        return Coords(self.qx + dqx, self.qy + dqy, self.grid)

    def subset(self, mask: np.ndarray) -> "Coords":
        """Points context for the texels where ``mask`` is true (mask has ``shape``)."""
        qx = np.broadcast_to(self.qx, self.shape)[mask]
        qy = np.broadcast_to(self.qy, self.shape)[mask]
        return Coords(qx, qy, False)


def table_lookup(fn: Callable, i: np.ndarray, j: np.ndarray, *, max_ratio: float = 4.0) -> np.ndarray:
    """``fn(i, j)`` for integer index arrays, via a bounding-box table when compact.

    ``fn`` must be elementwise (value depends only on the (i, j) pair), so both
    ways give bit-identical results.
    """
    i = np.asarray(i, dtype=np.int64)
    j = np.asarray(j, dtype=np.int64)
    shape = np.broadcast_shapes(i.shape, j.shape)
    n = int(np.prod(shape)) if shape else 1
    if n == 0:
        return fn(i, j)
    i0, i1 = int(i.min()), int(i.max())
    j0, j1 = int(j.min()), int(j.max())
    size = (i1 - i0 + 1) * (j1 - j0 + 1)
    if size > max_ratio * n + 4096:
        ib, jb = np.broadcast_arrays(i, j)
        return fn(ib, jb)
    ii = np.arange(i0, i1 + 1, dtype=np.int64)[None, :]
    jj = np.arange(j0, j1 + 1, dtype=np.int64)[:, None]
    table = fn(ii, jj)
    return table[j - j0, i - i0]


def lattice_interp(c: Coords, cell_m: float, lattice_fn: Callable, *, smooth: bool = True,
                   table: bool = False) -> np.ndarray:
    """Interpolate lattice values (spacing ``cell_m``, anchored at 0) at ``c``.

    Parameters
    ----------
    c : Coords
    cell_m : float
        Lattice spacing in m (rounded to whole quanta).
    lattice_fn : callable
        ``(ix, iy) -> float32`` for broadcastable int64 lattice indices.
    smooth : bool
        Smoothstep (value noise) or plain bilinear weights.
    table : bool
        For scattered points: evaluate ``lattice_fn`` once on the bounding box of the
        needed nodes when compact (use for expensive lattice functions).
    """
    cell_q = int(round(cell_m * QUANTA_PER_M))
    ix, wx = _weights(c.qx, cell_q, smooth)
    iy, wy = _weights(c.qy, cell_q, smooth)
    if c.grid:
        ix = ix[0]
        wx = wx[0]
        ixs = int(ix.min())
        lx = ix - ixs
        iys = int(iy.min())
        ly = iy[:, 0] - iys
        nlx = int(lx.max()) + 2
        nly = int(ly.max()) + 2
        L = lattice_fn(np.arange(ixs, ixs + nlx, dtype=np.int64)[None, :],
                       np.arange(iys, iys + nly, dtype=np.int64)[:, None])
        L = np.ascontiguousarray(L, dtype=_F32)
        A0 = L[:, lx]
        A = A0 + (L[:, lx + 1] - A0) * wx
        B0 = A[ly]
        return B0 + (A[ly + 1] - B0) * wy
    if table:
        def g(i, j):
            return table_lookup(lattice_fn, i, j)
    else:
        g = lattice_fn
    l00 = g(ix, iy)
    l10 = g(ix + 1, iy)
    l01 = g(ix, iy + 1)
    l11 = g(ix + 1, iy + 1)
    a0 = l00 + (l10 - l00) * wx
    a1 = l01 + (l11 - l01) * wx
    return a0 + (a1 - a0) * wy


def value_noise(c: Coords, cell_m: float, salt: int) -> np.ndarray:
    """Smooth value noise in [-1, 1], feature size ~``cell_m``."""
    return lattice_interp(c, cell_m, signed_lattice(salt))


def fbm_points(qx: np.ndarray, qy: np.ndarray, cells_m, gains, salt: int) -> np.ndarray:
    """Fractal sum of value-noise octaves at scattered quantised points (float32)."""
    c = Coords(np.asarray(qx, dtype=np.int64), np.asarray(qy, dtype=np.int64), False)
    out = None
    for k, (cell, gain) in enumerate(zip(cells_m, gains)):
        term = value_noise(c, cell, salt + 7919 * k) * _F32(gain)
        out = term if out is None else out + term
    return out


def fbm_lattice(node_m: float, cells_m, gains, salt: int) -> Callable:
    """Lattice function whose node values are an fBm evaluated at the node positions."""
    node_q = int(round(node_m * QUANTA_PER_M))

    def fn(ix, iy):
        ix, iy = np.broadcast_arrays(np.asarray(ix, dtype=np.int64), np.asarray(iy, dtype=np.int64))
        return fbm_points(ix * node_q, iy * node_q, cells_m, gains, salt)
    return fn
