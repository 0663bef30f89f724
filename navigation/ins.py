"""Strapdown INS mechanisation over a flat, non-rotating Earth (world z up).

The IMU delivers increments over each sample interval: the rotation vector
``dtheta`` (body, rad) and the velocity increment ``dv`` (body, m/s, specific
force integrated). One step::

    R⁺ = R · exp(dθ)
    v⁺ = v + R · exp(dθ/2) · dv + g Δt
    p⁺ = p + (v + v⁺) Δt / 2
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .rotations import exp_so3

__all__ = ["GRAVITY", "NavState", "ins_step", "mechanise"]

#: gravity vector of the world frame (m/s², z up)
GRAVITY = np.array([0.0, 0.0, -9.80665])


@dataclass
class NavState:
    """Position (m), velocity (m/s) and attitude ``R_wb`` of the INS at time ``t`` (s)."""

    t: float
    p: np.ndarray
    v: np.ndarray
    R: np.ndarray

    def copy(self) -> "NavState":
        return NavState(float(self.t), self.p.copy(), self.v.copy(), self.R.copy())


def ins_step(state: NavState, dtheta: np.ndarray, dv: np.ndarray, dt: float) -> NavState:
    """Advance ``state`` by one IMU interval ``dt`` with increments ``dtheta``, ``dv`` (body frame)."""
    r_mid = state.R @ exp_so3(0.5 * dtheta)
    v_new = state.v + r_mid @ dv + GRAVITY * dt
    p_new = state.p + 0.5 * (state.v + v_new) * dt
    r_new = state.R @ exp_so3(dtheta)
    return NavState(state.t + dt, p_new, v_new, r_new)


def mechanise(state0: NavState, dtheta: np.ndarray, dv: np.ndarray, dt: float):
    """Integrate ``n`` IMU increments from ``state0`` → positions, velocities (n + 1, 3), attitudes (n + 1, 3, 3).

    Vectorised over time: the attitude chain is a cumulative product of the
    increments' rotation matrices (computed in blocks), then velocity and
    position are cumulative sums.
    """
    dtheta = np.asarray(dtheta, dtype=np.float64)
    dv = np.asarray(dv, dtype=np.float64)
    n = len(dtheta)
    inc = exp_so3(dtheta)
    half = exp_so3(0.5 * dtheta)
    rs = np.empty((n + 1, 3, 3))
    rs[0] = state0.R
    r = state0.R.copy()
    for k in range(n):  # 3×3 products: the chain is inherently sequential but cheap
        r = r @ inc[k]
        rs[k + 1] = r
    dv_w = np.einsum("kij,kjl,kl->ki", rs[:-1], half, dv) + GRAVITY * dt
    v = np.concatenate([state0.v[None], state0.v + np.cumsum(dv_w, axis=0)])
    p = np.concatenate([state0.p[None], state0.p + np.cumsum(0.5 * (v[:-1] + v[1:]) * dt, axis=0)])
    return p, v, rs
