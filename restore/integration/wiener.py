"""Fourier-domain integration: pseudo-inverse, one-shot Wiener, and exact Wiener (MAP).

Three estimators of ``theta`` from ``d_j(n) = theta(n dt + tau_j) - theta(n dt) + b_j(n)``:

``inverse``
    The patent's pseudo-inverse with a constant ``k``, fused over pairs:
    ``Theta = sum_j conj(G_j) D_j / (sum_i |G_i|² + k)`` (one pair: ``H_k``).
``wiener_fft``
    One-shot multi-pair Wiener filter ``H_j = conj(G_j) S / N_j / (1 + S sum_i |G_i|² / N_i)``
    with the signal PSD ``S`` and noise levels estimated from the data
    (:mod:`.spectrum`).  Gaps are filled with zeros before the FFT and the
    unobserved samples masked afterwards; the record is zero-padded.  Edges and
    gaps violate the circular model, so errors grow near them.
``wiener``
    The same Wiener criterion solved exactly on the finite, gappy record: the
    maximum a posteriori ``theta`` for a Gaussian stationary prior of PSD ``S``
    and white measurement noise, i.e. minimising
    ``sum_j sum_{n valid} (d_j(n) - (theta(n dt + tau_j) - theta(n dt)))² / sigma_j² + theta' C^-1 theta``.
    ``theta = L z`` is parametrised on a periodic grid longer than the record
    (``L`` filters by ``sqrt(S)``, fractional lags are exact phase ramps), and
    the normal equations ``(I + sum_j K_j' W_j K_j) z = sum_j K_j' W_j d_j``
    are solved by conjugate gradients preconditioned with their Fourier-diagonal
    approximation.  Gaps simply get zero weight, edges need no window, and no
    sample is extrapolated (the padding absorbs the wrap-around).
"""
from __future__ import annotations

import math

import numpy as np
from scipy.fft import irfft, next_fast_len, rfft

from ._common import check_positive, lagrange4_weights, prepare
from .gaps import estimable_mask
from .spectrum import SpectralEstimate, estimate_spectrum, notch_mask

__all__ = ["colour_on_grid", "integrate_inverse", "integrate_wiener_fft", "integrate_wiener", "WienerResult", "spectrum_for_lines",
           "lag_interpolation", "tone_order", "tone_sweep", "tone_waves", "tone_phase", "tone_chirps",
           "ceiling_on_grid"]


def _grid(n: int, taus: np.ndarray, dt: float, pad_fraction: float, max_lag_s: float = 0.0) -> int:
    ext = int(math.ceil((taus.max() + max_lag_s) / dt)) + 4
    return next_fast_len(int(n * (1 + pad_fraction)) + ext)


def _default_max_gap(taus: np.ndarray, dt: float, max_gap_s) -> int:
    if max_gap_s is None:
        return int(round(taus.max() / dt))
    return int(round(check_positive("max_gap_s", max_gap_s, allow_zero=True) / dt))


def lag_interpolation(lag_samples, m: int):
    """Sparse (n × m) operator ``x ↦ x(k + λ_k)`` on a periodic grid of ``m`` samples (4-point Lagrange).

    ``lag_samples`` (n,) are the extra lags in samples (finite). Its transpose
    is the adjoint the MAP normal equations need.
    """
    from scipy.sparse import csr_matrix

    lam = np.asarray(lag_samples, dtype=np.float64)
    n = lam.size
    pos = np.arange(n) + lam
    base = np.floor(pos)
    w = lagrange4_weights(pos - base)
    cols = (base.astype(np.int64)[:, None] + np.arange(-1, 3)[None, :]) % m
    rows = np.repeat(np.arange(n), 4)
    return csr_matrix((w.ravel(), (rows, cols.ravel())), shape=(n, m))


def _modulation(n_record: int, t: np.ndarray, dt: float, order: int) -> list:
    mid, half = 0.5 * (n_record - 1) * dt, 0.5 * max(n_record - 1, 1) * dt
    return [((t - mid) / half) ** k for k in range(order + 1)]


def tone_phase(freqs, t: np.ndarray, mid: float, chirps=None) -> np.ndarray:
    """(samples, tones) phase [rad] of tones of frequency ``freqs`` [Hz] at the record's middle ``mid`` [s],
    each sweeping at its ``chirps`` rate [Hz/s] (None: none): ``2π (f t + c (t − mid)² / 2)``."""
    ph = np.asarray(freqs, dtype=np.float64)[None, :] * t[:, None]
    if chirps is not None:
        ph = ph + 0.5 * np.asarray(chirps, dtype=np.float64)[None, :] * ((t - mid) ** 2)[:, None]
    return 2 * np.pi * ph


def tone_chirps(tones):
    """The sweep rates [Hz/s] of a ``tones`` tuple ``(frequencies, sd[, order[, chirps]])``, None without."""
    return None if tones is None or len(tones) < 4 or tones[3] is None else \
        np.atleast_1d(np.asarray(tones[3], dtype=np.float64))


def tone_waves(freqs, n: int, dt: float, order: int = 0, n_record: int | None = None,
               chirps=None) -> np.ndarray:
    """(n, 2q(order+1)) columns cos, sin of each frequency at ``k dt``, times 1, t′, … t′^order (t′ the
    time from the record's middle in half records); ``chirps`` [Hz/s]: each tone's frequency sweeps at that
    rate, ``freqs`` being the one at the record's middle (:func:`tone_phase`)."""
    t = np.arange(n) * dt
    nr = n if n_record is None else n_record
    ph = tone_phase(freqs, t, 0.5 * (nr - 1) * dt, chirps)
    mods = _modulation(nr, t, dt, order)
    return np.concatenate([np.cos(ph) * m[:, None] for m in mods] + [np.sin(ph) * m[:, None] for m in mods], axis=1)


def tone_columns(tones, n: int, taus, dt: float, lags) -> tuple:
    """Differentials (pair, sample, 2q(order+1)) of unit cos / sin tones (times 1, t′, …), with the lags, and
    their prior sd (``tones``: ``(frequencies, sd[, order[, chirps]])``)."""
    freqs, sd = np.atleast_1d(np.asarray(tones[0], dtype=np.float64)), float(tones[1])
    order = int(tones[2]) if len(tones) > 2 else 0
    chirps = tone_chirps(tones)
    t = np.arange(n) * dt
    now = tone_waves(freqs, n, dt, order, chirps=chirps)
    cols = []
    for j, tau in enumerate(taus):
        t1 = t + tau + (np.zeros(n) if lags is None else lags[j])
        ph = tone_phase(freqs, t1, 0.5 * (n - 1) * dt, chirps)
        mods = _modulation(n, t1, dt, order)
        cols.append(np.concatenate([np.cos(ph) * m[:, None] for m in mods] + [np.sin(ph) * m[:, None] for m in mods],
                                   axis=1) - now)
    x = np.stack(cols)
    return x, np.full(x.shape[2], sd)


