"""Mitsuba scene of the terrain: a triangle mesh of the DEM."""
from __future__ import annotations

import numpy as np

from . import choose_variant

__all__ = ["build_terrain_scene", "dem_mesh_arrays"]


def dem_mesh_arrays(dem) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (n, 3) float64 [m] and faces (m, 3) uint32 of a gridded DEM (two triangles per cell).

    The triangulation splits every cell along the same diagonal; the surface
    coincides with the bilinear DEM at the grid nodes and along cell edges.
    """
    ny, nx = dem.z.shape
    x = dem.x0_m + np.arange(nx) * dem.dx_m
    y = dem.y0_m + np.arange(ny) * dem.dy_m
    xx, yy = np.meshgrid(x, y)
    verts = np.stack([xx.ravel(), yy.ravel(), np.asarray(dem.z, dtype=np.float64).ravel()], axis=1)
    j, i = np.meshgrid(np.arange(ny - 1), np.arange(nx - 1), indexing="ij")
    a = (j * nx + i).ravel()
    b = a + 1
    c = a + nx
    d = c + 1
    faces = np.concatenate([np.stack([a, b, d], 1), np.stack([a, d, c], 1)]).astype(np.uint32)
    return verts, faces


def build_terrain_scene(dem):
    """A Mitsuba scene holding the DEM as one triangle mesh (local frame, metres, float32)."""
    choose_variant()
    import mitsuba as mi

    verts, faces = dem_mesh_arrays(dem)
    mesh = mi.Mesh("terrain", len(verts), len(faces), has_vertex_normals=False, has_vertex_texcoords=False)
    params = mi.traverse(mesh)
    params["vertex_positions"] = mi.Float(verts.astype(np.float32).ravel())
    params["faces"] = mi.UInt32(faces.ravel())
    params.update()
    return mi.load_dict({"type": "scene", "terrain": mesh})
