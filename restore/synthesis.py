"""Instant synthesis (patent step b; CNES §3.3.2).

For one band pair (A ahead, B behind, delay τ), every matched point gives a
residual ``measured − predicted`` position in band B (lines, columns). With
the attitude error δθ(t) = true − known, a point of line ``l`` of A gives, to
first order,

    residual ≈ S_B · (δθ(t_l + τ') − δθ(t_l)) = S_B · Δθ(t_l, τ)

where ``S_B = ∂(line, column)/∂(roll, pitch, yaw)`` is the sensitivity of the
image position in B (from the sensor model). Per line of A, the attitude
differentials ΔR, ΔT, ΔL are fitted by least squares weighted by match
quality, with iterated 3σ rejection of outliers. Lines with too few good
points are gaps (NaN), never zeros.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from simsat.units import AXES

__all__ = ["SynthesisResult", "instant_synthesis", "match_weights", "MATCH_STD_FLOOR_PX", "highpass_nan", "highpass_gain", "fill_short_gaps",
           "window_compensation", "spikes", "lowpass_sigma_lines"]



#: floor on each matched coordinate's σ in the synthesis's weights [px] (the matcher's σ is optimistic across bands)
MATCH_STD_FLOOR_PX = 0.02


def match_weights(pair, v: np.ndarray, *, covariance: bool = True) -> tuple[np.ndarray, np.ndarray | None]:
    """``(weights (n, 2), correlation (n,) or None)`` of the points ``v`` of ``pair`` for
    :func:`restore.synthesis.instant_synthesis`: the inverse variance of each matched coordinate (the matcher's
    σ, floored at :data:`MATCH_STD_FLOOR_PX`) and, with ``covariance`` and the matcher's
    :attr:`~restore.result.PairData.corr_line_col`, the correlation of the line and column errors under the same
    floor (the floor is independent noise: it adds to the variances, not to the covariance). Without the
    matcher's σ: the squared quality, the same on both coordinates."""
    if pair.std_line is None:
        return np.clip(pair.quality[v], 0.05, 1.0) ** 2, None
    sl, sc = np.asarray(pair.std_line, dtype=np.float64)[v], np.asarray(pair.std_col, dtype=np.float64)[v]
    var_l, var_c = sl ** 2 + MATCH_STD_FLOOR_PX ** 2, sc ** 2 + MATCH_STD_FLOOR_PX ** 2
    w = np.stack([1.0 / var_l, 1.0 / var_c], axis=1)
    if not covariance or pair.corr_line_col is None:
        return w, None
    rho = np.nan_to_num(np.asarray(pair.corr_line_col, dtype=np.float64)[v]) * sl * sc / np.sqrt(var_l * var_c)
    return w, np.where(np.isfinite(rho), rho, 0.0)


@dataclass
class SynthesisResult:
    """Per-line attitude differentials of one pair.

    Attributes
    ----------
    diff : ndarray (n_lines, 3)
        ΔR, ΔT, ΔL [rad] per line of band A (NaN = gap).
    sigma : ndarray (n_lines, 3)
        Formal 1-σ uncertainty of each differential [rad] (NaN = gap).
    n_points : ndarray (n_lines,)
        Inlier points used per line.
    inlier : ndarray (n_points,) bool
        Points kept after the outlier rejection.
    residual_rms_px : float
        RMS of the post-fit residuals of the inliers [px].
    """

    diff: np.ndarray
    sigma: np.ndarray
    n_points: np.ndarray
    inlier: np.ndarray
    residual_rms_px: float
    fitted_axes: tuple


def _accumulate(lines, rows_l, rows_c, res_l, res_c, w, n_lines, k, w_lc=None):
    """Per-line normal matrices (n_lines, k, k) and right-hand sides (n_lines, k).

    ``w`` is (n, 2): the diagonal of each point's 2 × 2 weight matrix (the line and column equations);
    ``w_lc`` (n,), optional: its off-diagonal term (the inverse covariance of correlated line and column errors).
    """
    nm = np.zeros((n_lines, k, k))
    rhs = np.zeros((n_lines, k))
    wl, wc = w[:, 0], w[:, 1]
    for a in range(k):
        r = wl * rows_l[:, a] * res_l + wc * rows_c[:, a] * res_c
        if w_lc is not None:
            r = r + w_lc * (rows_l[:, a] * res_c + rows_c[:, a] * res_l)
        rhs[:, a] = np.bincount(lines, r, minlength=n_lines)
        for b in range(a, k):
            q = wl * rows_l[:, a] * rows_l[:, b] + wc * rows_c[:, a] * rows_c[:, b]
            if w_lc is not None:
                q = q + w_lc * (rows_l[:, a] * rows_c[:, b] + rows_c[:, a] * rows_l[:, b])
            v = np.bincount(lines, q, minlength=n_lines)
            nm[:, a, b] = v
            nm[:, b, a] = v
    return nm, rhs