def _finish(theta: np.ndarray, valid, taus, dt, max_gap_s) -> np.ndarray:
    mask = estimable_mask(valid, taus, dt, max_gap=_default_max_gap(taus, dt, max_gap_s))
    out = np.where(mask, theta, np.nan)
    if mask.any():
        out -= np.nanmean(out)
    return out


def _psd_on_grid(psd, f: np.ndarray) -> np.ndarray:
    if callable(psd):
        s = np.asarray(psd(f), dtype=np.float64)
    else:
        fp, sp = psd
        s = np.interp(f, np.asarray(fp, float), np.asarray(sp, float), left=0.0, right=0.0)
    if s.shape != f.shape or not np.all(np.isfinite(s)) or np.any(s < 0):
        raise ValueError("psd: must give finite values >= 0 for every frequency")
    return s


def ceiling_on_grid(ceiling, f: np.ndarray) -> np.ndarray:
    """A PSD ceiling ``(freq, ceiling)`` (:func:`restore.knowledge_prior.knowledge_psd_ceiling`) at the
    frequencies ``f``: interpolated, infinite beyond its end and next to an infinite value."""
    fc, cc = (np.asarray(x, dtype=np.float64) for x in ceiling[:2])
    if fc.shape != cc.shape or fc.ndim != 1 or np.any(np.diff(fc) <= 0) or np.any(np.isnan(cc)) or np.any(cc < 0):
        raise ValueError("psd_ceiling: must be (freq, ceiling) with increasing frequencies and ceilings >= 0")
    big = np.isinf(cc)
    out = np.interp(f, fc, np.where(big, 0.0, cc), right=np.inf)
    # a bin next to an infinite ceiling is unbounded (interpolating towards inf gives inf anyway)
    out[np.interp(f, fc, big.astype(float)) > 0] = np.inf
    return out


def floor_on_grid(ceiling, f: np.ndarray) -> np.ndarray:
    """The PSD floor of a ``(freq, ceiling, floor)`` triple at the frequencies ``f`` (zero without one, and
    beyond its end)."""
    if len(ceiling) < 3:
        return np.zeros(np.shape(f))
    fc, fl = np.asarray(ceiling[0], dtype=np.float64), np.asarray(ceiling[2], dtype=np.float64)
    if fl.shape != fc.shape or np.any(~np.isfinite(fl)) or np.any(fl < 0):
        raise ValueError("psd_ceiling: its floor must be finite and >= 0 on the ceiling's frequencies")
    return np.interp(f, fc, fl, right=0.0)


def colour_on_grid(noise_colour, f: np.ndarray, p: int) -> np.ndarray:
    """``noise_colour`` = (freq, colour (pair, freq)) interpolated at ``f`` (constant beyond its ends)."""
    fc, col = noise_colour
    fc = np.asarray(fc, dtype=np.float64)
    col = np.atleast_2d(np.asarray(col, dtype=np.float64))
    if col.shape != (p, fc.size):
        raise ValueError(f"noise_colour: expected ({p}, {fc.size}) values for {p} pairs, got {col.shape}")
    if not np.all(np.isfinite(col)) or np.any(col <= 0):
        raise ValueError("noise_colour: every value must be finite and > 0")
    return np.array([np.interp(f, fc, c) for c in col])


def integrate_inverse(diffs, taus, dt, *, k: float = 0.1, pad_fraction: float = 0.5,
                      max_gap_s: float | None = None) -> np.ndarray:
    """Pseudo-inverse integration with a constant ``k`` (patent's ``H_k``), fused over pairs.

    Parameters
    ----------
    diffs, taus, dt
        As for :func:`restore.integration.integrate`.
    k : float, keyword-only
        Regularisation (noise-to-signal ratio), > 0.
    pad_fraction : float, keyword-only
        Zero padding as a fraction of the record.
    max_gap_s : float, keyword-only
        Longest unobserved interior run returned (s); default the longest lag.

    Returns
    -------
    ndarray
        theta at ``n dt`` (rad), mean removed, NaN where not estimated.
    """
    D, valid, taus, dt = prepare(diffs, taus, dt)
    k = check_positive("k", k)
    m = _grid(D.shape[1], taus, dt, check_positive("pad_fraction", pad_fraction, allow_zero=True))
    f = np.fft.rfftfreq(m, dt)
    g = np.exp(2j * np.pi * f[None, :] * taus[:, None]) - 1
    X = rfft(np.where(valid, D - np.nanmean(D, axis=1, keepdims=True), 0.0), n=m, axis=-1)
    theta = irfft((np.conj(g) * X).sum(0) / ((np.abs(g) ** 2).sum(0) + k), n=m)[:D.shape[1]]
    return _finish(theta, valid, taus, dt, max_gap_s)


def integrate_wiener_fft(diffs, taus, dt, *, noise_std=None, psd=None, pad_fraction: float = 0.5,
                         max_gap_s: float | None = None, spectrum_options: dict | None = None
                         ) -> np.ndarray:
    """One-shot multi-pair Wiener filter in the Fourier domain.

    Parameters
    ----------
    diffs, taus, dt
        As for :func:`restore.integration.integrate`.
    noise_std : float or sequence, keyword-only
        Per-pair noise standard deviation (rad); estimated if None.
    psd : callable or (freq, psd), keyword-only
        Two-sided signal PSD of theta (rad²/Hz) as ``f -> S(f)`` or sampled;
        estimated from the differentials if None.
    pad_fraction, max_gap_s
        As for :func:`integrate_inverse`.
    spectrum_options : dict, keyword-only
        Passed to :func:`~restore.integration.spectrum.estimate_spectrum`.
    weights : sequence of arrays, keyword-only
        Relative weight of each sample, one array per pair (e.g. the number of
        matched points behind each line's differential): the noise variance of
        sample ``n`` of pair ``j`` is ``noise_std_j² / weights_j[n]``, with the
        weights scaled to mean 1 over the pair's valid samples (``noise_std``
        stays the pair's typical level). Non-finite or <= 0 = no weight.

    Returns
    -------
    ndarray
        theta at ``n dt`` (rad), mean removed, NaN where not estimated.
    """
    D, valid, taus, dt = prepare(diffs, taus, dt)
    n = D.shape[1]
    m = _grid(n, taus, dt, check_positive("pad_fraction", pad_fraction, allow_zero=True))
    spec = estimate_spectrum(D, taus, dt, n_fft=m, noise_std=noise_std, **(spectrum_options or {}))
    S = spec.psd if psd is None else _psd_on_grid(psd, spec.freq)
    g = np.exp(2j * np.pi * spec.freq[None, :] * taus[:, None]) - 1
    snr = S[None, :] / (spec.noise_std[:, None] ** 2 * dt)
    h = np.conj(g) * snr / (1 + (np.abs(g) ** 2 * snr).sum(0))
    X = rfft(np.where(valid, D - np.nanmean(D, axis=1, keepdims=True), 0.0), n=m, axis=-1)
    theta = irfft((h * X).sum(0), n=m)[:n]
    return _finish(theta, valid, taus, dt, max_gap_s)


