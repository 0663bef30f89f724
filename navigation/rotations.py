"""Rotation helpers (SO(3)) in float64: skew matrices, exponential and logarithm maps."""
from __future__ import annotations

import numpy as np

__all__ = ["skew", "exp_so3", "log_so3", "rot_x", "rot_y", "rot_z", "body_to_world"]


def skew(v) -> np.ndarray:
    """Cross-product matrix ``[v×]`` (…, 3, 3) with ``[v×] u = v × u``."""
    v = np.asarray(v, dtype=np.float64)
    z = np.zeros(v.shape[:-1])
    return np.stack([np.stack([z, -v[..., 2], v[..., 1]], -1),
                     np.stack([v[..., 2], z, -v[..., 0]], -1),
                     np.stack([-v[..., 1], v[..., 0], z], -1)], -2)


def exp_so3(phi) -> np.ndarray:
    """Rotation matrix of the rotation vector ``phi`` (…, 3) (Rodrigues, exact for any angle)."""
    phi = np.asarray(phi, dtype=np.float64)
    a = np.linalg.norm(phi, axis=-1)[..., None, None]
    k = skew(phi)
    small = a < 1e-8
    a_safe = np.where(small, 1.0, a)
    s = np.where(small, 1.0 - a ** 2 / 6.0, np.sin(a_safe) / a_safe)
    c = np.where(small, 0.5 - a ** 2 / 24.0, (1.0 - np.cos(a_safe)) / a_safe ** 2)
    return np.eye(3) + s * k + c * (k @ k)


def log_so3(r) -> np.ndarray:
    """Rotation vector (…, 3) of the rotation matrix ``r`` (angles below π)."""
    r = np.asarray(r, dtype=np.float64)
    cos_a = np.clip((np.trace(r, axis1=-2, axis2=-1) - 1.0) / 2.0, -1.0, 1.0)
    a = np.arccos(cos_a)
    w = np.stack([r[..., 2, 1] - r[..., 1, 2], r[..., 0, 2] - r[..., 2, 0], r[..., 1, 0] - r[..., 0, 1]], -1)
    s = np.sin(a)
    f = np.where(a < 1e-6, 0.5 + a ** 2 / 12.0, a / (2.0 * np.where(a < 1e-6, 1.0, s)))
    return f[..., None] * w


def rot_x(a) -> np.ndarray:
    """Right-handed rotation about x by ``a`` rad (…, 3, 3)."""
    a = np.asarray(a, dtype=np.float64)
    c, s, o, z = np.cos(a), np.sin(a), np.ones_like(a), np.zeros_like(a)
    return np.stack([np.stack([o, z, z], -1), np.stack([z, c, -s], -1), np.stack([z, s, c], -1)], -2)


def rot_y(a) -> np.ndarray:
    """Right-handed rotation about y by ``a`` rad (…, 3, 3)."""
    a = np.asarray(a, dtype=np.float64)
    c, s, o, z = np.cos(a), np.sin(a), np.ones_like(a), np.zeros_like(a)
    return np.stack([np.stack([c, z, s], -1), np.stack([z, o, z], -1), np.stack([-s, z, c], -1)], -2)


def rot_z(a) -> np.ndarray:
    """Right-handed rotation about z by ``a`` rad (…, 3, 3)."""
    a = np.asarray(a, dtype=np.float64)
    c, s, o, z = np.cos(a), np.sin(a), np.ones_like(a), np.zeros_like(a)
    return np.stack([np.stack([c, -s, z], -1), np.stack([s, c, z], -1), np.stack([z, z, o], -1)], -2)


def body_to_world(heading, climb, bank) -> np.ndarray:
    """Attitude ``R_wb`` (body x forward, y left, z up → world) from heading, climb and bank angles.

    ``heading`` is counter-clockwise from world +x, ``climb`` nose up and
    ``bank`` right wing down, all in rad: ``R = Rz(heading) Ry(-climb) Rx(bank)``.
    """
    return rot_z(heading) @ rot_y(-np.asarray(climb, dtype=np.float64)) @ rot_x(bank)
