"""Kalman filter with textbook names, in function and class forms that agree (as filterpy does).

:func:`kf_predict` / :func:`kf_update` are the equations; :class:`KalmanFilter`
holds ``x, P, F, Q`` and calls them. :func:`ins_error_dynamics` gives the
15-state error model of the strapdown INS (:mod:`.ins`):

====  ==========  =========================================
idx   state       meaning (INS minus truth)
====  ==========  =========================================
0–2   δp          position error, world (m)
3–5   δv          velocity error, world (m/s)
6–8   δθ          attitude error, world (rad): R_ins = exp(δθ) R
9–11  δb_a        accelerometer bias not yet compensated (m/s²)
12–14 δb_g        gyro bias not yet compensated (rad/s)
15–17 δs_a        accelerometer scale factors (1)
18–20 δs_g        gyro scale factors (1)
====  ==========  =========================================

The scale factors matter over turns (300 ppm of a 90° turn is 0.5 mrad of
heading): a filter without them is overconfident after every turn.
"""
from __future__ import annotations

import numpy as np

from .rotations import skew

__all__ = ["kf_predict", "kf_update", "KalmanFilter", "ins_error_dynamics", "N_STATES", "P_", "V_", "TH_", "BA_",
           "BG_", "SA_", "SG_"]

N_STATES = 21
P_, V_, TH_, BA_, BG_ = slice(0, 3), slice(3, 6), slice(6, 9), slice(9, 12), slice(12, 15)
SA_, SG_ = slice(15, 18), slice(18, 21)


def kf_predict(x: np.ndarray, P: np.ndarray, F: np.ndarray, Q: np.ndarray):
    """Prior ``(x⁻, P⁻) = (F x, F P Fᵀ + Q)``."""
    x = F @ x
    P = F @ P @ F.T + Q
    return x, 0.5 * (P + P.T)


def kf_update(x: np.ndarray, P: np.ndarray, z: np.ndarray, H: np.ndarray, R: np.ndarray):
    """Posterior of a linear measurement ``z = H x + v``, ``v ~ N(0, R)`` (Joseph form).

    Returns ``(x⁺, P⁺, y, S)`` with the innovation ``y = z − H x`` and its
    covariance ``S = H P Hᵀ + R``.
    """
    y = z - H @ x
    S = H @ P @ H.T + R
    K = np.linalg.solve(S, H @ P).T          # P Hᵀ S⁻¹ (S and P symmetric)
    x = x + K @ y
    ikh = np.eye(len(x)) - K @ H
    P = ikh @ P @ ikh.T + K @ R @ K.T
    return x, 0.5 * (P + P.T), y, S


class KalmanFilter:
    """The same equations, holding the state: ``predict()`` then ``update(z, H, R)``."""

    def __init__(self, x: np.ndarray, P: np.ndarray):
        self.x = np.asarray(x, dtype=np.float64).copy()
        self.P = np.asarray(P, dtype=np.float64).copy()
        self.y = None
        self.S = None

    def predict(self, F: np.ndarray, Q: np.ndarray) -> None:
        self.x, self.P = kf_predict(self.x, self.P, F, Q)

    def update(self, z: np.ndarray, H: np.ndarray, R: np.ndarray) -> None:
        self.x, self.P, self.y, self.S = kf_update(self.x, self.P, z, H, R)

    @property
    def nis(self) -> float:
        """Normalised innovation squared of the last update, ``yᵀ S⁻¹ y``."""
        return float(self.y @ np.linalg.solve(self.S, self.y))


def ins_error_dynamics(f_world: np.ndarray, R_wb: np.ndarray, dt: float, *, accel_vrw: float, gyro_arw: float,
                       accel_bias_rw: float = 0.0, gyro_bias_rw: float = 0.0, omega_body=None):
    """Discrete transition ``F`` and process noise ``Q`` of the INS error state over ``dt``.

    Continuous model: δṗ = δv, δv̇ = −[f×] δθ + R (δb_a + diag(f_b) δs_a),
    δθ̇ = R (δb_g + diag(ω_b) δs_g), biases random walks, scale factors
    constant; ``F = I + A dt + A² dt²/2``, ``Q`` from the noise densities
    (white noises integrated over ``dt``). ``omega_body`` (rad/s) defaults to 0.
    """
    A = np.zeros((N_STATES, N_STATES))
    A[P_, V_] = np.eye(3)
    A[V_, TH_] = -skew(f_world)
    A[V_, BA_] = R_wb
    A[TH_, BG_] = R_wb
    A[V_, SA_] = R_wb * (R_wb.T @ f_world)[None, :]
    A[TH_, SG_] = R_wb * (np.zeros(3) if omega_body is None else np.asarray(omega_body))[None, :]
    F = np.eye(N_STATES) + A * dt + A @ A * (dt * dt / 2.0)
    q = np.zeros(N_STATES)
    q[V_] = accel_vrw ** 2
    q[TH_] = gyro_arw ** 2
    q[BA_] = accel_bias_rw ** 2
    q[BG_] = gyro_bias_rw ** 2
    Qc = np.diag(q)
    # first-order integration of the white noises, with the position picking up the velocity noise
    Q = Qc * dt
    Q[P_, P_] += Qc[V_, V_] * dt ** 3 / 3.0
    Q[P_, V_] += Qc[V_, V_] * dt ** 2 / 2.0
    Q[V_, P_] += Qc[V_, V_] * dt ** 2 / 2.0
    return F, Q