class WienerResult:
    """Details of :func:`integrate_wiener` (``return_details=True``).

    Attributes
    ----------
    theta : ndarray
        Estimate (rad), NaN where not estimated.
    theta_full : ndarray
        Posterior mean at every sample (also inside long gaps).
    theta_grid : ndarray or None
        Posterior mean on the whole periodic grid the MAP is solved on (the
        record, then its padding back to the start), mean removed as
        ``theta_full``: a filter applied there never meets an end of record.
    spectrum : SpectralEstimate
        PSD and noise levels used.
    iterations : int
        Conjugate-gradient iterations.
    residual : float
        Final relative residual of the normal equations.
    objective : float
        The MAP objective at the solution (−2 log posterior, white noise model).
    predicted : ndarray
        (pair, sample) differentials the solution predicts (tones included), NaN where none was measured.
    tones : ndarray or None
        The tones' coefficients, when ``tones`` was given.
    """

    def __init__(self, theta, theta_full, spectrum, iterations, residual, theta_grid=None):
        self.theta = theta
        self.theta_full = theta_full
        self.theta_grid = theta_grid
        self.spectrum = spectrum
        self.iterations = iterations
        self.residual = residual


def _colour_weighting(w: np.ndarray, colour: np.ndarray | None, m: int):
    """The noise's inverse covariance as an operator on (pair, sample) residuals: ``w`` per sample, or with a
    ``colour`` (pair, ``m // 2 + 1``) ``√w C⁻¹ √w``, ``C`` the circulant of spectrum ``colour`` on the grid
    of ``m`` (symmetric positive definite: a zero-phase filter of positive gain between two diagonals)."""
    if colour is None:
        return lambda r: r * w
    sw, n = np.sqrt(w), w.shape[1]
    inv = 1.0 / colour
    return lambda r: sw * irfft(rfft(sw * r, n=m, axis=-1) * inv, n=m, axis=-1)[:, :n]


def _cg_solve(D, valid, taus, dt, freq, S, sigma, m, *, tol, maxiter, theta0=None, rel_weights=None,
              lag_ops=None, extra=None, colour=None):
    """Solve the MAP normal equations on the periodic grid of length ``m``.

    ``theta0`` (length ``m``, optional) warm-starts the iteration;
    ``rel_weights`` (pair, sample), optional, scales each sample's inverse
    noise variance ``1 / sigma_j²`` (mean 1 over the valid samples);
    ``lag_ops`` (one :func:`lag_interpolation` per pair, optional) makes the
    forward model ``θ(t + τ_j + λ_j(t)) − θ(t)`` exactly (time synchronisation
    inside the MAP instead of a correction of the data). ``extra`` (``X``
    (pair, sample, q), ``sd`` (q,)), optional, adds q parameters ``a`` of
    prior ``N(0, sd²)`` whose differentials are ``X a`` (a tone on a
    frequency every pair is blind to, seen through the lags only:
    :func:`blind_tones`); their estimate is returned last. ``colour``
    (pair, ``m // 2 + 1``), optional: each pair's noise power relative to
    white at the grid's frequencies (the noise covariance becomes
    ``W^-1/2 C W^-1/2``, see :func:`_colour_weighting`).
    Returns (theta on the record, theta on the grid, predicted differentials,
    iterations, residual, extra parameters or None, ``rᵀ z``: the normal
    equations' residual times the iterate, by which ``Dᵀ W (D − A z)`` exceeds
    the quadratic's value at the iterate when the iteration stopped short).
    """
    p, n = D.shape
    c = np.sqrt(S / dt)
    kop = c[None, :] * (np.exp(2j * np.pi * freq[None, :] * taus[:, None]) - 1)
    w = np.where(valid, 1.0 / sigma[:, None] ** 2, 0.0)
    if rel_weights is not None:
        w = w * rel_weights
    dz = np.where(valid, D, 0.0)
    if lag_ops is None:
        def forward(z: np.ndarray) -> np.ndarray:
            return irfft(kop * rfft(z)[None, :], n=m, axis=-1)[:, :n]

        def adjoint(r: np.ndarray) -> np.ndarray:
            return irfft((np.conj(kop) * rfft(r, n=m, axis=-1)).sum(0), n=m)
    else:
        shift = np.exp(2j * np.pi * freq[None, :] * taus[:, None])

        def forward(z: np.ndarray) -> np.ndarray:
            th = c * rfft(z)
            ahead = irfft(shift * th[None, :], n=m, axis=-1)
            now = irfft(th, n=m)[:n]
            return np.stack([lag_ops[j] @ ahead[j] for j in range(p)]) - now[None, :]

        def adjoint(r: np.ndarray) -> np.ndarray:
            back = np.stack([lag_ops[j].T @ r[j] for j in range(p)])
            acc = (np.conj(shift) * rfft(back, n=m, axis=-1)).sum(0) - rfft(r.sum(0), n=m)
            return irfft(c * acc, n=m)

    q = 0
    if extra is not None:
        xs = np.asarray(extra[0], dtype=np.float64) * np.asarray(extra[1], dtype=np.float64)[None, None, :]
        q = xs.shape[2]
        xs = np.where(valid[:, :, None], xs, 0.0)
        field_fwd, field_adj = forward, adjoint

        def forward(u: np.ndarray) -> np.ndarray:  # noqa: F811 - the field and the extra parameters
            return field_fwd(u[:m]) + np.einsum("pnq,q->pn", xs, u[m:])

        def adjoint(r: np.ndarray) -> np.ndarray:  # noqa: F811
            return np.concatenate([field_adj(r), np.einsum("pnq,pn->q", xs, r)])

    weigh = _colour_weighting(w, colour, m)

    def normal(z: np.ndarray) -> np.ndarray:
        return z + adjoint(weigh(forward(z)))

    b = adjoint(weigh(dz))
    frac = valid.sum(1) / m
    gain = (frac / sigma**2)[:, None] / (1.0 if colour is None else colour)
    diag = 1.0 + (np.abs(kop) ** 2 * gain).sum(0)
    diag_x = 1.0 + np.einsum("pnq,pn->q", xs * xs, w) if q else None

    def precond(r: np.ndarray) -> np.ndarray:
        out = irfft(rfft(r[:m]) / diag, n=m)
        return out if not q else np.concatenate([out, r[m:] / diag_x])

    # plain sums rather than BLAS dots: cheap at this size, and immune to BLAS threading
    if theta0 is None:
        z = np.zeros(m + q)
        r = b.copy()
    else:  # z0 = L^-1 theta0 on the prior's support
        z = np.concatenate([irfft(np.where(c > 0, rfft(theta0) / np.where(c > 0, c, 1.0), 0.0), n=m), np.zeros(q)])
        r = b - normal(z)
    bn = math.sqrt(float(np.sum(b * b))) or 1.0
    y = precond(r)
    d = y.copy()
    ry = float(np.sum(r * y))
    it = 0
    res = math.sqrt(float(np.sum(r * r))) / bn
    while it < int(maxiter) and res > tol and ry > 0:
        ad = normal(d)
        alpha = ry / float(np.sum(d * ad))
        z += alpha * d
        r -= alpha * ad
        it += 1
        res = math.sqrt(float(np.sum(r * r))) / bn
        y = precond(r)
        ry_new = float(np.sum(r * y))
        d = y + (ry_new / ry) * d
        ry = ry_new
    grid = irfft(c * rfft(z[:m]), n=m)
    # the quadratic at the iterate is Dᵀ W D − bᵀ z − rᵀ z: what the identity Dᵀ W (D − A z) misses short of
    # the minimum (its error first order in z − z*, the quadratic's second order)
    short = float(np.sum(r * z))
    if q:
        return grid[:n], grid, forward(z), it, res, z[m:] * np.asarray(extra[1], dtype=np.float64), short
    return grid[:n], grid, forward(z), it, res, None, short


