"""One aiding measurement from a short image sequence: tracks → 3-D lines → map matches → Kalman rows.

The INS gives the camera poses of the sequence (accurate relative to each
other, offset as a whole by the INS error). Under an error hypothesis
``δ = (δp, δv, δθ)`` at the last frame, the true poses are
``p_j = p̂_j − δp + δv (t_end − t_j)`` and ``R_j = exp(−δθ) R̂_j``; the lines
reconstructed with them should lie on their reference lines (horizontal
normal distances) and on the terrain (height above the DEM). The residuals
``r(δ)`` are linearised numerically (``r ≈ r₀ + J δ``), so the Kalman update
sees ``z = −r₀ = J δ + v``. The noise ``v`` propagates the image-line error
(``line_sigma_px``, through the same reconstruction) and the reference map's
own error (``map_sigma_m``, common to both ends of a segment) — the
patent's "cálculo de propagación de errores".
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .camera import CameraPose, PinholeCamera
from .homography import plane_homography
from .kalman import N_STATES
from .map_matching import match_to_reference, normal_distances
from .reconstruction import reconstruct_line
from .rotations import exp_so3
from .tracking import track_sequence

__all__ = ["AidingSettings", "SequenceMeasurement", "sequence_measurement", "ground_plane_homographies"]


@dataclass(frozen=True)
class AidingSettings:
    min_views: int = 5
    max_rms_px: float = 1.0
    max_range_m: float = 5000.0
    min_length_m: float = 30.0
    max_height_error_m: float = 60.0
    line_sigma_px: float = 0.4
    map_sigma_m: float = 2.0
    min_lines: int = 5
    common_sigma_m: float = 1.0
    tol_m: float = 6.0
    gate_sigmas: float = 4.0


@dataclass
class SequenceMeasurement:
    """The measurement and its diagnostics (counts of segments found, tracked, reconstructed, matched)."""

    status: str
    found: int = 0
    tracked: int = 0
    reconstructed: int = 0
    matched: int = 0
    z: np.ndarray | None = None
    H: np.ndarray | None = None
    R: np.ndarray | None = None
    shift: np.ndarray = field(default_factory=lambda: np.zeros(2))
    lines: list = field(default_factory=list)      # reconstructed (world) lines [(a, b)]
    matched_ref: list = field(default_factory=list)  # matched reference segments (4,)

    @property
    def ok(self) -> bool:
        return self.status == "ok"


def _poses(camera: PinholeCamera, p, R, t, t_end, delta) -> list[CameraPose]:
    dp, dv, dth = delta[0:3], delta[3:6], delta[6:9]
    rot = exp_so3(-dth)
    return [camera.pose(pj - dp + dv * (t_end - tj), rot @ Rj) for pj, Rj, tj in zip(p, R, t)]


def ground_plane_homographies(camera, poses, dem):
    """Homographies k → k+1 induced by the level ground plane at the DEM height where the first view looks."""
    c = poses[0]
    ray = c.R_wc @ np.array([0.0, 0.0, 1.0])
    s = (c.c[2] - float(np.nanmean(dem.z))) / max(-ray[2], 0.05)
    look = c.c + min(s, 4000.0) * ray
    h = float(dem.height(look[0], look[1], outside="clamp"))
    return [plane_homography(camera.K, a, b, [0, 0, 1], h) for a, b in zip(poses[:-1], poses[1:])]


def _residuals(camera, obs, frames_p, frames_R, t, t_end, delta, pairs, ref, dem):
    """Stacked residuals (4 per matched line: 2 horizontal normal distances, 2 heights above the DEM)."""
    poses = _poses(camera, frames_p, frames_R, t, t_end, delta)
    out = []
    for (i, j) in pairs:
        fr, segs = obs[i]
        line = reconstruct_line(camera.K, segs, [poses[f] for f in fr])
        if line is None:
            return None
        ends = np.stack([line.a, line.b])
        rseg = np.tile(ref.segments[j], (2, 1))
        out += list(normal_distances(ends[:, :2], rseg))
        out += list(ends[:, 2] - dem.height(ends[:, 0], ends[:, 1], outside="clamp"))
    return np.array(out)


def sequence_measurement(camera: PinholeCamera, segments: list, frames_p: np.ndarray, frames_R: np.ndarray,
                         t: np.ndarray, P: np.ndarray, ref, dem, settings: AidingSettings = AidingSettings(),
                         rng=None) -> SequenceMeasurement:
    """Long: the whole of one aiding step (tracking, reconstruction, matching, linearisation) reads in one place.

    ``segments``: per frame (n_k, 4) px; ``frames_p``, ``frames_R``, ``t``: the
    INS positions, attitudes and times of the frames; ``P``: the filter's
    covariance (sets the matching gate).
    """
    s = settings
    t_end = float(t[-1])
    zero = np.zeros(9)
    poses = _poses(camera, frames_p, frames_R, t, t_end, zero)
    found = int(sum(len(x) for x in segments))
    tr = track_sequence(segments, ground_plane_homographies(camera, poses, dem), width=camera.width,
                        height=camera.height, rng=rng)
    good = [x for x in tr.tracks if x.real_count >= s.min_views]
    # a ground line lies on the terrain; the INS's own error moves the reconstruction off it, so the
    # height gate widens with the filter's vertical and horizontal uncertainty (terrain slopes ≤ ~0.3)
    dz_max = s.max_height_error_m + 3.0 * (float(np.sqrt(P[2, 2])) + 0.3 * float(np.sqrt(P[0, 0] + P[1, 1])))
    obs, lines = [], []
    for x in good:
        fr, segs = x.real()
        line = reconstruct_line(camera.K, segs, [poses[f] for f in fr])
        if line is None or line.rms_px > s.max_rms_px:
            continue
        ends = np.stack([line.a, line.b])
        rng_m = np.linalg.norm(ends - poses[-1].c, axis=1).max()
        dz = ends[:, 2] - dem.height(ends[:, 0], ends[:, 1], outside="clamp")
        if rng_m > s.max_range_m or np.linalg.norm(line.b - line.a) < s.min_length_m or \
                np.abs(dz).max() > dz_max:
            continue
        obs.append((fr, segs))
        lines.append(ends)
    m = SequenceMeasurement("ok", found=found, tracked=len(good), reconstructed=len(lines), lines=lines)
    if len(lines) < s.min_lines:
        m.status = f"{len(lines)} reconstructed lines (< {s.min_lines})"
        return m
    sig_h = float(np.sqrt(np.linalg.eigvalsh(P[0:2, 0:2]).max()))
    sig_th = float(np.sqrt(P[8, 8]))
    gate = float(np.clip(s.gate_sigmas * (sig_h + sig_th * 3000.0) + 2 * s.tol_m, 25.0, 800.0))
    lxy = np.array([[a[0], a[1], b[0], b[1]] for a, b in lines])
    mm = match_to_reference(lxy, ref, gate_m=gate, tol_m=s.tol_m, min_lines=s.min_lines,
                            prior_sigma_m=sig_h + sig_th * 3000.0)
    m.shift = mm.shift
    m.matched = len(mm.pairs)
    if mm.status != "ok":
        m.status = mm.status
        return m
    r0 = _residuals(camera, obs, frames_p, frames_R, t, t_end, zero, mm.pairs, ref, dem)
    if r0 is None:
        m.status = "degenerate reconstruction"
        return m
    steps = np.array([1.0] * 3 + [0.05] * 3 + [1e-4] * 3)
    J = np.zeros((len(r0), N_STATES))
    for k in range(9):
        d = np.zeros(9)
        d[k] = steps[k]
        rk = _residuals(camera, obs, frames_p, frames_R, t, t_end, d, mm.pairs, ref, dem)
        if rk is None:
            m.status = "degenerate reconstruction under perturbation"
            return m
        J[:, k] = (rk - r0) / steps[k]
    R = _measurement_noise(camera, obs, poses, mm.pairs, ref, dem, s)
    # model error common to the whole sequence (raster edges, mesh vs DEM, shared detector biases): the
    # reconstruction as a whole may be offset by common_sigma_m in each axis, as a position error would
    R = R + s.common_sigma_m ** 2 * (J[:, 0:3] @ J[:, 0:3].T)
    m.z, m.H, m.R = -r0, J, R
    m.matched_ref = [ref.segments[j] for _, j in mm.pairs]
    return m


def _measurement_noise(camera, obs, poses, pairs, ref, dem, s: AidingSettings) -> np.ndarray:
    """Covariance of the residuals: image-line noise propagated through the reconstruction, plus map error."""
    n = len(pairs)
    R = np.zeros((4 * n, 4 * n))
    for q, (i, j) in enumerate(pairs):
        fr, segs = obs[i]
        pz = [poses[f] for f in fr]
        base = reconstruct_line(camera.K, segs, pz)
        b_ends = np.stack([base.a, base.b])
        rseg = np.tile(ref.segments[j], (2, 1))
        r_base = np.concatenate([normal_distances(b_ends[:, :2], rseg), b_ends[:, 2]])
        cols = []
        for v in range(len(segs)):
            d = segs[v, 2:] - segs[v, :2]
            nrm = np.array([-d[1], d[0]]) / np.linalg.norm(d)
            for e in (0, 2):
                sp = segs.copy()
                sp[v, e:e + 2] += s.line_sigma_px * nrm
                ln = reconstruct_line(camera.K, sp, pz)
                if ln is None:
                    continue
                ends = np.stack([ln.a, ln.b])
                # endpoints slide along the line when a view changes: compare the line, not the ends
                ends = _closest_on_line(ends, b_ends)
                cols.append(np.concatenate([normal_distances(ends[:, :2], rseg), ends[:, 2]]) - r_base)
        Jo = np.array(cols).T if cols else np.zeros((4, 1))
        block = Jo @ Jo.T
        block[:2, :2] += s.map_sigma_m ** 2 * np.ones((2, 2)) + 0.25 * np.eye(2)
        block[2:, 2:] += 1.0 * np.eye(2)    # DEM interpolation / line-on-ground modelling (1 m)
        R[4 * q:4 * q + 4, 4 * q:4 * q + 4] = block
    return R


def _closest_on_line(ends: np.ndarray, ref_ends: np.ndarray) -> np.ndarray:
    """Points of the line through ``ends`` nearest to ``ref_ends`` (2, 3)."""
    u = ends[1] - ends[0]
    u /= np.linalg.norm(u)
    return np.stack([ends[0] + ((p - ends[0]) @ u) * u for p in ref_ends])
