"""Time-domain regularised least-squares integration with per-sample lags.

Unknowns: θ on the sample grid ``n·dt``. Every differential sample is one
equation

    θ(n·dt + τ_j + λ_j[n]) − θ(n·dt) = D_j[n]

where ``λ_j[n]`` is an optional per-sample extra lag (time synchronisation:
pitch jitter changes the actual delay after which band B sees what band A
saw), and θ at fractional times is read by 4-tap cubic (Keys) interpolation.
Gaps are simply missing equations — no filling, no Fourier transform.

The normal equations are regularised by a Gaussian prior on θ — a ridge
``α‖θ‖²`` (Wiener-like: α = σ_D²/σ_θ²) and a curvature term ``β‖Δ²θ‖²`` (the
jitter is band-limited well below the line rate) — which also sets θ at the
frequencies every pair is blind to. The system is banded (bandwidth
``max τ/dt + 3``) and solved by sparse Cholesky/LU.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.signal import welch

__all__ = ["integrate_lsq", "keys_weights"]


def keys_weights(frac: np.ndarray) -> np.ndarray:
    """Keys cubic-convolution weights (a = −0.5) of the 4 taps at offsets −1, 0, 1, 2 for ``frac`` ∈ [0, 1)."""
    f = np.asarray(frac, dtype=np.float64)
    a = -0.5
    def k(x):
        x = np.abs(x)
        return np.where(x <= 1, (a + 2) * x ** 3 - (a + 3) * x ** 2 + 1,
                        np.where(x < 2, a * x ** 3 - 5 * a * x ** 2 + 8 * a * x - 4 * a, 0.0))
    return np.stack([k(f + 1), k(f), k(1 - f), k(2 - f)], axis=-1)


def _robust_std(x: np.ndarray) -> float:
    x = x[np.isfinite(x)]
    if x.size < 3:
        return float("nan")
    return float(1.4826 * np.median(np.abs(x - np.median(x))))


def integrate_lsq(diffs, taus, dt, *, lags=None, sigmas=None, alpha: float | None = None, beta: float | None = None,
                  noise_std: float | None = None, signal_std: float | None = None,
                  bandwidth_hz: float | None = None, gcv: bool = True, return_weights: bool = False):
    """Integrate differentials by regularised least squares in the time domain.

    Parameters
    ----------
    diffs : sequence of 1-D arrays (N,)
        ``diffs[j][n] ≈ θ(n dt + taus[j] + lags[j][n]) − θ(n dt)`` [rad]; NaN = gap.
    taus : sequence of float
        Nominal lag of each pair [s].
    dt : float
        Sample step [s].
    lags : sequence of 1-D arrays, optional
        Extra lag per sample [s] (default 0).
    sigmas : sequence of 1-D arrays, optional
        1-σ of each differential sample [rad] (weights 1/σ²); default: one
        robust noise level per pair estimated from the data.
    alpha, beta : float, optional
        Ridge and curvature weights (relative to unit-weight equations);
        default from the noise and signal levels.
    noise_std, signal_std : float, optional
        Noise of the differentials and standard deviation of θ [rad] used for
        the default α = (σ_D/σ_θ)²; estimated from the data when omitted.
    bandwidth_hz : float, optional
        Typical highest frequency of θ, for the default β; estimated from the
        differentials' spectra when omitted.
    gcv : bool
        Refine the curvature weight by generalised cross-validation
        (multipliers 0.3–30 of the default; tr(H) by a Hutchinson estimator).
    return_weights : bool
        Also return the weights the solve used, ``{"alpha": α, "beta": β}``:
        given back (with ``gcv=False``) they make the estimator the same
        linear map on other differentials (a frozen rerun).

    Returns
    -------
    ndarray (N,)
        θ at ``n dt`` [rad], mean removed; NaN where no equation reaches
        (beyond the last measured sample or in gaps longer than the pairs' lags).
        With ``return_weights``: ``(θ, weights)``.
    """
    diffs, taus, n = _checked(diffs, taus, dt)
    if lags is None:
        lags = [np.zeros(n)] * len(diffs)
    A, b, w, noise_levels = _equations(diffs, taus, dt, lags, sigmas)
    if A is None:
        return (np.full(n, np.nan), {"alpha": alpha, "beta": beta}) if return_weights else np.full(n, np.nan)
    wn = w / np.median(w)  # relative weights: median equation has weight 1
    sigma_d = float(np.median(noise_levels)) if noise_std is None else float(noise_std)
    dv = np.concatenate([d[np.isfinite(d)] for d in diffs])
    if bandwidth_hz is None and beta is None:
        bandwidth_hz = _bandwidth_hz(diffs, dt)
    D2 = sp.diags([np.ones(n - 2), -2 * np.ones(n - 2), np.ones(n - 2)], [0, 1, 2], shape=(n - 2, n))
    AtWA = (A.T @ sp.diags(wn) @ A).tocsc()
    DtD = (D2.T @ D2).tocsc()
    eye = sp.identity(n, format="csc")
    y = A.T @ (wn * b)
    # empirical Bayes: the formal noise level of the differentials is re-scaled by the
    # post-fit residuals (matching errors are larger than their formal σ), then the
    # prior weights are recomputed and the system solved again
    passes = 1 if (noise_std is not None or (alpha is not None and beta is not None)) else 3
    for _ in range(passes):
        a, bt = _prior_weights(dv, sigma_d, dt, alpha=alpha, beta=beta, signal_std=signal_std,
                               bandwidth_hz=bandwidth_hz)
        theta = spla.spsolve((AtWA + a * eye + bt * DtD).tocsc(), y)
        r = A @ theta - b
        m_eq = r.size
        dof = max(m_eq - n, m_eq // 4)  # the fit absorbs about one equation per unknown
        new = float(np.sqrt(np.sum(wn * r ** 2) / dof))
        if not np.isfinite(new) or new <= 0:
            break
        sigma_d = new
    if gcv:
        theta, kappa = _gcv_solution(A, b, wn, AtWA + a * eye, bt, DtD, y)
        bt = kappa * bt
    # where no equation constrains θ (beyond the reach of every pair) there is no estimate
    reach = np.asarray(abs(A).sum(axis=0)).ravel() > 0
    covered = _dilate_coverage(reach, n)
    theta = np.where(covered, theta, np.nan)
    m = np.isfinite(theta)
    if m.any():
        theta = theta - theta[m].mean()
    return (theta, {"alpha": float(a), "beta": float(bt)}) if return_weights else theta


def _checked(diffs, taus, dt) -> tuple:
    """The differentials as float arrays of one length, the lags as floats, and that length."""
    diffs = [np.asarray(d, dtype=np.float64) for d in diffs]
    if not diffs:
        raise ValueError("diffs: at least one differential series is required")
    n = diffs[0].size
    if any(d.shape != (n,) for d in diffs):
        raise ValueError("diffs: all series must be 1-D with the same length")
    taus = [float(t) for t in taus]
    if len(taus) != len(diffs):
        raise ValueError(f"taus: expected {len(diffs)} values, got {len(taus)}")
    if any(t <= 0 for t in taus):
        raise ValueError("taus: must all be > 0")
    if not dt > 0:
        raise ValueError(f"dt: must be > 0, got {dt}")
    return diffs, taus, n


def _pair_weights(d, idx, sigma_j) -> tuple:
    """Weights 1/σ² of a pair's equations and its noise level: given σ, or robust from third differences."""
    if sigma_j is not None:
        s = np.asarray(sigma_j, dtype=np.float64)[idx]
        good = np.isfinite(s) & (s > 0)
        s = np.where(good, s, np.nanmedian(s[good]) if good.any() else 1.0)
        return 1.0 / s ** 2, np.nanmedian(s)
    # robust noise of the pair: third differences are noise-dominated for band-limited jitter
    s = _robust_std(np.diff(d, 3)) / np.sqrt(20.0)
    s = s if np.isfinite(s) and s > 0 else 1e-12
    return np.full(idx.size, 1.0 / s ** 2), s


def _equations(diffs, taus, dt, lags, sigmas) -> tuple:
    """The sparse system ``A θ = b`` (one row per measured sample, Keys taps at the lagged time), weights, noise.

    Returns ``(None, None, None, None)`` when no sample gives an equation.
    """
    n = diffs[0].size
    rows, cols, vals, rhs, wts = [], [], [], [], []
    r0 = 0
    noise_levels = []
    for j, (d, tau) in enumerate(zip(diffs, taus)):
        lag = np.nan_to_num(np.asarray(lags[j], dtype=np.float64))
        pos = np.arange(n) + (tau + lag) / dt
        i0 = np.floor(pos).astype(np.int64)
        frac = pos - i0
        ok = np.isfinite(d) & (i0 - 1 >= 0) & (i0 + 2 < n)
        idx = np.flatnonzero(ok)
        if idx.size == 0:
            continue
        w4 = keys_weights(frac[idx])
        m = idx.size
        rr = r0 + np.arange(m)
        for k, off in enumerate((-1, 0, 1, 2)):
            rows.append(rr)
            cols.append(i0[idx] + off)
            vals.append(w4[:, k])
        rows.append(rr)
        cols.append(idx)
        vals.append(-np.ones(m))
        rhs.append(d[idx])
        wj, sj = _pair_weights(d, idx, None if sigmas is None else sigmas[j])
        wts.append(wj)
        noise_levels.append(sj)
        r0 += m
    if r0 == 0:
        return None, None, None, None
    A = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(r0, n))
    return A, np.concatenate(rhs), np.concatenate(wts), noise_levels