def integrate_wiener(diffs, taus, dt, *, noise_std=None, psd=None, pad_fraction: float = 0.5,
                     tol: float = 1e-7, maxiter: int = 300, refine: int | None = None,
                     max_gap_s: float | None = None, spectrum_options: dict | None = None,
                     weights=None, psd_ceiling=None, lags=None, tones=None, noise_colour=None,
                     return_details: bool = False):
    """Exact multi-pair Wiener (MAP) integration on the finite record, by conjugate gradients.

    With gaps, the first PSD estimate comes from the gap-free segments only
    (coarse resolution); each of the ``refine`` passes then re-estimates the PSD
    from the differentials with their gaps filled by the current estimate's
    predictions (full resolution) and the noise from the residuals on valid
    samples, and solves again (an EM-like iteration).

    Parameters
    ----------
    diffs, taus, dt
        As for :func:`restore.integration.integrate`.
    noise_std : float or sequence, keyword-only
        Per-pair noise standard deviation (rad); estimated if None.
    psd : callable or (freq, psd), keyword-only
        Two-sided prior PSD of theta (rad²/Hz); estimated from the data if None.
    pad_fraction : float, keyword-only
        Extra periodic domain beyond the record, as a fraction of its length.
    tol, maxiter : keyword-only
        Conjugate-gradient stopping rule (relative residual, iterations).
    refine : int, keyword-only
        Refinement passes (default 2 when more than 1 % of samples are missing,
        else 0; ignored when ``psd`` is given).
    max_gap_s : float, keyword-only
        Longest unobserved interior run returned (s); default the longest lag.
    spectrum_options : dict, keyword-only
        Passed to :func:`~restore.integration.spectrum.estimate_spectrum`.
    weights : sequence of arrays, keyword-only
        Relative weight of each sample, one array per pair (e.g. the number of
        matched points behind each line's differential): the noise variance of
        sample ``n`` of pair ``j`` is ``noise_std_j² / weights_j[n]``, with the
        weights scaled to mean 1 over the pair's valid samples (``noise_std``
        stays the pair's typical level). Non-finite or <= 0 = no weight.
    psd_ceiling : (freq, ceiling), keyword-only
        Upper bound of the estimated prior PSD (rad²/Hz, ``inf`` = none), e.g.
        what the AOCS knowledge already knows
        (:func:`restore.knowledge_prior.knowledge_psd_ceiling`); ignored when
        ``psd`` is given. The reported spectrum is the bounded one.
    lags : sequence of arrays, keyword-only
        Extra lag of each pair at each sample [s] (time synchronisation:
        ``diffs[j][n] ≈ θ(n dt + τ_j + λ_j[n]) − θ(n dt)``), modelled exactly in
        the normal equations (4-point interpolation of the shifted estimate,
        :func:`lag_interpolation`); non-finite = 0. The prior, when estimated,
        is estimated from the differentials as given (a lag of a few samples
        barely moves a PSD smoothed over many bins).
    tones : (frequencies, sd[, order]), keyword-only
        Sinusoids [Hz] on frequencies every pair is blind to, estimated with
        the field (prior ``N(0, sd²)`` on each coefficient, rad; cos and sin
        times a polynomial of degree ``order`` in time, 0 by default): there
        the differentials see them only through the lags (:func:`blind_tones`);
        ignored without lags (differentials at the nominal delays: a frozen
        rerun on simulated ones).
        The estimate returned includes them; ``WienerResult.tones`` holds
        their (cos, sin) coefficients.
    noise_colour : (freq, colour), keyword-only
        Each pair's noise power relative to its white level, ``colour`` (pair,
        freq) > 0 at ``freq`` [Hz] (e.g. what the predicted σ's check of the
        fit residual measured, :func:`restore.posterior.noise_colour_estimate`):
        the normal equations weigh the residual by the inverse of that
        coloured covariance (:func:`_colour_weighting`) instead of per sample
        only. The reported objective stays the white one.
    return_details : bool, keyword-only
        Return a :class:`WienerResult` instead of the array.

    Returns
    -------
    ndarray or WienerResult
        theta at ``n dt`` (rad), mean removed, NaN where not estimated.
    """
    D, valid, taus, dt = prepare(diffs, taus, dt)
    p, n = D.shape
    if int(maxiter) < 1:
        raise ValueError(f"maxiter: must be >= 1, got {maxiter}")
    rel = None
    if weights is not None:
        rel = np.asarray([np.asarray(x, dtype=np.float64) for x in weights]) if len(weights) else None
        if rel is None or rel.shape != D.shape:
            raise ValueError(f"weights: expected {p} arrays of {n} samples, got shape "
                             f"{None if rel is None else rel.shape}")
        ok = valid & np.isfinite(rel) & (rel > 0)
        rel = np.where(ok, rel, 0.0)
        for j in range(p):
            mj = rel[j][valid[j]].mean() if valid[j].any() else 0.0
            rel[j] = rel[j] / mj if mj > 0 else rel[j]
    tol = check_positive("tol", tol)
    if refine is None:
        refine = 2 if valid.mean() < 0.99 else 0
    if int(refine) < 0:
        raise ValueError(f"refine: must be >= 0, got {refine}")
    lag_arr = None
    if lags is not None:
        lag_arr = [np.nan_to_num(np.asarray(x, dtype=np.float64)) for x in lags]
        if len(lag_arr) != p or any(x.shape != (n,) for x in lag_arr):
            raise ValueError(f"lags: expected {p} arrays of {n} samples, got {[x.shape for x in lag_arr]}")
        if not any(np.any(x != 0) for x in lag_arr):
            lag_arr = None
    # the padding also holds the longest extra lag (+2 for the interpolation's support): a lagged sample
    # must not wrap around to the record's start
    max_lag = 0.0 if lag_arr is None else max(float(np.max(np.abs(x))) for x in lag_arr) + 2 * dt
    m = _grid(n, taus, dt, check_positive("pad_fraction", pad_fraction, allow_zero=True), max_lag)
    lag_ops = None if lag_arr is None else [lag_interpolation(x / dt, m) for x in lag_arr]
    if lag_arr is None:
        tones = None  # without lags a tone on a common blind frequency leaves nothing to estimate it from
    opts = dict(spectrum_options or {})
    spec: SpectralEstimate = estimate_spectrum(D, taus, dt, n_fft=m, noise_std=noise_std, **opts)
    passes = 0 if psd is not None else int(refine)
    colour = None if noise_colour is None else colour_on_grid(noise_colour, spec.freq, p)
    grid = None
    ceiling = None if psd is not None or psd_ceiling is None else ceiling_on_grid(psd_ceiling, spec.freq)
    floor = None if ceiling is None else np.minimum(floor_on_grid(psd_ceiling, spec.freq), ceiling)
    above = None
    for k in range(passes + 1):
        if ceiling is not None:
            # where the data's estimate reaches the ceiling, the differentials show more than the attitude can
            # have there: the AOCS knowledge proves the excess is theirs (kept for the choice of the high-pass)
            above = spec.psd >= ceiling
            spec.psd = np.clip(spec.psd, floor, ceiling)
        S = spec.psd.copy() if psd is None else _psd_on_grid(psd, spec.freq)
        S[0] = 0.0
        if m % 2 == 0:
            S[-1] = 0.0  # keep the operator exactly self-adjoint on real signals
        out = _cg_solve(D, valid, taus, dt, spec.freq, S, spec.noise_std, m, tol=tol, maxiter=maxiter,
                        theta0=grid, rel_weights=rel, lag_ops=lag_ops,
                        extra=None if tones is None else tone_columns(tones, n, taus, dt, lag_arr), colour=colour)
        full, grid, pred, it, res = out[:5]
        if k == passes:
            break
        sigma = noise_std
        if sigma is None:
            sigma = np.array([math.sqrt(float(np.mean((D[j] - pred[j])[valid[j]] ** 2)))
                              for j in range(p)])
        filled = np.where(valid, D, pred)
        spec = estimate_spectrum(filled, taus, dt, n_fft=m, noise_std=sigma, **opts)
    coefs = out[5]
    # the MAP objective ‖u‖² + ‖D − A u‖²_W: at its minimum Dᵀ W (D − A u) (the quadratic's identity); where the
    # conjugate gradients stopped short of it (their iteration limit: at 2 px of jitter a tone's solve stopped at
    # a residual 15 × the tolerance) the identity errs to first order, by ± tens on a 1.6 s record (the blind
    # tones' decisions compare such drops), and rᵀu takes it to the quadratic's value at the iterate
    wgt = np.where(valid, 1.0, 0.0) / spec.noise_std[:, None] ** 2 if rel is None else \
        np.where(valid, rel, 0.0) / spec.noise_std[:, None] ** 2
    objective = float(np.sum(wgt * np.where(valid, D * (D - pred), 0.0)))
    if colour is None:  # with a colour the reported objective stays the white identity
        objective -= out[6]
    if coefs is not None:  # the tones join the field, on the record and on the grid
        wave = tone_waves(tones[0], m, dt, int(tones[2]) if len(tones) > 2 else 0, n_record=n,
                          chirps=tone_chirps(tones)) @ coefs
        full, grid = full + wave[:n], grid + wave
    theta = _finish(full, valid, taus, dt, max_gap_s)
    spec.above_ceiling = above
    if return_details:
        r = WienerResult(theta, full - np.mean(full), spec, it, res, theta_grid=grid - np.mean(full))
        r.tones = coefs
        r.objective = objective
        r.predicted = np.where(valid, pred, np.nan)
        return r
    return theta


