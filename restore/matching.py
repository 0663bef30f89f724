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
    # lines first: (N, h, wp) is small for wide, short windows
    rows = wl[:, 0, None, None] * patches[:, 0:h, :]
    for k in range(1, m + 1):
        rows += wl[:, k, None, None] * patches[:, k:k + h, :]
    out = wc[:, 0, None, None] * rows[:, :, 0:w]
    for k in range(1, m + 1):
        out += wc[:, k, None, None] * rows[:, :, k:k + w]
    return out


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
    """(N, 2*half_l+1, 2*half_c+1) patches centred on integer (l0, c0); out-of-image is clipped."""
    nl, nc = image.shape
    dl = np.arange(-half_l, half_l + 1)
    dc = np.arange(-half_c, half_c + 1)
    inside = (l0 - half_l >= 0) & (l0 + half_l < nl) & (c0 - half_c >= 0) & (c0 + half_c < nc)
    rows = np.clip(l0[:, None] + dl, 0, nl - 1)
    cols = np.clip(c0[:, None] + dc, 0, nc - 1)
    return image[rows[:, :, None], cols[:, None, :]], inside


def _normalise(win: np.ndarray):
    """Zero-mean windows and their L2 norms."""
    z = win - win.mean(axis=(1, 2), keepdims=True)
    return z, np.sqrt(np.einsum("nij,nij->n", z, z))


def _ncc(a_z: np.ndarray, a_norm: np.ndarray, b: np.ndarray) -> np.ndarray:
    b_z, b_norm = _normalise(b)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.einsum("nij,nij->n", a_z, b_z) / (a_norm * b_norm)


