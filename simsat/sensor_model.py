"""Sensor model of a push-broom instrument: direct and inverse location.

Pure NumPy, float64, independent of the Mitsuba renderer (the geometry tests
compare the two implementations).

Conventions
-----------
* Local frame: x along-track, y across-track, z up [m].
* Attitude of the line of sight: angles ``(roll, pitch, yaw)`` [rad] about the
  body x, y, z axes; body → local rotation ``R = Rz(yaw) · Ry(pitch) · Rx(roll)``.
  A positive roll moves the ground point towards +y (columns), a positive pitch
  towards -x (lines), yaw rotates the line (seen at the field edges in lines).
* Image coordinates: ``line`` (time: ``t = t0 + line · Te``, line centre of the
  integration window) and ``column`` (pixel centres at integer values).
* An *attitude* argument is any callable ``attitude(t) -> (roll, pitch, yaw)``
  of arrays of times [s] (e.g. ``AttitudeModel.evaluate`` or
  ``AttitudeSeries.at``).
"""
from __future__ import annotations

from typing import Callable

import numpy as np

from .instrument import Detector, Instrument
from .platform import Platform, rotation_matrices

__all__ = ["rotation_matrices", "los_body", "intersect_dem", "SensorModel", "constant_attitude",
           "offset_attitude", "tdi_mean_attitude", "flat_ground_delay_s"]

AttitudeFn = Callable[[np.ndarray], tuple]


def los_body(focal_length_m: float, x_m, y_m) -> np.ndarray:
    """Unit body-frame line of sight of focal-plane points ``(x, y)`` [m], shape (..., 3)."""
    x, y = np.broadcast_arrays(np.asarray(x_m, dtype=np.float64), np.asarray(y_m, dtype=np.float64))
    d = np.stack([x / focal_length_m, y / focal_length_m, -np.ones_like(x)], axis=-1)
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def flat_ground_delay_s(platform, instrument, ahead, behind) -> float:
    """Delay τ [s] after which detector ``behind`` sees what ``ahead`` saw, in the platform's nominal pointing.

    The one place τ is computed. The line of sight of ``ahead``'s central
    pixel meets flat ground (z = 0) at the along-track position ``x_A`` at the
    platform's reference time (the scan's zero, the middle of the
    acquisition); τ is the time after which ``behind``'s central pixel looks at
    ``x_A`` — the platform's motion, its orbit and its scan (spin, mirror)
    all enter through :meth:`Platform.nominal_ground_point`. At nadir over a
    straight track ``τ = H (a − b) / (f v)``; rolled by φ, ``τ = H (a − b) /
    (f v cos φ)``; swept by a scan at ``ω`` from a fixed point, ``τ = (a − b) /
    (f ω)`` (small angles).
    """
    f = instrument.focal_length_m
    t_ref = platform.scan.t_ref_s

    def los(det) -> np.ndarray:
        return los_body(f, det.along_m, det.focal_plane_y(0.5 * (det.pixels - 1)))

    a, b = instrument.detector(ahead), instrument.detector(behind)
    x_a = float(platform.nominal_ground_point(t_ref, los(a))[0])
    lb = los(b)
    tau = (a.along_m - b.along_m) / f * platform.altitude_m / platform.ground_speed_m_s  # nadir guess
    for _ in range(30):  # secant on x_B(t_ref + τ) = x_A
        h = max(abs(tau) * 1e-3, 1e-9)
        x0 = float(platform.nominal_ground_point(t_ref + tau, lb)[0])
        x1 = float(platform.nominal_ground_point(t_ref + tau + h, lb)[0])
        step = (x_a - x0) * h / (x1 - x0)
        tau += step
        if abs(step) < 1e-15 + 1e-13 * abs(tau):
            break
    return float(tau)


def constant_attitude(roll: float = 0.0, pitch: float = 0.0, yaw: float = 0.0) -> AttitudeFn:
    """An attitude callable returning constant angles [rad]."""
    def fn(t):
        t = np.asarray(t, dtype=np.float64)
        return (np.full(t.shape, roll), np.full(t.shape, pitch), np.full(t.shape, yaw))
    return fn