def common_blind_frequencies(taus, dt: float, record_s: float, top_hz: float) -> np.ndarray:
    """Frequencies in (0, ``top_hz``] at which every pair is blind (``f τ_j`` whole for all j) [Hz].

    Found on a grid of a quarter of the record's resolution: the local minima
    of ``Σ_j |G_j(f)|²`` below a hundredth of the pairs' count, i.e. where
    the fused gain is what a mismatch of a fraction of a bin leaves.
    """
    taus = np.asarray(taus, dtype=np.float64)
    step = 0.25 / max(record_s, 1e-9)
    f = np.arange(0.5 / taus.max(), min(top_hz, 0.5 / dt) + step, step)
    if f.size < 3:
        return np.zeros(0)
    g = (2 * (1 - np.cos(2 * np.pi * f[:, None] * taus[None, :]))).sum(1)
    low = g < 0.01 * taus.size * 4
    i = np.flatnonzero(low[1:-1] & (g[1:-1] <= g[:-2]) & (g[1:-1] <= g[2:])) + 1
    # the vertex of the parabola through the grid's minimum and its neighbours (g is quadratic there)
    den = g[i - 1] - 2 * g[i] + g[i + 1]
    off = np.where(den > 0, 0.5 * (g[i - 1] - g[i + 1]) / np.where(den > 0, den, 1.0), 0.0)
    return f[i] + np.clip(off, -1.0, 1.0) * step