def _integer_search(a_z, a_norm, region, h, w, sl, sc):
    """NCC over the integer search grid: (N, 2sl+1, 2sc+1)."""
    n = a_z.shape[0]
    npx = h * w
    view = np.lib.stride_tricks.sliding_window_view(region, (h, w), axis=(1, 2))
    # (N, 2sl+1, 2sc+1, h, w) -> (N, K, h*w) (one copy of K windows per point)
    mat = view.reshape(n, (2 * sl + 1) * (2 * sc + 1), npx)
    num = np.matmul(mat, a_z.reshape(n, npx, 1))[..., 0]
    s1 = mat.sum(axis=2)
    s2 = np.einsum("nkp,nkp->nk", mat, mat)
    var = np.maximum(s2 - s1 * s1 / npx, 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        surf = num / (np.sqrt(var) * a_norm[:, None])
    surf = np.where(np.isfinite(surf), surf, -np.inf)
    return surf.reshape(n, 2 * sl + 1, 2 * sc + 1)


def _parabola(minus, centre, plus):
    den = minus - 2.0 * centre + plus
    with np.errstate(divide="ignore", invalid="ignore"):
        d = np.where(den < 0, 0.5 * (minus - plus) / den, 0.0)
    return np.clip(np.nan_to_num(d), -0.5, 0.5)


def _phase_step(a_z: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Residual shift of ``b`` w.r.t. ``a`` by a weighted phase-plane fit (px)."""
    h, w = a_z.shape[1:]
    fa = np.fft.rfft2(a_z)
    fb = np.fft.rfft2(b - b.mean(axis=(1, 2), keepdims=True))
    q = fb * np.conj(fa)  # b(x) = a(x - s)  =>  phase = -2 pi f.s
    wgt = np.abs(q)
    phi = np.angle(q)
    u = np.fft.fftfreq(h)[:, None] * np.ones((1, w // 2 + 1))
    v = np.fft.rfftfreq(w)[None, :] * np.ones((h, 1))
    # conjugate-symmetric half plane: the v = 0 column holds u and -u twice,
    # the others stand for their mirror too -> weight 2 except v = 0
    half = np.where(v == 0, 1.0, 2.0)
    wgt = wgt * half
    uu = np.einsum("nij,ij->n", wgt, u * u)
    vv = np.einsum("nij,ij->n", wgt, v * v)
    uv = np.einsum("nij,ij->n", wgt, u * v)
    pu = np.einsum("nij,ij->n", wgt * phi, u)
    pv = np.einsum("nij,ij->n", wgt * phi, v)
    det = uu * vv - uv * uv
    with np.errstate(divide="ignore", invalid="ignore"):
        sl = (vv * pu - uv * pv) / det
        sc = (uu * pv - uv * pu) / det
    k = -1.0 / (2.0 * np.pi)
    return np.nan_to_num(k * sl), np.nan_to_num(k * sc)


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
    max_iter: int = 10,
    tol: float = 1e-4,
) -> MatchResult:
    """Match points of band A in band B to sub-pixel accuracy.

    Parameters
    ----------
    image_a, image_b : ndarray, shape (lines, columns)
        The two bands (any radiometric unit; gain and offset between them are
        estimated per window). Non-finite pixels are no data.
    lines_a, cols_a : array_like of float, shape (N,)
        Points in A (px). The A window is centred on the rounded point.
    pred_lines_b, pred_cols_b : array_like of float, shape (N,)
        Predicted position of each point in B (px, fractional).
    window : (int, int), keyword-only
        Window size (lines, columns), odd; PHR uses 3 x 31.
    search : (int, int), keyword-only
        Half-range of the integer search around the prediction (lines,
        columns), px; size it by the predictor's accuracy.
    method : {"ncc", "phase"}, keyword-only
        Sub-pixel estimator (see the module docstring). Both start from the
        integer NCC peak.
    min_quality : float, keyword-only
        Matches whose final NCC is below this are flagged ``LOW_CORRELATION``.
    max_std : float or None, keyword-only
        If given, matches whose estimated standard deviation (px) exceeds it
        on either axis are flagged ``IMPRECISE``.
    order : int, keyword-only
        Lanczos order of the interpolator of B (reads ``order`` more pixels of
        B on each side).
    max_iter : int, keyword-only
        Maximum number of sub-pixel iterations.
    tol : float, keyword-only
        Convergence threshold on the update (px).

    Returns
    -------
    MatchResult
        Positions in B, quality, validity, rejection flags and estimated
        standard deviations, one per point.

    Raises
    ------
    ValueError
        On a bad parameter; the message names it.
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
    pts = [np.atleast_1d(np.asarray(v, dtype=float)) for v in (lines_a, cols_a, pred_lines_b, pred_cols_b)]
    names = ("lines_a", "cols_a", "pred_lines_b", "pred_cols_b")
    n = pts[0].shape[0]
    for name, v in zip(names, pts):
        if v.ndim != 1 or v.shape[0] != n:
            raise ValueError(f"{name}: expected shape ({n},), got {v.shape}")
        if not np.all(np.isfinite(v)):
            raise ValueError(f"{name}: must be finite")

    parts = [
        _match_chunk(image_a, image_b, *(v[i:i + _CHUNK] for v in pts), h=h, w=w, sl=sl, sc=sc,
                     method=method, min_quality=float(min_quality), max_std=max_std, order=int(order),
                     max_iter=int(max_iter), tol=float(tol))
        for i in range(0, max(n, 1), _CHUNK)
    ]
    fields = MatchResult.__dataclass_fields__
    return MatchResult(**{f: np.concatenate([p[f] for p in parts]) for f in fields})


def _match_chunk(image_a, image_b, la, ca, pl, pc, *, h, w, sl, sc, method, min_quality, max_std,
                 order, max_iter, tol) -> dict:
    n = la.shape[0]
    hl, hc = h // 2, w // 2
    g = order - 1
    flags = np.zeros(n, dtype=np.int64)

    ra_l, ra_c = np.rint(la).astype(np.int64), np.rint(ca).astype(np.int64)
    # prediction for the rounded A point (local translation model)
    pr_l, pr_c = pl - (la - ra_l), pc - (ca - ra_c)
    c0_l, c0_c = np.rint(pr_l).astype(np.int64), np.rint(pr_c).astype(np.int64)

    # --- A: window and its gradient ------------------------------------------------
    a_patch, in_a = _gather(image_a, ra_l, ra_c, hl + g, hc + g)
    # --- B: everything the search and the refinement can read ---------------------
    b_big, in_b = _gather(image_b, c0_l, c0_c, hl + sl + order, hc + sc + order)
    flags[~(in_a & in_b)] |= MatchFlag.OUT_OF_BOUNDS
    bad = ~(np.isfinite(a_patch).all(axis=(1, 2)) & np.isfinite(b_big).all(axis=(1, 2)))
    flags[bad] |= MatchFlag.NO_DATA
    a_patch = np.where(np.isfinite(a_patch), a_patch, 0.0)
    b_big = np.where(np.isfinite(b_big), b_big, 0.0)

    a_win = a_patch[:, g:g + h, g:g + w]
    a_z, a_norm = _normalise(a_win)
    scale = np.abs(a_win).max(axis=(1, 2)) + np.abs(b_big).max(axis=(1, 2)) + 1e-300
    flat_a = a_norm <= 1e-9 * scale * np.sqrt(h * w)

    # --- integer search ----------------------------------------------------------
    region = b_big[:, order:order + h + 2 * sl, order:order + w + 2 * sc]
    surf = _integer_search(a_z, a_norm, region, h, w, sl, sc)
    k = np.argmax(surf.reshape(n, -1), axis=1)
    il, ic = np.divmod(k, 2 * sc + 1)
    peak = surf.reshape(n, -1)[np.arange(n), k]
    flat_b = ~np.isfinite(peak)
    # initial sub-pixel guess: parabola through the peak on each axis
    idx = np.arange(n)
    d_l = np.zeros(n)
    d_c = np.zeros(n)
    if sl > 0:
        inner = (il > 0) & (il < 2 * sl)
        m, p = np.clip(il - 1, 0, 2 * sl), np.clip(il + 1, 0, 2 * sl)
        d_l = np.where(inner, _parabola(surf[idx, m, ic], surf[idx, il, ic], surf[idx, p, ic]), 0.0)
    if sc > 0:
        inner = (ic > 0) & (ic < 2 * sc)
        m, p = np.clip(ic - 1, 0, 2 * sc), np.clip(ic + 1, 0, 2 * sc)
        d_c = np.where(inner, _parabola(surf[idx, il, m], surf[idx, il, ic], surf[idx, il, p]), 0.0)
    d_l = np.nan_to_num(d_l)
    d_c = np.nan_to_num(d_c)

    # patch of B centred on the integer peak, with the interpolation support
    hp, wp = h + 2 * order, w + 2 * order
    rows = il[:, None] + np.arange(hp)
    cols = ic[:, None] + np.arange(wp)
    patch = b_big[idx[:, None, None], rows[:, :, None], cols[:, None, :]]

    # --- design matrix of the Gauss-Newton fit (fixed: gradient of A) ------------
    dfil = derivative_filter(order=order)
    g_l = np.zeros_like(a_win)
    g_c = np.zeros_like(a_win)
    for j, dk in enumerate(dfil):
        if dk != 0.0:
            g_l += dk * a_patch[:, j:j + h, g:g + w]
            g_c += dk * a_patch[:, g:g + h, j:j + w]
    jac = np.stack([a_z, np.ones_like(a_z), g_l, g_c], axis=-1).reshape(n, h * w, 4)
    normal = np.einsum("npi,npj->nij", jac, jac)
    dscale = np.sqrt(np.einsum("nii->ni", normal)) + 1e-300
    corr = normal / (dscale[:, :, None] * dscale[:, None, :])
    eig_min = np.linalg.eigvalsh(corr)[:, 0]
    singular = ~(eig_min > 1e-8) | flat_a | flat_b
    corr = np.where(singular[:, None, None], np.eye(4), corr)
    ninv = np.linalg.inv(corr) / (dscale[:, :, None] * dscale[:, None, :])

    def fit_photometry(b):
        gain = np.einsum("nij,nij->n", a_z, b) / np.where(flat_a, 1.0, a_norm**2)
        return gain, b.mean(axis=(1, 2))

    converged = np.zeros(n, dtype=bool)
    b_res = resample_windows(patch, d_l, d_c, order=order)
    gain, offset = fit_photometry(b_res)
    for _ in range(max_iter):
        if method == "ncc":
            r = (b_res - gain[:, None, None] * a_z - offset[:, None, None]).reshape(n, h * w)
            p = -np.einsum("nij,nj->ni", ninv, np.einsum("npi,np->ni", jac, r))
            safe = np.where(np.abs(gain) > 1e-12, gain, 1.0)
            step_l, step_c = p[:, 2] / safe, p[:, 3] / safe
            gain, offset = gain - p[:, 0], offset - p[:, 1]
        else:
            step_l, step_c = _phase_step(a_z, b_res)
        step_l = np.where(singular, 0.0, step_l)
        step_c = np.where(singular, 0.0, step_c)
        d_l = np.clip(d_l + step_l, -0.999, 0.999)
        d_c = np.clip(d_c + step_c, -0.999, 0.999)
        converged = (np.abs(step_l) < tol) & (np.abs(step_c) < tol)
        b_res = resample_windows(patch, d_l, d_c, order=order)
        if method == "phase":
            gain, offset = fit_photometry(b_res)
        if converged.all():
            break

    # --- quality and a-posteriori precision ---------------------------------------
    quality = _ncc(a_z, a_norm, b_res)
    gain, offset = fit_photometry(b_res)
    r = (b_res - gain[:, None, None] * a_z - offset[:, None, None]).reshape(n, h * w)
    dof = max(h * w - 4, 1)
    sigma2 = np.einsum("np,np->n", r, r) / dof
    with np.errstate(divide="ignore", invalid="ignore"):
        std_l = np.sqrt(sigma2 * ninv[:, 2, 2]) / np.abs(gain)
        std_c = np.sqrt(sigma2 * ninv[:, 3, 3]) / np.abs(gain)

    line_b = c0_l + (il - sl) + d_l + (la - ra_l)
    col_b = c0_c + (ic - sc) + d_c + (ca - ra_c)
    off_l = c0_l + (il - sl) + d_l - pr_l
    off_c = c0_c + (ic - sc) + d_c - pr_c

    flags[singular] |= MatchFlag.FLAT
    flags[(np.abs(off_l) > sl) | (np.abs(off_c) > sc)] |= MatchFlag.SEARCH_BORDER
    flags[~converged | (np.abs(d_l) >= 0.99) | (np.abs(d_c) >= 0.99)] |= MatchFlag.NOT_CONVERGED
    flags[~(quality >= min_quality)] |= MatchFlag.LOW_CORRELATION
    if max_std is not None:
        flags[~((std_l <= max_std) & (std_c <= max_std))] |= MatchFlag.IMPRECISE
    quality = np.where(singular, np.nan, quality)
    return {
        "line_b": line_b, "col_b": col_b, "quality": quality, "valid": flags == 0,
        "flags": flags, "std_line": std_l, "std_col": std_c,
    }