def offset_attitude(attitude: AttitudeFn, droll: float = 0.0, dpitch: float = 0.0, dyaw: float = 0.0) -> AttitudeFn:
    """An attitude callable equal to ``attitude`` plus constant offsets [rad]."""
    def fn(t):
        r, p, y = attitude(t)
        return (np.asarray(r) + droll, np.asarray(p) + dpitch, np.asarray(y) + dyaw)
    return fn


def tdi_mean_attitude(attitude: AttitudeFn, stages: int, line_period_s: float) -> AttitudeFn:
    """The attitude a TDI line dated ``t`` shows: the mean of ``attitude(t − k Te)`` over its ``stages``.

    A TDI pixel integrates stage k (row ``along_m + k pitch``) at ``t − k Te``;
    under jitter its image position is the mean of the stages' positions, i.e.
    (to first order in the attitude) that of the mean attitude. Using the
    attitude at the date instead is off by about ``(N − 1) Te / 2`` of delay
    (CNES §3.3.4: "the correction Pan signal must be out of phase with the
    correction XS signal").
    """
    if stages <= 1:
        return attitude
    offsets = np.arange(stages) * float(line_period_s)

    def fn(t):
        t = np.asarray(t, dtype=np.float64)
        acc = [np.zeros(t.shape), np.zeros(t.shape), np.zeros(t.shape)]
        for dt in offsets:
            for i, a in enumerate(attitude(t - dt)):
                acc[i] = acc[i] + np.asarray(a)
        return tuple(a / stages for a in acc)
    return fn


def intersect_dem(dem, origins, directions, *, max_steps: int = 256, bisections: int = 40) -> np.ndarray:
    """First intersection of rays with a gridded DEM (bilinear surface).

    Marches each ray from above the highest terrain down to below the lowest,
    with steps no longer than half a DEM cell horizontally, finds the first
    sign change of ``z(s) - h(x(s), y(s))`` and refines it by bisection.

    Parameters
    ----------
    dem : simsat.terrain.Dem
        Gridded heights with ``height(x, y)`` (NaN outside), ``z_min``,
        ``z_max``, ``dx_m``, ``dy_m``.
    origins, directions : array_like, shape (..., 3)
        Ray origins [m] (above the terrain) and directions (pointing down).

    Returns
    -------
    ndarray, shape (..., 3)
        Ground points [m]; NaN where the ray misses the DEM.
    """
    o = np.asarray(origins, dtype=np.float64)
    d = np.asarray(directions, dtype=np.float64)
    o, d = np.broadcast_arrays(o, d)
    shape = o.shape[:-1]
    o = o.reshape(-1, 3)
    d = d.reshape(-1, 3)
    if np.any(d[:, 2] >= 0):
        raise ValueError("directions: every ray must point downwards (d_z < 0)")
    z_top = float(dem.z_max) + 1.0
    z_bot = float(dem.z_min) - 1.0
    s_top = (o[:, 2] - z_top) / (-d[:, 2])
    s_bot = (o[:, 2] - z_bot) / (-d[:, 2])
    horiz = (s_bot - s_top) * np.hypot(d[:, 0], d[:, 1])
    cell = 0.5 * min(float(dem.dx_m), float(dem.dy_m))
    n = int(np.clip(np.ceil(np.max(horiz) / cell) if horiz.size else 1, 1, max_steps))

    def f(s):
        p = o + s[:, None] * d
        return p[:, 2] - dem.height(p[:, 0], p[:, 1])

    lo = s_top.copy()
    f_lo = f(lo)
    hi = np.full_like(lo, np.nan)
    found = np.zeros(lo.shape, dtype=bool)
    for k in range(1, n + 1):
        s = s_top + (s_bot - s_top) * (k / n)
        fs = f(s)
        cross = ~found & (fs <= 0) & np.isfinite(fs)
        hi[cross] = s[cross]
        found |= cross
        adv = ~found
        lo[adv] = s[adv]
        f_lo[adv] = fs[adv]
        if found.all():
            break
    out = np.full(o.shape, np.nan)
    if found.any():
        a = lo[found]
        b = hi[found]
        of, df = o[found], d[found]
        for _ in range(bisections):
            m = 0.5 * (a + b)
            p = of + m[:, None] * df
            fm = p[:, 2] - dem.height(p[:, 0], p[:, 1])
            above = fm > 0
            a = np.where(above, m, a)
            b = np.where(above, b, m)
        s = 0.5 * (a + b)
        out[found] = of + s[:, None] * df
    return out.reshape(shape + (3,))