#: :func:`blind_tones`: the probability that noise alone, as the model describes it, passes the χ² test of one
#: notch search (over all its candidates). 1e-8 missed a 0.2 px CMG harmonic 0.19 Hz off the common blind
#: frequency of an unseen off-nadir scene (the best candidate's drop 54.1 against a threshold of 54.6; the pitch
#: error 0.141 px outside the yaw, 0.024 with the tone); a tone taken where none is costs ≈ 0.01 px. Misfit the
#: model does not hold is the controls' to reject (:data:`CONTROL_OFFSETS_BINS`), not this level's.
TONE_FALSE_ALARM = 1e-6


def blind_tones(diffs, taus, dt, *, psd, noise_std, weights=None, lags, tol: float = 1e-6,
                maxiter: int = 300, false_alarm: float = TONE_FALSE_ALARM, max_tones: int | None = None,
                order: int = 2,
                max_order: int = 4, base_objective: float | None = None, base_prediction=None):
    """A tone on a frequency every pair is blind to, seen through the per-line lags: ``(frequencies, sd, order)``
    or None.

    At a common blind frequency ``f_b`` the differentials of a tone vanish at
    the nominal delays, but band B sees line l at ``t + τ + λ(l)``: the tone
    leaves ``θ'(t) λ(t)`` — sidebands at ``f_b ± `` the lags' frequencies,
    which a spectrum estimate takes for attitude there. Near each common
    blind frequency below the prior's highest frequency (× 1.2) the MAP is
    solved with one tone of broad prior added, at the blind frequency and
    ± half and one resolution bin, and at the line the pairs see directly
    inside the notch the spectrum estimate leaves unestimated around it, if
    any (:func:`notch_peaks`, on what the MAP without a tone leaves
    unexplained); the tone that lowers the MAP objective most
    is kept if the drop exceeds what pure noise gives with probability
    ``false_alarm`` over all the candidates (a generalised likelihood ratio,
    χ² with the tone's coefficients: where the field already explains the
    data — a tone off the blind frequency, broadband power in the notch — a
    tone gains little);
    then the next, with the kept ones in the model, at most one per slot and
    ``max_tones`` in all (default: one per slot). A notch has two slots: its
    blind frequency (the candidates within a bin of it, seen through the lags
    only) and the line the pairs see directly inside it (the
    :func:`notch_peaks` candidate, 1.5 bins or more away), which may both be
    there: on an unseen CMG scene a harmonic at 129.6 Hz took the 135.1 Hz
    notch's only tone and a 0.5 px line on 135.135 Hz stayed whole in the
    error (0.36 px RMS; 0.017 / 0.028 px with a slot each). Never two tones
    of one kind in a notch: an unseen CMG with lines in the notches at 135
    and 270 Hz kept 0.19 px of the other with one tone in all, but on the
    off-nadir stress scenario a second tone for a CMG line drifting across
    the notch gained nothing on roll and cost pitch 0.008 px.
    The tone's cos and sin each carry a polynomial of degree ``order`` in
    time (a line whose amplitude and phase drift over the record, as a CMG
    harmonic's do: on that scenario the roll error 0.050 → 0.029 px with
    ``order = 2``, none with 1); once the tones are chosen the degree rises
    by 2 at a time up to ``max_order`` while the data call for it
    (:func:`tone_order`; ``max_order = order``: never). ``base_objective``,
    ``base_prediction``: the objective and the predicted differentials
    (:attr:`WienerResult.predicted`) of the same MAP without a tone, when the
    caller has solved it already.

    The notch's line is looked for in the residual of that MAP, not in the
    differentials: at large amplitude the lags' sidebands of lines outside
    the notch (70 + 61 Hz of a CMG's harmonics at 2 px, 131 Hz) are stronger
    in the differentials than a line inside it, and the MAP explains them (on
    an unseen 2 px CMG scene the raw differentials' peak was that sideband, the
    residual's the 140 Hz line, 0.3 px, which then went unrestored in pitch).

    ``false_alarm`` (:data:`TONE_FALSE_ALARM`) weighs the two errors the
    test can make, which cost very differently: a tone taken where none is
    adds a few polynomial-modulated coefficients' noise (≈ 0.01 px), a line on
    the blind frequency left out stays whole in the error (0.1-0.4 px).

    The χ² holds under the noise model. Where the data carry misfit it does
    not model (at 3 px of jitter and more the matching errs with the signal,
    sidebands included), a tone anywhere near the notch lowers the objective
    more: a candidate's drop must exceed the largest drop of the same tone
    moved ± 4 and ± 6 bins away (:data:`CONTROL_OFFSETS_BINS`) by the
    threshold too, and the :data:`CANDIDATES_CHECKED` best are tried in turn
    (misfit may make a wrong candidate the best) — on an unseen 3.2 px CMG
    scenario a tone "found" at 134.5 Hz in pitch, where none was, cost 0.010 px.
    It lowers the false alarms, it does not end them: with 1 px of misfit at
    128-142 Hz (synthetic, six draws) a tone is "found" in 2 of 6 records
    against 6 of 6 by the χ² alone; the price is sensitivity under such misfit
    (a real 0.3 px tone under 0.3 px of it found in 3 of 6, 5 of 6 by the χ²
    alone; without misfit 6 of 6 either way).
    """
    D, valid, taus_a, dt = prepare(diffs, taus, dt)
    n = D.shape[1]
    f, S = np.asarray(psd[0], dtype=np.float64), np.asarray(psd[1], dtype=np.float64)
    if lags is None or not np.any(S > 0):
        return None
    record_s = n * dt
    top = 1.2 * float(f[S > 0].max())
    centres = common_blind_frequencies(taus_a, dt, record_s, top)
    if centres.size == 0:
        return None
    sd = 2.0 * math.sqrt(max(2.0 * float(np.sum(S)) * float(f[1] - f[0]), 1e-300))

    solved: dict = {}

    def solve(tones):
        # the degree's and the sweep's steps meet tones already solved (the chosen one, the stencil's overlap)
        key = None if tones is None else (tuple(float(x) for x in tones[0]), float(tones[1]),
                                          int(tones[2]) if len(tones) > 2 else 0,
                                          None if tone_chirps(tones) is None else tuple(tone_chirps(tones)))
        if key not in solved:
            solved[key] = integrate_wiener(diffs, taus, dt, psd=psd, noise_std=noise_std, weights=weights,
                                           lags=lags, tones=tones, tol=tol, maxiter=maxiter, return_details=True)
        return solved[key]

    from scipy.stats import chi2

    offsets = (-1.0, -0.5, 0.0, 0.5, 1.0)
    # (frequency, its slot): at most one tone per slot — in each notch, one on the blind frequency (seen through
    # the lags only) and one on a line the pairs see directly inside the notch (:func:`notch_peaks`)
    candidates = [(fc + k / record_s, (i, "blind")) for i, fc in enumerate(centres) for k in offsets]
    if base_objective is None or base_prediction is None:
        first = solve(None)
        base_objective, base_prediction = first.objective, first.predicted
    left = np.where(valid, D - np.nan_to_num(np.asarray(base_prediction, dtype=np.float64)), 0.0)
    candidates += [(fk, (i, "line")) for i, fk in notch_peaks(left, valid, taus_a, dt, noise_std, centres,
                                                               exclude_hz=1.5 / record_s, false_alarm=false_alarm)]
    # the objective's drop is −2 log of a likelihood ratio: χ² with the tone's 2(order + 1) coefficients
    # under no tone, over every candidate tried (Bonferroni)
    threshold = float(chi2.isf(false_alarm / len(candidates), 2 * (order + 1)))
    chosen: list = []
    chosen_slots: list = []
    base = float(base_objective)
    slots = len({i for _, i in candidates})
    # a notch's second tone stands apart from its first by the width a drifting line spans: closer, the two
    # would be one line drifting across the notch
    apart = TONE_SEPARATION_BINS / record_s
    for _ in range(slots if max_tones is None else min(int(max_tones), slots)):
        gains = []
        for fk, i in candidates:
            if i in chosen_slots or any(j[0] == i[0] and abs(fk - fc) < apart for fc, j in zip(chosen, chosen_slots)):
                continue
            gains.append((base - solve((chosen + [fk], sd, order)).objective, fk, i))
        best = None
        # the χ² assumes the noise model; where the data carry misfit it does not (at several pixels of
        # jitter the matching errs with the signal), any tone near the notch gains more: the same tone a few
        # bins away, where no blind tone sits, measures by how much, and the candidate must gain that much more
        for gain, fk, i in sorted(gains, reverse=True)[:CANDIDATES_CHECKED]:
            if gain < threshold:
                break
            controls = [base - solve((chosen + [fk + k / record_s], sd, order)).objective
                        for k in CONTROL_OFFSETS_BINS]
            if gain - max(controls + [0.0]) >= threshold:
                best = (gain, fk, i)
                break
        if best is None:
            break
        chosen.append(best[1])
        chosen_slots.append(best[2])
        base -= best[0]
    if not chosen:
        return None
    order = tone_order(solve, chosen, sd, order, base, max_order=max_order)
    return tone_sweep(solve, chosen, sd, order, record_s, gain_needed=float(chi2.isf(false_alarm, 2)))


