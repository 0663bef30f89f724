"""The platform: a trajectory, a scan law and a nominal pointing.

The platform flies a :mod:`trajectory <simsat.trajectory>` (a straight track
over a flat Earth, a circular orbit over a round one) and may sweep its lines
of sight with a :mod:`scan law <simsat.scan>` (spin, scan mirror). The
body-frame line of sight ``b`` of a focal-plane point, at time ``t`` and
attitude ``(roll, pitch, yaw)``, points in the local frame along

    ``F(t) · R(roll, pitch, yaw) · S(t) · b``

(:meth:`Platform.pointing`): ``F`` the orbital frame of the trajectory, ``R``
the attitude (its nominal part is the off-nadir pointing, added to the
attitude model by the scenario), ``S`` the scan. The renderer and the sensor
model both go through :meth:`Platform.pointing`; adding a trajectory or a scan
touches its own module and its registry entry, not them.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from .config import Section
from .scan import MirrorScan, ScanLaw, SpinScan, SCAN_KINDS, spin_rate_rad_s
from .trajectory import (CircularOrbit, StraightTrack, Trajectory, TRAJECTORY_KINDS, EARTH_RADIUS_M,
                         GEOSTATIONARY_ALTITUDE_M)

__all__ = ["Platform", "platform_from_config", "rotation_matrices"]


def rotation_matrices(roll, pitch, yaw) -> np.ndarray:
    """Body → orbital-frame rotation matrices ``Rz(yaw) Ry(pitch) Rx(roll)``, shape (..., 3, 3)."""
    roll, pitch, yaw = np.broadcast_arrays(*(np.asarray(a, dtype=np.float64) for a in (roll, pitch, yaw)))
    cr, sr = np.cos(roll), np.sin(roll)
    cp, sp = np.cos(pitch), np.sin(pitch)
    cy, sy = np.cos(yaw), np.sin(yaw)
    r = np.empty(roll.shape + (3, 3))
    r[..., 0, 0] = cy * cp
    r[..., 0, 1] = cy * sp * sr - sy * cr
    r[..., 0, 2] = cy * sp * cr + sy * sr
    r[..., 1, 0] = sy * cp
    r[..., 1, 1] = sy * sp * sr + cy * cr
    r[..., 1, 2] = sy * sp * cr - cy * sr
    r[..., 2, 0] = -sp
    r[..., 2, 1] = cp * sr
    r[..., 2, 2] = cp * cr
    return r


@dataclass(frozen=True)
class Platform:
    """Trajectory + scan law + nominal off-nadir pointing.

    Parameters
    ----------
    trajectory : Trajectory
    scan : ScanLaw
        Default: no sweep.
    off_nadir_roll_rad, off_nadir_pitch_rad : float
        Nominal pointing of the line of sight (added to the attitude model).
    """

    trajectory: Trajectory
    scan: ScanLaw = field(default_factory=ScanLaw)
    off_nadir_roll_rad: float = 0.0
    off_nadir_pitch_rad: float = 0.0

    @classmethod
    def straight(cls, *, altitude_m: float, ground_speed_m_s: float, x_at_t0_m: float = 0.0, y_m: float = 0.0,
                 off_nadir_roll_rad: float = 0.0, off_nadir_pitch_rad: float = 0.0) -> "Platform":
        """A push-broom on a straight track (no scan)."""
        return cls(StraightTrack(altitude_m=float(altitude_m), speed_m_s=float(ground_speed_m_s),
                                 x_at_t0_m=float(x_at_t0_m), y_m=float(y_m)),
                   off_nadir_roll_rad=float(off_nadir_roll_rad), off_nadir_pitch_rad=float(off_nadir_pitch_rad))

    # -- what the rest of simsat reads -------------------------------------------------
    @property
    def altitude_m(self) -> float:
        return float(self.trajectory.altitude_m)

    @property
    def earth_radius_m(self) -> float:
        return float(self.trajectory.earth_radius_m)

    @property
    def ground_speed_m_s(self) -> float:
        """Nominal speed at which the lines of sight sweep the ground (track + scan, at nadir) [m/s]."""
        return float(self.trajectory.ground_speed_m_s + self.altitude_m * self.scan.los_rate_rad_s)

    @property
    def x_at_t0_m(self) -> float:
        return float(self.trajectory.position(0.0)[0])

    @property
    def y_m(self) -> float:
        return float(self.trajectory.position(0.0)[1])

    def position(self, t) -> np.ndarray:
        """Platform position at times ``t`` [s] → array (..., 3) [m]."""
        return self.trajectory.position(t)

    def velocity(self, t=0.0) -> np.ndarray:
        return self.trajectory.velocity(t)

    def pointing(self, t, roll, pitch, yaw) -> np.ndarray:
        """Body → local rotation ``F(t) R(roll, pitch, yaw) S(t)`` of the lines of sight, shape ``t.shape + (3, 3)``."""
        t = np.asarray(t, dtype=np.float64)
        r = rotation_matrices(roll, pitch, yaw)
        r = np.broadcast_to(r, t.shape + (3, 3)) if r.shape[:-2] != t.shape else r
        if self.scan.los_rate_rad_s != 0.0:
            r = r @ self.scan.rotation(t)
        if not self.trajectory.flat_frame:
            r = self.trajectory.frame(t) @ r
        return r

    def nominal_ground_point(self, t, body_los, z_m=0.0) -> np.ndarray:
        """Where the body line of sight ``body_los`` (..., 3) meets the plane ``z = z_m`` at ``t``, nominal pointing."""
        t = np.asarray(t, dtype=np.float64)
        r = self.pointing(t, self.off_nadir_roll_rad, self.off_nadir_pitch_rad, 0.0)
        d = np.einsum("...ij,...j->...i", r, np.asarray(body_los, dtype=np.float64))
        s = self.position(t)
        k = (s[..., 2] - z_m) / (-d[..., 2])
        return s + k[..., None] * d

    def centred(self, *, t_mid_s: float, along_angle_rad: float = 0.0) -> "Platform":
        """Copy whose nominal line of sight hits (0, 0) at ``t_mid_s`` (the scan's zero there too).

        ``along_angle_rad`` is the along-track angle of the focal-plane point
        that should be centred (e.g. the mean of the detector positions / f).
        """
        p = replace(self, scan=self.scan.referenced(t_mid_s))
        b = np.array([math.tan(along_angle_rad), 0.0, -1.0])
        for _ in range(4):  # a round Earth turns the track slightly: a few fixed-point steps
            g = p.nominal_ground_point(t_mid_s, b)
            if abs(g[0]) < 1e-7 and abs(g[1]) < 1e-7:
                break
            p = replace(p, trajectory=p.trajectory.shifted(-float(g[0]), -float(g[1])))
        return p

    def attrs(self) -> dict:
        """Attributes written to ``product.nc`` (read back by :func:`simsat.product.read_product`)."""
        return {**self.trajectory.attrs(), **self.scan.attrs(), "ground_speed_m_s": self.ground_speed_m_s,
                "platform_x_at_t0_m": self.x_at_t0_m, "platform_y_m": self.y_m,
                "off_nadir_roll_rad": self.off_nadir_roll_rad, "off_nadir_pitch_rad": self.off_nadir_pitch_rad}


# --------------------------------------------------------------------------- configuration
def _straight_from_config(sec: Section, h: float) -> Trajectory:
    v = sec.number("ground_speed_m_s", gt=0, le=2e4)  # LEO ground speed is ~7e3 m/s
    return StraightTrack(altitude_m=h, speed_m_s=v)


def _orbit_from_config(sec: Section, h: float) -> Trajectory:
    if sec.has("ground_speed_m_s"):
        raise sec.error("ground_speed_m_s", "an orbit's ground speed follows from its altitude and inclination "
                        "(Kepler); remove the key or use trajectory = \"straight\"")
    inc = sec.number("inclination_deg", 98.0, ge=0, le=180)
    radius = sec.number("earth_radius_m", EARTH_RADIUS_M, ge=1e5, le=1e8)
    return CircularOrbit(altitude_m=h, inclination_rad=math.radians(inc), earth_radius_m=radius)


#: ``[platform] trajectory`` kind → builder from the table
_TRAJECTORY_BUILDERS = {"straight": _straight_from_config, "orbit": _orbit_from_config}
assert tuple(_TRAJECTORY_BUILDERS) == TRAJECTORY_KINDS


#: ``[platform.scan] kind`` → builder from the table
_SCAN_BUILDERS = {
    "none": lambda sec: ScanLaw(),
    "spin": lambda sec: SpinScan(rate_rad_s=spin_rate_rad_s(sec.number("rate_rpm", gt=0, le=600))),
    "mirror": lambda sec: MirrorScan(mirror_rate_rad_s=math.radians(sec.number("mirror_rate_deg_s", gt=0, le=1000)),
                                     scan_frequency_hz=sec.number("scan_frequency_hz", gt=0, le=1000)),
}
assert tuple(_SCAN_BUILDERS) == SCAN_KINDS


def _scan_from_config(sec: Section) -> ScanLaw:
    law = _SCAN_BUILDERS[sec.string("kind", "none", choices=SCAN_KINDS)](sec)
    sec.finish()
    return law


def platform_from_config(sec: Section) -> Platform:
    """Build a :class:`Platform` from the ``[platform]`` table (not yet centred)."""
    h = sec.number("altitude_m", gt=1000.0, le=5e7)  # up to beyond geostationary (3.6e7 m)
    kind = sec.string("trajectory", "straight", choices=TRAJECTORY_KINDS)
    trajectory = _TRAJECTORY_BUILDERS[kind](sec, h)
    roll = np.deg2rad(sec.number("off_nadir_roll_deg", 0.0, ge=-45, le=45))
    pitch = np.deg2rad(sec.number("off_nadir_pitch_deg", 0.0, ge=-45, le=45))
    scan = _scan_from_config(sec.section("scan"))
    sec.finish()
    sweep = trajectory.ground_speed_m_s + h * scan.los_rate_rad_s
    if not sweep > 1e-3:
        where = "platform.scan.kind"
        raise sec.error("scan", f"the lines of sight do not sweep the ground (ground track {trajectory.ground_speed_m_s:.3g} "
                        f"m/s{', a geostationary orbit' if abs(h - GEOSTATIONARY_ALTITUDE_M) < 1e4 else ''}): "
                        f"set {where} = \"spin\" or \"mirror\"")
    return Platform(trajectory=trajectory, scan=scan, off_nadir_roll_rad=float(roll), off_nadir_pitch_rad=float(pitch))
