"""The forward camera's frames: perspective ray casting (simsat's Mitsuba renderer) and shading.

For a short sequence, :meth:`FrameRenderer.prepare` crops the DEM around the
views, synthesises the ground albedo over the sequence's ground footprint
(one tile, ``texel_m``) and builds the ray caster; :meth:`FrameRenderer.render`
then casts ``supersample²`` rays per pixel and shades them: Lambert sun and
sky light from the hit's normal, atmospheric haze from the range
(Koschmieder: extinction 3.912 / visibility), sky where rays miss, and a
sensor noise (shot + read). The ``ir`` band is an emission-like image
(inverted, weaker contrast, little sun shading).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from .camera import CameraPose, PinholeCamera

__all__ = ["FrameRenderer", "SensorSettings"]


@dataclass(frozen=True)
class SensorSettings:
    band: str = "visible"          # "visible" or "ir"
    visibility_m: float = 8000.0
    max_range_m: float = 7000.0
    supersample: int = 2
    snr: float = 80.0              # signal-to-noise at mean radiance
    texel_m: float = 2.0
    sun_elevation_deg: float = 40.0
    sun_azimuth_deg: float = 135.0

    def __post_init__(self):
        if self.band not in ("visible", "ir"):
            raise ValueError(f"band: must be 'visible' or 'ir', got {self.band!r}")
        for name in ("visibility_m", "max_range_m", "snr", "texel_m"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name}: must be > 0, got {getattr(self, name)}")


class FrameRenderer:
    """Renders frames of one camera over a :class:`~navigation.world.World` and its DEM."""

    def __init__(self, world, dem, camera: PinholeCamera, sensor: SensorSettings = SensorSettings()):
        self.world, self.dem, self.camera, self.sensor = world, dem, camera, sensor
        self._tile = None
        self._caster = None
        self.rays = 0

    def footprint(self, poses: list[CameraPose]) -> tuple[float, float, float, float]:
        """Ground bounding box ``(x0, x1, y0, y1)`` seen by ``poses`` within ``max_range_m``."""
        pts = []
        z0 = float(np.nanmin(self.dem.z))
        for pose in poses:
            d = self.camera.pixel_rays(pose, stride=32).reshape(-1, 3)
            with np.errstate(divide="ignore", invalid="ignore"):
                t = np.where(d[:, 2] < 0, (z0 - pose.c[2]) / d[:, 2], np.inf)
            t = np.minimum(t, self.sensor.max_range_m)
            pts.append(pose.c[:2] + t[:, None] * d[:, :2])
            pts.append(pose.c[None, :2])
        p = np.concatenate(pts)
        m = 60.0
        return p[:, 0].min() - m, p[:, 0].max() + m, p[:, 1].min() - m, p[:, 1].max() + m

    def prepare(self, poses: list[CameraPose]) -> None:
        """Albedo tile and ray caster for a sequence seen from ``poses``."""
        from simsat.render.perspective import TerrainRayCaster

        x0, x1, y0, y1 = self.footprint(poses)
        te = self.sensor.texel_m
        nx, ny = int(math.ceil((x1 - x0) / te)), int(math.ceil((y1 - y0) / te))
        alb = self.world.albedo_grid(x0, y0, te, nx, ny)
        self._tile = (cv2.GaussianBlur(alb, (0, 0), 0.5), x0, y0, te)
        dem = self.dem.crop((x0 - 200, x1 + 200), (y0 - 200, y1 + 200))
        self._caster = TerrainRayCaster(dem, origin=np.array([0.5 * (x0 + x1), 0.5 * (y0 + y1), 0.0]))

    def _albedo_at(self, xy: np.ndarray, shape) -> np.ndarray:
        alb, x0, y0, te = self._tile
        mx = ((xy[:, 0] - x0) / te - 0.5).astype(np.float32).reshape(shape)
        my = ((xy[:, 1] - y0) / te - 0.5).astype(np.float32).reshape(shape)
        return cv2.remap(alb, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE).ravel()

    def render(self, pose: CameraPose, *, visibility_m: float | None = None,
               rng: np.random.Generator | None = None) -> np.ndarray:
        """One frame (height, width) float32 radiance (0–1 scale) seen from ``pose``."""
        if self._caster is None:
            raise RuntimeError("FrameRenderer.render: call prepare(poses) first")
        cam, s = self.camera, self.sensor
        ss = s.supersample
        u = (np.arange(cam.width * ss) + 0.5) / ss
        v = (np.arange(cam.height * ss) + 0.5) / ss
        uu, vv = np.meshgrid(u, v)
        d = np.stack([(uu - 0.5 * cam.width) / cam.focal_px, (vv - 0.5 * cam.height) / cam.focal_px,
                      np.ones_like(uu)], -1).reshape(-1, 3)
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        d = d @ pose.R_wc.T
        hits = self._caster.cast(pose.c, d, max_distance=s.max_range_m)
        self.rays += len(d)
        vis = float(visibility_m or s.visibility_m)
        sky = 0.30 + 0.15 * np.clip(d[:, 2] * 4.0, 0.0, 1.0)
        alb = self._albedo_at(hits.point[:, :2], uu.shape)
        e, a = math.radians(s.sun_elevation_deg), math.radians(s.sun_azimuth_deg)
        sun = np.array([math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e)])
        lambert = np.clip(hits.normal @ sun, 0.0, None)
        if s.band == "visible":
            ground = alb * (0.25 + 0.9 * lambert)
        else:
            ground = np.where(alb < 0.06, 0.18, 0.22 + 0.7 * (0.40 - alb)) * (0.9 + 0.15 * lambert)
        r = np.where(hits.valid, hits.distance, s.max_range_m)
        trans = np.exp(-3.912 * r / vis) * np.clip((s.max_range_m - r) / (0.1 * s.max_range_m), 0.0, 1.0)
        rad = np.where(hits.valid, trans * ground + (1 - trans) * sky, sky)
        img = rad.reshape(cam.height, ss, cam.width, ss).mean(axis=(1, 3)).astype(np.float32)
        if rng is not None and s.snr > 0:
            mean = float(img.mean())
            sigma = np.sqrt(np.maximum(img, 0) * mean / s.snr ** 2 * 0.7 + 0.3 * (mean / s.snr) ** 2)
            img = img + (rng.standard_normal(img.shape) * sigma).astype(np.float32)
        return img