def tone_order(solve, chosen: list, sd: float, order: int, objective: float, *, max_order: int) -> int:
    """The degree of the tones' polynomial modulation the data call for: from ``order`` up by 2 while the
    MAP objective (−2 log posterior) drops by more than 2 per added coefficient (4 per tone: Akaike's
    criterion, the degree expected to predict best; nested models, the higher degree contains the lower);
    ``objective`` is that of ``order``.

    ``solve(tones)`` is the MAP with ``tones = (frequencies, sd, order)``. A
    CMG harmonic drifts by 0.3-1 % over a record, a turn of phase or more at
    130 Hz, which a quadratic in time follows only at first. The tones are
    already found (the search's strict false alarm guards against inventing
    one); here a higher degree only shapes a tone that is there, within a few
    bins of it, and what counts is the error, not a test: a 0.3 px line
    drifting 1.2 Hz over the record lowers the objective by 40 at degree 4
    (its error 0.016 → 0.007 px). :func:`blind_tones` stops at 4: a
    polynomial of degree 6 swings at the record's ends (an unseen CMG's roll
    0.029 px at degree 4, 0.044 at 6, which Akaike's criterion chose).
    """
    best, base = int(order), float(objective)
    for o in range(int(order) + 2, int(max_order) + 1, 2):
        obj = solve((chosen, sd, o)).objective
        if base - obj < ORDER_PER_COEFFICIENT * 2 * (o - best) * len(chosen):
            break
        best, base = o, obj
    return best


def tone_sweep(solve, freqs, sd: float, order: int, record_s: float, *, gain_needed: float,
               rounds: int | None = None) -> tuple:
    """The found tones with their frequency and sweep rate refined: ``(frequencies, sd, order[, chirps])``.

    A CMG harmonic drifts over a record (0.3-1 % of 67 Hz: its second
    harmonic sweeps 0.4-1.2 Hz in 1.6 s, one or two resolution bins), and
    the search places its line on a grid of half bins. The polynomial
    modulation follows a phase that turns by a cycle or so; beyond that the
    restored line is off (an unseen CMG's 134.4-135.3 Hz sweep, found at
    135.17 Hz, restored 0.020 px off in 125-145 Hz at degree 4; degree 6
    follows it better but swings at the record's ends elsewhere).
    Each tone in turn: the MAP objective at the eight neighbours of its
    (frequency, rate) in steps of a quarter bin and of one bin swept over the
    record (``1 / record_s²`` Hz/s), moving to the best while it drops by more
    than ``gain_needed`` (−2 log of a likelihood ratio: χ² with the two
    parameters), at most ``rounds`` times (default :data:`SWEEP_ROUNDS`). On that scene the objective chose
    135.01 Hz sweeping 0.39 Hz/s: the restored roll 0.027 -> 0.021 px; a steady
    line (the same scene's pitch) keeps its frequency and no sweep. ``chirps`` is given only when a
    rate is not zero (``solve(tones)``: the MAP with those tones).
    """
    freqs, chirps = [float(f) for f in freqs], [0.0] * len(freqs)
    objective = solve((freqs, sd, order)).objective
    df, dc = 0.25 / record_s, 1.0 / record_s ** 2
    for i in range(len(freqs)):
        for _ in range(SWEEP_ROUNDS if rounds is None else int(rounds)):
            best = None
            for a in (-1, 0, 1):
                for b in (-1, 0, 1):
                    if a == b == 0:
                        continue
                    f2, c2 = list(freqs), list(chirps)
                    f2[i] += a * df
                    c2[i] += b * dc
                    obj = solve((f2, sd, order, c2)).objective
                    if best is None or obj < best[0]:
                        best = (obj, f2, c2)
            if objective - best[0] <= gain_needed:
                break
            objective, freqs, chirps = best
    return (freqs, sd, order, chirps) if any(c != 0.0 for c in chirps) else (freqs, sd, order)