#: largest |correlation| of a point's line and column errors the fit takes (its weight matrix stays invertible)
MAX_LINE_COL_CORRELATION = 0.99


def _weight_matrices(w: np.ndarray, correlation) -> tuple[np.ndarray, np.ndarray | None]:
    """(diagonal (n, 2), off-diagonal (n,) or None) of each point's 2 × 2 weight matrix: the inverse of the
    covariance ``[[1/w_l, ρ/√(w_l w_c)], [ρ/√(w_l w_c), 1/w_c]]``."""
    if correlation is None:
        return w, None
    rho = np.clip(np.nan_to_num(np.asarray(correlation, dtype=np.float64)), -MAX_LINE_COL_CORRELATION,
                  MAX_LINE_COL_CORRELATION)
    k = 1.0 / (1.0 - rho * rho)
    return w * k[:, None], -rho * np.sqrt(w[:, 0] * w[:, 1]) * k


def instant_synthesis(lines, residual_lines, residual_columns, sensitivities, *, n_lines: int, weights=None,
                      correlation=None, axes=AXES, min_points: int = 4, n_sigma: float = 3.0, max_iter: int = 5,
                      sigma_floor_px: float = 1e-4) -> SynthesisResult:
    """Fit attitude differentials per line from point residuals.

    Parameters
    ----------
    lines : array of int (n,)
        Line of band A of each point (the sample index of the differential).
    residual_lines, residual_columns : array (n,)
        Measured − predicted position in band B [px].
    sensitivities : array (n, 2, 3)
        ∂(line, column)/∂(roll, pitch, yaw) at each point in band B [px/rad].
    n_lines : int
        Number of lines (length of the output).
    weights : array (n,) or (n, 2), optional
        Match-quality weights (default 1); with shape (n, 2), separate weights
        of the line and column equations (e.g. 1/σ² of each matched coordinate).
    correlation : array (n,), optional
        Correlation of each point's line and column errors (the matcher's
        :attr:`~restore.matching.MatchResult.corr_line_col`, with the same
        variances as ``weights``): the fit weighs each point by the inverse
        of its 2 × 2 covariance (generalised least squares), so that a match
        on an edge, whose slide along the edge moves both coordinates
        together, counts once across the edge and hardly along it. None:
        independent line and column errors. The outlier test keeps each
        coordinate's marginal standardised residual.
    axes : sequence of str
        Axes to fit (subset of roll, pitch, yaw); the others are reported as NaN.
    min_points : int
        Minimum inliers for a line to be estimated (else it is a gap).
    n_sigma : float
        Rejection threshold (iterated), in robust standard deviations of the
        residuals of the whole pair, per image axis.
    max_iter : int
        Rejection iterations.

    Returns
    -------
    SynthesisResult
    """
    lines, rl, rc, s, w, ok, idx = _checked_inputs(lines, residual_lines, residual_columns, sensitivities,
                                                   weights, axes, min_points, n_lines)
    if correlation is not None and np.shape(correlation) != (lines.size,):
        raise ValueError(f"correlation: expected shape ({lines.size},), got {np.shape(correlation)}")
    w_fit, w_lc = _weight_matrices(w, correlation)
    k = len(idx)
    # scale unknowns to µrad-ish magnitude for conditioning
    scale = 1e-6
    # rows of unusable points are zeroed: their weight is 0, and 0 × NaN would poison the line's sums
    rows_l = np.where(ok[:, None], s[:, 0, idx], 0.0) * scale
    rows_c = np.where(ok[:, None], s[:, 1, idx], 0.0) * scale
    inl = ok.copy()
    x = np.full((n_lines, k), np.nan)
    npts = np.zeros(n_lines, dtype=np.int64)
    sig_l = sig_c = 1.0
    rms = np.nan
    for it in range(max_iter + 1):
        li = np.where(inl, lines, 0)
        nm, rhs = _accumulate(li, rows_l, rows_c, np.where(inl, rl, 0.0), np.where(inl, rc, 0.0),
                              np.where(inl[:, None], w_fit, 0.0), n_lines, k,
                              None if w_lc is None else np.where(inl, w_lc, 0.0))
        npts = np.bincount(li[inl], minlength=n_lines)
        x = _solve_lines(nm, rhs, npts >= min_points, n_lines, k)
        # residuals of every point against its line's fit
        xp = x[np.clip(lines, 0, n_lines - 1)]  # points off the record are not usable (ok is False)
        has = np.all(np.isfinite(xp), axis=1)
        el = rl - np.einsum("nk,nk->n", rows_l, np.nan_to_num(xp))
        ec = rc - np.einsum("nk,nk->n", rows_c, np.nan_to_num(xp))
        use = inl & has
        if use.sum() < 3:
            break
        # standardised residuals (weights are relative inverse variances)
        zl = el * np.sqrt(w[:, 0])
        zc = ec * np.sqrt(w[:, 1])
        sig_l = _robust_sigma(zl[use], sigma_floor_px)
        sig_c = _robust_sigma(zc[use], sigma_floor_px)
        rms = float(np.sqrt(np.mean(np.concatenate([el[use], ec[use]]) ** 2)))
        if it == max_iter:
            break
        new = ok & has & (np.abs(zl) <= n_sigma * sig_l) & (np.abs(zc) <= n_sigma * sig_c)
        new |= ok & ~has & inl  # keep points of lines not (yet) estimable
        if np.array_equal(new, inl):
            break
        inl = new
    cov_diag = _formal_sigma(x, inl, lines, rows_l, rows_c, w_fit, sig_l, sig_c, n_lines, w_lc)
    diff = np.full((n_lines, 3), np.nan)
    sigma = np.full((n_lines, 3), np.nan)
    diff[:, idx] = x * scale
    sigma[:, idx] = cov_diag * scale
    return SynthesisResult(diff=diff, sigma=sigma, n_points=npts, inlier=inl, residual_rms_px=rms,
                           fitted_axes=tuple(axes))


