"""Platform trajectory in the local ground frame.

The scene is small (tens of km) compared with the orbit, so the platform is
modelled as flying a straight line at constant altitude above the local
East-North-Up tangent frame, along +x of its orbit frame, which is aligned with
the local frame's x axis (x along-track, y across-track, z up). Positions are
float64 metres in that local frame, centred on the scene.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .config import Section

__all__ = ["Platform", "platform_from_config"]


@dataclass(frozen=True)
class Platform:
    """Straight, constant-speed, constant-altitude trajectory.

    Parameters
    ----------
    altitude_m : float
        Height of the platform above the local frame origin [m].
    ground_speed_m_s : float
        Speed of the sub-satellite point along +x [m/s].
    x_at_t0_m, y_m : float
        Position of the platform at t = 0 [m] (x) and its constant y [m].
    off_nadir_roll_rad, off_nadir_pitch_rad : float
        Nominal pointing of the line of sight (added to the attitude model).
    """

    altitude_m: float
    ground_speed_m_s: float
    x_at_t0_m: float = 0.0
    y_m: float = 0.0
    off_nadir_roll_rad: float = 0.0
    off_nadir_pitch_rad: float = 0.0

    def position(self, t) -> np.ndarray:
        """Platform position at times ``t`` [s] → array (..., 3) [m]."""
        t = np.asarray(t, dtype=np.float64)
        out = np.empty(t.shape + (3,), dtype=np.float64)
        out[..., 0] = self.x_at_t0_m + self.ground_speed_m_s * t
        out[..., 1] = self.y_m
        out[..., 2] = self.altitude_m
        return out

    def velocity(self) -> np.ndarray:
        """Constant velocity vector [m/s]."""
        return np.array([self.ground_speed_m_s, 0.0, 0.0])

    def centred(self, *, t_mid_s: float, along_angle_rad: float = 0.0) -> "Platform":
        """Copy whose nominal line of sight hits (0, 0, 0) at ``t_mid_s``.

        ``along_angle_rad`` is the along-track angle of the focal-plane point
        that should be centred (e.g. the mean of the detector positions / f).
        """
        h = self.altitude_m
        # Ry(pitch) (a, 0, -1) has x = a cos p - sin p: the ground x is S_x + H tan(atan(a) - p).
        x_mid = -h * np.tan(along_angle_rad - self.off_nadir_pitch_rad)
        # Rx(roll) (0,0,-1) = (0, sin r, -cos r): the ground y is S_y + H tan r.
        y = -h * np.tan(self.off_nadir_roll_rad)
        return Platform(altitude_m=h, ground_speed_m_s=self.ground_speed_m_s,
                        x_at_t0_m=float(x_mid - self.ground_speed_m_s * t_mid_s), y_m=float(y),
                        off_nadir_roll_rad=self.off_nadir_roll_rad, off_nadir_pitch_rad=self.off_nadir_pitch_rad)


def platform_from_config(sec: Section) -> Platform:
    """Build a :class:`Platform` from the ``[platform]`` table (not yet centred)."""
    h = sec.number("altitude_m", gt=1000.0, le=5e7)  # up to beyond geostationary (3.6e7 m)
    v = sec.number("ground_speed_m_s", gt=0, le=2e4)  # LEO ground speed is ~7e3 m/s
    roll = np.deg2rad(sec.number("off_nadir_roll_deg", 0.0, ge=-45, le=45))
    pitch = np.deg2rad(sec.number("off_nadir_pitch_deg", 0.0, ge=-45, le=45))
    sec.finish()
    return Platform(altitude_m=h, ground_speed_m_s=v, off_nadir_roll_rad=float(roll), off_nadir_pitch_rad=float(pitch))
