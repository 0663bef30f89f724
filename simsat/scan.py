"""Scan laws: how the line of sight is swept across the ground besides the platform's motion.

EP1843295 (claims 16–17, figs. 16–17) applies the restoration to a detector
that sweeps the Earth "either by the rotation of the satellite or by the sweep
of a steerable mirror on the instrument's optical path", on a non-stationary
or a geostationary orbit. A scan law is a rotation ``S(t)`` of the
instrument's lines of sight about the body's across-track axis (y), applied
before the attitude: the line of sight of focal-plane point ``b`` is
``F(t) · R(roll, pitch, yaw) · S(t) · b`` (``F`` the orbital frame, ``R`` the
attitude, see :mod:`simsat.platform`). ``S(t) = R_y(−σ(t))`` with the sweep
angle σ increasing with time, so the lines of sight move forward (+x) like
the ground track of a push-broom: a detector ahead on the focal plane still
sees a ground point first.

Kinds (``[platform.scan] kind``), in :data:`SCAN_KINDS`:

``none``
    No sweep (the push-broom of a moving platform).
``spin``
    A spin-stabilised platform rotating about its across-track axis at
    ``rate_rpm`` (fig. 16; TIROS's "cartwheel"): ``σ = ω (t − t_ref)``. Spin-rate
    jitter is pitch jitter, nutation shows on roll and yaw
    (``[[attitude.jitter]]``).
``mirror``
    A scan mirror on a stabilised platform (fig. 17), turning at
    ``mirror_rate_deg_s`` during the active half of a scan of period
    ``1 / scan_frequency_hz``; reflection doubles the angle: ``σ = 2 ω_m (t −
    t_ref)``. The acquisition must fit in one sweep. Mirror jitter (angle
    noise, harmonics of the scan frequency) is attitude jitter.

``t_ref`` is the time at which the sweep angle is zero (the platform centres
it on the middle of the acquisition).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from .trajectory import rotation_about_y

__all__ = ["ScanLaw", "NoScan", "SpinScan", "MirrorScan", "SCAN_KINDS", "scan_from_attrs"]


@dataclass(frozen=True)
class ScanLaw:
    """No sweep: the identity (base class of the scan laws)."""

    t_ref_s: float = 0.0
    kind = "none"

    @property
    def los_rate_rad_s(self) -> float:
        """Rate at which the lines of sight turn forward [rad/s]."""
        return 0.0

    def sweep_angle(self, t) -> np.ndarray:
        """Sweep angle σ(t) [rad]."""
        return self.los_rate_rad_s * (np.asarray(t, dtype=np.float64) - self.t_ref_s)

    def rotation(self, t) -> np.ndarray:
        """``S(t) = R_y(−σ(t))``, shape ``t.shape + (3, 3)``."""
        return rotation_about_y(-self.sweep_angle(t))

    def referenced(self, t_ref_s: float) -> "ScanLaw":
        """The same law with its zero at ``t_ref_s``."""
        return replace(self, t_ref_s=float(t_ref_s))

    def check_span(self, t_start: float, t_end: float) -> str | None:
        """A message if the law cannot hold over ``[t_start, t_end]``, else None."""
        return None

    def attrs(self) -> dict:
        return {"scan": self.kind, "scan_t_ref_s": self.t_ref_s}


NoScan = ScanLaw


@dataclass(frozen=True)
class SpinScan(ScanLaw):
    """Spin about the across-track axis at ``rate_rad_s`` (> 0)."""

    rate_rad_s: float = 0.0
    kind = "spin"

    @property
    def los_rate_rad_s(self) -> float:
        return self.rate_rad_s

    def attrs(self) -> dict:
        return {**super().attrs(), "scan_rate_rad_s": self.rate_rad_s}


@dataclass(frozen=True)
class MirrorScan(ScanLaw):
    """A mirror turning at ``mirror_rate_rad_s`` (the line of sight at twice it), sweeping at ``scan_frequency_hz``."""

    mirror_rate_rad_s: float = 0.0
    scan_frequency_hz: float = 1.0
    kind = "mirror"

    @property
    def los_rate_rad_s(self) -> float:
        return 2.0 * self.mirror_rate_rad_s

    @property
    def sweep_duration_s(self) -> float:
        """Duration of the active half of a scan period [s]."""
        return 0.5 / self.scan_frequency_hz

    def check_span(self, t_start: float, t_end: float) -> str | None:
        if t_end - t_start > self.sweep_duration_s:
            return (f"the acquisition lasts {t_end - t_start:.4g} s but one mirror sweep lasts "
                    f"{self.sweep_duration_s:.4g} s (1 / (2 scan_frequency_hz)); lower scan_frequency_hz or "
                    "acquisition.lines")
        return None

    def attrs(self) -> dict:
        return {**super().attrs(), "scan_mirror_rate_rad_s": self.mirror_rate_rad_s,
                "scan_frequency_hz": self.scan_frequency_hz}


#: ``[platform.scan] kind`` values
SCAN_KINDS = ("none", "spin", "mirror")


def scan_from_attrs(attrs) -> ScanLaw:
    """Rebuild the scan law a product recorded (none when the product predates scans)."""
    kind = str(attrs.get("scan", "none"))
    t_ref = float(attrs.get("scan_t_ref_s", 0.0))
    if kind == "none":
        return ScanLaw(t_ref_s=t_ref)
    if kind == "spin":
        return SpinScan(t_ref_s=t_ref, rate_rad_s=float(attrs["scan_rate_rad_s"]))
    if kind == "mirror":
        return MirrorScan(t_ref_s=t_ref, mirror_rate_rad_s=float(attrs["scan_mirror_rate_rad_s"]),
                          scan_frequency_hz=float(attrs["scan_frequency_hz"]))
    raise ValueError(f"scan: unknown kind {kind!r} (known: {', '.join(SCAN_KINDS)})")


def spin_rate_rad_s(rpm: float) -> float:
    """Revolutions per minute → rad/s."""
    return rpm * 2.0 * math.pi / 60.0