def _checked_inputs(lines, residual_lines, residual_columns, sensitivities, weights, axes, min_points, n_lines):
    """The inputs as arrays, the (n, 2) weights normalised to a median of 1, the usable points, the axes' indices."""
    lines = np.asarray(lines, dtype=np.int64)
    rl = np.asarray(residual_lines, dtype=np.float64)
    rc = np.asarray(residual_columns, dtype=np.float64)
    s = np.asarray(sensitivities, dtype=np.float64)
    n = lines.size
    if s.shape != (n, 2, 3):
        raise ValueError(f"sensitivities: expected shape ({n}, 2, 3), got {s.shape}")
    if min_points < 2:
        raise ValueError(f"min_points: must be >= 2, got {min_points}")
    unknown = [a for a in axes if a not in AXES]
    if unknown:
        raise ValueError(f"axes: unknown axis {unknown[0]!r}; allowed: roll, pitch, yaw")
    idx = [AXES.index(a) for a in axes]
    w = np.ones((n, 2)) if weights is None else np.asarray(weights, dtype=np.float64).copy()
    if w.ndim == 1:
        w = np.repeat(w[:, None], 2, axis=1)
    if w.shape != (n, 2):
        raise ValueError(f"weights: expected shape ({n},) or ({n}, 2), got {w.shape}")
    w = w / np.nanmedian(np.where(w > 0, w, np.nan)) if np.any(w > 0) else w
    ok = np.isfinite(rl) & np.isfinite(rc) & np.all(np.isfinite(w) & (w > 0), axis=1) & \
        np.all(np.isfinite(s), axis=(1, 2))
    ok &= (lines >= 0) & (lines < n_lines)
    return lines, rl, rc, s, w, ok, idx


def _solve_lines(nm, rhs, good, n_lines: int, k: int) -> np.ndarray:
    """Per-line least-squares solutions (n_lines, k); NaN on lines with too few points or a singular system."""
    det_ok = np.zeros(n_lines, dtype=bool)
    if good.any():
        with np.errstate(all="ignore"):
            cond = np.linalg.cond(nm[good])
        det_ok[np.flatnonzero(good)] = np.isfinite(cond) & (cond < 1e10)
    good = good & det_ok
    x = np.full((n_lines, k), np.nan)
    if good.any():
        x[good] = np.linalg.solve(nm[good], rhs[good][..., None])[..., 0]
    return x


