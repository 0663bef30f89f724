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


def backprojection_planes(K: np.ndarray, segs: np.ndarray, poses: list[CameraPose]):
    """Unit world normals (n, 3) and offsets (n,) of the planes ``n·X = d`` through each view's segment."""
    segs = np.asarray(segs, dtype=np.float64).reshape(-1, 4)
    p = np.column_stack([segs[:, :2], np.ones(len(segs))])
    q = np.column_stack([segs[:, 2:], np.ones(len(segs))])
    lines = np.cross(p, q)
    nrm = np.stack([pose.R_wc @ (K.T @ l) for pose, l in zip(poses, lines)])
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    d = np.einsum("ij,ij->i", nrm, np.stack([pose.c for pose in poses]))
    return nrm, d


def _ray_line_param(c: np.ndarray, r: np.ndarray, p0: np.ndarray, u: np.ndarray) -> float:
    """Parameter ``s`` on the line ``p0 + s u`` closest to the ray ``c + t r``."""
    w = p0 - c
    b = u @ r
    den = 1.0 - b * b
    if den < 1e-12:
        return float(-(w @ u))
    return float((b * (w @ r) - (w @ u)) / den)


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
    # a point: the planes plus u·p = u·c₀ (the point of the line nearest the first centre's plane ⊥ u)
    A = np.vstack([nrm, u])
    rhs = np.concatenate([d, [u @ poses[0].c]])
    p0 = np.linalg.lstsq(A, rhs, rcond=None)[0]
    Kinv = np.linalg.inv(K)
    lo, hi = [], []
    for pose, s in zip(poses, segs):
        ss = []
        for e in (s[:2], s[2:]):
            r = pose.R_wc @ (Kinv @ np.array([e[0], e[1], 1.0]))
            ss.append(_ray_line_param(pose.c, r / np.linalg.norm(r), p0, u))
        lo.append(min(ss))
        hi.append(max(ss))
    s0, s1 = float(np.median(lo)), float(np.median(hi))
    a, b = p0 + s0 * u, p0 + s1 * u
    # re-projection check: distance of each observed endpoint to the projected 3-D line (px)
    res = []
    for pose, s in zip(poses, segs):
        xa = K @ (pose.R_cw @ (a - pose.c))
        xb = K @ (pose.R_cw @ (b - pose.c))
        if xa[2] <= 0 or xb[2] <= 0:
            return None
        l = np.cross(xa, xb)
        l /= max(np.hypot(l[0], l[1]), 1e-12)
        res += [l @ np.array([s[0], s[1], 1.0]), l @ np.array([s[2], s[3], 1.0])]
    return Line3D(a, b, float(np.sqrt(np.mean(np.square(res)))), cond)
