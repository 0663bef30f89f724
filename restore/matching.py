"""Sub-pixel matching of characteristic points between two bands (patent step a).

A small window of band A (PHR: 3 lines x 31 columns) is centred on each
characteristic point; its homologue is searched in band B around a predicted,
fractional position, over an integer grid of offsets sized by the predictor's
accuracy. The integer peak of the normalised cross-correlation (NCC) is then
refined to sub-pixel accuracy by one of two estimators, both batched over all
points (``(N, lines, columns)`` stacks, no Python loop per point):

``"ncc"``
    Gauss-Newton (Lucas-Kanade) registration of the A window on band B
    resampled at the current sub-pixel position, with a gain and an offset
    between the bands. The Jacobian uses the gradient of the A window (fixed,
    computed once), so the fixed point, ``sum(grad A * (B(x + d) - gain A - offset)) = 0``,
    carries no first-order noise bias, and the estimate is insensitive to the
    smoothing that interpolation applies at half-pixel positions (no pixel
    locking, unlike a parabola fit of the NCC surface).
``"phase"``
    Phase correlation in the spirit of Kim & Su (1993): the phase of the
    cross-power spectrum of the A window and of band B resampled at the current
    position is fitted by a plane (weighted least squares through the origin);
    the slope gives the residual shift, and the resampling is iterated until it
    vanishes (so the periodic-boundary leakage of the tiny window vanishes too).

Band B is resampled by a separable, normalised Lanczos kernel (order 4 by
default), reading a few lines and columns of B around the window: the window
itself may be only 3 lines high.

Coordinates are ``(line, column)`` with pixel centres at integers. A point of A
matched at ``(line_b, col_b)`` in B means that the ground seen at ``(line_a,
col_a)`` in A is seen at ``(line_b, col_b)`` in B.

References
----------
.. [1] S. Kim, W. Su, "Subpixel accuracy image registration by spectrum
       cancellation", ICASSP 1993.
.. [2] J. Delon, B. Rouge, "Small baseline stereovision", J. Math. Imaging
       Vision 28, 2007 (matching precision vs local gradient energy).
"""
from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np

__all__ = [
    "MatchFlag",
    "MatchResult",
    "match_points",
    "support_margin",
    "lanczos_weights",
    "derivative_filter",
    "resample_windows",
]

_METHODS = ("ncc", "phase")
_CHUNK = 4096  # points per batch: bounds memory, not a per-point loop
#: antisymmetric gradient filter of the A window (Gauss-Newton Jacobian), 1/px
_GRADIENT = np.array([1.0, -8.0, 0.0, 8.0, -1.0]) / 12.0


class MatchFlag(enum.IntFlag):
    """Reasons for rejecting a match (bit mask, ``0`` = valid)."""

    OK = 0
    #: window, search area or interpolation support leaves the image
    OUT_OF_BOUNDS = 1
    #: a non-finite pixel (no data) in the support
    NO_DATA = 2
    #: degenerate window: no texture in A or B, or a singular normal matrix
    FLAT = 4
    #: the refined match lies beyond the search area (peak on its border)
    SEARCH_BORDER = 8
    #: correlation at the refined position below ``min_quality``
    LOW_CORRELATION = 16
    #: the refinement did not converge, or left the integer peak's cell
    NOT_CONVERGED = 32
    #: estimated standard deviation above ``max_std``
    IMPRECISE = 64


@dataclass(frozen=True)
class MatchResult:
    """Matches of ``N`` points of band A in band B.

    Attributes
    ----------
    line_b, col_b : ndarray of float, shape (N,)
        Sub-pixel position in B of each point of A (px).
    quality : ndarray of float, shape (N,)
        Normalised cross-correlation between the A window and B resampled at
        the match, in [-1, 1]; ``nan`` where it could not be computed.
    valid : ndarray of bool, shape (N,)
        ``flags == 0``.
    flags : ndarray of int, shape (N,)
        :class:`MatchFlag` bit mask of the rejection reasons.
    std_line, std_col : ndarray of float, shape (N,)
        A-posteriori standard deviation of the match per axis (px), from the
        residual of the fit and the gradient energy of the window
        (Delon & Rouge: ``std ~ noise / sqrt(sum(gradient**2))``).
    """

    line_b: np.ndarray
    col_b: np.ndarray
    quality: np.ndarray
    valid: np.ndarray
    flags: np.ndarray
    std_line: np.ndarray
    std_col: np.ndarray

    def __len__(self) -> int:
        return int(self.line_b.shape[0])


