"""A 2-D matrix detector taking successive overlapping frames (EP1843295 fig. 1).

The matrix has ``rows`` rows of ``pixels`` columns; every row is exposed at the
same time, one frame every ``frame_period`` (``[acquisition] frame_period_ms``),
each frame integrating over the instrument's line period (its exposure). Row 0
is the forward-most (it sees a ground point first, like a detector ahead on a
push-broom focal plane); row ``r`` sits at the along-track focal-plane position
``along_m + ((rows − 1) / 2 − r) · pitch``. Successive frames overlap when the
ground advances by fewer rows than the matrix has in a frame period: a ground
point at row ``r`` of frame k is at about row ``r + s`` of frame k + 1, ``s =
v T / GSD``. In the product the frames are the ``line`` dimension (one time per
frame), the rows a ``row`` dimension.

Pure NumPy geometry (exact, no iteration: a frame has a single time): direct
location of (row, column) pixels of a frame, and its inverse, the (row,
column) at which a frame sees ground points.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from .instrument import Detector
from .sensor_model import intersect_dem, los_body

__all__ = ["row_along_m", "row_detector", "frame_direct_location", "frame_inverse_location",
           "frame_sensitivities", "rows_per_frame", "render_frames"]


def row_along_m(det: Detector, rows) -> np.ndarray:
    """Along-track focal-plane position [m] of (fractional) matrix rows (row 0 forward-most)."""
    return det.along_m + ((det.rows - 1) / 2.0 - np.asarray(rows, dtype=np.float64)) * det.pitch_m


def row_detector(det: Detector, row: int) -> Detector:
    """Row ``row`` of a matrix as a single-line detector (what the push-broom renderer draws)."""
    return replace(det, along_m=float(row_along_m(det, row)), rows=1, tdi_stages=1)


def _pointing(sm, t, attitude):
    t = np.asarray(t, dtype=np.float64)
    return sm.platform.pointing(t, *attitude(t)), sm.platform.position(t)


def frame_direct_location(sm, det: Detector, t: float, rows, cols, *, attitude=None, dem=None) -> np.ndarray:
    """Ground points (…, 3) [m] seen by pixels (rows, cols) of the frame taken at ``t`` [s]."""
    att = attitude or sm.attitude
    rows, cols = np.broadcast_arrays(np.asarray(rows, dtype=np.float64), np.asarray(cols, dtype=np.float64))
    r, s = _pointing(sm, np.array([t]), att)
    b = los_body(sm.instrument.focal_length_m, row_along_m(det, rows), det.focal_plane_y(cols))
    d = np.einsum("ij,...j->...i", r[0], b)
    return intersect_dem(dem or sm.dem, np.broadcast_to(s[0], d.shape), d)


def frame_inverse_location(sm, det: Detector, t: float, ground, *, attitude=None):
    """(rows, cols) at which the frame taken at ``t`` [s] sees ground points (…, 3) [m]."""
    att = attitude or sm.attitude
    g = np.asarray(ground, dtype=np.float64)
    r, s = _pointing(sm, np.array([t]), att)
    b = np.einsum("ji,...j->...i", r[0], g - s[0])  # Rᵀ (g − S)
    f = sm.instrument.focal_length_m
    x = f * b[..., 0] / (-b[..., 2])
    y = f * b[..., 1] / (-b[..., 2])
    rows = (det.rows - 1) / 2.0 - (x - det.along_m) / det.pitch_m
    return rows, det.column_of_y(y)


def frame_sensitivities(sm, det: Detector, t: float, ground, *, attitude=None, step_rad: float = 1e-6) -> np.ndarray:
    """∂(row, column)/∂(roll, pitch, yaw) [px/rad] of ground points in the frame at ``t``, shape (…, 2, 3)."""
    from .sensor_model import offset_attitude

    att = attitude or sm.attitude
    g = np.asarray(ground, dtype=np.float64)
    out = np.empty(g.shape[:-1] + (2, 3))
    for k in range(3):
        dp = [0.0, 0.0, 0.0]
        dp[k] = step_rad
        rp, cp = frame_inverse_location(sm, det, t, g, attitude=offset_attitude(att, *dp))
        dp[k] = -step_rad
        rm, cm = frame_inverse_location(sm, det, t, g, attitude=offset_attitude(att, *dp))
        out[..., 0, k] = (rp - rm) / (2 * step_rad)
        out[..., 1, k] = (cp - cm) / (2 * step_rad)
    return out


def rows_per_frame(platform, det: Detector, focal_length_m: float, frame_period_s: float) -> float:
    """Nominal ground advance between frames, in matrix rows (``v T / GSD``)."""
    gsd = platform.altitude_m * det.pitch_m / focal_length_m
    return platform.ground_speed_m_s * frame_period_s / gsd


def render_frames(renderer, det: Detector, frame_times: np.ndarray, *, progress=None) -> np.ndarray:
    """Radiance (frames, rows, columns) float32 of a matrix detector: every row at every frame time.

    ``progress(n)`` is called after each row with the number of frames it rendered.
    """
    t = np.asarray(frame_times, dtype=np.float64)
    out = np.empty((len(t), det.rows, det.pixels), dtype=np.float32)
    try:
        for r in range(det.rows):
            out[:, r, :] = renderer.render_block(row_detector(det, r), t)
            if progress is not None:
                progress(len(t))
    finally:
        renderer.stop_prefetch()  # the frames path calls render_block itself: end the prefetch here
    return out
