"""Strapdown IMU error model: turn-on biases, scale factors and random walks.

Errors act on the increments an integrating IMU delivers::

    dθ̃ = (1 + s_g) dθ + b_g Δt + N(0, ARW² Δt)
    dṽ = (1 + s_a) dv + b_a Δt + N(0, VRW² Δt)

Specifications come in the units of IMU data sheets (°/h, mg, °/√h, m/s/√h,
ppm) and are converted to SI once, in :meth:`ImuModel.si`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["ImuModel", "ImuErrors", "DEG_PER_H", "MILLI_G"]

DEG_PER_H = math.radians(1.0) / 3600.0   # rad/s
MILLI_G = 9.80665e-3                      # m/s²


@dataclass(frozen=True)
class ImuModel:
    """Data-sheet figures of a tactical-grade IMU (1-σ of the turn-on errors, densities of the noises)."""

    gyro_bias_deg_h: float = 5.0
    accel_bias_mg: float = 3.0
    gyro_arw_deg_sqrt_h: float = 0.1
    accel_vrw_m_s_sqrt_h: float = 0.05
    gyro_scale_ppm: float = 300.0
    accel_scale_ppm: float = 300.0
    rate_hz: float = 200.0

    def __post_init__(self):
        for name in ("gyro_bias_deg_h", "accel_bias_mg", "gyro_arw_deg_sqrt_h", "accel_vrw_m_s_sqrt_h",
                     "gyro_scale_ppm", "accel_scale_ppm"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"{name}: must be >= 0, got {v}")
        if not (math.isfinite(self.rate_hz) and self.rate_hz > 0):
            raise ValueError(f"rate_hz: must be > 0, got {self.rate_hz}")

    def si(self) -> dict:
        """The figures in SI: biases (rad/s, m/s²), noise densities (rad/√s, m/s/√s), scale factors (1)."""
        return {"gyro_bias": self.gyro_bias_deg_h * DEG_PER_H,
                "accel_bias": self.accel_bias_mg * MILLI_G,
                "gyro_arw": math.radians(self.gyro_arw_deg_sqrt_h) / 60.0,
                "accel_vrw": self.accel_vrw_m_s_sqrt_h / 60.0,
                "gyro_scale": self.gyro_scale_ppm * 1e-6,
                "accel_scale": self.accel_scale_ppm * 1e-6}

    def draw(self, rng: np.random.Generator) -> "ImuErrors":
        """One unit's turn-on errors (biases and scale factors), each axis drawn at its 1-σ."""
        s = self.si()
        return ImuErrors(gyro_bias=rng.normal(0, s["gyro_bias"], 3), accel_bias=rng.normal(0, s["accel_bias"], 3),
                         gyro_scale=rng.normal(0, s["gyro_scale"], 3), accel_scale=rng.normal(0, s["accel_scale"], 3),
                         gyro_arw=s["gyro_arw"], accel_vrw=s["accel_vrw"])


@dataclass
class ImuErrors:
    """The errors of one IMU unit (SI)."""

    gyro_bias: np.ndarray
    accel_bias: np.ndarray
    gyro_scale: np.ndarray
    accel_scale: np.ndarray
    gyro_arw: float
    accel_vrw: float

    def apply(self, dtheta: np.ndarray, dv: np.ndarray, dt: float, rng: np.random.Generator):
        """Measured increments ``(dθ̃, dṽ)`` from the true ones (n, 3) each."""
        n = len(dtheta)
        g = (1.0 + self.gyro_scale) * dtheta + self.gyro_bias * dt + rng.normal(0, self.gyro_arw * math.sqrt(dt),
                                                                                 (n, 3))
        a = (1.0 + self.accel_scale) * dv + self.accel_bias * dt + rng.normal(0, self.accel_vrw * math.sqrt(dt),
                                                                              (n, 3))
        return g, a