# ---------------------------------------------------------------------------
# interpolation kernel


def _lanczos(x: np.ndarray, order: int) -> np.ndarray:
    return np.where(np.abs(x) < order, np.sinc(x) * np.sinc(x / order), 0.0)


def lanczos_weights(shift, *, order: int = 4) -> np.ndarray:
    """Weights of a normalised Lanczos kernel for a fractional shift.

    Parameters
    ----------
    shift : array_like of float, shape (N,)
        Position to interpolate, relative to the central tap (px); must lie in
        ``(-1, 1)`` for all non-zero weights to fall on the taps.
    order : int, keyword-only
        Lanczos order ``a`` (half-width of the kernel, px).

    Returns
    -------
    ndarray, shape (N, 2 * order + 1)
        Weights of taps ``k = -order .. order``: ``f(shift) ~ sum_k w_k f[k]``.
        They sum to 1.
    """
    if order < 1:
        raise ValueError(f"order: must be >= 1, got {order}")
    shift = np.asarray(shift, dtype=float)
    k = np.arange(-order, order + 1, dtype=float)
    w = _lanczos(k - shift[..., None], order)
    return w / w.sum(axis=-1, keepdims=True)


def derivative_filter(*, order: int = 4) -> np.ndarray:
    """Antisymmetric derivative filter matched to the Lanczos interpolator.

    Parameters
    ----------
    order : int, keyword-only
        Lanczos order ``a``.

    Returns
    -------
    ndarray, shape (2 * order - 1,)
        Taps ``D_k``, ``k = -(order - 1) .. order - 1`` such that
        ``f'(i) ~ sum_k D_k f[i + k]`` (1/px); exact on linear ramps.
    """
    if order < 1:
        raise ValueError(f"order: must be >= 1, got {order}")
    k = np.arange(-(order - 1), order, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        d = np.where(k == 0, 0.0, -np.cos(np.pi * k) / k * np.sinc(k / order))
    if order == 1:
        d = np.array([0.0])
    s = np.sum(k * d)
    return d / s if s != 0 else d


def resample_windows(patches: np.ndarray, shift_lines, shift_cols, *, order: int = 4) -> np.ndarray:
    """Resample a stack of patches at a per-patch sub-pixel shift.

    Parameters
    ----------
    patches : ndarray, shape (N, h + 2 * order, w + 2 * order)
        Patches whose central ``(h, w)`` part is the window at zero shift.
    shift_lines, shift_cols : array_like of float, shape (N,)
        Shift of each window (px), in ``(-1, 1)``.
    order : int, keyword-only
        Lanczos order.

    Returns
    -------
    ndarray, shape (N, h, w)
        ``out[n, i, j] ~ f_n(i + shift_lines[n], j + shift_cols[n])`` with ``f_n``
        the band-limited interpolant of the patch (central window at 0).
    """
    patches = np.asarray(patches)
    n, hp, wp = patches.shape
    m = 2 * order
    h, w = hp - m, wp - m
    if h < 1 or w < 1:
        raise ValueError(f"patches: need more than {m} lines and columns, got {patches.shape}")
    wl = lanczos_weights(shift_lines, order=order).astype(patches.dtype, copy=False)
    wc = lanczos_weights(shift_cols, order=order).astype(patches.dtype, copy=False)
    swv = np.lib.stride_tricks.sliding_window_view
    # lines first: (N, h, wp) is small for wide, short windows
    rows = np.einsum("nk,nkij->nij", wl, swv(patches, h, axis=1).transpose(0, 1, 3, 2))
    return np.einsum("nk,nijk->nij", wc, swv(rows, m + 1, axis=2))


# ---------------------------------------------------------------------------
# helpers


def support_margin(*, window=(3, 31), search=(2, 2), order: int = 4) -> tuple[int, int]:
    """Pixels of image needed on each side of a point to match it.

    Parameters
    ----------
    window : (int, int), keyword-only
        Window size (lines, columns), odd.
    search : (int, int), keyword-only
        Search half-range (lines, columns), px.
    order : int, keyword-only
        Lanczos order of the interpolator.

    Returns
    -------
    (int, int)
        Margin (lines, columns) around the (rounded) point in A and the
        (rounded) predicted position in B that must lie inside the image.
    """
    window = _check_window(window)
    search = _check_search(search)
    return (window[0] // 2 + search[0] + order, window[1] // 2 + search[1] + order)


def _check_window(window) -> tuple[int, int]:
    try:
        h, w = (int(v) for v in window)
    except (TypeError, ValueError):
        raise ValueError(f"window: expected two odd integers (lines, columns), got {window!r}") from None
    if h < 1 or w < 3 or h % 2 == 0 or w % 2 == 0 or (h, w) != tuple(window):
        raise ValueError(f"window: expected two odd integers (lines >= 1, columns >= 3), got {window!r}")
    return h, w


def _check_search(search) -> tuple[int, int]:
    try:
        sl, sc = (int(v) for v in search)
    except (TypeError, ValueError):
        raise ValueError(f"search: expected two integers >= 0 (lines, columns), got {search!r}") from None
    if sl < 0 or sc < 0 or (sl, sc) != tuple(search):
        raise ValueError(f"search: expected two integers >= 0 (lines, columns), got {search!r}")
    return sl, sc


def _gather(image: np.ndarray, l0: np.ndarray, c0: np.ndarray, half_l: int, half_c: int):
    """Patches ``(N, 2*half_l+1, 2*half_c+1)`` centred on integer ``(l0, c0)``.

    Patches that would leave the image are shifted inside it (their content is
    then meaningless) and reported by the returned ``inside`` mask.
    """
    nl, nc = image.shape
    hl, hc = 2 * half_l + 1, 2 * half_c + 1
    if nl < hl or nc < hc:
        return np.zeros((l0.size, hl, hc)), np.zeros(l0.size, dtype=bool)
    s_l, s_c = l0 - half_l, c0 - half_c
    inside = (s_l >= 0) & (s_l + hl <= nl) & (s_c >= 0) & (s_c + hc <= nc)
    view = np.lib.stride_tricks.sliding_window_view(image, (hl, hc))
    return view[np.clip(s_l, 0, nl - hl), np.clip(s_c, 0, nc - hc)], inside


def _box_sums(region: np.ndarray, h: int, w: int) -> np.ndarray:
    """Sums over every ``(h, w)`` window of a stack: (N, L - h + 1, C - w + 1)."""
    nr = region.shape[1] - h + 1
    rows = region[:, 0:nr, :].copy()
    for p in range(1, h):
        rows += region[:, p:p + nr, :]
    cs = np.cumsum(rows, axis=2, dtype=np.float64)
    out = cs[:, :, w - 1:].copy()
    out[:, :, 1:] -= cs[:, :, :-w]
    return out


def _integer_search(a_z, a_norm, region, h, w, sl, sc):
    """NCC of the A windows over the integer search grid: (N, 2sl+1, 2sc+1).

    A loop over the handful of integer offsets; each step is batched over the
    points. Non-computable entries (flat B) are ``-inf``.
    """
    n = a_z.shape[0]
    num = np.empty((n, 2 * sl + 1, 2 * sc + 1), dtype=np.float64)
    for i in range(2 * sl + 1):
        for j in range(2 * sc + 1):
            num[:, i, j] = np.einsum("nij,nij->n", a_z, region[:, i:i + h, j:j + w])
    s1 = _box_sums(region, h, w)
    s2 = _box_sums(region * region, h, w)
    var = np.maximum(s2 - s1 * s1 / (h * w), 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        surf = num / (np.sqrt(var) * a_norm[:, None, None])
    return np.where(np.isfinite(surf), surf, -np.inf)


def _inv3(m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Inverse of a stack of symmetric 3x3 matrices and their determinants."""
    a, b, c = m[:, 0, 0], m[:, 0, 1], m[:, 0, 2]
    d, e, f = m[:, 1, 1], m[:, 1, 2], m[:, 2, 2]
    c00, c01, c02 = d * f - e * e, c * e - b * f, b * e - c * d
    c11, c12, c22 = a * f - c * c, b * c - a * e, a * d - b * b
    det = a * c00 + b * c01 + c * c02
    inv = np.stack([c00, c01, c02, c01, c11, c12, c02, c12, c22], axis=1).reshape(-1, 3, 3)
    with np.errstate(divide="ignore", invalid="ignore"):
        return inv / det[:, None, None], det


def _phase_grids(h: int, w: int):
    """Frequencies (cycles/px) of the rfft2 half plane and its multiplicity."""
    u = np.fft.fftfreq(h)[:, None] * np.ones((1, w // 2 + 1))
    v = np.fft.rfftfreq(w)[None, :] * np.ones((h, 1))
    # the half plane stands for its mirror too, except the v = 0 column
    # (and the Nyquist column of an even width)
    mult = np.where((v == 0) | ((w % 2 == 0) & (v == 0.5)), 1.0, 2.0)
    return u, v, mult


def _phase_shift(fa: np.ndarray, b: np.ndarray, grids):
    """Shift of ``b`` w.r.t. the A window (spectrum ``fa``) from the phase plane (px).

    Weighted least-squares fit through the origin of the cross-power-spectrum
    phase, ``phase(F_b conj(F_a)) = -2 pi (u s_l + v s_c)``, weights ``|F_b F_a|``
    (Kim & Su 1993). Valid for small residual shifts (no phase wrapping),
    which the iteration provides.
    """
    u, v, mult = grids
    q = np.fft.rfft2(b) * np.conj(fa)
    wgt = np.abs(q) * mult
    wphi = wgt * np.angle(q)
    uu = np.einsum("nij,ij->n", wgt, u * u)
    vv = np.einsum("nij,ij->n", wgt, v * v)
    uv = np.einsum("nij,ij->n", wgt, u * v)
    pu = np.einsum("nij,ij->n", wphi, u)
    pv = np.einsum("nij,ij->n", wphi, v)
    det = uu * vv - uv * uv
    with np.errstate(divide="ignore", invalid="ignore"):
        s_l = -(vv * pu - uv * pv) / (2.0 * np.pi * det)
        s_c = -(uu * pv - uv * pu) / (2.0 * np.pi * det)
    return np.nan_to_num(s_l), np.nan_to_num(s_c)


# ---------------------------------------------------------------------------
# main entry point


def match_points(
    image_a,
    image_b,
    lines_a,
    cols_a,
    pred_lines_b,
    pred_cols_b,
    *,
    window=(3, 31),
    search=(2, 2),
    method: str = "ncc",
    min_quality: float = 0.5,
    max_std: float | None = None,
    order: int = 4,
    max_iter: int = 8,
    tol: float = 1e-3,
) -> MatchResult:
    """Match points of band A in band B to sub-pixel accuracy.

    Parameters
    ----------
    image_a, image_b : ndarray, shape (lines, columns)
        The two bands (any radiometric unit; gain and offset between them are
        estimated per window). Non-finite pixels are no data.
    lines_a, cols_a : array_like of float, shape (N,)
        Points in A (px). The A window is centred on the rounded point; the
        match is reported for the point itself (local translation).
    pred_lines_b, pred_cols_b : array_like of float, shape (N,)
        Predicted position of each point in B (px, fractional).
    window : (int, int), keyword-only
        Window size (lines, columns), odd; PHR uses 3 x 31.
    search : (int, int), keyword-only
        Half-range of the integer search around the prediction (lines,
        columns), px; size it by the predictor's accuracy.
    method : {"ncc", "phase"}, keyword-only
        Sub-pixel estimator (see the module docstring). Both start from the
        peak of the normalised cross-correlation over the integer grid.
    min_quality : float, keyword-only
        Matches whose final NCC is below this are flagged ``LOW_CORRELATION``.
    max_std : float or None, keyword-only
        If given, matches whose estimated standard deviation (px) exceeds it
        on either axis are flagged ``IMPRECISE``.
    order : int, keyword-only
        Lanczos order of the interpolator of B (reads ``order`` more pixels of
        B on each side of the search area).
    max_iter : int, keyword-only
        Maximum number of sub-pixel iterations.
    tol : float, keyword-only
        A point stops iterating once its update is below this (px); the last
        update is applied, so the remaining error is much smaller.

    Returns
    -------
    MatchResult
        Positions in B, quality, validity, rejection flags and estimated
        standard deviations, one per point.

    Raises
    ------
    ValueError
        On a bad parameter; the message names it.

    Notes
    -----
    A match is flagged ``SEARCH_BORDER`` when it is not bracketed by the
    searched integer grid (beyond its outermost offsets; beyond ±0.5 px on an
    axis whose half-range is 0).
    """
    if method not in _METHODS:
        raise ValueError(f"method: expected one of {_METHODS}, got {method!r}")
    h, w = _check_window(window)
    sl, sc = _check_search(search)
    if not (-1.0 <= float(min_quality) <= 1.0):
        raise ValueError(f"min_quality: must lie in [-1, 1], got {min_quality}")
    if max_std is not None and not float(max_std) > 0:
        raise ValueError(f"max_std: must be > 0, got {max_std}")
    if int(order) != order or order < 1:
        raise ValueError(f"order: must be an integer >= 1, got {order}")
    if int(max_iter) != max_iter or max_iter < 1:
        raise ValueError(f"max_iter: must be an integer >= 1, got {max_iter}")
    if not float(tol) > 0:
        raise ValueError(f"tol: must be > 0, got {tol}")
    image_a = np.asarray(image_a, dtype=float)
    image_b = np.asarray(image_b, dtype=float)
    for name, img in (("image_a", image_a), ("image_b", image_b)):
        if img.ndim != 2:
            raise ValueError(f"{name}: expected a 2-D (line, column) array, got shape {img.shape}")
    names = ("lines_a", "cols_a", "pred_lines_b", "pred_cols_b")
    pts = [np.atleast_1d(np.asarray(v, dtype=float)) for v in (lines_a, cols_a, pred_lines_b, pred_cols_b)]
    n = pts[0].shape[0]
    for name, v in zip(names, pts):
        if v.ndim != 1 or v.shape[0] != n:
            raise ValueError(f"{name}: expected shape ({n},), got {v.shape}")
        if not np.all(np.isfinite(v)):
            raise ValueError(f"{name}: must be finite")

    opts = dict(h=h, w=w, sl=sl, sc=sc, method=method, min_quality=float(min_quality),
                max_std=max_std, order=int(order), max_iter=int(max_iter), tol=float(tol))
    parts = [_match_chunk(image_a, image_b, *(v[i:i + _CHUNK] for v in pts), **opts)
             for i in range(0, n, _CHUNK)]
    if not parts:
        parts = [_match_chunk(image_a, image_b, *pts, **opts)]
    fields = MatchResult.__dataclass_fields__
    return MatchResult(**{f: np.concatenate([p[f] for p in parts]) for f in fields})


def _match_chunk(image_a, image_b, la, ca, pl, pc, *, h, w, sl, sc, method, min_quality, max_std,
                 order, max_iter, tol) -> dict:
    n = la.shape[0]
    npx = h * w
    hl, hc = h // 2, w // 2
    dfil = _GRADIENT.astype(np.float32)
    g = dfil.size // 2
    flags = np.zeros(n, dtype=np.int64)
    ftype = np.float32

    ra_l, ra_c = np.rint(la).astype(np.int64), np.rint(ca).astype(np.int64)
    # prediction for the rounded A point (local translation model)
    pr_l, pr_c = pl - (la - ra_l), pc - (ca - ra_c)
    c0_l, c0_c = np.rint(pr_l).astype(np.int64), np.rint(pr_c).astype(np.int64)

    # --- gather A (window + gradient support) and B (search + interpolation) ------
    a_patch, in_a = _gather(image_a, ra_l, ra_c, hl + g, hc + g)
    b_big, in_b = _gather(image_b, c0_l, c0_c, hl + sl + order, hc + sc + order)
    flags[~(in_a & in_b)] |= MatchFlag.OUT_OF_BOUNDS
    ok_a = np.isfinite(a_patch).all(axis=(1, 2))
    ok_b = np.isfinite(b_big).all(axis=(1, 2))
    flags[~(ok_a & ok_b)] |= MatchFlag.NO_DATA
    if not (ok_a.all() and ok_b.all()):
        a_patch = np.where(np.isfinite(a_patch), a_patch, 0.0)
        b_big = np.where(np.isfinite(b_big), b_big, 0.0)
    # remove a per-point level, then work in single precision
    a_ref = a_patch[:, g:g + h, g:g + w].mean(axis=(1, 2))
    b_ref = b_big.mean(axis=(1, 2))
    a_patch = a_patch.astype(ftype)
    a_patch -= a_ref.astype(ftype)[:, None, None]
    b_big = b_big.astype(ftype)
    b_big -= b_ref.astype(ftype)[:, None, None]
    a_win = a_patch[:, g:g + h, g:g + w]
    a_z = a_win - a_win.mean(axis=(1, 2), keepdims=True)
    a_norm2 = np.einsum("nij,nij->n", a_z, a_z, dtype=np.float64)
    a_norm = np.sqrt(a_norm2)
    # flat: no texture at all, or below single precision w.r.t. the level
    flat_a = ~(a_norm > 1e-6 * np.sqrt(npx) * np.abs(a_ref))

    # --- integer search ------------------------------------------------------------
    region = b_big[:, order:order + h + 2 * sl, order:order + w + 2 * sc]
    surf = _integer_search(a_z, a_norm, region, h, w, sl, sc)
    k = np.argmax(surf.reshape(n, -1), axis=1)
    il, ic = np.divmod(k, 2 * sc + 1)
    flat_b = ~np.isfinite(surf.reshape(n, -1)[np.arange(n), k])
    # B patch centred on the integer peak, with the interpolation support
    hp, wp = h + 2 * order, w + 2 * order
    patch = np.lib.stride_tricks.sliding_window_view(b_big, (hp, wp), axis=(1, 2))[np.arange(n), il, ic]

    # --- Gauss-Newton design: zero-mean [A, dA/dl, dA/dc] (fixed) -------------------
    swv = np.lib.stride_tricks.sliding_window_view
    g_l = np.einsum("k,nijk->nij", dfil, swv(a_patch[:, :, g:g + w], 2 * g + 1, axis=1))
    g_c = np.einsum("k,nijk->nij", dfil, swv(a_patch[:, g:g + h, :], 2 * g + 1, axis=2))
    jac = np.stack([a_z, g_l - g_l.mean(axis=(1, 2), keepdims=True),
                    g_c - g_c.mean(axis=(1, 2), keepdims=True)], axis=1).reshape(n, 3, npx)
    normal = np.einsum("nqp,nrp->nqr", jac, jac, dtype=np.float64)
    dsc = np.sqrt(np.einsum("nii->ni", normal))
    with np.errstate(divide="ignore", invalid="ignore"):
        det_corr = _inv3(normal / (dsc[:, :, None] * dsc[:, None, :]))[1]
    singular = ~(det_corr > 1e-6) | flat_a | flat_b
    normal[singular] = np.eye(3)
    ninv = _inv3(normal)[0]

    # --- sub-pixel iterations (active set shrinks as points converge) ---------------
    d_l = np.zeros(n)
    d_c = np.zeros(n)
    stats = np.zeros((n, 4))  # <J_q, B~> (q = 0..2) and |B~ - mean|^2 at the last evaluation
    converged = singular.copy()
    kappa = np.ones((n, 2))  # secant estimate of the gain of the step
    prev = np.zeros((n, 4))  # previous (d_l, d_c, F_l, F_c)
    if method == "phase":
        fa = np.fft.rfft2(a_z)
        grids = _phase_grids(h, w)
    active = np.flatnonzero(~converged)
    for it in range(max_iter + 1):
        if active.size == 0:
            break
        if it == 0:  # at the integer peak: no resampling needed
            b_res = patch[active, order:order + h, order:order + w]
        else:
            b_res = resample_windows(patch[active], d_l[active], d_c[active], order=order)
        c = np.einsum("nqp,np->nq", jac[active], b_res.reshape(-1, npx), dtype=np.float64)
        b_mean = b_res.mean(axis=(1, 2), dtype=np.float64)
        sb = np.einsum("np,np->n", b_res.reshape(-1, npx), b_res.reshape(-1, npx),
                       dtype=np.float64) - npx * b_mean**2
        stats[active] = np.column_stack([c, sb])
        if it == max_iter:
            break
        if method == "ncc" or it == 0:
            gain = c[:, 0] / a_norm2[active]  # variable projection of the gain
            p = -np.einsum("nij,nj->ni", ninv[active], c - gain[:, None] * normal[active, :, 0])
            safe = np.where(np.abs(gain) > 1e-12, gain, 1.0)
            f_l, f_c = p[:, 1] / safe, p[:, 2] / safe
        if method == "phase":
            # the first move is the Lucas-Kanade step; the phase estimate at the
            # integer peak only seeds the secant
            ph_l, ph_c = _phase_shift(fa[active], b_res - b_mean[:, None, None].astype(ftype), grids)
            if it > 0:
                f_l, f_c = ph_l, ph_c
        else:
            ph_l, ph_c = f_l, f_c
        # both estimators return a residual shift F(d) with the same root but a
        # slope that is not exactly -1: per-axis secant update of that slope
        if it > 0:
            for ax, (dd, ff) in enumerate(((d_l, f_l), (d_c, f_c))):
                dx = dd[active] - prev[active, ax]
                df = prev[active, 2 + ax] - ff
                upd = np.abs(dx) > 1e-4
                kappa[active, ax] = np.where(upd, np.clip(df / np.where(upd, dx, 1.0), 0.2, 2.0),
                                             kappa[active, ax])
        prev[active] = np.column_stack([d_l[active], d_c[active], ph_l, ph_c])
        step_l, step_c = f_l / kappa[active, 0], f_c / kappa[active, 1]
        d_l[active] = np.clip(d_l[active] + step_l, -0.999, 0.999)
        d_c[active] = np.clip(d_c[active] + step_c, -0.999, 0.999)
        done = (np.abs(step_l) < tol) & (np.abs(step_c) < tol)
        converged[active[done]] = True
        active = active[~done]

    # --- quality and a-posteriori precision ---------------------------------------
    c0, sb = stats[:, 0], stats[:, 3]
    with np.errstate(divide="ignore", invalid="ignore"):
        quality = c0 / (a_norm * np.sqrt(sb))
        gain = c0 / a_norm2
        sigma2 = np.maximum(sb - c0 * gain, 0.0) / max(npx - 4, 1)
        std_l = np.sqrt(sigma2 * ninv[:, 1, 1]) / np.abs(gain)
        std_c = np.sqrt(sigma2 * ninv[:, 2, 2]) / np.abs(gain)

    off_l = (il - sl) + d_l
    off_c = (ic - sc) + d_c
    line_b = c0_l + off_l + (la - ra_l)
    col_b = c0_c + off_c + (ca - ra_c)

    flags[singular] |= MatchFlag.FLAT
    lim_l, lim_c = (sl if sl else 0.5), (sc if sc else 0.5)
    flags[(np.abs(off_l) > lim_l) | (np.abs(off_c) > lim_c)] |= MatchFlag.SEARCH_BORDER
    flags[~converged | (np.abs(d_l) >= 0.99) | (np.abs(d_c) >= 0.99)] |= MatchFlag.NOT_CONVERGED
    flags[~(quality >= min_quality)] |= MatchFlag.LOW_CORRELATION
    if max_std is not None:
        flags[~((std_l <= max_std) & (std_c <= max_std))] |= MatchFlag.IMPRECISE
    quality = np.where(singular, np.nan, quality)
    return {
        "line_b": line_b, "col_b": col_b, "quality": quality, "valid": flags == 0,
        "flags": flags, "std_line": std_l, "std_col": std_c,
    }
