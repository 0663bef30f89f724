"""Trajectories: where the platform is, and how its orbital frame is turned, at any time.

Every trajectory works in the scene's local frame (x along-track, y across-track,
z up, metres, origin on the ground at the scene centre) and offers

* ``position(t)`` → (..., 3) [m] and ``velocity(t)`` → (..., 3) [m/s];
* ``frame(t)`` → (..., 3, 3): the orbital frame (x along the ground track, y
  across, z away from the Earth's centre) expressed in the local frame — the
  identity over a flat Earth, a rotation about y over a round one;
* ``altitude_m``, ``ground_speed_m_s`` (speed of the sub-satellite point),
  ``earth_radius_m`` (``inf`` for a flat Earth: the DEM gets no curvature);
* ``shifted(dx_m, dy_m)``: the same motion with its ground track moved by
  ``dx`` along and ``dy`` across (used to centre the acquisition on the scene);
* ``attrs()``: the parameters written to ``product.nc`` (``trajectory_from_attrs``
  reads them back).

Kinds (``[platform] trajectory``), in :data:`TRAJECTORY_KINDS`:

``straight``
    A straight, constant-altitude track at constant speed over a flat Earth
    (the scene is tens of km; the historic model).
``orbit``
    A circular Keplerian orbit over a spherical, rotating Earth: radius
    ``R + H``, mean motion ``n = sqrt(μ / (R + H)³)``, and the ground track
    advancing at ``n − ω_E cos i`` (the Earth's rotation along the track; its
    across-track part is neglected). At the geostationary altitude with
    ``i = 0`` the platform is still over the ground: a scan (spin, mirror) must
    sweep the scene.
``ephemeris``
    Positions sampled at the line times (``product.nc``'s ``ephemeris``),
    interpolated by a cubic spline; the orbital frame follows the local
    vertical of the Earth (flat or round) under the platform.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

__all__ = ["EARTH_RADIUS_M", "EARTH_MU_M3_S2", "EARTH_ROTATION_RAD_S", "GEOSTATIONARY_ALTITUDE_M",
           "Trajectory", "StraightTrack", "CircularOrbit", "SampledEphemeris", "TRAJECTORY_KINDS",
           "trajectory_from_attrs", "rotation_about_y"]

EARTH_RADIUS_M = 6_371_008.8            #: mean Earth radius (IUGG) [m]
EARTH_MU_M3_S2 = 3.986004418e14         #: Earth's gravitational parameter [m³/s²]
EARTH_ROTATION_RAD_S = 7.2921150e-5     #: sidereal rotation rate of the Earth [rad/s]
#: altitude of a circular equatorial orbit whose mean motion equals the Earth's rotation [m]
GEOSTATIONARY_ALTITUDE_M = (EARTH_MU_M3_S2 / EARTH_ROTATION_RAD_S ** 2) ** (1 / 3) - EARTH_RADIUS_M


def rotation_about_y(angle) -> np.ndarray:
    """Rotation matrices about +y by ``angle`` [rad], shape (..., 3, 3): (0, 0, 1) → (sin a, 0, cos a)."""
    a = np.asarray(angle, dtype=np.float64)
    c, s = np.cos(a), np.sin(a)
    r = np.zeros(a.shape + (3, 3))
    r[..., 0, 0] = c
    r[..., 0, 2] = s
    r[..., 1, 1] = 1.0
    r[..., 2, 0] = -s
    r[..., 2, 2] = c
    return r


class Trajectory:
    """Interface of a trajectory (see the module docstring)."""

    kind = ""
    #: True when the orbital frame is the local frame at every time (a flat Earth): pointing skips it
    flat_frame = False

    @property
    def ground_speed_m_s(self) -> float:  # pragma: no cover - interface
        raise NotImplementedError

    def position(self, t) -> np.ndarray:  # pragma: no cover - interface
        raise NotImplementedError

    def velocity(self, t, *, dt_s: float = 1e-3) -> np.ndarray:
        """Velocity [m/s] at ``t`` (central difference of :meth:`position` unless overridden)."""
        t = np.asarray(t, dtype=np.float64)
        return (self.position(t + dt_s) - self.position(t - dt_s)) / (2 * dt_s)

    def frame(self, t) -> np.ndarray:
        """Orbital frame → local frame rotation at ``t``, shape ``t.shape + (3, 3)``."""
        t = np.asarray(t, dtype=np.float64)
        return np.broadcast_to(np.eye(3), t.shape + (3, 3)).copy()

    def shifted(self, dx_m: float, dy_m: float) -> "Trajectory":  # pragma: no cover - interface
        raise NotImplementedError

    def attrs(self) -> dict:  # pragma: no cover - interface
        raise NotImplementedError


@dataclass(frozen=True)
class StraightTrack(Trajectory):
    """Straight, constant-speed, constant-altitude track along +x over a flat Earth.

    Parameters
    ----------
    altitude_m : float
        Height above the local frame's origin [m].
    ground_speed_m_s : float
        Speed along +x [m/s].
    x_at_t0_m, y_m : float
        x at t = 0 and the constant y [m].
    """

    altitude_m: float
    speed_m_s: float
    x_at_t0_m: float = 0.0
    y_m: float = 0.0
    kind = "straight"
    earth_radius_m = math.inf
    flat_frame = True

    @property
    def ground_speed_m_s(self) -> float:
        return self.speed_m_s

    def position(self, t) -> np.ndarray:
        t = np.asarray(t, dtype=np.float64)
        out = np.empty(t.shape + (3,), dtype=np.float64)
        out[..., 0] = self.x_at_t0_m + self.speed_m_s * t
        out[..., 1] = self.y_m
        out[..., 2] = self.altitude_m
        return out

    def velocity(self, t=0.0, **_) -> np.ndarray:
        t = np.asarray(t, dtype=np.float64)
        return np.broadcast_to(np.array([self.speed_m_s, 0.0, 0.0]), t.shape + (3,)).copy()

    def shifted(self, dx_m: float, dy_m: float) -> "StraightTrack":
        return replace(self, x_at_t0_m=float(self.x_at_t0_m + dx_m), y_m=float(self.y_m + dy_m))

    def attrs(self) -> dict:
        return {"trajectory": self.kind, "altitude_m": self.altitude_m, "ground_speed_m_s": self.speed_m_s,
                "platform_x_at_t0_m": self.x_at_t0_m, "platform_y_m": self.y_m}


@dataclass(frozen=True)
class CircularOrbit(Trajectory):
    """Circular Keplerian orbit over a spherical Earth whose centre is at (0, 0, −R).

    The platform moves in the plane ``y = y_m`` at the angle
    ``θ(t) = θ₀ + ω t`` from the local vertical, ``ω = n − ω_E cos i``:
    ``position = (0, y, −R) + (R + H) (sin θ, 0, cos θ)``; its orbital frame is
    the rotation by θ about y.

    Parameters
    ----------
    altitude_m : float
        Height above the sphere [m] (35 786 km: geostationary).
    inclination_rad : float
        Orbit inclination (0: equatorial; 98°: sun-synchronous LEO).
    theta0_rad : float
        Angle at t = 0.
    y_m : float
        Across-track offset of the orbit plane [m].
    earth_radius_m, mu_m3_s2, earth_rotation_rad_s : float
        The Earth's radius, gravitational parameter and rotation rate.
    """

    altitude_m: float
    inclination_rad: float = math.radians(98.0)
    theta0_rad: float = 0.0
    y_m: float = 0.0
    earth_radius_m: float = EARTH_RADIUS_M
    mu_m3_s2: float = EARTH_MU_M3_S2
    earth_rotation_rad_s: float = EARTH_ROTATION_RAD_S
    kind = "orbit"

    @property
    def mean_motion_rad_s(self) -> float:
        return math.sqrt(self.mu_m3_s2 / (self.earth_radius_m + self.altitude_m) ** 3)

    @property
    def angular_rate_rad_s(self) -> float:
        """Rate of the ground track's angle relative to the rotating Earth [rad/s]."""
        return self.mean_motion_rad_s - self.earth_rotation_rad_s * math.cos(self.inclination_rad)

    @property
    def ground_speed_m_s(self) -> float:
        return self.angular_rate_rad_s * self.earth_radius_m

    def theta(self, t) -> np.ndarray:
        return self.theta0_rad + self.angular_rate_rad_s * np.asarray(t, dtype=np.float64)

    def position(self, t) -> np.ndarray:
        th = self.theta(t)
        r = self.earth_radius_m + self.altitude_m
        out = np.empty(th.shape + (3,), dtype=np.float64)
        out[..., 0] = r * np.sin(th)
        out[..., 1] = self.y_m
        out[..., 2] = r * np.cos(th) - self.earth_radius_m
        return out

    def velocity(self, t=0.0, **_) -> np.ndarray:
        th = self.theta(t)
        v = (self.earth_radius_m + self.altitude_m) * self.angular_rate_rad_s
        out = np.zeros(th.shape + (3,), dtype=np.float64)
        out[..., 0] = v * np.cos(th)
        out[..., 2] = -v * np.sin(th)
        return out

    def frame(self, t) -> np.ndarray:
        return rotation_about_y(self.theta(t))

    def shifted(self, dx_m: float, dy_m: float) -> "CircularOrbit":
        return replace(self, theta0_rad=float(self.theta0_rad + dx_m / self.earth_radius_m),
                       y_m=float(self.y_m + dy_m))

    def attrs(self) -> dict:
        return {"trajectory": self.kind, "altitude_m": self.altitude_m, "ground_speed_m_s": self.ground_speed_m_s,
                "orbit_inclination_rad": self.inclination_rad, "orbit_theta0_rad": self.theta0_rad,
                "platform_y_m": self.y_m, "earth_radius_m": self.earth_radius_m, "earth_mu_m3_s2": self.mu_m3_s2,
                "earth_rotation_rad_s": self.earth_rotation_rad_s,
                "platform_x_at_t0_m": float(self.position(0.0)[0])}


