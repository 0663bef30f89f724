"""Run report data: 3-d scene (see :mod:`reports.report_data`)."""
from __future__ import annotations

import numpy as np

from .loading import RunData

__all__ = ['scene_geometry']


def scene_geometry(run: RunData, *, edge_samples: int = 160, max_dem_side: int = 160, margin_frac: float = 0.15) -> dict:
    """DEM (cropped around the footprints, decimated) and the bands' ground footprints.

    Footprints are the outlines of each band's image on the ground by the
    product's sensor model (knowledge attitude, known DEM):
    ``direct_location(band, lines, cols)`` along the four image edges.

    Returns
    -------
    dict
        ``x``, ``y`` (1-D, m), ``z`` (2-D, m, rows = y); ``footprints``
        {band: (N, 3) closed outline, m}; ``centre_line`` {band: (M, 3) ground
        track of the middle column}; ``z_exaggeration`` (suggested vertical
        exaggeration for drawing).
    """
    p = run.product
    sm = p.sensor_model()
    n_lines = p.time.size
    fps = {}
    centre = {}
    for d in p.instrument.detectors:
        nl = run.image_shapes.get(d.name, (n_lines, d.pixels))[0]
        nc = d.pixels
        ls = np.linspace(0, nl - 1, edge_samples)
        cs = np.linspace(0, nc - 1, max(8, edge_samples // 3))
        lines = np.concatenate([np.zeros(cs.size), ls, np.full(cs.size, nl - 1), ls[::-1], [0]])
        cols = np.concatenate([cs, np.full(ls.size, nc - 1), cs[::-1], np.zeros(ls.size), [0]])
        g = sm.direct_location(d.name, lines, cols)
        fps[d.name] = g
        centre[d.name] = sm.direct_location(d.name, ls, np.full(ls.size, 0.5 * (nc - 1)))
    dem = p.dem
    allp = np.concatenate([g[np.all(np.isfinite(g), axis=1)] for g in fps.values()] or [np.zeros((0, 3))])
    x, y, z = dem.x, dem.y, dem.z
    if allp.size:
        x0, x1 = allp[:, 0].min(), allp[:, 0].max()
        y0, y1 = allp[:, 1].min(), allp[:, 1].max()
        mx = margin_frac * max(x1 - x0, y1 - y0, 10 * dem.dx_m)
        ix = np.flatnonzero((x >= x0 - mx) & (x <= x1 + mx))
        iy = np.flatnonzero((y >= y0 - mx) & (y <= y1 + mx))
        if ix.size >= 2 and iy.size >= 2:
            x, y, z = x[ix], y[iy], z[np.ix_(iy, ix)]
    sx = max(1, int(np.ceil(x.size / max_dem_side)))
    sy = max(1, int(np.ceil(y.size / max_dem_side)))
    x, y, z = x[::sx], y[::sy], np.asarray(z)[::sy, ::sx]
    horiz = max(float(x[-1] - x[0]), float(y[-1] - y[0]), 1.0)
    relief = float(np.ptp(z)) if z.size else 0.0
    ex = 1.0 if relief <= 0 else float(np.clip(0.15 * horiz / relief, 1.0, 20.0))
    return {"x": x, "y": y, "z": z, "footprints": fps, "centre_line": centre, "z_exaggeration": ex,
            "dem_source": "product DEM (known by the ground segment)"}