def _prior_weights(dv, sigma_d: float, dt: float, *, alpha, beta, signal_std, bandwidth_hz) -> tuple:
    """Ridge α = (σ_D/σ_θ)² and curvature β = (σ_D / ((2π f dt)² σ_θ))² unless given."""
    sig_t = float(signal_std) if signal_std is not None else \
        max(np.sqrt(max(np.var(dv) - sigma_d ** 2, 0.0) / 2.0), sigma_d)
    a = alpha if alpha is not None else (sigma_d / sig_t) ** 2
    if beta is None:
        # curvature of a band-limited signal: |Δ²θ| ≈ (2π f dt)² |θ|
        curv = (2 * np.pi * bandwidth_hz * dt) ** 2 * sig_t
        return a, (sigma_d / max(curv, 1e-30)) ** 2
    return a, beta


def _gcv_solution(A, b, wn, base, bt: float, DtD, y) -> tuple[np.ndarray, float]:
    """Generalised cross-validation over a multiplier (0.3–30) of the curvature weight; tr(H) by Hutchinson.
    Returns the solution and the multiplier chosen."""
    r0 = A.shape[0]
    rng = np.random.default_rng(0)
    probes = rng.choice([-1.0, 1.0], size=(3, r0))
    best = None
    sw = np.sqrt(wn)
    for kappa in (0.3, 1.0, 3.0, 10.0, 30.0):
        lu = spla.splu((base + kappa * bt * DtD).tocsc())
        th = lu.solve(y)
        res = sw * (A @ th - b)
        # tr(H) with H = W^1/2 A M^-1 A^T W^1/2
        tr = np.mean([z @ (sw * (A @ lu.solve(A.T @ (sw * z)))) for z in probes])
        g = r0 * float(res @ res) / max(r0 - tr, 1.0) ** 2
        if best is None or g < best[0]:
            best = (g, th, kappa)
    return best[1], best[2]


def _dilate_coverage(reach: np.ndarray, n: int) -> np.ndarray:
    """Samples inside the span of constrained samples (interior gaps shorter than 2 samples tolerated)."""
    idx = np.flatnonzero(reach)
    out = np.zeros(n, dtype=bool)
    if idx.size:
        out[idx[0]:idx[-1] + 1] = True
    return out


def _bandwidth_hz(diffs, dt) -> float:
    """A typical highest frequency of the signal: the frequency below which 95 % of the
    differentials' power lies (noise floor removed)."""
    ps = []
    for d in diffs:
        x = np.asarray(d, dtype=np.float64)
        m = np.isfinite(x)
        if m.sum() < 64:
            continue
        x = np.where(m, x, 0.0) - np.mean(x[m])
        f, p = welch(x, fs=1.0 / dt, nperseg=min(1024, x.size))
        ps.append(p)
    if not ps:
        return 0.1 / dt
    p = np.mean(ps, axis=0)
    floor = np.median(p[len(p) // 2:])
    p = np.clip(p - floor, 0, None)
    c = np.cumsum(p)
    if c[-1] <= 0:
        return 0.1 / dt
    return float(max(f[np.searchsorted(c, 0.95 * c[-1])], 5.0))
