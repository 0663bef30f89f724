"""The aided navigation loop: INS mechanisation between image sequences, error-state Kalman updates at them.

Between two aiding sequences the INS integrates the compensated IMU
increments (:func:`~navigation.ins.mechanise`) and the filter propagates its
covariance at ``propagation_hz``. At the last frame of a sequence the
measurement of :mod:`.measurement` is gated line by line (χ², 4 residuals
per line, 99.9 %) and fused; the estimated errors are fed back into the INS
(closed loop) and the state reset. A sequence that gives no trustworthy fix
is recorded as "no aiding" with its reason, and the covariance keeps growing.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.stats import chi2

from .ins import NavState, mechanise
from .kalman import BA_, BG_, N_STATES, P_, SA_, SG_, TH_, V_, ins_error_dynamics, kf_update
from .measurement import AidingSettings, sequence_measurement
from .rotations import exp_so3

__all__ = ["Sequence", "InitialErrors", "SeedRun", "run_seed"]


@dataclass
class Sequence:
    """A rendered aiding sequence: IMU sample indices of its frames and each frame's segments."""

    frame_index: np.ndarray
    segments: list
    fog: bool = False


@dataclass(frozen=True)
class InitialErrors:
    position_m: float = 5.0
    velocity_mps: float = 0.1
    attitude_mrad: float = 0.3
    heading_mrad: float = 1.0


@dataclass
class SeedRun:
    t: np.ndarray                  # record times (s)
    unaided: np.ndarray            # (n, 3)
    aided: np.ndarray              # (n, 3)
    sigma: np.ndarray              # (n, 3) 1-σ of the aided position (filter)
    updates: list = field(default_factory=list)


def _initial_state(flight, init: InitialErrors, rng):
    p = flight.p[0] + rng.normal(0, init.position_m, 3)
    v = flight.v[0] + rng.normal(0, init.velocity_mps, 3)
    dth = np.array([rng.normal(0, init.attitude_mrad), rng.normal(0, init.attitude_mrad),
                    rng.normal(0, init.heading_mrad)]) * 1e-3
    return NavState(float(flight.t[0]), p, v, exp_so3(dth) @ flight.R[0])


def _initial_covariance(init: InitialErrors, imu_si: dict) -> np.ndarray:
    q = np.zeros(N_STATES)
    q[P_] = init.position_m ** 2
    q[V_] = init.velocity_mps ** 2
    q[TH_] = (np.array([init.attitude_mrad, init.attitude_mrad, init.heading_mrad]) * 1e-3) ** 2
    q[BA_] = imu_si["accel_bias"] ** 2 + 1e-12
    q[BG_] = imu_si["gyro_bias"] ** 2 + 1e-18
    q[SA_] = imu_si["accel_scale"] ** 2 + 1e-14
    q[SG_] = imu_si["gyro_scale"] ** 2 + 1e-14
    return np.diag(q)


def _propagate(P, p_chunk_R, dv, dtheta, dt, step, imu_si):
    """Covariance over a chunk, ``step`` IMU samples at a time."""
    n = len(dv)
    for k in range(0, n, step):
        m = min(step, n - k)
        f_w = p_chunk_R[k] @ (dv[k:k + m].sum(0) / (m * dt))
        F, Q = ins_error_dynamics(f_w, p_chunk_R[k], m * dt, accel_vrw=imu_si["accel_vrw"],
                                  gyro_arw=imu_si["gyro_arw"], omega_body=dtheta[k:k + m].sum(0) / (m * dt))
        P = F @ P @ F.T + Q
    return 0.5 * (P + P.T)


