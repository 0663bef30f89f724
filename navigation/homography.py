"""Homographies between consecutive frames: predicted from poses and a ground plane, fitted to line segments.

The patent registers two consecutive images by a homography ``H`` found by
least squares from corresponding features (claim 3). Here the features are
the 2-D segments themselves: a segment ``(x_a, x_b)`` of image 1 and the line
``l'`` of its correspondent in image 2 give two linear equations
``l'ᵀ H x_a = 0``, ``l'ᵀ H x_b = 0`` (the endpoints need not correspond, only
the lines), solved by SVD after Hartley normalisation, inside RANSAC.
"""
from __future__ import annotations

import numpy as np

from .camera import CameraPose

__all__ = ["plane_homography", "map_segments", "segment_lines", "fit_homography_lines", "ransac_homography_lines",
           "trimmed_homography_lines", "line_distances"]


def plane_homography(K: np.ndarray, pose1: CameraPose, pose2: CameraPose, normal_w, offset_w: float) -> np.ndarray:
    """Homography image 1 → image 2 induced by the world plane ``n·X = d`` (``normal_w``, ``offset_w``).

    ``H = K (R₂₁ + t₂₁ n₁ᵀ / d₁) K⁻¹`` with ``X₂ = R₂₁ X₁ + t₂₁`` and the plane
    ``n₁·X₁ = d₁`` in camera-1 coordinates.
    """
    n_w = np.asarray(normal_w, dtype=np.float64)
    R21 = pose2.R_cw @ pose1.R_wc
    t21 = pose2.R_cw @ (pose1.c - pose2.c)
    n1 = pose1.R_cw @ n_w
    d1 = offset_w - n_w @ pose1.c
    H = K @ (R21 + np.outer(t21, n1) / d1) @ np.linalg.inv(K)
    return H / H[2, 2]


def map_segments(H: np.ndarray, seg: np.ndarray) -> np.ndarray:
    """Segments (n, 4) ``x1, y1, x2, y2`` mapped by ``H``."""
    seg = np.asarray(seg, dtype=np.float64).reshape(-1, 4)
    pts = np.concatenate([seg[:, :2], seg[:, 2:]], 0)
    ph = np.column_stack([pts, np.ones(len(pts))]) @ H.T
    q = ph[:, :2] / ph[:, 2:3]
    n = len(seg)
    return np.column_stack([q[:n], q[n:]])


def segment_lines(seg: np.ndarray) -> np.ndarray:
    """Homogeneous lines (n, 3) through the segments' endpoints, scaled so that ``(a, b)`` is a unit normal."""
    seg = np.asarray(seg, dtype=np.float64).reshape(-1, 4)
    p = np.column_stack([seg[:, :2], np.ones(len(seg))])
    q = np.column_stack([seg[:, 2:], np.ones(len(seg))])
    l = np.cross(p, q)
    return l / np.maximum(np.hypot(l[:, 0], l[:, 1]), 1e-12)[:, None]


def line_distances(lines: np.ndarray, seg: np.ndarray) -> np.ndarray:
    """Signed distances (n, 2) of each segment's endpoints to the corresponding unit line."""
    seg = np.asarray(seg, dtype=np.float64).reshape(-1, 4)
    d1 = lines[:, 0] * seg[:, 0] + lines[:, 1] * seg[:, 1] + lines[:, 2]
    d2 = lines[:, 0] * seg[:, 2] + lines[:, 1] * seg[:, 3] + lines[:, 2]
    return np.column_stack([d1, d2])


def _normaliser(pts: np.ndarray) -> np.ndarray:
    c = pts.mean(0)
    s = np.sqrt(2.0) / max(np.sqrt(((pts - c) ** 2).sum(1)).mean(), 1e-12)
    return np.array([[s, 0, -s * c[0]], [0, s, -s * c[1]], [0, 0, 1.0]])