def _robust_sigma(z: np.ndarray, floor: float) -> float:
    """1.4826 × median absolute deviation of ``z`` (a robust σ), at least ``floor``."""
    return max(1.4826 * np.median(np.abs(z - np.median(z))), floor)


def _formal_sigma(x, inl, lines, rows_l, rows_c, w, sig_l, sig_c, n_lines: int, w_lc=None) -> np.ndarray:
    """Formal 1-σ of each line's unknowns: diag((Nm)⁻¹) scaled by the residual variance (weights are relative)."""
    n, k = lines.size, x.shape[1]
    cov_diag = np.full((n_lines, k), np.nan)
    good = np.all(np.isfinite(x), axis=1)
    if good.any():
        nm, _ = _accumulate(np.where(inl, lines, 0), rows_l, rows_c, np.zeros(n), np.zeros(n),
                            np.where(inl[:, None], w, 0.0), n_lines, k,
                            None if w_lc is None else np.where(inl, w_lc, 0.0))
        s2 = 0.5 * (sig_l ** 2 + sig_c ** 2)
        inv = np.linalg.inv(nm[good])
        cov_diag[good] = np.sqrt(np.maximum(np.einsum("nii->ni", inv), 0) * s2)
    return cov_diag


def highpass_gain(freq, cutoff_hz: float) -> np.ndarray:
    """Gain of the estimate's high-pass at ``freq`` [Hz]: ``1 − 2^(−(f/f_c)²/2)`` (the complement of the
    Gaussian low-pass :func:`highpass_nan` subtracts, −3 dB at ``cutoff_hz``)."""
    return 1.0 - 2.0 ** (-0.5 * (np.asarray(freq, dtype=np.float64) / cutoff_hz) ** 2)


def lowpass_sigma_lines(*, dt: float, cutoff_hz: float) -> float:
    """σ [lines] of the Gaussian low-pass :func:`highpass_nan` subtracts: its transfer ``exp(−2π²σ²f²)`` is
    1/√2 at ``cutoff_hz``, so ``σ = √(ln 2) / (2π f_c)`` [s], over ``dt``."""
    return float(np.sqrt(np.log(2.0)) / (2 * np.pi * cutoff_hz) / dt)


def highpass_nan(signal: np.ndarray, *, dt: float, cutoff_hz: float, mode: str = "constant") -> np.ndarray:
    """Remove frequencies below ``cutoff_hz`` from a gappy signal (NaN kept as NaN).

    Subtracts a NaN-aware Gaussian-smoothed copy (normalised convolution) whose
    −3 dB point is at ``cutoff_hz``; beyond the ends is treated as missing
    (``mode="constant"``), or the signal is periodic (``mode="wrap"``).
    """
    from scipy.ndimage import gaussian_filter1d

    if cutoff_hz <= 0:
        raise ValueError(f"cutoff_hz: must be > 0, got {cutoff_hz}")
    x = np.asarray(signal, dtype=np.float64)
    m = np.isfinite(x)
    if not m.any():
        return x.copy()
    sigma = lowpass_sigma_lines(dt=dt, cutoff_hz=cutoff_hz)
    # outside the record is missing data, like a gap (normalised convolution): padding with
    # the edge sample would put its jitter into the low-pass estimate near the ends
    if mode not in ("constant", "wrap"):
        raise ValueError(f"mode: 'constant' or 'wrap', got {mode!r}")
    num = gaussian_filter1d(np.where(m, x, 0.0), sigma, mode=mode, cval=0.0)
    den = gaussian_filter1d(m.astype(np.float64), sigma, mode=mode, cval=0.0)
    low = num / np.maximum(den, 1e-12)
    out = x - low
    out[~m] = np.nan
    return out


def drop_sparse(signal: np.ndarray, *, half_window: int, min_fraction: float = 0.5) -> np.ndarray:
    """NaN the samples whose neighbourhood is mostly gaps.

    A sample is kept when at least ``min_fraction`` of the ``2 half_window + 1``
    samples centred on it are finite. Isolated differentials in a stretch of
    gaps (the frayed edge of a cloud, a scatter of water) rest on few points and
    would let the integration return lines it cannot really constrain; without
    them the stretch is one long gap, reported as not estimated.
    """
    from scipy.ndimage import uniform_filter1d

    x = np.asarray(signal, dtype=np.float64).copy()
    if half_window <= 0:
        return x
    m = np.isfinite(x)
    frac = uniform_filter1d(m.astype(np.float64), 2 * int(half_window) + 1, mode="constant", cval=0.0)
    # at the record ends, judge on the part of the window inside the record
    inside = uniform_filter1d(np.ones(x.size), 2 * int(half_window) + 1, mode="constant", cval=0.0)
    x[m & (frac < min_fraction * inside - 1e-12)] = np.nan
    return x