def _gate_lines(m, P, min_lines: int):
    """Drop lines whose 4 residuals are inconsistent with the prediction (χ²₄ at 99.9 %); None if too few stay."""
    keep = np.ones(len(m.z) // 4, bool)
    lim = chi2.ppf(0.999, 4)
    for _ in range(3):
        rows = np.repeat(keep, 4)
        H, R, z = m.H[rows], m.R[np.ix_(rows, rows)], m.z[rows]
        S = H @ P @ H.T + R
        d2 = []
        for q in range(int(keep.sum())):
            b = slice(4 * q, 4 * q + 4)
            d2.append(z[b] @ np.linalg.solve(S[b, b], z[b]))
        bad = np.array(d2) > lim
        if not bad.any():
            break
        idx = np.flatnonzero(keep)
        keep[idx[bad]] = False
    if keep.sum() < min_lines:
        return None
    rows = np.repeat(keep, 4)
    return m.z[rows], m.H[rows], m.R[np.ix_(rows, rows)], int(keep.sum())


def run_seed(flight, dtheta, dv, sequences: list, camera, ref, dem, imu_model, *, seed: int,
             init: InitialErrors = InitialErrors(), settings: AidingSettings = AidingSettings(),
             record_hz: float = 1.0, propagation_hz: float = 10.0, aiding: bool = True) -> SeedRun:
    """Long: one Monte Carlo run — IMU errors drawn, unaided and aided INS, every update recorded.

    ``dtheta``, ``dv``: the true IMU increments along ``flight``; the IMU's
    errors (turn-on biases, scale factors, noises) are drawn from ``seed``.
    """
    rng = np.random.default_rng([int(seed), 0x1A5])
    imu_si = imu_model.si()
    errors = imu_model.draw(rng)
    dt = flight.dt
    mth, mdv = errors.apply(dtheta, dv, dt, rng)
    s0 = _initial_state(flight, init, rng)
    p_un, _, _ = mechanise(s0, mth, mdv, dt)
    rec_step = max(int(round(1.0 / (record_hz * dt))), 1)
    prop_step = max(int(round(1.0 / (propagation_hz * dt))), 1)
    P = _initial_covariance(init, imu_si)
    b_a, b_g, s_a, s_g = np.zeros(3), np.zeros(3), np.zeros(3), np.zeros(3)
    cur = s0
    k0 = 0
    n = len(flight.t)
    aided = np.zeros((n, 3))
    sig = np.zeros((n, 3))
    updates = []
    stops = [int(s.frame_index[-1]) for s in sequences] + [n - 1]
    for u, k_end in enumerate(stops):
        cdth = (mth[k0:k_end] - b_g * dt) / (1.0 + s_g)
        cdv = (mdv[k0:k_end] - b_a * dt) / (1.0 + s_a)
        p, v, R = mechanise(cur, cdth, cdv, dt)
        aided[k0:k_end + 1] = p
        P_start = P
        P = _propagate(P, R, cdv, cdth, dt, prop_step, imu_si)
        # σ over the chunk: interpolate the variance linearly in time (recorded at 1 Hz only)
        w = np.linspace(0, 1, k_end - k0 + 1)[:, None]
        sig[k0:k_end + 1] = np.sqrt((1 - w) * np.diag(P_start)[:3] + w * np.diag(P)[:3])
        cur = NavState(float(flight.t[k_end]), p[-1], v[-1], R[-1])
        if u == len(sequences):
            break
        seq = sequences[u]
        rel = seq.frame_index - k0
        rec = {"t": float(flight.t[k_end]), "distance_m": float(flight.distance_m[k_end]), "fog": seq.fog}
        if aiding:
            m = sequence_measurement(camera, seq.segments, p[rel], R[rel], flight.t[seq.frame_index], P, ref, dem,
                                     settings, rng=np.random.default_rng([int(seed), u]))
            rec.update(status=m.status, found=m.found, tracked=m.tracked, reconstructed=m.reconstructed,
                       matched=m.matched, used=0, nis=np.nan, nis_dof=0)
            gated = _gate_lines(m, P, settings.min_lines) if m.ok else None
            if m.ok and gated is None:
                rec["status"] = "lines inconsistent with the filter"
            if gated is not None:
                z, H, Rm, used = gated
                x, P, y, S = kf_update(np.zeros(N_STATES), P, z, H, Rm)
                rec.update(used=used, nis=float(y @ np.linalg.solve(S, y)), nis_dof=len(y),
                           matched_ref=np.array(m.matched_ref).reshape(-1, 4))
                cur = NavState(cur.t, cur.p - x[P_], cur.v - x[V_], exp_so3(-x[TH_]) @ cur.R)
                b_a = b_a + x[BA_]
                b_g = b_g + x[BG_]
                s_a = s_a + x[SA_]
                s_g = s_g + x[SG_]
                aided[k_end] = cur.p
        e = aided[k_end] - flight.p[k_end]
        rec["nees"] = float(e @ np.linalg.solve(P[P_, P_], e))
        rec["error_m"] = e.tolist()
        rec["sigma_m"] = np.sqrt(np.diag(P)[:3]).tolist()
        updates.append(rec)
        sig[k_end] = np.sqrt(np.diag(P)[:3])
        k0 = k_end
    idx = np.arange(0, n, rec_step)
    return SeedRun(flight.t[idx], p_un[idx], aided[idx], sig[idx], updates)