def fit_homography_lines(seg1: np.ndarray, seg2: np.ndarray) -> np.ndarray:
    """Least-squares homography mapping segments ``seg1`` (image 1) onto the lines of ``seg2`` (image 2).

    Needs ≥ 4 correspondences in general position (two lines per... four lines,
    no three concurrent). Returns H with ``H[2, 2] = 1``.
    """
    seg1 = np.asarray(seg1, dtype=np.float64).reshape(-1, 4)
    seg2 = np.asarray(seg2, dtype=np.float64).reshape(-1, 4)
    if len(seg1) < 4:
        raise ValueError(f"fit_homography_lines: needs >= 4 segment pairs, got {len(seg1)}")
    T1 = _normaliser(np.concatenate([seg1[:, :2], seg1[:, 2:]]))
    T2 = _normaliser(np.concatenate([seg2[:, :2], seg2[:, 2:]]))
    s1 = map_segments(T1, seg1)
    s2 = map_segments(T2, seg2)
    l2 = segment_lines(s2)
    rows = []
    for end in (s1[:, :2], s1[:, 2:]):
        x = np.column_stack([end, np.ones(len(end))])
        rows.append(np.einsum("ni,nj->nij", l2, x).reshape(-1, 9))
    A = np.concatenate(rows)
    _, _, vt = np.linalg.svd(A)
    Hn = vt[-1].reshape(3, 3)
    H = np.linalg.inv(T2) @ Hn @ T1
    return H / H[2, 2]


def ransac_homography_lines(seg1: np.ndarray, seg2: np.ndarray, *, threshold_px: float = 2.0, iterations: int = 200,
                            rng: np.random.Generator | None = None):
    """Robust :func:`fit_homography_lines`: RANSAC over 4-pair samples, refit on the inliers.

    A pair is an inlier when both mapped endpoints of ``seg1`` lie within
    ``threshold_px`` of the line of ``seg2``. Returns ``(H, inliers)``;
    ``H`` is None when fewer than 4 pairs or no sample has ≥ 4 inliers.
    """
    seg1 = np.asarray(seg1, dtype=np.float64).reshape(-1, 4)
    seg2 = np.asarray(seg2, dtype=np.float64).reshape(-1, 4)
    n = len(seg1)
    if n < 4:
        return None, np.zeros(n, bool)
    rng = rng if rng is not None else np.random.default_rng(0)
    l2 = segment_lines(seg2)
    best = np.zeros(n, bool)
    needed = iterations if n > 4 else 1
    k = 0
    while k < needed:
        k += 1
        idx = rng.choice(n, 4, replace=False)
        try:
            H = fit_homography_lines(seg1[idx], seg2[idx])
        except (np.linalg.LinAlgError, ValueError):
            continue
        if not np.all(np.isfinite(H)):
            continue
        inl = np.abs(line_distances(l2, map_segments(H, seg1))).max(1) < threshold_px
        if inl.sum() > best.sum():
            best = inl
            # adaptive stop: enough samples for a 99 % chance of one all-inlier draw
            w = best.sum() / n
            needed = min(needed, int(np.ceil(np.log(0.01) / np.log(max(1 - w ** 4, 1e-12)))) + 1)
    if best.sum() < 4:
        return None, best
    H = fit_homography_lines(seg1[best], seg2[best])
    inl = np.abs(line_distances(l2, map_segments(H, seg1))).max(1) < threshold_px
    if inl.sum() >= 4:
        H = fit_homography_lines(seg1[inl], seg2[inl])
    return H, inl


def trimmed_homography_lines(seg1: np.ndarray, seg2: np.ndarray, *, threshold_px: float = 2.0,
                             iterations: int = 4, rng: np.random.Generator | None = None):
    """Least squares over all pairs, trimmed: refit on the pairs within ``threshold_px``, a few times.

    The tracker's pairs come from a homography predicted by the INS, so most are
    right: a handful of least-squares fits does what RANSAC's many minimal
    samples would. When fewer than half the pairs survive, it falls back to
    :func:`ransac_homography_lines`. Returns ``(H, inliers)`` like it.
    """
    seg1 = np.asarray(seg1, dtype=np.float64).reshape(-1, 4)
    seg2 = np.asarray(seg2, dtype=np.float64).reshape(-1, 4)
    n = len(seg1)
    if n < 4:
        return None, np.zeros(n, bool)
    l2 = segment_lines(seg2)
    keep = np.ones(n, bool)
    H = None
    for _ in range(iterations):
        try:
            H = fit_homography_lines(seg1[keep], seg2[keep])
        except (np.linalg.LinAlgError, ValueError):
            H = None
            break
        err = np.abs(line_distances(l2, map_segments(H, seg1))).max(1)
        # trim progressively: the worst pairs first, the threshold at the end
        limit = max(threshold_px, float(np.percentile(err[keep], 80))) if _ < iterations - 1 else threshold_px
        new = err < limit
        if new.sum() < 4 or np.array_equal(new, keep):
            keep = new
            break
        keep = new
    if H is None or keep.sum() < max(4, n // 2):
        return ransac_homography_lines(seg1, seg2, threshold_px=threshold_px, rng=rng)
    return fit_homography_lines(seg1[keep], seg2[keep]), keep