def spikes(residual: np.ndarray, *, n_sigma: float, size: int = 9, max_fraction: float = 0.005) -> np.ndarray:
    """Lines whose residual is an isolated gross error: boolean mask (False where the residual is NaN).

    ``residual`` is what a model of the jitter leaves of a differential (the
    measured minus the differential the integrated attitude predicts): noise
    and a little smooth misfit. A line that departs from the running median
    of its ``size`` finite neighbours by more than ``n_sigma`` robust
    standard deviations (1.4826 × MAD of those departures), while both its
    neighbours stay within, is a failed synthesis (a repeated texture, a
    handful of matches all wrong), not jitter: left in, a 6 px spike on one
    line of one pair spreads over tenths of a second of the integrated
    attitude. Lines that depart that far *in runs* are the model's misfit,
    not failed lines (at several pixels of jitter the integration misses part
    of it where the attitude moves fastest, a few lines at a time): when more
    than ``max_fraction`` of the lines (and more than ``size``: one running
    median's worth, a local misfit) do, the model is what fails and nothing
    is flagged. ``n_sigma <= 0``: none.
    """
    from scipy.ndimage import median_filter

    x = np.asarray(residual, dtype=np.float64)
    out = np.zeros(x.shape, dtype=bool)
    ok = np.isfinite(x)
    if n_sigma <= 0 or ok.sum() < 4 * size:
        return out
    v = x[ok]
    r = v - median_filter(v, size=int(size), mode="mirror")
    sigma = 1.4826 * float(np.median(np.abs(r - np.median(r))))
    if not sigma > 0:
        return out
    far = np.abs(r) > n_sigma * sigma
    alone = far & ~np.r_[False, far[:-1]] & ~np.r_[far[1:], False]
    if (far & ~alone).sum() > max(float(size), max_fraction * v.size):
        return out
    out[np.flatnonzero(ok)[alone]] = True
    return out


def fill_short_gaps(signal: np.ndarray, *, max_gap: int) -> np.ndarray:
    """Fill runs of at most ``max_gap`` NaN samples by cubic interpolation of their neighbours.

    Longer runs, and runs touching the ends (which would need extrapolation),
    stay NaN.
    """
    from scipy.interpolate import CubicSpline

    x = np.asarray(signal, dtype=np.float64).copy()
    m = np.isfinite(x)
    if max_gap <= 0 or m.all() or m.sum() < 4:
        return x
    idx = np.arange(x.size)
    nan = ~m
    # run lengths of NaN samples
    edges = np.diff(np.r_[0, nan.astype(np.int8), 0])
    starts = np.flatnonzero(edges == 1)
    ends = np.flatnonzero(edges == -1)  # exclusive
    fill = np.zeros(x.size, dtype=bool)
    for a, b in zip(starts, ends):
        if b - a <= max_gap and a > 0 and b < x.size:
            fill[a:b] = True
    if fill.any():
        cs = CubicSpline(idx[m], x[m])
        x[fill] = cs(idx[fill])
    return x


def window_compensation(signal: np.ndarray, *, window_lines: int) -> np.ndarray:
    """Undo, to fourth order in ωTe, the moving average of a ``window_lines``-line matching window.

    A window of ``n`` lines measures the mean of the differential over those
    lines: a moving average with gain ``M(ω) = sin(nωTe/2) / (n sin(ωTe/2)) ≈ 1 − (n²−1)(ωTe)²/24``.
    The 3-tap filter ``[−a, 1+2a, −a]`` with ``a = (n²−1)/24`` has gain
    ``≈ 1 + (n²−1)(ωTe)²/24``, so their product is 1 up to O((ωTe)⁴)
    (PHR, 3 lines, 155 Hz: 0.950 → 0.997). NaNs propagate to their neighbours.
    """
    n = int(window_lines)
    if n <= 1:
        return np.asarray(signal, dtype=np.float64).copy()
    a = (n * n - 1) / 24.0
    x = np.asarray(signal, dtype=np.float64)
    out = np.full_like(x, np.nan)
    out[1:-1] = (1 + 2 * a) * x[1:-1] - a * (x[:-2] + x[2:])
    return out
