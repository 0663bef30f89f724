"""Ray casting for frame cameras (perspective views) over the terrain mesh.

The navigation camera builds its rays on the host in float64; this module
re-centres them on a local origin (so that Mitsuba's float32 keeps millimetre
precision over a few kilometres), casts them against the DEM mesh and returns
the hits in float64 world coordinates. Shading stays with the caller: this is
the only place the frame camera touches Mitsuba.
"""
from __future__ import annotations

import time as _time
from dataclasses import dataclass

import numpy as np

from . import choose_variant

__all__ = ["TerrainRayCaster", "RayHits"]


@dataclass
class RayHits:
    """Hits of ``n`` rays: mask, distance (m), world point (n, 3) and the geometric normal (n, 3, z ≥ 0)."""

    valid: np.ndarray
    distance: np.ndarray
    point: np.ndarray
    normal: np.ndarray


class TerrainRayCaster:
    """The DEM as a Mitsuba triangle mesh centred on ``origin`` (world m), ready for perspective rays."""

    def __init__(self, dem, *, origin=None):
        choose_variant()
        import mitsuba as mi

        from .scene import dem_mesh_arrays

        verts, faces = dem_mesh_arrays(dem)
        self.origin = (np.asarray(origin, dtype=np.float64) if origin is not None
                       else np.array([verts[:, 0].mean(), verts[:, 1].mean(), 0.0]))
        local = (verts - self.origin).astype(np.float32)
        mesh = mi.Mesh("terrain", len(verts), len(faces), has_vertex_normals=False, has_vertex_texcoords=False)
        params = mi.traverse(mesh)
        params["vertex_positions"] = mi.Float(local.ravel())
        params["faces"] = mi.UInt32(faces.ravel())
        params.update()
        self.scene = mi.load_dict({"type": "scene", "terrain": mesh})
        self.rays_cast = 0
        self.seconds = 0.0

    def cast(self, origins: np.ndarray, directions: np.ndarray, *, max_distance: float = 1e6) -> RayHits:
        """Intersect rays (float64 world origins (n, 3) or (3,), unit directions (n, 3))."""
        import drjit as dr
        import mitsuba as mi

        t0 = _time.perf_counter()
        d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
        o = np.broadcast_to(np.asarray(origins, dtype=np.float64) - self.origin, d.shape)
        ray = mi.Ray3f(mi.Point3f(*(mi.Float(np.ascontiguousarray(o[:, k], np.float32)) for k in range(3))),
                       mi.Vector3f(*(mi.Float(np.ascontiguousarray(d[:, k], np.float32)) for k in range(3))))
        ray.maxt = float(max_distance)
        si = self.scene.ray_intersect(ray)
        dr.eval(si.t, si.n)
        valid = np.array(si.is_valid(), dtype=bool)
        t = np.array(si.t, dtype=np.float64)
        n = np.stack([np.array(si.n.x), np.array(si.n.y), np.array(si.n.z)], 1).astype(np.float64)
        n *= np.where(n[:, 2:3] < 0, -1.0, 1.0)
        t = np.where(valid, t, np.inf)
        # the hit point recomputed in float64 from the float64 ray (only t comes from float32)
        p = np.asarray(origins, dtype=np.float64) + np.where(valid, t, 0.0)[:, None] * d
        self.rays_cast += len(d)
        self.seconds += _time.perf_counter() - t0
        return RayHits(valid, t, p, n)
