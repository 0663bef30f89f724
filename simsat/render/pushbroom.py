"""Push-broom rendering with Mitsuba 3.

For every line time and detector pixel, rays leave the platform along the
pixel's line of sight under the *true* attitude at that instant, are
intersected with the terrain mesh (``scene.ray_intersect``) and shaded from a
multi-band Dr.Jit texture holding reflectance × sun irradiance.

Sampling of the integration:

* time: ``time_subsamples`` instants evenly spread inside the line period
  (centred on the line time), each with its own attitude and platform
  position — jitter of hundreds of Hz blurs and displaces the image;
* space: ``spatial_subsamples``² rays per pixel inside its focal-plane
  footprint, or (``spatial_subsamples = 1``) an equivalent prefiltering of the
  ground texture by the pixel footprint (a box of one ground sample);
* optics: the Gaussian PSF (from the MTF at Nyquist) is applied as a ground
  prefilter of the texture.

Precision (docs/design.md, "Numerical pitfalls"): lines of sight, attitudes and
platform positions are computed in float64 on the host in the local frame
centred on the scene; each ray is started ``lift_m`` above the highest terrain
along its float64 path before being handed to Mitsuba in float32.

Rendering proceeds in blocks of lines so memory stays bounded whatever the
image length; the texture is generated strip by strip for the ground each
block sees.
"""
from __future__ import annotations

import time as _time
from dataclasses import dataclass, field, replace

import numpy as np

from . import choose_variant
from .scene import build_terrain_scene
from .texture_bake import TILE_STORE, bake_key, texture_fingerprint
from ..sensor_model import los_body

__all__ = ["RenderStats", "PushbroomRenderer", "ground_prefilter_kernel"]


@dataclass
class RenderStats:
    rays: int = 0
    intersect_s: float = 0.0
    texture_s: float = 0.0
    texture_synthesis_s: float = 0.0
    texture_strip_s: float = 0.0
    prefilter_s: float = 0.0
    raygen_s: float = 0.0
    shade_s: float = 0.0
    wall_s: float = 0.0
    blocks: int = 0
    variant: str = ""
    misses: int = 0
    baked_tiles: int = 0
    extra: dict = field(default_factory=dict)

    @property
    def rays_per_s(self) -> float:
        return self.rays / self.wall_s if self.wall_s > 0 else float("nan")


def _box_kernel(width: float) -> np.ndarray:
    """1-D box of (fractional) ``width`` samples, unit sum, odd length, centred."""
    if width <= 1.0:
        return np.array([1.0])
    half = width / 2.0
    n = int(np.ceil(half - 0.5))
    x = np.arange(-n, n + 1, dtype=np.float64)
    # overlap of [x-0.5, x+0.5] with [-half, half]
    w = np.clip(np.minimum(x + 0.5, half) - np.maximum(x - 0.5, -half), 0.0, 1.0)
    return w / w.sum()


def _gauss_kernel(sigma: float) -> np.ndarray:
    if sigma <= 1e-3:
        return np.array([1.0])
    n = int(np.ceil(4 * sigma))
    x = np.arange(-n, n + 1, dtype=np.float64)
    g = np.exp(-0.5 * (x / sigma) ** 2)
    return g / g.sum()


def ground_prefilter_kernel(*, box_texels: float, psf_sigma_texels: float) -> np.ndarray:
    """Separable 1-D prefilter: box (pixel aperture) ⊛ Gaussian (optics PSF)."""
    return np.convolve(_box_kernel(box_texels), _gauss_kernel(psf_sigma_texels))


