"""The world the vehicle flies over: a 2-D line map (roads, field edges, shorelines, building outlines)
burnt into a ground albedo, and the reference map a mission would carry.

Everything is generated around the route (a corridor of ``corridor_m`` on each
side) from the scenario seed:

* **fields** — square farm blocks of ``block_m``, each with its own parcel
  grid orientation and parcel size; a parcel's albedo is a hash of its index.
  A parcel border is a map line where the albedo steps by ≥ ``edge_contrast``;
* **roads** — long gently bending polylines ``road_width_m`` wide, dark
  asphalt; the map holds both edges;
* **lakes** — smooth wobbly polygons of dark water; the map holds the shoreline;
* **villages** — clusters of bright-roofed rectangles near the roads;
* **desert stretches** — along-route intervals where the ground is uniform
  sand and the map is empty (the degraded case).

The albedo raster is the map burnt in (OpenCV polygon fill, anti-aliased by
2× super-sampling) over a faint procedural background (simsat's texture, at
``background_weight``) that adds real-looking clutter the map does not hold.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import cv2
import numpy as np
from scipy.spatial import cKDTree

__all__ = ["LineMap", "World", "WorldSpec", "KINDS", "clip_segments_to_box"]

KINDS = ("road_edge", "field_edge", "shoreline", "building")
_SAND = 0.33
_WATER = 0.045
_ROAD = 0.07
_ROOF = 0.42


@dataclass
class LineMap:
    """2-D segments (n, 4) ``x1, y1, x2, y2`` (m) with their kind index into :data:`KINDS`."""

    segments: np.ndarray
    kinds: np.ndarray

    def __len__(self) -> int:
        return len(self.segments)

    def subset(self, mask) -> "LineMap":
        return LineMap(self.segments[mask], self.kinds[mask])

    def near(self, xy, radius_m: float) -> "LineMap":
        """Segments whose midpoint lies within ``radius_m`` (+ half their length) of ``xy``."""
        mid = 0.5 * (self.segments[:, :2] + self.segments[:, 2:])
        half = 0.5 * np.hypot(*(self.segments[:, 2:] - self.segments[:, :2]).T)
        return self.subset(np.hypot(*(mid - np.asarray(xy)[:2]).T) <= radius_m + half)


@dataclass(frozen=True)
class WorldSpec:
    """What the world is made of (see the module docstring)."""

    corridor_m: float = 9000.0
    block_m: float = 5000.0
    field_size_m: tuple = (150.0, 450.0)
    edge_contrast: float = 0.05
    road_spacing_m: float = 4000.0
    road_width_m: float = 9.0
    lakes_per_100km: float = 6.0
    villages_per_100km: float = 8.0
    background_weight: float = 0.35
    deserts: tuple = ()          # ((from_m, to_m), ...) along-route distance intervals


def clip_segments_to_box(seg: np.ndarray, box) -> tuple[np.ndarray, np.ndarray]:
    """Liang–Barsky clipping of segments (n, 4) to ``box = (x0, x1, y0, y1)`` → (clipped, kept mask)."""
    seg = np.asarray(seg, dtype=np.float64).reshape(-1, 4)
    x0, x1, y0, y1 = box
    dx, dy = seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1]
    t0, t1 = np.zeros(len(seg)), np.ones(len(seg))
    keep = np.ones(len(seg), bool)
    for p, q in ((-dx, seg[:, 0] - x0), (dx, x1 - seg[:, 0]), (-dy, seg[:, 1] - y0), (dy, y1 - seg[:, 1])):
        par = np.abs(p) < 1e-12
        keep &= ~(par & (q < 0))
        with np.errstate(divide="ignore", invalid="ignore"):
            r = np.where(par, 0.0, q / np.where(par, 1.0, p))
        t0 = np.where(~par & (p < 0), np.maximum(t0, r), t0)
        t1 = np.where(~par & (p > 0), np.minimum(t1, r), t1)
    keep &= t0 < t1 - 1e-9
    out = np.column_stack([seg[:, 0] + t0 * dx, seg[:, 1] + t0 * dy, seg[:, 0] + t1 * dx, seg[:, 1] + t1 * dy])
    return out[keep], keep


def _road_polygons(roads: list, half_width: float) -> list:
    """Each road as quads (its legs offset by ± half the width) and octagons at its bends (round joins).

    Filled polygons keep the exact width; a thick polyline would round it to whole texels.
    """
    out = []
    for pl in roads:
        d = np.diff(pl, axis=0)
        n = np.column_stack([-d[:, 1], d[:, 0]]) / np.hypot(*d.T)[:, None] * half_width
        for a, b, m in zip(pl[:-1], pl[1:], n):
            out.append(np.array([a + m, b + m, b - m, a - m]))
        ang = np.linspace(0, 2 * np.pi, 16, endpoint=False)
        ring = half_width * np.column_stack([np.cos(ang), np.sin(ang)])
        out += [p + ring for p in pl[1:-1]]
    return out


def _hash01(*ints) -> np.ndarray:
    """Deterministic uniform [0, 1) from integer arrays (splitmix-like)."""
    with np.errstate(over="ignore"):
        return _mix(ints)


def _mix(ints) -> np.ndarray:
    h = np.uint64(0x9E3779B97F4A7C15)
    for k, a in enumerate(ints):
        a = np.asarray(a).astype(np.int64).astype(np.uint64)
        h = h ^ (a + np.uint64(0x9E3779B97F4A7C15) + np.uint64(k * 0x632BE5AB))
        h = (h ^ (h >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        h = (h ^ (h >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        h = h ^ (h >> np.uint64(31))
    return (h >> np.uint64(11)).astype(np.float64) / float(1 << 53)


@dataclass
class World:
    """The generated world around a route (see :func:`World.generate`)."""

    spec: WorldSpec
    seed: int
    route_xy: np.ndarray
    route_s: np.ndarray
    roads: list = field(default_factory=list)       # polylines (k, 2)
    lakes: list = field(default_factory=list)       # polygons (k, 2)
    buildings: list = field(default_factory=list)   # rectangles (4, 2)
    line_map: LineMap | None = None
    background: object = None

    # -- generation ---------------------------------------------------------------
    @classmethod
    def generate(cls, spec: WorldSpec, route_xy: np.ndarray, route_s: np.ndarray, *, seed: int) -> "World":
        """Roads, lakes, villages and the true line map around ``route_xy`` (route distance ``route_s``)."""
        from simsat.terrain.texture import ProceduralTexture

        rng = np.random.default_rng([int(seed), 0x4E41])
        step = max(len(route_xy) // 2000, 1)
        w = cls(spec, int(seed), np.asarray(route_xy)[::step], np.asarray(route_s)[::step])
        w._tree = cKDTree(w.route_xy)
        w.roads = w._make_roads(rng)
        w.lakes = w._make_lakes(rng)
        w.buildings = w._make_villages(rng)
        w.line_map = w._make_line_map()
        w.background = ProceduralTexture(seed=int(seed), bands=["pan"], water_fraction=0.0, urban_fraction=0.0,
                                         forest_fraction=0.15, field_size_m=120.0, workers=2)
        return w

    def _corridor_points(self, rng, n: int, spread: float) -> np.ndarray:
        i = rng.integers(0, len(self.route_xy), n)
        return self.route_xy[i] + rng.uniform(-spread, spread, (n, 2))

    def _make_roads(self, rng) -> list:
        length = float(self.route_s[-1] - self.route_s[0])
        n = max(int(length / self.spec.road_spacing_m), 1)
        roads = []
        for c in self._corridor_points(rng, n, 0.5 * self.spec.corridor_m):
            ang = rng.uniform(0, np.pi)
            pts = [c]
            for sgn in (1.0, -1.0):
                p, a = c.copy(), ang
                side = []
                for _ in range(int(1.6 * self.spec.corridor_m / 700.0)):
                    a += rng.normal(0, math.radians(12))
                    p = p + sgn * rng.uniform(500, 900) * np.array([math.cos(a), math.sin(a)])
                    side.append(p)
                pts = (pts + side) if sgn > 0 else (side[::-1] + pts)
            roads.append(np.array(pts))
        return roads

    def _make_lakes(self, rng) -> list:
        length = float(self.route_s[-1] - self.route_s[0])
        n = int(rng.poisson(self.spec.lakes_per_100km * length / 1e5))
        lakes = []
        for c in self._corridor_points(rng, n, 0.7 * self.spec.corridor_m):
            r0 = rng.uniform(250, 1200)
            a = np.linspace(0, 2 * np.pi, 40, endpoint=False)
            wob = 1 + sum(rng.uniform(-0.18, 0.18) * np.cos(k * a + rng.uniform(0, 6.3)) for k in (2, 3, 5))
            lakes.append(c + (r0 * wob)[:, None] * np.column_stack([np.cos(a), np.sin(a)]))
        return lakes

    def _make_villages(self, rng) -> list:
        length = float(self.route_s[-1] - self.route_s[0])
        n = int(rng.poisson(self.spec.villages_per_100km * length / 1e5))
        out = []
        for c in self._corridor_points(rng, n, 0.6 * self.spec.corridor_m):
            ang = rng.uniform(0, np.pi)
            u = np.array([math.cos(ang), math.sin(ang)])
            v = np.array([-u[1], u[0]])
            for _ in range(int(rng.integers(10, 30))):
                o = c + rng.uniform(-350, 350) * u + rng.uniform(-350, 350) * v
                a, b = rng.uniform(12, 40), rng.uniform(10, 25)
                out.append(np.array([o, o + a * u, o + a * u + b * v, o + b * v]))
        return out

    # -- the albedo function --------------------------------------------------------
    def _block_params(self, bi, bj):
        h = [_hash01(bi, bj, self.seed, k) for k in range(4)]
        theta = h[0] * np.pi
        lo, hi = self.spec.field_size_m
        return theta, lo + (hi - lo) * h[1], lo + (hi - lo) * h[2]

    def parcel_albedo(self, x, y) -> np.ndarray:
        """Albedo of the field parcels at points (no roads, lakes, buildings)."""
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        B = self.spec.block_m
        bi, bj = np.floor(x / B), np.floor(y / B)
        theta, lu, lv = self._block_params(bi, bj)
        c, s = np.cos(theta), np.sin(theta)
        u = c * (x - bi * B) + s * (y - bj * B)
        v = -s * (x - bi * B) + c * (y - bj * B)
        return 0.12 + 0.24 * _hash01(bi, bj, np.floor(u / lu), np.floor(v / lv), self.seed)

    def parcel_albedo_grid(self, xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
        """:meth:`parcel_albedo` on the grid ``xs × ys``, one farm block at a time (block constants hashed once)."""
        B = self.spec.block_m
        out = np.empty((len(ys), len(xs)), np.float32)
        bx, by = np.floor(xs / B), np.floor(ys / B)
        for bi in np.unique(bx):
            ci = np.flatnonzero(bx == bi)
            for bj in np.unique(by):
                cj = np.flatnonzero(by == bj)
                theta, lu, lv = (float(a) for a in self._block_params(np.float64(bi), np.float64(bj)))
                c, s = math.cos(theta), math.sin(theta)
                X = xs[ci][None, :] - bi * B
                Y = ys[cj][:, None] - bj * B
                iu = np.floor((c * X + s * Y) / lu).astype(np.int64)
                iv = np.floor((-s * X + c * Y) / lv).astype(np.int64)
                # hash each parcel once (a block holds a few hundred), then look the texels up
                u0, v0 = iu.min(), iv.min()
                U, V = np.meshgrid(np.arange(u0, iu.max() + 1), np.arange(v0, iv.max() + 1), indexing="ij")
                table = (0.12 + 0.24 * _hash01(bi, bj, U.astype(float), V.astype(float), self.seed)).astype(np.float32)
                out[cj[0]:cj[-1] + 1, ci[0]:ci[-1] + 1] = table[iu - u0, iv - v0]
        return out

    def desert_distance(self, x, y) -> np.ndarray:
        """Along-route distance of the route point nearest to each (x, y) (m)."""
        _, i = self._tree.query(np.column_stack([np.ravel(x), np.ravel(y)]))
        return self.route_s[i].reshape(np.shape(x))

    def in_desert(self, x, y) -> np.ndarray:
        if not self.spec.deserts:
            return np.zeros(np.shape(x), bool)
        s = self.desert_distance(x, y)
        return np.any([(s >= a) & (s <= b) for a, b in self.spec.deserts], axis=0)

    # -- the line map -----------------------------------------------------------------
    def _blocks(self):
        B, c = self.spec.block_m, self.spec.corridor_m
        lo = self.route_xy.min(0) - c
        hi = self.route_xy.max(0) + c
        out = []
        for bi in range(int(math.floor(lo[0] / B)), int(math.floor(hi[0] / B)) + 1):
            for bj in range(int(math.floor(lo[1] / B)), int(math.floor(hi[1] / B)) + 1):
                centre = np.array([(bi + 0.5) * B, (bj + 0.5) * B])
                if self._tree.query(centre)[0] <= c + 0.75 * B:
                    out.append((bi, bj))
        return out

    def _field_edges(self) -> np.ndarray:
        """Parcel borders of every block near the corridor whose albedo step is ≥ ``edge_contrast``."""
        B = self.spec.block_m
        out = []
        for bi, bj in self._blocks():
            theta, lu, lv = (float(np.asarray(a)) for a in self._block_params(np.float64(bi), np.float64(bj)))
            c, s = math.cos(theta), math.sin(theta)
            corners = np.array([[0, 0], [B, 0], [0, B], [B, B]], float)
            uc = c * corners[:, 0] + s * corners[:, 1]
            vc = -s * corners[:, 0] + c * corners[:, 1]
            for (l1, l2, a1, a2, along_u) in ((lu, lv, uc, vc, True), (lv, lu, vc, uc, False)):
                k = np.arange(math.floor(a1.min() / l1) + 1, math.floor(a1.max() / l1) + 1)
                j = np.arange(math.floor(a2.min() / l2), math.floor(a2.max() / l2) + 1)
                kk, jj = np.meshgrid(k, j, indexing="ij")
                kk, jj = kk.ravel().astype(float), jj.ravel().astype(float)
                if along_u:   # lines u = k lu, sides v ∈ [j lv, (j+1) lv]; parcels (k-1, j) | (k, j)
                    alb = [_hash01(bi, bj, kk - 1, jj, self.seed), _hash01(bi, bj, kk, jj, self.seed)]
                    u0, u1, v0, v1 = kk * lu, kk * lu, jj * lv, (jj + 1) * lv
                else:         # lines v = k lv, sides u ∈ [j lu, (j+1) lu]; parcels (j, k-1) | (j, k)
                    alb = [_hash01(bi, bj, jj, kk - 1, self.seed), _hash01(bi, bj, jj, kk, self.seed)]
                    u0, u1, v0, v1 = jj * lu, (jj + 1) * lu, kk * lv, kk * lv
                strong = 0.24 * np.abs(alb[1] - alb[0]) >= self.spec.edge_contrast
                x0 = c * u0 - s * v0 + bi * B
                y0 = s * u0 + c * v0 + bj * B
                x1 = c * u1 - s * v1 + bi * B
                y1 = s * u1 + c * v1 + bj * B
                seg = np.column_stack([x0, y0, x1, y1])[strong]
                seg, _ = clip_segments_to_box(seg, (bi * B, (bi + 1) * B, bj * B, (bj + 1) * B))
                out.append(seg)
        return np.concatenate(out) if out else np.zeros((0, 4))

    def _make_line_map(self) -> LineMap:
        from matplotlib.path import Path as MplPath

        segs, kinds = [], []
        fe = self._field_edges()
        segs.append(fe)
        kinds.append(np.full(len(fe), KINDS.index("field_edge")))
        half = 0.5 * self.spec.road_width_m
        for pl in self.roads:
            d = np.diff(pl, axis=0)
            n = np.column_stack([-d[:, 1], d[:, 0]]) / np.hypot(*d.T)[:, None]
            for sgn in (1.0, -1.0):
                e = np.column_stack([pl[:-1] + sgn * half * n, pl[1:] + sgn * half * n])
                segs.append(e)
                kinds.append(np.full(len(e), KINDS.index("road_edge")))
        for poly in self.lakes:
            e = np.column_stack([poly, np.roll(poly, -1, axis=0)])
            segs.append(e)
            kinds.append(np.full(len(e), KINDS.index("shoreline")))
        for rect in self.buildings:
            e = np.column_stack([rect, np.roll(rect, -1, axis=0)])
            segs.append(e)
            kinds.append(np.full(len(e), KINDS.index("building")))
        seg = np.concatenate(segs)
        kind = np.concatenate(kinds)
        mid = 0.5 * (seg[:, :2] + seg[:, 2:])
        keep = self._tree.query(mid)[0] <= self.spec.corridor_m
        keep &= ~self.in_desert(mid[:, 0], mid[:, 1])
        wet = np.zeros(len(seg), bool)
        for poly in self.lakes:
            wet |= MplPath(poly).contains_points(mid)
        keep &= ~(wet & (kind != KINDS.index("shoreline")))
        return LineMap(seg[keep], kind[keep])

    def reference_map(self, rng: np.random.Generator, *, segment_sigma_m: float, bias_m=(0.0, 0.0),
                      keep_fraction: float = 0.85, min_length_m: float = 40.0) -> LineMap:
        """The map a mission carries: the true lines, some missing, each offset by its own position error.

        Each kept segment is shifted by N(0, ``segment_sigma_m``) in x and y
        (the digitisation error of its source) plus a common ``bias_m``
        (the map's registration error).
        """
        lm = self.line_map
        length = np.hypot(*(lm.segments[:, 2:] - lm.segments[:, :2]).T)
        keep = (rng.uniform(size=len(lm)) < keep_fraction) & (length >= min_length_m)
        seg = lm.segments[keep].copy()
        off = rng.normal(0, segment_sigma_m, (len(seg), 2)) + np.asarray(bias_m, dtype=np.float64)
        seg[:, :2] += off
        seg[:, 2:] += off
        return LineMap(seg, lm.kinds[keep])

    # -- raster ----------------------------------------------------------------------------
    def albedo_grid(self, x0: float, y0: float, texel: float, nx: int, ny: int) -> np.ndarray:
        """Ground albedo (ny, nx) float32 on texels centred at ``(x0 + (i+½) texel, y0 + (j+½) texel)``."""
        xs = x0 + (np.arange(nx) + 0.5) * texel
        ys = y0 + (np.arange(ny) + 0.5) * texel
        # parcels super-sampled 2 × 2 and box-averaged: a border lands where it is, not on the texel grid
        fine = self.parcel_albedo_grid(x0 + (np.arange(2 * nx) + 0.5) * texel / 2,
                                       y0 + (np.arange(2 * ny) + 0.5) * texel / 2)
        alb = cv2.resize(fine, (nx, ny), interpolation=cv2.INTER_AREA)
        del fine
        bg = self.background.grid(x0, y0, texel, nx, ny)[0]
        w = self.spec.background_weight
        alb = (1 - w) * alb + w * (bg - float(bg.mean()) + 0.22)

        def burn(polys, value, *, closed=True, thickness=None):
            if not polys:
                return
            mask = np.zeros((ny, nx), np.uint8)
            pts = [np.round(((p - [x0, y0]) / texel - 0.5) * 16).astype(np.int32) for p in polys]
            if thickness is None:
                cv2.fillPoly(mask, pts, 255, lineType=cv2.LINE_AA, shift=4)
            else:
                cv2.polylines(mask, pts, closed, 255, thickness=max(int(round(thickness)), 1),
                              lineType=cv2.LINE_AA, shift=4)
            m = mask.astype(np.float32) / 255.0
            alb[:] = (1 - m) * alb + m * value

        burn(self.lakes, _WATER)
        burn(_road_polygons(self.roads, 0.5 * self.spec.road_width_m), _ROAD)
        burn(self.buildings, _ROOF)
        if self.spec.deserts:
            step = max(int(round(50.0 / texel)), 1)
            cx, cy = xs[::step], ys[::step]
            CX, CY = np.meshgrid(cx, cy)
            coarse = self.in_desert(CX, CY).astype(np.float32)
            if coarse.any():
                m = cv2.resize(coarse, (nx, ny), interpolation=cv2.INTER_LINEAR)
                sand = _SAND + 0.15 * (bg - float(bg.mean()))
                alb = (1 - m) * alb + m * sand
        return np.clip(alb, 0.01, 1.0).astype(np.float32)