class SensorModel:
    """Direct and inverse location for a push-broom instrument.

    Parameters
    ----------
    platform : Platform
    instrument : Instrument
    dem : simsat.terrain.Dem
        The DEM used to intersect lines of sight (the ground segment uses the
        DEM it knows, the truth uses the true one).
    attitude : callable
        Default attitude ``attitude(t) -> (roll, pitch, yaw)`` [rad].
    t0_s : float
        Time of line 0 [s].
    """

    def __init__(self, *, platform: Platform, instrument: Instrument, dem, attitude: AttitudeFn, t0_s: float = 0.0):
        self.platform = platform
        self.instrument = instrument
        self.dem = dem
        self.attitude = attitude
        self.t0_s = float(t0_s)

    # -- time ------------------------------------------------------------------
    @property
    def line_period_s(self) -> float:
        return self.instrument.line_period_s

    def line_time(self, line) -> np.ndarray:
        """Time [s] of (fractional) lines."""
        return self.t0_s + np.asarray(line, dtype=np.float64) * self.instrument.line_period_s

    def time_line(self, t) -> np.ndarray:
        """Fractional line of times ``t`` [s]."""
        return (np.asarray(t, dtype=np.float64) - self.t0_s) / self.instrument.line_period_s

    def _det(self, detector) -> Detector:
        return detector if isinstance(detector, Detector) else self.instrument.detector(detector)

    def nominal_delay_s(self, ahead, behind) -> float:
        """Nominal delay τ [s] after which detector ``behind`` sees what ``ahead`` saw (:func:`flat_ground_delay_s`)."""
        self._det(ahead), self._det(behind)
        return flat_ground_delay_s(self.platform, self.instrument, ahead, behind)

    # -- direct location -----------------------------------------------------
    def viewing_rays(self, detector, lines, columns, *, attitude: AttitudeFn | None = None):
        """Origins and unit directions (local frame) of the lines of sight.

        Returns
        -------
        origins, directions : ndarray, shape (..., 3)
        """
        det = self._det(detector)
        att = attitude or self.attitude
        lines, columns = np.broadcast_arrays(np.asarray(lines, dtype=np.float64),
                                             np.asarray(columns, dtype=np.float64))
        t = self.line_time(lines)
        r = self.platform.pointing(t, *att(t))
        b = los_body(self.instrument.focal_length_m, det.along_m, det.focal_plane_y(columns))
        d = np.einsum("...ij,...j->...i", r, b)
        return self.platform.position(t), d

    def direct_location(self, detector, lines, columns, *, attitude: AttitudeFn | None = None, dem=None) -> np.ndarray:
        """Ground point (x, y, z) [m] seen by ``detector`` at (line, column).

        Parameters
        ----------
        detector : str or Detector
        lines, columns : array_like
            Fractional image coordinates (broadcast together).
        attitude : callable, optional
            Attitude to use (default: the model's).
        dem : Dem, optional
            DEM to intersect (default: the model's).
        """
        o, d = self.viewing_rays(detector, lines, columns, attitude=attitude)
        return intersect_dem(dem or self.dem, o, d)

    # -- inverse location ----------------------------------------------------
    def _first_guess_time(self, det: Detector, g: np.ndarray, att: AttitudeFn) -> np.ndarray:
        """Time at which ``det``'s central line of sight, at the attitude of line 0, crosses each point's x.

        Its ground x at each point's height, at t₀ and t₀ + 1 s, gives the
        sweep rate (the track, the orbit, the scan: whatever the platform does);
        one secant step from t₀. Newton refines it.
        """
        p = self.platform
        t0 = np.array([self.t0_s, self.t0_s + 1.0])
        r = p.pointing(t0, *att(np.full(2, self.t0_s)))
        d = r @ los_body(self.instrument.focal_length_m, det.along_m, 0.0)  # (2, 3)
        s = p.position(t0)
        x = s[:, None, 0] + (s[:, None, 2] - g[None, :, 2]) * d[:, None, 0] / (-d[:, None, 2])  # (2, n)
        return self.t0_s + (g[:, 0] - x[0]) / (x[1] - x[0])

    def _along_residual(self, det: Detector, g: np.ndarray, t: np.ndarray, att: AttitudeFn):
        r = self.platform.pointing(t, *att(t))
        v = g - self.platform.position(t)
        b = np.einsum("...ji,...j->...i", r, v)  # R^T v
        a = det.along_m / self.instrument.focal_length_m
        return b[..., 0] / (-b[..., 2]) - a, b

    def inverse_location(self, detector, ground, *, attitude: AttitudeFn | None = None, max_iter: int = 30,
                         tol_line: float = 1e-9):
        """Image position (line, column) at which ``detector`` sees ground points.

        Solves for the time t at which the point lies in the plane of the
        detector line (Newton iterations on the along-track body angle), then
        reads the column from the across-track angle.

        Parameters
        ----------
        detector : str or Detector
        ground : array_like, shape (..., 3)
            Ground points [m] in the local frame.
        attitude : callable, optional
        max_iter : int
        tol_line : float
            Convergence tolerance [lines].

        Returns
        -------
        lines, columns : ndarray
            Fractional image coordinates (NaN for NaN inputs).
        """
        det = self._det(detector)
        att = attitude or self.attitude
        g = np.asarray(ground, dtype=np.float64)
        shape = g.shape[:-1]
        g = g.reshape(-1, 3)
        f = self.instrument.focal_length_m
        te = self.instrument.line_period_s
        t = self._first_guess_time(det, g, att)
        h = 0.05 * te
        ok = np.isfinite(t)
        t = np.where(ok, t, self.t0_s)
        f0, _ = self._along_residual(det, g, t, att)
        for _ in range(max_iter):
            f1, _ = self._along_residual(det, g, t + h, att)
            deriv = (f1 - f0) / h
            step = -f0 / deriv
            step = np.clip(step, -50 * te, 50 * te)
            ok &= np.isfinite(step)  # a NaN ground point (or a flat residual) stays out, never a NaN time
            step = np.where(ok, step, 0.0)
            # safeguarded Newton: a step that does not reduce |residual| is halved (fast jitter of
            # several pixels makes the residual's slope change within a step and plain Newton cycle)
            t_new = t + step
            f_new, _ = self._along_residual(det, g, t_new, att)
            for _ in range(8):
                worse = ok & ~(np.abs(f_new) < np.abs(f0)) & (step != 0)
                if not worse.any():
                    break
                step = np.where(worse, 0.5 * step, step)
                t_new = np.where(worse, t + step, t_new)
                f_new[worse] = self._along_residual(det, g[worse], t_new[worse], att)[0]
            t, f0 = t_new, f_new
            if np.nanmax(np.abs(step)) < tol_line * te:
                break
        _, b = self._along_residual(det, g, t, att)
        cols = det.column_of_y(f * b[:, 1] / (-b[:, 2]))
        lines = self.time_line(t)
        lines[~ok] = np.nan
        cols[~ok] = np.nan
        return lines.reshape(shape), cols.reshape(shape)

    # -- sensitivities ------------------------------------------------------------
    def sensitivities(self, detector, ground, *, attitude: AttitudeFn | None = None, step_rad: float = 1e-6) -> np.ndarray:
        """∂(line, column)/∂(roll, pitch, yaw) of the image position of ground points.

        Central finite differences of :meth:`inverse_location` under constant
        attitude offsets of ±``step_rad``.

        Returns
        -------
        ndarray, shape (..., 2, 3)
            ``[..., 0, k]`` = ∂line/∂θ_k, ``[..., 1, k]`` = ∂column/∂θ_k [px/rad].
        """
        att = attitude or self.attitude
        g = np.asarray(ground, dtype=np.float64)
        out = np.empty(g.shape[:-1] + (2, 3))
        for k in range(3):
            dp = [0.0, 0.0, 0.0]
            dm = [0.0, 0.0, 0.0]
            dp[k] = step_rad
            dm[k] = -step_rad
            lp, cp = self.inverse_location(detector, g, attitude=offset_attitude(att, *dp))
            lm, cm = self.inverse_location(detector, g, attitude=offset_attitude(att, *dm))
            out[..., 0, k] = (lp - lm) / (2 * step_rad)
            out[..., 1, k] = (cp - cm) / (2 * step_rad)
        return out
