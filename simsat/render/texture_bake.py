"""The scene's prefiltered texture, baked once per process and reused by later renders.

Synthesising the procedural ground texture costs about as much CPU as the ray
intersection itself (``simsat bench render``). A study renders the same ground
many times (other jitter, other noise, other seeds of the restoration), so the
renderer keeps the prefiltered tiles it synthesised in a process-wide store,
keyed by a fingerprint of everything a tile depends on: the texture's own
parameters, the sun irradiance grid, the prefilter kernel, the tile grid. A tile
taken from the store is the very array a fresh synthesis gives, so a render is
byte for byte the same whether its texture was baked or not.

The store lives in memory only and is off in a one-shot run (``simsat run``
renders its ground once: baking would only hold memory). Where renders repeat
— the points of a study (a Dask worker keeps the store across the points it
runs), ``simsat bench render`` — :func:`enable_bake` turns it on with a bound
(1024 MiB by default); least recently used tiles are dropped first. The
environment variable ``SIMSAT_TEXTURE_BAKE_MB`` overrides the bound everywhere
(0 turns baking off, also in studies).
"""
from __future__ import annotations

import hashlib
import os
import threading
from collections import OrderedDict

import numpy as np

__all__ = ["TileStore", "TILE_STORE", "enable_bake", "texture_fingerprint", "array_fingerprint", "bake_key"]


class TileStore:
    """Thread-safe least-recently-used store of read-only arrays, bounded in bytes.

    Parameters
    ----------
    max_bytes : int
        Capacity; an array larger than it is never kept. 0 disables the store.
    """

    def __init__(self, max_bytes: int):
        self.max_bytes = int(max_bytes)
        self._items: "OrderedDict[tuple, np.ndarray]" = OrderedDict()
        self._bytes = 0
        self._lock = threading.Lock()

    @property
    def nbytes(self) -> int:
        """Bytes held now."""
        return self._bytes

    def __len__(self) -> int:
        return len(self._items)

    def get(self, key):
        """The array stored under ``key``, or None."""
        if key is None:
            return None
        with self._lock:
            arr = self._items.get(key)
            if arr is not None:
                self._items.move_to_end(key)
            return arr

    def put(self, key, arr: np.ndarray) -> None:
        """Keep ``arr`` (made read-only) under ``key``, dropping the oldest entries beyond capacity."""
        if key is None or arr.nbytes > self.max_bytes:
            return
        arr.setflags(write=False)
        with self._lock:
            old = self._items.pop(key, None)
            if old is not None:
                self._bytes -= old.nbytes
            self._items[key] = arr
            self._bytes += arr.nbytes
            while self._bytes > self.max_bytes:
                _, dropped = self._items.popitem(last=False)
                self._bytes -= dropped.nbytes

    def clear(self) -> None:
        """Drop everything."""
        with self._lock:
            self._items.clear()
            self._bytes = 0


#: Bound of the store where :func:`enable_bake` turns it on [MiB].
DEFAULT_BAKE_MIB = 1024


def _capacity_from_env() -> int | None:
    raw = os.environ.get("SIMSAT_TEXTURE_BAKE_MB")
    if raw is None:
        return None
    try:
        mb = float(raw)
    except ValueError:
        raise ValueError(f"SIMSAT_TEXTURE_BAKE_MB: expected a number of MiB, got {raw!r}") from None
    if not np.isfinite(mb) or mb < 0:
        raise ValueError(f"SIMSAT_TEXTURE_BAKE_MB: must be ≥ 0, got {raw!r}")
    return int(mb * 2 ** 20)


#: The process-wide store the renderer uses (off until :func:`enable_bake`, unless the environment says).
TILE_STORE = TileStore(_capacity_from_env() or 0)


def enable_bake(mib: float = DEFAULT_BAKE_MIB) -> TileStore:
    """Turn the process-wide store on with a bound of ``mib`` MiB (the environment variable, when set, wins)."""
    env = _capacity_from_env()
    TILE_STORE.max_bytes = env if env is not None else int(mib * 2 ** 20)
    return TILE_STORE


def array_fingerprint(a) -> str:
    """A digest of an array's dtype, shape and bytes."""
    a = np.ascontiguousarray(a)
    h = hashlib.sha256()
    h.update(str((a.dtype.str, a.shape)).encode())
    h.update(memoryview(a).cast("B"))    # the buffer itself, not a copy
    return h.hexdigest()


def texture_fingerprint(texture) -> str | None:
    """What identifies a texture's ``grid`` output, or None when it cannot be known (then nothing is baked).

    A texture may say it itself (a ``fingerprint()`` method); otherwise None.
    """
    fn = getattr(texture, "fingerprint", None)
    if fn is None:
        return None
    fp = fn()
    return None if fp is None else str(fp)


def bake_key(texture_fp: str | None, irradiance, cloud_irradiance: float, kernel: np.ndarray,
             grid: tuple) -> str | None:
    """The store key of a renderer's tiles (without the tile index), or None when not bakeable.

    ``grid`` holds the tile grid (texel size, across-track origin and size,
    along-track tile length): anything that changes which texels a tile holds.
    """
    if texture_fp is None:
        return None
    h = hashlib.sha256()
    h.update(texture_fp.encode())
    if irradiance is None:
        h.update(b"no-irradiance")
    else:
        h.update(str((float(irradiance.x0_m), float(irradiance.y0_m), float(irradiance.dx_m),
                      float(irradiance.dy_m))).encode())
        h.update(array_fingerprint(np.asarray(irradiance.z)).encode())
    h.update(repr(float(cloud_irradiance)).encode())
    h.update(array_fingerprint(np.asarray(kernel, dtype=np.float64)).encode())
    h.update(repr(tuple(float(g) for g in grid)).encode())
    return h.hexdigest()