class PushbroomRenderer:
    """Render a scenario's acquisition.

    Parameters
    ----------
    platform : simsat.platform.Platform
    instrument : simsat.instrument.Instrument
    dem : simsat.terrain.Dem
        The true terrain.
    texture : object
        Has ``bands`` (sequence of names), ``texel_m`` and
        ``grid(x0_m, y0_m, texel_m, nx, ny, *, ground_irradiance=None, cloud_irradiance=1.0)
        -> (nbands, ny, nx)`` reflectance (× irradiance when given).
    attitude : callable
        True attitude ``attitude(t) -> (roll, pitch, yaw)`` [rad].
    irradiance : simsat.terrain.Dem-like or None
        Sun irradiance factor on the DEM grid (``height(x, y)`` bilinear); None
        = uniform illumination of 1. It shades the ground, not the clouds.
    cloud_irradiance : float
        Irradiance factor of cloud tops (horizontal, above the relief's
        shading and shadows): flat-ground sun + sky light.
    lift_m : float
        Height above the highest terrain where rays start (float32 hand-off).
    tile_store : simsat.render.texture_bake.TileStore, optional
        Where prefiltered texture tiles are baked for later renders of the
        same ground (default: the process-wide store).
    """

    def __init__(self, *, platform, instrument, dem, texture, attitude, irradiance=None, lift_m: float = 2000.0,
                 texel_m: float | None = None, cloud_irradiance: float = 1.0, tile_store=None):
        self.variant = choose_variant()
        import mitsuba as mi  # noqa: F401  (variant set)

        self.platform = platform
        self.instrument = instrument
        self.dem = dem
        self.texture = texture
        self.attitude = attitude
        self.irradiance = irradiance
        self.cloud_irradiance = float(cloud_irradiance)
        self.lift_m = float(lift_m)
        self.texel_m = float(texel_m or getattr(texture, "texel_m", 1.0))
        self.scene = build_terrain_scene(dem)
        self.z_lift = float(dem.z_max) + self.lift_m
        self.stats = RenderStats(variant=self.variant)
        self.tile_store = TILE_STORE if tile_store is None else tile_store

    # -- geometry -------------------------------------------------------------
    def _subsample_offsets(self):
        ns = self.instrument.spatial_subsamples
        return (np.arange(ns) + 0.5) / ns - 0.5  # in pixel units, centred

    def _sample_times(self, t_lines: np.ndarray) -> np.ndarray:
        nt = self.instrument.time_subsamples
        te = self.instrument.line_period_s
        off = ((np.arange(nt) + 0.5) / nt - 0.5) * te
        return t_lines[:, None] + off[None, :]  # (L, nt)

    def body_directions(self, det) -> np.ndarray:
        """Body-frame unit LOS of every (column, sub-pixel) of a detector, shape (C, ns², 3)."""
        f = self.instrument.focal_length_m
        off = self._subsample_offsets()
        cols = np.arange(det.pixels, dtype=np.float64)
        ys = det.focal_plane_y(cols[:, None] + off[None, :])  # (C, ns)
        xs = det.along_m + off * det.pitch_m  # (ns,)
        yy = np.repeat(ys[:, None, :], len(off), axis=1)  # (C, ns_x, ns_y)
        xx = np.broadcast_to(xs[None, :, None], yy.shape)
        b = los_body(f, xx, yy)
        return b.reshape(det.pixels, -1, 3)

    def rays(self, det, t_lines: np.ndarray):
        """float64 ray origins (lifted) and directions for a block of lines.

        Returns arrays of shape (L, nt, C, ns², 3).
        """
        ts = self._sample_times(t_lines)
        r = self.platform.pointing(ts.ravel(), *self.attitude(ts.ravel())).reshape(ts.shape + (3, 3))
        s = self.platform.position(ts)  # (L, nt, 3)
        b = self.body_directions(det)  # (C, S, 3)
        d = np.einsum("lnij,csj->lncsi", r, b, optimize=True)
        lift = (s[..., 2][:, :, None, None] - self.z_lift) / (-d[..., 2])
        o = s[:, :, None, None, :] + lift[..., None] * d
        return o, d

    # -- texture strips ---------------------------------------------------------
    def _prefilter_kernel(self) -> np.ndarray:
        te = self.texel_m
        gsd = self.platform.altitude_m * self.instrument.detectors[0].pitch_m / self.instrument.focal_length_m
        psf_sigma_m = self.instrument.psf_sigma_px() * gsd
        box_m = gsd if self.instrument.spatial_subsamples == 1 else 0.0
        return ground_prefilter_kernel(box_texels=box_m / te, psf_sigma_texels=psf_sigma_m / te)

    def _tile(self, k: int) -> np.ndarray:
        """Prefiltered reflectance × irradiance of along-track tile ``k`` (all bands), cached.

        A tile being prefetched (:meth:`_prefetch`) is waited for rather than
        computed twice.
        """
        if k in self._tiles:
            return self._tiles[k]
        fut = self._pending.pop(k, None)
        tex = None if fut is not None else self.tile_store.get(self._bake_key(k))
        if tex is None:
            tex, synth_s, filt_s = fut.result() if fut is not None else self._make_tile(k)
            self.stats.texture_synthesis_s += synth_s
            self.stats.prefilter_s += filt_s
            self.tile_store.put(self._bake_key(k), tex)
        else:
            self.stats.baked_tiles += 1
        # keep only tiles that later blocks may need (the push-broom moves forward)
        for old in [j for j in self._tiles if j < k - 2]:
            del self._tiles[old]
        self._tiles[k] = tex
        return tex

    def _make_tile(self, k: int):
        """Synthesise and prefilter tile ``k`` → (texture, synthesis s, prefilter s); no shared state.

        The tile is synthesised with a margin of the prefilter's half-width on
        every side, filtered, and cropped: since the texture is a function of
        absolute ground coordinates, the mosaic of tiles equals the prefiltered
        texture of the whole scene, and every texel is synthesised and filtered
        once.
        """
        te = self.texel_m
        pad = len(self._kernel) // 2 + 1
        x0 = k * self._tile_nx * te - pad * te
        y0 = self._tile_y0 - pad * te
        nx = self._tile_nx + 2 * pad
        ny = self._tile_ny + 2 * pad
        t0 = _time.perf_counter()
        if self.irradiance is not None:
            # terrain shading lights the ground; cloud tops get the flat-ground irradiance
            xs = x0 + (np.arange(nx) + 0.5) * te
            ys = y0 + (np.arange(ny) + 0.5) * te
            irr = _bilinear_grid(self.irradiance, xs, ys).astype(np.float32)
            tex = np.asarray(self.texture.grid(x0, y0, te, nx, ny, ground_irradiance=irr,
                                               cloud_irradiance=self.cloud_irradiance), dtype=np.float32)
        else:
            tex = np.asarray(self.texture.grid(x0, y0, te, nx, ny), dtype=np.float32)
        t1 = _time.perf_counter()
        if len(self._kernel) > 1:
            import cv2
            kk = self._kernel.astype(np.float32)
            tex = np.stack([cv2.sepFilter2D(np.ascontiguousarray(b), cv2.CV_32F, kk, kk,
                                            borderType=cv2.BORDER_REPLICATE) for b in tex])
        tex = np.ascontiguousarray(tex[:, pad:pad + self._tile_ny, pad:pad + self._tile_nx])
        return tex, t1 - t0, _time.perf_counter() - t1

    def _prefetch(self, k: int) -> None:
        """Start synthesising tile ``k`` in the background (overlaps the blocks that do not need it yet)."""
        if k in self._tiles or k in self._pending:
            return
        baked = self.tile_store.get(self._bake_key(k))
        if baked is not None:
            self._tiles[k] = baked
            self.stats.baked_tiles += 1
            return
        if self._executor is None:
            from concurrent.futures import ThreadPoolExecutor
            self._executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="simsat-texture")
        self._pending[k] = self._executor.submit(self._make_tile, k)

    def _bake_key(self, k: int):
        """Key of tile ``k`` in the process-wide store (:mod:`.texture_bake`), None when not bakeable."""
        if self._bake_prefix is None:
            return None
        return (self._bake_prefix, int(k))

    def _texture_strip(self, x_min: float, x_max: float):
        """Prefiltered texture (nbands, ny, nx) covering [x_min, x_max] and its origin (x0, y0) [m]."""
        te = self.texel_m
        k0 = int(np.floor((x_min - 2 * te) / (self._tile_nx * te)))
        k1 = int(np.floor((x_max + 2 * te) / (self._tile_nx * te)))
        tex = np.concatenate([self._tile(k) for k in range(k0, k1 + 1)], axis=2) if k1 > k0 else self._tile(k0)
        # the next block will most likely need the tile beyond, in the direction the strips move
        # (forward until a strip has been seen to move back)
        step = -1 if self._last_k0 is not None and k0 < self._last_k0 else 1
        self._last_k0 = k0
        self._prefetch(k1 + 1 if step > 0 else k0 - 1)
        x0 = k0 * self._tile_nx * te
        i0 = max(int(np.floor((x_min - x0) / te)) - 2, 0)
        i1 = min(int(np.ceil((x_max - x0) / te)) + 3, tex.shape[2])
        return tex[:, :, i0:i1], x0 + i0 * te, self._tile_y0

    def _setup_tiles(self, y_min: float, y_max: float):
        te = self.texel_m
        self._tile_y0 = float(np.floor(y_min / te)) * te
        self._tile_ny = int(np.ceil((y_max - self._tile_y0) / te)) + 1
        self._tile_nx = max(64, int(round(256.0 / te)))

    # -- rendering ---------------------------------------------------------------
    def _rays_drjit(self, det, t_lines: np.ndarray):
        """Lifted float32 rays built in Dr.Jit from float64 attitude/positions (one fused kernel)."""
        import drjit as dr
        import mitsuba as mi

        F64 = dr.llvm.ad.Float64 if self.variant.startswith("llvm") else dr.cuda.ad.Float64
        U32 = mi.UInt32
        ts = self._sample_times(t_lines).ravel()
        r = self.platform.pointing(ts, *self.attitude(ts)).reshape(-1, 9)
        s = self.platform.position(ts)
        b = self.body_directions(det).reshape(-1, 3)
        n_cs = b.shape[0]
        n = ts.size * n_cs
        idx = dr.arange(U32, n)
        ti = idx // n_cs
        ci = idx - ti * n_cs
        R = [dr.gather(F64, F64(r[:, k]), ti) for k in range(9)]
        B = [dr.gather(F64, F64(b[:, k]), ci) for k in range(3)]
        S = [dr.gather(F64, F64(s[:, k]), ti) for k in range(3)]
        d = [R[3 * i] * B[0] + R[3 * i + 1] * B[1] + R[3 * i + 2] * B[2] for i in range(3)]
        lift = (S[2] - self.z_lift) / (-d[2])
        o = [S[i] + lift * d[i] for i in range(3)]
        ray = mi.Ray3f(mi.Point3f(mi.Float(o[0]), mi.Float(o[1]), mi.Float(o[2])),
                       mi.Vector3f(mi.Float(d[0]), mi.Float(d[1]), mi.Float(d[2])))
        # ground x-extent of the block: edge columns only (cheap), between z_max and z_min
        bb = b.reshape(det.pixels, -1, 3)[[0, -1]].reshape(-1, 3)
        de = np.einsum("tij,cj->tci", r.reshape(-1, 3, 3), bb)
        xs = []
        for z in (self.dem.z_max, self.dem.z_min):
            sz = (s[:, None, 2] - z) / (-de[..., 2])
            xs.append(s[:, None, 0] + sz * de[..., 0])
        xs = np.concatenate([x.ravel() for x in xs])
        return ray, n, (float(xs.min()) - 20.0, float(xs.max()) + 20.0)

    def render_block(self, det, t_lines: np.ndarray) -> np.ndarray:
        """Render lines at times ``t_lines`` for one detector → (L, C) float32 radiance.

        A TDI detector (``tdi_stages`` N > 1) is the mean of its N rows: row
        ``along_m + k pitch`` at ``t − k Te`` (the charge moves with the image;
        the line is dated at its last stage, ``k = 0``).
        """
        if det.tdi_stages > 1:
            te = self.instrument.line_period_s
            acc = None
            for k in range(det.tdi_stages):
                row = replace(det, along_m=det.along_m + k * det.pitch_m, tdi_stages=1)
                img = self.render_block(row, t_lines - k * te)
                acc = img.astype(np.float64) if acc is None else acc + img
            return (acc / det.tdi_stages).astype(np.float32)
        import drjit as dr
        import mitsuba as mi

        if not hasattr(self, "_tiles"):
            self._init_tiles()
        t0 = _time.perf_counter()
        ray, n, (x_min, x_max) = self._rays_drjit(det, t_lines)
        t1 = _time.perf_counter()
        si = self.scene.ray_intersect(ray)
        px, py, valid = si.p.x, si.p.y, si.is_valid()
        # the intersection kernel runs asynchronously (Dr.Jit's thread pool or the GPU) while the
        # host synthesises the texture strip this block needs; then wait for both
        dr.eval(px, py, valid)
        t2 = _time.perf_counter()
        tex, x0, y0 = self._strip_cache(x_min, x_max)
        bi = list(self.texture.bands).index(det.band)
        t3 = _time.perf_counter()
        dr.sync_thread()
        t3b = _time.perf_counter()
        band = tex[bi]
        ny, nx = band.shape
        te = self.texel_m
        dtex = mi.Texture2f(mi.TensorXf(band[:, :, None]), use_accel=False, migrate=False,
                            filter_mode=dr.FilterMode.Linear, wrap_mode=dr.WrapMode.Clamp)
        # texel (j, i) is centred at (x0 + (i + 1/2) te, y0 + (j + 1/2) te): u = (x - x0) / (nx te)
        u = (px - float(x0)) / float(nx * te)
        v = (py - float(y0)) / float(ny * te)
        val = dr.select(valid, dtex.eval(mi.Point2f(u, v))[0], 0.0)
        shape = (len(t_lines), self.instrument.time_subsamples, det.pixels, self.instrument.spatial_subsamples ** 2)
        out = np.array(val, dtype=np.float32).reshape(shape)
        misses = int(n - dr.count(valid)[0]) if hasattr(dr.count(valid), "__getitem__") else int(n - dr.count(valid))
        t4 = _time.perf_counter()
        st = self.stats
        st.rays += n
        st.raygen_s += t1 - t0
        st.intersect_s += (t2 - t1) + (t3b - t3)
        st.texture_s += t3 - t2
        st.shade_s += t4 - t3b
        st.misses += misses
        st.blocks += 1
        # mean over time sub-samples and sub-pixels: (L, nt, C, S) -> (L, C)
        return out.mean(axis=(1, 3))

    def _init_tiles(self):
        self._kernel = self._prefilter_kernel()
        self._tiles = {}
        self._pending = {}
        self._executor = None
        self._last_k0 = None
        self._strip = None
        # across-track extent: every detector's edge columns over the DEM height range (+ margin)
        f = self.instrument.focal_length_m
        ys = []
        t_ref = self.platform.scan.t_ref_s
        for d in self.instrument.detectors:
            for u in (-1.0, d.pixels):
                b = los_body(f, d.along_m, d.focal_plane_y(u))
                ys.append(float(self.platform.nominal_ground_point(t_ref, b, self.dem.z_min)[1]))
        margin = 100.0
        self._setup_tiles(min(ys) - margin, max(ys) + margin)
        self._bake_prefix = None
        if self.tile_store.max_bytes > 0:
            self._bake_prefix = bake_key(texture_fingerprint(self.texture), self.irradiance, self.cloud_irradiance,
                                         self._kernel, (self.texel_m, self._tile_y0, self._tile_ny, self._tile_nx))
        along = [d.along_m + k * (d.rows - 1) / 2 * d.pitch_m for d in self.instrument.detectors for k in (-1, 1)]
        self._band_spread_m = (max(along) - min(along)) / f * self.platform.altitude_m

    def _strip_cache(self, x_min: float, x_max: float):
        """The prefiltered strip for the current block, shared by every detector of the block."""
        st = self._strip
        if st is not None and st[1] <= x_min and x_max <= st[2]:
            return st[0]
        # one strip per block covering all detectors (bands are a few hundred metres apart)
        lo = x_min - self._band_spread_m - 20.0
        hi = x_max + self._band_spread_m + 20.0
        t0 = _time.perf_counter()
        strip = self._texture_strip(lo, hi)
        self.stats.texture_strip_s += _time.perf_counter() - t0
        self._strip = (strip, lo, hi)
        return strip

    def render(self, t_lines: np.ndarray, *, block_lines: int = 256, progress=None) -> dict[str, np.ndarray]:
        """Render every detector at the line times → {name: (L, C) float32 radiance}.

        Holds the whole acquisition in memory; :meth:`render_blocks` streams it.
        """
        out = {d.name: np.empty((len(t_lines), d.pixels), dtype=np.float32) for d in self.instrument.detectors}
        for sl, block in self.render_blocks(t_lines, block_lines=block_lines, progress=progress):
            for name, img in block.items():
                out[name][sl] = img
        return out

    def render_blocks(self, t_lines: np.ndarray, *, block_lines: int = 256, progress=None):
        """Render block after block of lines: yields ``(line slice, {name: (l, C) float32 radiance})``.

        Memory is bounded by one block of every detector, whatever the image length.
        """
        n_blocks = int(np.ceil(len(t_lines) / block_lines))
        try:
            for bi in range(n_blocks):
                t_start = _time.perf_counter()
                sl = slice(bi * block_lines, min(len(t_lines), (bi + 1) * block_lines))
                block = {det.name: self.render_block(det, t_lines[sl]) for det in self.instrument.detectors}
                self.stats.wall_s += _time.perf_counter() - t_start
                if progress is not None:
                    progress(sl.stop - sl.start)
                yield sl, block
        finally:
            self.stop_prefetch()

    def stop_prefetch(self) -> None:
        """End of a render: keep the tiles prefetched and finished (in the bake), drop the rest, stop the thread.

        Does not wait for a tile still being synthesised (the next block that
        would have needed it will not come); the next render starts afresh.
        """
        ex = getattr(self, "_executor", None)
        if ex is not None:
            for k, fut in self._pending.items():
                if fut.done() and fut.exception() is None:
                    self.tile_store.put(self._bake_key(k), fut.result()[0])
            ex.shutdown(wait=False, cancel_futures=True)
            self._executor = None
        if hasattr(self, "_pending"):
            self._pending = {}
            self._last_k0 = None

    def ray_intersect_ceiling(self, det, t_lines: np.ndarray, *, repeats: int = 3) -> float:
        """Raw ``scene.ray_intersect`` throughput [rays/s] on this block's rays (prepared beforehand)."""
        import drjit as dr

        ray, n, _ = self._rays_drjit(det, t_lines)
        dr.eval(ray)
        dr.sync_thread()
        best = np.inf
        for _ in range(repeats):
            t0 = _time.perf_counter()
            si = self.scene.ray_intersect(ray)
            dr.eval(si.p.x, si.p.y, si.is_valid())
            dr.sync_thread()
            best = min(best, _time.perf_counter() - t0)
        return n / best


def _bilinear_grid(grid_dem, xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
    """Bilinear samples of a Dem-like grid on the tensor grid ys × xs (clamped at the edges)."""
    z = np.asarray(grid_dem.z, dtype=np.float64)
    fx = np.clip((xs - grid_dem.x0_m) / grid_dem.dx_m, 0, z.shape[1] - 1.000001)
    fy = np.clip((ys - grid_dem.y0_m) / grid_dem.dy_m, 0, z.shape[0] - 1.000001)
    ix = np.floor(fx).astype(int)
    iy = np.floor(fy).astype(int)
    wx = fx - ix
    wy = fy - iy
    a = z[np.ix_(iy, ix)]
    b = z[np.ix_(iy, ix + 1)]
    c = z[np.ix_(iy + 1, ix)]
    d = z[np.ix_(iy + 1, ix + 1)]
    wx = wx[None, :]
    wy = wy[:, None]
    return (a * (1 - wx) + b * wx) * (1 - wy) + (c * (1 - wx) + d * wx) * wy
