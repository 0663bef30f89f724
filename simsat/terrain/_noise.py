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
    a = np.asarray(ix).astype(_U32)
    b = np.asarray(iy).astype(_U32)
    h = _mix32(a ^ _U32(salt & 0xFFFFFFFF))
    h = _mix32(h + b * _U32(0x9E3779B9))
    return h


def hash3(ix, iy, iz, salt: int) -> np.ndarray:
    """Hash of three integer coordinates → uint32."""
    h = hash2(ix, iy, salt)
    c = np.asarray(iz).astype(_U32)
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



class Lookup:
    """Elementwise functions of integer indices (i, j), tabulated on a shared box.

    ``Lookup(fns, i_lo, i_hi, j_lo, j_hi, n)`` tabulates each ``fn(i, j)`` on
    ``[i_lo, i_hi] × [j_lo, j_hi]`` when that box is small compared with ``n``
    (the number of texels that will use it); otherwise the functions are called
    directly. Either way the values are bit-identical. A function may return a
    tuple of arrays; outputs are numbered in order over all functions.
    """

    def __init__(self, fns, i_lo: int, i_hi: int, j_lo: int, j_hi: int, n: int, *, max_ratio: float = 4.0):
        self.fns = fns
        self.i0, self.j0 = int(i_lo), int(j_lo)
        self.w = int(i_hi) - self.i0 + 1
        h = int(j_hi) - self.j0 + 1
        self.tabulated = self.w * h <= max_ratio * n + 4096
        if self.tabulated:
            ii = np.arange(self.i0, self.i0 + self.w, dtype=np.int64)[None, :]
            jj = np.arange(self.j0, self.j0 + h, dtype=np.int64)[:, None]
            self.tables = []
            for f in fns:
                r = f(ii, jj)
                for a in (r if isinstance(r, tuple) else (r,)):
                    self.tables.append(np.ascontiguousarray(np.broadcast_to(a, (h, self.w))).ravel())

    @classmethod
    def around(cls, fns, i, j, n: int, *, margin_i: int = 0, margin_j: int = 0) -> "Lookup":
        if np.size(i) == 0:
            return cls(fns, 0, 0, 0, 0, 1)
        return cls(fns, int(np.min(i)) - margin_i, int(np.max(i)) + margin_i,
                   int(np.min(j)) - margin_j, int(np.max(j)) + margin_j, n)

    def index(self, i, j):
        """An opaque index for (i, j) (a flat table index, or the pair itself)."""
        if self.tabulated:
            idx = np.asarray(j) * self.w + np.asarray(i)
            idx -= self.j0 * self.w + self.i0
            return idx
        return np.broadcast_arrays(np.asarray(i, np.int64), np.asarray(j, np.int64))

    def shift_i(self, idx, di):
        """Index of (i + di, j) given the index of (i, j); ``di`` may be an array."""
        if self.tabulated:
            return idx + di
        return (idx[0] + di, idx[1])

    def take(self, k: int, idx):
        """Values of output ``k`` at an index."""
        if self.tabulated:
            return self.tables[k][idx]
        # direct evaluation, memoised per index (the arrays are kept, so ids stay unique)
        key = (id(idx[0]), id(idx[1]))
        memo = self.__dict__.setdefault("_memo", {})
        if key not in memo:
            outs = []
            for f in self.fns:
                r = f(*idx)
                outs.extend(r if isinstance(r, tuple) else (r,))
            memo[key] = (idx, outs)
        return memo[key][1][k]


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

    Notes
    -----
    The grid path (separable: interpolate lattice rows along x, then along y) and
    the points path (four corners per point) perform the same float32 operations
    in the same order, so they agree bit for bit.
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
        L = np.ascontiguousarray(np.broadcast_to(L, (nly, nlx)), dtype=_F32)
        A0 = L[:, lx]
        A = A0 + (L[:, lx + 1] - A0) * wx
        B0 = A[ly]
        return B0 + (A[ly + 1] - B0) * wy
    if table and ix.size:
        look = Lookup.around([lattice_fn], ix, iy, ix.size, margin_i=1, margin_j=1)
        i00 = look.index(ix, iy)
        i01 = look.index(ix, iy + 1)
        l00 = look.take(0, i00)
        l10 = look.take(0, look.shift_i(i00, 1))
        l01 = look.take(0, i01)
        l11 = look.take(0, look.shift_i(i01, 1))
    else:
        l00 = lattice_fn(ix, iy)
        l10 = lattice_fn(ix + 1, iy)
        l01 = lattice_fn(ix, iy + 1)
        l11 = lattice_fn(ix + 1, iy + 1)
    a0 = l00 + (l10 - l00) * wx
    a1 = l01 + (l11 - l01) * wx
    return a0 + (a1 - a0) * wy


