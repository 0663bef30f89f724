"""The true flight: a low-level route with turns and terrain-following altitude, and the IMU's true increments.

The route is built in two steps so that the terrain can be generated around it:
:func:`plan_route` (horizontal track: constant ground speed, smooth turns with
coordinated bank) and :func:`fly` (altitude above the terrain, attitude,
velocity; positions integrate the sampled velocity with the same trapezoid
rule as the INS). :func:`true_increments` then gives the increments a
perfect integrating IMU would output, so that mechanising them reproduces the
truth to rounding: every INS error comes from the IMU's errors.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.ndimage import gaussian_filter1d, maximum_filter1d

from .ins import GRAVITY
from .rotations import body_to_world, exp_so3, log_so3

__all__ = ["RoutePlan", "Flight", "plan_route", "fly", "true_increments"]


@dataclass
class RoutePlan:
    """Horizontal track sampled at the IMU rate."""

    t: np.ndarray            # (n,) s
    xy: np.ndarray           # (n, 2) m
    heading: np.ndarray      # (n,) rad, counter-clockwise from +x
    heading_rate: np.ndarray  # (n,) rad/s
    speed_mps: float

    @property
    def distance_m(self) -> np.ndarray:
        return self.speed_mps * self.t


@dataclass
class Flight:
    """The true trajectory sampled at the IMU rate (world frame, z up)."""

    t: np.ndarray     # (n,)
    p: np.ndarray     # (n, 3)
    v: np.ndarray     # (n, 3)
    R: np.ndarray     # (n, 3, 3) body → world
    agl: np.ndarray   # (n,) height above the terrain (m)
    distance_m: np.ndarray

    @property
    def dt(self) -> float:
        return float(self.t[1] - self.t[0])

    def index_at(self, t: float) -> int:
        return int(round((t - self.t[0]) / self.dt))


def plan_route(*, length_m: float, speed_mps: float, rate_hz: float, turns: int, max_bank_deg: float,
               rng: np.random.Generator, heading0_rad: float = 0.0) -> RoutePlan:
    """A track of ``length_m`` at ``speed_mps`` with ``turns`` smooth turns (raised-cosine bank profiles).

    Each turn changes the heading by 25–90° (random sign) over a duration
    chosen so that the coordinated bank ``atan(V ψ̇ / g)`` peaks at most at
    ``max_bank_deg``; turns are spread over the route with straight legs between.
    """
    T = length_m / speed_mps
    dt = 1.0 / rate_hz
    t = np.arange(int(round(T * rate_hz)) + 1) * dt
    rate = np.zeros_like(t)
    if turns:
        slots = np.linspace(0.08 * T, 0.92 * T, turns + 1)
        for a, b in zip(slots[:-1], slots[1:]):
            dpsi = math.radians(rng.uniform(25, 90)) * rng.choice([-1.0, 1.0])
            peak_rate = 9.80665 * math.tan(math.radians(max_bank_deg) * rng.uniform(0.5, 1.0)) / speed_mps
            dur = min(max(2.0 * abs(dpsi) / peak_rate, 8.0), 0.8 * (b - a))
            t0 = rng.uniform(a, b - dur)
            m = (t >= t0) & (t <= t0 + dur)
            rate[m] += dpsi / dur * (1.0 - np.cos(2 * np.pi * (t[m] - t0) / dur))
    heading = heading0_rad + np.concatenate([[0.0], np.cumsum(0.5 * (rate[1:] + rate[:-1]) * dt)])
    vxy = speed_mps * np.stack([np.cos(heading), np.sin(heading)], 1)
    xy = np.concatenate([[[0.0, 0.0]], np.cumsum(0.5 * (vxy[1:] + vxy[:-1]) * dt, axis=0)])
    return RoutePlan(t, xy, heading, rate, float(speed_mps))


def fly(route: RoutePlan, height_fn, *, agl_min_m: float, agl_max_m: float, rng: np.random.Generator,
        climb_limit_deg: float = 8.0) -> Flight:
    """Terrain-following altitude over ``height_fn(x, y)`` between ``agl_min_m`` and ``agl_max_m``.

    The wanted altitude is the terrain's running maximum over ±15 s, smoothed
    over 6 s, plus a height above ground that wanders between the bounds over
    ~60 s; the vertical speed is its derivative (climb angle clipped), and the
    altitude integrates the vertical speed.
    """
    t, dt = route.t, route.t[1] - route.t[0]
    ground = height_fn(route.xy[:, 0], route.xy[:, 1])
    win = max(int(15.0 / dt), 1)
    cover = gaussian_filter1d(maximum_filter1d(ground, 2 * win + 1, mode="nearest"), 6.0 / dt, mode="nearest")
    knots = np.linspace(t[0], t[-1], max(int((t[-1] - t[0]) / 60.0), 1) + 2)
    lift = np.interp(t, knots, rng.uniform(0.2, 0.8, len(knots)))
    lift = gaussian_filter1d(lift, 10.0 / dt, mode="nearest")
    z_want = cover + agl_min_m + lift * (agl_max_m - agl_min_m)
    vz = np.gradient(z_want, dt)
    vmax = route.speed_mps * math.tan(math.radians(climb_limit_deg))
    vz = gaussian_filter1d(np.clip(vz, -vmax, vmax), 1.0 / dt, mode="nearest")
    z = z_want[0] + np.concatenate([[0.0], np.cumsum(0.5 * (vz[1:] + vz[:-1]) * dt)])
    v = np.column_stack([route.speed_mps * np.cos(route.heading), route.speed_mps * np.sin(route.heading), vz])
    climb = np.arctan2(vz, route.speed_mps)
    bank = np.arctan(-route.speed_mps * route.heading_rate / -GRAVITY[2])
    R = body_to_world(route.heading, climb, bank)
    p = np.column_stack([route.xy, z])
    return Flight(t=t, p=p, v=v, R=R, agl=z - ground, distance_m=route.distance_m)


def true_increments(flight: Flight):
    """Increments ``(dθ, dv)`` (n − 1, 3) of a perfect integrating IMU along ``flight`` (body frame).

    ``dθ = log(R_kᵀ R_k+1)`` and ``dv = (R_k exp(dθ/2))ᵀ (v_k+1 − v_k − g Δt)``:
    exactly what :func:`~navigation.ins.ins_step` needs to reproduce the truth.
    """
    R, v, dt = flight.R, flight.v, flight.dt
    dtheta = log_so3(np.einsum("kji,kjl->kil", R[:-1], R[1:]))
    r_mid = R[:-1] @ exp_so3(0.5 * dtheta)
    dv = np.einsum("kji,kj->ki", r_mid, v[1:] - v[:-1] - GRAVITY * dt)
    return dtheta, dv