def notch_peaks(D, valid, taus, dt: float, noise_std, centres, *, exclude_hz: float,
                false_alarm: float = 1e-8) -> list:
    """``[(centre index, frequency)]``: in each notch around a common blind frequency
    (:func:`restore.integration.spectrum.notch_mask`), the frequency where the differentials hold most power
    for a tone (their periodograms weighted by each pair's ``|G_j|² / ν_j``, normalised so that white noise
    of the pairs' levels gives exponential values of mean 1), outside ``exclude_hz`` of the blind frequency
    itself, when that power is a line the pairs see directly:
    above ``ln(bins scanned / false_alarm)``, what noise exceeds with probability ``false_alarm`` over the
    notch. A tone's sidebands through the lags do not count: far off the blind frequency they could fit
    misfit (at 270 Hz, second-order sidebands fall on 1 px of misfit at 128-142 Hz), and the control tones
    of :func:`blind_tones` would not tell.

    The spectrum estimate does not estimate the notch (its prior there is
    bridged from the edges, so that leakage and the lags' sidebands are not
    divided by ~0). But a notch spans Hz around the blind frequency (± 4 Hz
    at 135 Hz on the phr_cmg delays), and a line inside it that one pair sees
    well (a CMG harmonic at 132 Hz, |G| = 0.41 for B1/B2) was left wholly in
    the error: these peaks are the tone candidates :func:`blind_tones` tries
    besides the blind frequency.
    """
    p, n = D.shape
    m = next_fast_len(int(1.5 * n))
    f = np.fft.rfftfreq(m, dt)
    sig = np.broadcast_to(np.asarray(noise_std, dtype=np.float64), (p,))
    nu = np.maximum(sig, 1e-300) ** 2 * dt
    poor = notch_mask(f, taus, nu)
    g2 = 2 * (1 - np.cos(2 * np.pi * f[None, :] * np.asarray(taus)[:, None]))
    stat = np.zeros(f.size)
    for j in range(p):
        x = np.where(valid[j], D[j] - (D[j][valid[j]].mean() if valid[j].any() else 0.0), 0.0)
        # |X|² of white noise of variance σ² over k valid lines has mean k σ² = k ν / dt
        stat += np.abs(rfft(x, n=m)) ** 2 * dt / max(int(valid[j].sum()), 1) * g2[j] / nu[j] ** 2
    stat /= np.maximum((g2 / nu[:, None]).sum(0), 1e-300)
    out = []
    for i, fc in enumerate(np.atleast_1d(centres)):
        zone = poor & (np.abs(f - fc) > exclude_hz)
        # the notch this blind frequency sits in: its contiguous poor bins
        k0 = int(np.argmin(np.abs(f - fc)))
        lo = k0
        while lo > 0 and poor[lo - 1]:
            lo -= 1
        hi = k0
        while hi < f.size - 1 and poor[hi + 1]:
            hi += 1
        idx = np.flatnonzero(zone[lo:hi + 1]) + lo
        if idx.size:
            k = idx[np.argmax(stat[idx])]
            if stat[k] > math.log(idx.size / false_alarm):
                out.append((i, float(f[k])))
    return out


#: :func:`blind_tones`: the control tones' offsets from a candidate [resolution bins] (beyond the candidates' ± 1
#: and the width a second-order drift gives a line)
CONTROL_OFFSETS_BINS = (-6.0, -4.0, 4.0, 6.0)
#: :func:`blind_tones`: a notch's two tones (its blind frequency's, a line the pairs see inside it) lie at least this
#: far apart [resolution bins] — the width a CMG harmonic's drift gives a line (1 % at 130 Hz over 1.6 s: 2.1
#: bins); 4 bins (the controls' nearest offset) kept out a roll harmonic 0.18 Hz off forward_view's blind
#: frequency on seed 2027, 2.8 bins from the yaw's line seen as roll: 0.094 px of roll left in the error
TONE_SEPARATION_BINS = 2.5
#: :func:`blind_tones`: the best candidates (by their drop) checked against their controls, in turn
CANDIDATES_CHECKED = 3
#: rounds of :func:`tone_sweep`'s refinement of a found tone's frequency and sweep rate
SWEEP_ROUNDS = 4
#: :func:`tone_order`: a step up in a found tone's modulation degree must lower the MAP objective by this much per
#: added coefficient (2: Akaike's criterion)
ORDER_PER_COEFFICIENT = 2.0


def spectrum_for_lines(diffs, taus, dt, *, noise_std=None, spectrum_options: dict | None = None,
                       gap_threshold: float = 0.01) -> SpectralEstimate:
    """Spectrum with full frequency resolution even when the differentials have gaps.

    Without gaps (missing fraction <= ``gap_threshold``) this is
    :func:`estimate_spectrum`.  With gaps, the gap-free segments only give a
    coarse resolution, so the spectrum is the one refined by
    :func:`~restore.integration.wiener.integrate_wiener` (gaps filled by its
    predictions, noise from its residuals).
    """
    D, valid, taus, dt = prepare(diffs, taus, dt)
    opts = dict(spectrum_options or {})
    if 1.0 - valid.mean() <= gap_threshold:
        return estimate_spectrum(D, taus, dt, noise_std=noise_std, **opts)
    res = integrate_wiener(D, taus, dt, noise_std=noise_std, spectrum_options=opts,
                           return_details=True)
    return res.spectrum