def value_noise(c: Coords, cell_m: float, salt: int) -> np.ndarray:
    """Smooth value noise in [-1, 1], feature size ~``cell_m``."""
    return lattice_interp(c, cell_m, signed_lattice(salt))


def fbm(c: Coords, cells_m, gains, salt: int) -> np.ndarray:
    """Fractal sum of value-noise octaves (float32) at ``c``."""
    out = None
    for k, (cell, gain) in enumerate(zip(cells_m, gains)):
        term = value_noise(c, cell, salt + 7919 * k) * _F32(gain)
        out = term if out is None else out + term
    return out


def fbm_points(qx: np.ndarray, qy: np.ndarray, cells_m, gains, salt: int) -> np.ndarray:
    """:func:`fbm` at scattered quantised points."""
    return fbm(Coords(np.asarray(qx, dtype=np.int64), np.asarray(qy, dtype=np.int64), False), cells_m, gains, salt)


def _is_grid(ix, iy) -> bool:
    return ix.ndim == 2 and iy.ndim == 2 and ix.shape[0] == 1 and iy.shape[1] == 1


def fbm_lattice(node_m: float, cells_m, gains, salt: int) -> Callable:
    """Lattice function whose node values are an fBm evaluated at the node positions.

    Called with a row of x indices and a column of y indices (as the grid path of
    :func:`lattice_interp` does), it evaluates the fBm on that grid of nodes with
    the fast separable path; the values equal the point-wise ones bit for bit.
    """
    node_q = int(round(node_m * QUANTA_PER_M))

    def fn(ix, iy):
        ix = np.asarray(ix, dtype=np.int64)
        iy = np.asarray(iy, dtype=np.int64)
        if _is_grid(ix, iy):
            return fbm(Coords(ix * node_q, iy * node_q, True), cells_m, gains, salt)
        ix, iy = np.broadcast_arrays(ix, iy)
        return fbm_points(ix * node_q, iy * node_q, cells_m, gains, salt)
    return fn


class CachedLattice:
    """Memoise an elementwise lattice function ``fn(ix, iy)`` by square blocks of nodes.

    Neighbouring texture tiles need the same coarse nodes (macro land-use fields,
    urban block codes); evaluating them once per block of ``block × block`` nodes
    saves the per-tile overhead. Values are those of ``fn`` itself (it is
    elementwise), so caching cannot change any result. Thread-safe; keeps at most
    ``max_blocks`` blocks (least recently used are dropped).
    """

    def __init__(self, fn: Callable, *, block: int = 64, max_blocks: int = 512):
        import threading
        from collections import OrderedDict
        self.fn = fn
        self.block = int(block)
        self.max_blocks = int(max_blocks)
        self._cache: "OrderedDict[tuple, np.ndarray]" = OrderedDict()
        self._lock = threading.Lock()

    def __getstate__(self):
        return {"fn": self.fn, "block": self.block, "max_blocks": self.max_blocks}

    def __setstate__(self, state):
        self.__init__(state["fn"], block=state["block"], max_blocks=state["max_blocks"])

    def _get(self, bx: int, by: int) -> np.ndarray:
        key = (bx, by)
        with self._lock:
            arr = self._cache.get(key)
            if arr is not None:
                self._cache.move_to_end(key)
                return arr
        b = self.block
        arr = self.fn(np.arange(bx * b, bx * b + b, dtype=np.int64)[None, :],
                      np.arange(by * b, by * b + b, dtype=np.int64)[:, None])
        arr = np.ascontiguousarray(np.broadcast_to(arr, (b, b)))
        arr.setflags(write=False)
        with self._lock:
            self._cache[key] = arr
            while len(self._cache) > self.max_blocks:
                self._cache.popitem(last=False)
        return arr

    def __call__(self, ix, iy):
        ix = np.asarray(ix, dtype=np.int64)
        iy = np.asarray(iy, dtype=np.int64)
        if ix.size == 0 or iy.size == 0:
            return self.fn(ix, iy)
        b = self.block
        bx0, bx1 = int(ix.min()) // b, int(ix.max()) // b
        by0, by1 = int(iy.min()) // b, int(iy.max()) // b
        nbx, nby = bx1 - bx0 + 1, by1 - by0 + 1
        if nbx * nby > self.max_blocks:
            return self.fn(*np.broadcast_arrays(ix, iy))
        region = np.empty((nby * b, nbx * b), dtype=self._get(bx0, by0).dtype)
        for j in range(nby):
            for i in range(nbx):
                region[j * b:(j + 1) * b, i * b:(i + 1) * b] = self._get(bx0 + i, by0 + j)
        return region[iy - by0 * b, ix - bx0 * b]