class SampledEphemeris(Trajectory):
    """Positions sampled in time, interpolated by a cubic spline (extrapolated a little at the ends).

    Parameters
    ----------
    time_s : array, shape (n,)
        Increasing sample times [s] (n ≥ 4).
    position_m : array, shape (n, 3)
        Positions in the local frame [m].
    earth_radius_m : float
        ``inf`` (flat Earth: the orbital frame is the identity) or the radius of
        the sphere centred at (0, 0, −R) whose local vertical gives the frame.
    """

    kind = "ephemeris"

    def __init__(self, time_s, position_m, *, earth_radius_m: float = math.inf):
        from scipy.interpolate import CubicSpline

        t = np.asarray(time_s, dtype=np.float64)
        p = np.asarray(position_m, dtype=np.float64)
        if t.ndim != 1 or len(t) < 4 or p.shape != (len(t), 3):
            raise ValueError(f"ephemeris: need ≥ 4 times and (n, 3) positions, got {t.shape} and {p.shape}")
        if not np.all(np.diff(t) > 0) or not np.isfinite(p).all():
            raise ValueError("ephemeris: times must increase and positions be finite")
        self.time_s, self.position_m = t, p
        self._spline = CubicSpline(t, p, axis=0, extrapolate=True)
        self.earth_radius_m = float(earth_radius_m)
        self.flat_frame = not math.isfinite(self.earth_radius_m)
        mid = self.position(t[len(t) // 2])
        self.altitude_m = float(np.hypot(np.hypot(mid[0], mid[1]), mid[2] + self.earth_radius_m)
                                - self.earth_radius_m) if math.isfinite(self.earth_radius_m) else float(mid[2])

    @property
    def ground_speed_m_s(self) -> float:
        v = self.velocity(self.time_s[len(self.time_s) // 2])
        speed = float(np.hypot(v[0], v[2]))  # along the track (the y offset is constant)
        if math.isfinite(self.earth_radius_m):
            return speed * self.earth_radius_m / (self.earth_radius_m + self.altitude_m)
        return speed

    def position(self, t) -> np.ndarray:
        return self._spline(np.asarray(t, dtype=np.float64))

    def velocity(self, t, **_) -> np.ndarray:
        return self._spline(np.asarray(t, dtype=np.float64), 1)

    def frame(self, t) -> np.ndarray:
        if not math.isfinite(self.earth_radius_m):
            return super().frame(t)
        p = self.position(t)
        return rotation_about_y(np.arctan2(p[..., 0], p[..., 2] + self.earth_radius_m))

    def shifted(self, dx_m: float, dy_m: float) -> "SampledEphemeris":
        return SampledEphemeris(self.time_s, self.position_m + np.array([dx_m, dy_m, 0.0]),
                                earth_radius_m=self.earth_radius_m)

    def attrs(self) -> dict:
        return {"trajectory": self.kind, "altitude_m": self.altitude_m, "ground_speed_m_s": self.ground_speed_m_s,
                "earth_radius_m": self.earth_radius_m}


#: ``[platform] trajectory`` kinds written by the scenario (``ephemeris`` is read from products)
TRAJECTORY_KINDS = ("straight", "orbit")


def trajectory_from_attrs(attrs, *, ephemeris_time=None, ephemeris=None) -> Trajectory:
    """Rebuild the trajectory a product recorded (attributes written by :meth:`Trajectory.attrs`).

    A product written before trajectories had kinds has no ``trajectory``
    attribute: it is a straight track. ``ephemeris`` alone (with its times)
    gives a :class:`SampledEphemeris`.
    """
    kind = str(attrs.get("trajectory", "straight"))
    if kind == "straight":
        return StraightTrack(altitude_m=float(attrs["altitude_m"]), speed_m_s=float(attrs["ground_speed_m_s"]),
                             x_at_t0_m=float(attrs["platform_x_at_t0_m"]), y_m=float(attrs["platform_y_m"]))
    if kind == "orbit":
        return CircularOrbit(altitude_m=float(attrs["altitude_m"]),
                             inclination_rad=float(attrs["orbit_inclination_rad"]),
                             theta0_rad=float(attrs["orbit_theta0_rad"]), y_m=float(attrs["platform_y_m"]),
                             earth_radius_m=float(attrs["earth_radius_m"]), mu_m3_s2=float(attrs["earth_mu_m3_s2"]),
                             earth_rotation_rad_s=float(attrs["earth_rotation_rad_s"]))
    if kind == "ephemeris":
        if ephemeris is None:
            raise KeyError("ephemeris")
        return SampledEphemeris(ephemeris_time, ephemeris, earth_radius_m=float(attrs.get("earth_radius_m", math.inf)))
    raise ValueError(f"trajectory: unknown kind {kind!r} (known: straight, orbit, ephemeris)")
