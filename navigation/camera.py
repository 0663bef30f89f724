"""Forward-looking pinhole camera: intrinsics, mounting, projection and rays (pure NumPy)."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .rotations import rot_y

__all__ = ["PinholeCamera", "CameraPose"]

#: camera axes (x right, y down, z optical axis) in the body frame (x forward, y left, z up), looking level
_BODY_FROM_CAM_LEVEL = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])


@dataclass(frozen=True)
class CameraPose:
    """Camera → world rotation ``R_wc`` and centre ``c`` (world, m)."""

    R_wc: np.ndarray
    c: np.ndarray

    @property
    def R_cw(self) -> np.ndarray:
        return self.R_wc.T


@dataclass(frozen=True)
class PinholeCamera:
    """A pinhole camera looking forward and down by ``depression_deg`` (no lens distortion).

    Parameters
    ----------
    width, height : int
        Image size (px).
    hfov_deg : float
        Horizontal field of view (deg).
    depression_deg : float
        Optical axis below the body's x axis (deg).
    """

    width: int = 640
    height: int = 480
    hfov_deg: float = 50.0
    depression_deg: float = 12.0

    def __post_init__(self):
        if int(self.width) != self.width or self.width < 16 or int(self.height) != self.height or self.height < 16:
            raise ValueError(f"width, height: must be integers >= 16, got {self.width} x {self.height}")
        if not (1.0 < self.hfov_deg < 150.0):
            raise ValueError(f"hfov_deg: must be in (1, 150), got {self.hfov_deg}")
        if not (-30.0 <= self.depression_deg <= 80.0):
            raise ValueError(f"depression_deg: must be in [-30, 80], got {self.depression_deg}")

    @property
    def focal_px(self) -> float:
        return 0.5 * self.width / math.tan(math.radians(self.hfov_deg) / 2.0)

    @property
    def K(self) -> np.ndarray:
        f = self.focal_px
        return np.array([[f, 0.0, 0.5 * self.width], [0.0, f, 0.5 * self.height], [0.0, 0.0, 1.0]])

    @property
    def vfov_deg(self) -> float:
        return math.degrees(2.0 * math.atan(0.5 * self.height / self.focal_px))

    @property
    def R_bc(self) -> np.ndarray:
        """Camera → body rotation (the mounting)."""
        return rot_y(math.radians(self.depression_deg)) @ _BODY_FROM_CAM_LEVEL

    def pose(self, p_world: np.ndarray, R_wb: np.ndarray) -> CameraPose:
        """The camera's pose for a vehicle at ``p_world`` with attitude ``R_wb`` (no lever arm)."""
        return CameraPose(R_wb @ self.R_bc, np.asarray(p_world, dtype=np.float64))

    def project(self, X: np.ndarray, pose: CameraPose):
        """Pixel coordinates (…, 2) of world points ``X`` (…, 3) and their depth along the optical axis."""
        xc = (np.asarray(X, dtype=np.float64) - pose.c) @ pose.R_wc
        z = xc[..., 2]
        uv = (xc[..., :2] / z[..., None]) * self.focal_px + np.array([0.5 * self.width, 0.5 * self.height])
        return uv, z

    def pixel_rays(self, pose: CameraPose, *, stride: int = 1) -> np.ndarray:
        """Unit world directions (h, w, 3) through the pixel centres (every ``stride``-th pixel)."""
        u = np.arange(0, self.width, stride) + 0.5
        v = np.arange(0, self.height, stride) + 0.5
        uu, vv = np.meshgrid(u, v)
        d = np.stack([(uu - 0.5 * self.width) / self.focal_px, (vv - 0.5 * self.height) / self.focal_px,
                      np.ones_like(uu)], -1)
        d /= np.linalg.norm(d, axis=-1, keepdims=True)
        return d @ pose.R_wc.T

    def normalised(self, uv: np.ndarray) -> np.ndarray:
        """Normalised image coordinates (…, 2) of pixels ``uv``."""
        return (np.asarray(uv, dtype=np.float64) - np.array([0.5 * self.width, 0.5 * self.height])) / self.focal_px
