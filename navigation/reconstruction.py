"""3-D reconstruction of a line from its 2-D images in several views of known pose (Faugeras, line-based).

Each image line ``l`` back-projects to the plane through the camera centre
``c`` with world normal ``n = R_wc Kᵀ l``; the 3-D line lies in every such
plane. Its direction is the direction most orthogonal to all normals (the
smallest right singular vector of the stacked unit normals); a point of it
solves the planes in least squares. The endpoints are where the rays through
the observed endpoints come closest to the line (the extent covered by the
median of the per-view extremes).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .camera import CameraPose

__all__ = ["Line3D", "reconstruct_line", "backprojection_planes"]


@dataclass
class Line3D:
    """A reconstructed 3-D segment (world, m) and how well the views constrain it."""

    a: np.ndarray
    b: np.ndarray
    rms_px: float          # RMS distance of the re-projected endpoints' lines to the observations
    conditioning: float    # second-smallest / largest singular value of the plane normals (0: degenerate)

    @property
    def direction(self) -> np.ndarray:
        d = self.b - self.a
        return d / np.linalg.norm(d)


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.stack([a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1], a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
                     a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]], -1)


def backprojection_planes(K: np.ndarray, segs: np.ndarray, poses: list[CameraPose]):
    """Unit world normals (n, 3) and offsets (n,) of the planes ``n·X = d`` through each view's segment."""
    segs = np.asarray(segs, dtype=np.float64).reshape(-1, 4)
    one = np.ones(len(segs))
    lines = _cross(np.column_stack([segs[:, :2], one]), np.column_stack([segs[:, 2:], one]))
    R = np.stack([pose.R_wc for pose in poses])
    c = np.stack([pose.c for pose in poses])
    nrm = np.einsum("nij,nj->ni", R, lines @ K)           # R_wc Kᵀ l
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    return nrm, np.einsum("ij,ij->i", nrm, c)


def reconstruct_line(K: np.ndarray, segs: np.ndarray, poses: list[CameraPose]) -> Line3D | None:
    """The 3-D segment seen as ``segs`` (n, 4) px in views ``poses`` (n ≥ 2); None when degenerate."""
    segs = np.asarray(segs, dtype=np.float64).reshape(-1, 4)
    if len(segs) < 2:
        return None
    nrm, d = backprojection_planes(K, segs, poses)
    _, sv, vt = np.linalg.svd(nrm)
    u = vt[-1]
    cond = float(sv[1] / sv[0]) if len(sv) > 1 else 0.0
    if cond < 1e-6:
        return None
    R = np.stack([pose.R_wc for pose in poses])
    c = np.stack([pose.c for pose in poses])
    # a point: the planes plus u·p = u·c₀ (the point of the line nearest the first centre's plane ⊥ u)
    A = np.vstack([nrm, u])
    rhs = np.concatenate([d, [u @ c[0]]])
    p0 = np.linalg.lstsq(A, rhs, rcond=None)[0]
    # endpoints: where the rays through the observed endpoints pass closest to the line (all views at once)
    n = len(segs)
    pix = np.concatenate([np.column_stack([segs[:, :2], np.ones(n)]), np.column_stack([segs[:, 2:], np.ones(n)])])
    rays = np.einsum("nij,nj->ni", np.concatenate([R, R]), pix @ np.linalg.inv(K).T)
    rays /= np.linalg.norm(rays, axis=1, keepdims=True)
    cc = np.concatenate([c, c])
    w = p0 - cc
    b = rays @ u
    den = 1.0 - b * b
    wu, wr = w @ u, np.einsum("ij,ij->i", w, rays)
    s = np.where(den < 1e-12, -wu, (b * wr - wu) / np.where(den < 1e-12, 1.0, den))
    s0 = float(np.median(np.minimum(s[:n], s[n:])))
    s1 = float(np.median(np.maximum(s[:n], s[n:])))
    a, bb = p0 + s0 * u, p0 + s1 * u
    # re-projection check: distance of each observed endpoint to the projected 3-D line (px)
    Rt = np.swapaxes(R, 1, 2)
    xa = np.einsum("ij,nj->ni", K, np.einsum("nij,nj->ni", Rt, a - c))
    xb = np.einsum("ij,nj->ni", K, np.einsum("nij,nj->ni", Rt, bb - c))
    if (xa[:, 2] <= 0).any() or (xb[:, 2] <= 0).any():
        return None
    lines = _cross(xa, xb)
    lines /= np.maximum(np.hypot(lines[:, 0], lines[:, 1]), 1e-12)[:, None]
    res = np.concatenate([np.einsum("ij,ij->i", lines, pix[:n]), np.einsum("ij,ij->i", lines, pix[n:])])
    return Line3D(a, bb, float(np.sqrt(np.mean(np.square(res)))), cond)
