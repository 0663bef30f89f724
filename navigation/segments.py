"""2-D line segments of a frame (OpenCV's line segment detector), as (n, 4) float arrays ``x1, y1, x2, y2``."""
from __future__ import annotations

import cv2
import numpy as np

__all__ = ["SegmentExtractor", "segment_lengths", "segment_angles"]


def segment_lengths(seg: np.ndarray) -> np.ndarray:
    seg = np.asarray(seg).reshape(-1, 4)
    return np.hypot(seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1])


def segment_angles(seg: np.ndarray) -> np.ndarray:
    """Undirected orientation in [0, π)."""
    seg = np.asarray(seg).reshape(-1, 4)
    return np.mod(np.arctan2(seg[:, 3] - seg[:, 1], seg[:, 2] - seg[:, 0]), np.pi)


class SegmentExtractor:
    """Line segments of an 8-bit or float image (LSD, refined), longer than ``min_length_px``.

    Coordinates follow the camera model's convention: pixel ``i`` spans
    ``[i, i + 1)``, its centre at ``i + ½`` (LSD's own output is shifted by ½).

    Float images are scaled to 8 bits by their 0.5–99.5 percentiles (saturating). At most
    ``max_segments`` (the longest) are kept, so that a cluttered frame costs
    the tracker a bounded time.
    """

    def __init__(self, *, min_length_px: float = 20.0, max_segments: int = 300):
        if not min_length_px > 0:
            raise ValueError(f"min_length_px: must be > 0, got {min_length_px}")
        self.min_length_px = float(min_length_px)
        self.max_segments = int(max_segments)
        self._lsd = cv2.createLineSegmentDetector(cv2.LSD_REFINE_STD)

    def __call__(self, image: np.ndarray) -> np.ndarray:
        img = np.asarray(image)
        if img.dtype != np.uint8:
            lo, hi = np.percentile(img[::4, ::4], [0.5, 99.5])   # a 1/16 sample sets the stretch
            a = 255.0 / max(float(hi - lo), 1e-12)
            img = cv2.convertScaleAbs(np.ascontiguousarray(img, dtype=np.float32), alpha=a, beta=-float(lo) * a)
        lines = self._lsd.detect(img)[0]
        if lines is None:
            return np.zeros((0, 4))
        # LSD puts pixel centres at integer coordinates; simsat's cameras at half-integers (pixel i spans [i, i+1))
        seg = lines.reshape(-1, 4).astype(np.float64) + 0.5
        length = segment_lengths(seg)
        seg = seg[length >= self.min_length_px]
        length = length[length >= self.min_length_px]
        if len(seg) > self.max_segments:
            seg = seg[np.argsort(-length)[:self.max_segments]]
        return seg
