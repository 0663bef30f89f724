"""Sub-pixel matching of characteristic points between two bands (patent step a).

A small window of band A (PHR: 3 lines x 31 columns) is centred on each
characteristic point; its homologue is searched in band B around a predicted,
fractional position, over an integer grid of offsets sized by the predictor's
accuracy. The integer peak of the normalised cross-correlation (NCC) is then
refined to sub-pixel accuracy, batched over all points (``(N, lines, columns)``
stacks; the only Python loops run over integer offsets, filter taps and
iterations, never over points):

``"ncc"``
    Gauss-Newton (Lucas-Kanade) registration of the A window on band B
    resampled at the current sub-pixel position, with a gain and an offset
    between the bands. The Jacobian is the gradient of the A window (fixed,
    computed once by an antisymmetric filter), so the fixed point
    ``sum(grad A * (B(x + d) - gain * A - offset)) = 0`` carries no first-order
    noise bias and does not feel the smoothing that interpolation applies at
    half-pixel positions: no pixel locking, unlike a parabola fit of the NCC
    surface. Between identical bands it is the NCC maximum to first order.
``"phase"``
    Phase correlation in the spirit of Kim & Su (1993): the phase of the
    cross-power spectrum of the A window and of band B resampled at the
    current position is fitted by a plane through the origin (weighted least
    squares, weights ``|F_A F_B|``); its slope is the residual shift. Band B is
    resampled at the updated position until the slope vanishes, which also
    removes the periodic-boundary leakage of so small a window. The first move
    is the Lucas-Kanade step (the phase of a 3-line window says little about a
    shift of more than a few tenths of a line).

Both iterations look for the root of ``F(d)``, the residual shift the
estimator sees from the current position ``d``. Its slope matrix is the
identity only for identical, isotropic windows; a per-point 2 x 2 Broyden
(secant) update learns it (coupled axes on oriented texture, cross-band
contrast), with a bounded step, so that most points converge in two
resamplings. The integer base moves to a neighbour inside the search grid when
the refinement leaves its cell. Band B is resampled by a separable, normalised
Lanczos kernel (order 4 by default) from the lines and columns around the
window: the window itself may be only 3 lines high.

Points whose integer NCC peak is far below ``min_quality`` (clouds, unrelated
bands), outside the image or touching no data are not refined.

Two implementations of ``"ncc"``, selected by ``backend``: a compiled Numba
kernel (:mod:`restore._ncc_kernel`, the default: one point per iteration of a
parallel loop, its whole refinement in cache, 3-4x faster than the batched
form and faster per match than ``cv2.phaseCorrelate``, see ``simsat bench
matching``), and the batched NumPy form described above, kept as the
reference the tests compare the kernel with (positions agree to 1e-6 px).

Coordinates are ``(line, column)`` with pixel centres at integers. A point of A
matched at ``(line_b, col_b)`` means that the ground seen at ``(line_a, col_a)``
in A is seen at ``(line_b, col_b)`` in B.

References
----------
.. [1] Kim & Su (1993): sub-pixel shift from a plane fitted to the phase of
       the cross-power spectrum.
.. [2] J. Delon, B. Rouge, "Small baseline stereovision", J. Math. Imaging
       Vision 28, 2007: the matching precision is
       ``noise / sqrt(sum(gradient**2))`` over the window.
"""
from __future__ import annotations

import dataclasses

import enum
import threading
from dataclasses import dataclass, fields

import numpy as np

__all__ = [
    "match_points_in_blocks",
    "MatchFlag",
    "MatchResult",
    "match_points",
    "support_margin",
    "lanczos_weights",
    "resample_windows",
]

_METHODS = ("ncc", "phase")
_BACKENDS = ("auto", "compiled", "numpy")
#: points per batch: keeps the stacks in cache and bounds memory
_CHUNK = 2048
#: antisymmetric gradient filter of the A window (Gauss-Newton Jacobian), 1/px
_GRADIENT = np.array([1.0, -8.0, 0.0, 8.0, -1.0]) / 12.0
_G = _GRADIENT.size // 2
_F32 = np.float32
#: largest sub-pixel step per iteration and axis (px)
_MAX_STEP = 0.5
#: from this iteration on, a point whose step does not shrink is given up
_STALL_IT = 8


class MatchFlag(enum.IntFlag):
    """Reasons for rejecting a match (bit mask, ``0`` = valid)."""

    OK = 0
    #: window, search area or interpolation support leaves the image
    OUT_OF_BOUNDS = 1
    #: a non-finite pixel (no data) in the support
    NO_DATA = 2
    #: degenerate window: no texture in A or B, or a singular normal matrix
    FLAT = 4
    #: the refined match is not bracketed by the searched integer grid
    SEARCH_BORDER = 8
    #: correlation at the refined position below ``min_quality``
    LOW_CORRELATION = 16
    #: no convergence in ``max_iter`` iterations, a step that stopped
    #: shrinking (no root in reach), or the refinement stuck at the edge of
    #: the search grid
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
        fit residual and the gradient energy of the window (Delon & Rouge:
        ``std = sigma_residual / sqrt(sum(gradient**2))``, projected off the
        gain and offset). Use them, or ``quality``, as weights downstream.
        It is the Gauss-Newton (Cramer-Rao-like) figure: about right for
        ``"ncc"`` between identical bands, optimistic across bands (the band
        difference is not white) and for ``"phase"`` (less efficient on
        3-line windows), by up to a factor 1.5-2.
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
# interpolation


def lanczos_weights(shift, *, order: int = 4) -> np.ndarray:
    """Weights of a normalised Lanczos kernel for a fractional shift.

    Parameters
    ----------
    shift : array_like of float, shape (N,)
        Position to interpolate, relative to the central tap (px), in
        ``(-1, 1)`` so that every non-zero weight falls on a tap.
    order : int, keyword-only
        Lanczos order ``a`` (half-width of the kernel, px).

    Returns
    -------
    ndarray of float64, shape (N, 2 * order + 1)
        Weights of taps ``k = -order .. order``: ``f(shift) ~ sum_k w_k f[k]``.
        They sum to 1 (the kernel preserves a constant).

    Notes
    -----
    ``sinc(x) sinc(x / a)`` with ``x = k - shift`` is evaluated with two sines
    per point (angle addition) rather than two per tap.
    """
    if int(order) != order or order < 1:
        raise ValueError(f"order: must be an integer >= 1, got {order}")
    d = np.atleast_1d(np.asarray(shift, dtype=float))
    if d.ndim != 1:
        raise ValueError(f"shift: expected a 1-D array, got shape {d.shape}")
    if d.size and not np.all(np.abs(d) < 1.0):
        raise ValueError("shift: must lie in (-1, 1)")
    return _lanczos_weights(d, order)


def _lanczos_weights(d: np.ndarray, order: int) -> np.ndarray:
    """:func:`lanczos_weights` without checks, for any shape of ``d`` (taps last)."""
    k = np.arange(-order, order + 1, dtype=float)
    x = k - d[..., None]
    # sinc(x) sinc(x/a) = -a sin(pi d) (-1)^k sin(pi x / a) / (pi x)^2; the
    # factor common to all taps cancels in the normalisation
    s, c = np.sin(np.pi / order * d)[..., None], np.cos(np.pi / order * d)[..., None]
    sk, ck = np.cos(np.pi * k) * np.sin(np.pi * k / order), np.cos(np.pi * k) * np.cos(np.pi * k / order)
    w = (sk * c - ck * s) / np.where(x == 0.0, 1.0, x * x)
    w[np.abs(x) >= order] = 0.0
    on_tap = d == np.rint(d)  # integer position: the sample itself
    if on_tap.any():
        w[on_tap] = (x[on_tap] == 0.0).astype(float)
    w /= w.sum(axis=-1, keepdims=True)
    return w


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
    ndarray, shape (N, h, w), dtype of ``patches``
        ``out[n, i, j] ~ f_n(i + shift_lines[n], j + shift_cols[n])`` where
        ``f_n`` interpolates patch ``n`` with its window's first pixel at 0.
    """
    patches = np.asarray(patches)
    if patches.ndim != 3:
        raise ValueError(f"patches: expected an (N, lines, columns) stack, got shape {patches.shape}")
    m = 2 * order
    h, w = patches.shape[1] - m, patches.shape[2] - m
    if h < 1 or w < 1:
        raise ValueError(f"patches: need more than {m} lines and columns, got {patches.shape}")
    dtype = patches.dtype if patches.dtype in (np.float32, np.float64) else np.float64
    wl = lanczos_weights(shift_lines, order=order).astype(dtype)
    wc = lanczos_weights(shift_cols, order=order).astype(dtype)
    if wl.shape[0] != patches.shape[0] or wc.shape[0] != patches.shape[0]:
        raise ValueError("shift_lines, shift_cols: need one shift per patch")
    return _resample(patches, wl, wc)


def _resample(patches: np.ndarray, wl: np.ndarray, wc: np.ndarray) -> np.ndarray:
    """Separable resampling with per-patch tap weights (N, 2 order + 1) per axis."""
    m = wl.shape[1] - 1
    w = patches.shape[2] - m
    # lines first: the (N, h, w + 2 order) intermediate is small for short windows
    swv = np.lib.stride_tricks.sliding_window_view
    rows = np.einsum("nk,nijk->nij", wl, swv(patches, m + 1, axis=1))
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
        Margin (lines, columns) around the rounded point in A and the rounded
        prediction in B that must lie inside the images.
    """
    h, w = _check_window(window)
    sl, sc = _check_search(search)
    if int(order) != order or order < 1:
        raise ValueError(f"order: must be an integer >= 1, got {order}")
    return (h // 2 + max(sl + order, _G), w // 2 + max(sc + order, _G))


def _check_window(window) -> tuple[int, int]:
    try:
        h, w = (int(v) for v in window)
        same = (h, w) == tuple(window)
    except (TypeError, ValueError):
        same = False
    if not same or h < 1 or w < 3 or h % 2 == 0 or w % 2 == 0:
        raise ValueError(f"window: expected two odd integers (lines >= 1, columns >= 3), got {window!r}")
    return h, w


def _check_search(search) -> tuple[int, int]:
    try:
        sl, sc = (int(v) for v in search)
        same = (sl, sc) == tuple(search)
    except (TypeError, ValueError):
        same = False
    if not same or sl < 0 or sc < 0:
        raise ValueError(f"search: expected two integers >= 0 (lines, columns), got {search!r}")
    return sl, sc


def _gather(image: np.ndarray, l0: np.ndarray, c0: np.ndarray, half_l: int, half_c: int):
    """Patches ``(N, 2*half_l+1, 2*half_c+1)`` centred on integer ``(l0, c0)``.

    A patch that would leave the image is moved inside it (its content is then
    meaningless); the returned ``inside`` mask says which.
    """
    nl, nc = image.shape
    hl, hc = 2 * half_l + 1, 2 * half_c + 1
    if nl < hl or nc < hc:
        return np.zeros((l0.size, hl, hc)), np.zeros(l0.size, dtype=bool)
    s_l, s_c = l0 - half_l, c0 - half_c
    inside = (s_l >= 0) & (s_l + hl <= nl) & (s_c >= 0) & (s_c + hc <= nc)
    view = np.lib.stride_tricks.sliding_window_view(image, (hl, hc))
    return view[np.clip(s_l, 0, nl - hl), np.clip(s_c, 0, nc - hc)], inside


def _integer_search(a_z, a_norm, region, h, w):
    """NCC of the A windows over every integer offset of the region.

    Returns (N, L - h + 1, C - w + 1) in the region's dtype; ``-inf`` where B
    is flat. The loop runs over the handful of offsets, each step batched
    over the points; the local sums of B come from one matrix product with a
    band matrix.
    """
    n, nr, nc = region.shape
    kl, kc = nr - h + 1, nc - w + 1
    # numerators: every row of B at every column offset against every row of A, one
    # batched matrix product (N, rows x offsets, w) @ (N, w, h); then the h diagonals
    region = np.ascontiguousarray(region)  # (a view into the B patches: one compact copy first)
    rows_b = np.lib.stride_tricks.sliding_window_view(region, w, axis=2).reshape(n, nr * kc, w)
    x = np.matmul(rows_b, a_z.transpose(0, 2, 1)).reshape(n, nr, kc, h)
    num = x[:, 0:kl, :, 0].copy()
    for p in range(1, h):
        num += x[:, p:p + kl, :, p]
    band = np.zeros((nc, kc), dtype=region.dtype)
    for j in range(kc):
        band[j:j + w, j] = 1.0
    rows = np.zeros((2, n, kl, nc), dtype=region.dtype)  # line sums of B and B**2
    sq = region * region
    for p in range(h):
        rows[0] += region[:, p:p + kl]
        rows[1] += sq[:, p:p + kl]
    s1, s2 = (rows.reshape(-1, nc) @ band).reshape(2, n, kl, kc)
    den = np.sqrt(np.maximum(s2 - s1 * s1 * (1.0 / (h * w)), 0.0))
    den *= a_norm.astype(region.dtype)[:, None, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        surf = num / den
    surf[~(den > 0)] = -np.inf
    return surf


def _inv3(m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Inverses and determinants of a stack of symmetric 3x3 matrices."""
    a, b, c = m[:, 0, 0], m[:, 0, 1], m[:, 0, 2]
    d, e, f = m[:, 1, 1], m[:, 1, 2], m[:, 2, 2]
    c00, c01, c02 = d * f - e * e, c * e - b * f, b * e - c * d
    c11, c12, c22 = a * f - c * c, b * c - a * e, a * d - b * b
    det = a * c00 + b * c01 + c * c02
    inv = np.stack([c00, c01, c02, c01, c11, c12, c02, c12, c22], axis=1).reshape(-1, 3, 3)
    with np.errstate(divide="ignore", invalid="ignore"):
        return inv / det[:, None, None], det


def _phase_grids(h: int, w: int):
    """Frequencies (cycles/px) of the rfft2 half plane, times its multiplicity."""
    u = np.fft.fftfreq(h)[:, None] * np.ones((1, w // 2 + 1))
    v = np.fft.rfftfreq(w)[None, :] * np.ones((h, 1))
    # each column of the half plane stands for its mirror too, except v = 0
    # (and the Nyquist column of an even width)
    mult = np.where((v == 0) | ((w % 2 == 0) & (v == 0.5)), 1.0, 2.0)
    return (mult * u * u).ravel(), (mult * v * v).ravel(), (mult * u * v).ravel(), \
        (mult * u).ravel(), (mult * v).ravel()


def _phase_shift(fa: np.ndarray, b: np.ndarray, grids):
    """Shift of ``b`` w.r.t. the A window (spectrum ``fa``) from the phase plane (px).

    Weighted least-squares fit through the origin of the cross-power-spectrum
    phase, ``angle(F_b conj(F_a)) = -2 pi (u s_l + v s_c)``, weights
    ``|F_b F_a|``. Valid for small residual shifts (no phase wrapping), which
    the iteration provides.
    """
    uu, vv, uv, mu, mv = grids
    q = (np.fft.rfft2(b) * np.conj(fa)).reshape(b.shape[0], -1)
    wgt = np.abs(q)
    wphi = wgt * np.angle(q)
    m = np.stack([wgt @ uu, wgt @ vv, wgt @ uv, wphi @ mu, wphi @ mv])
    a_uu, a_vv, a_uv, pu, pv = m
    det = a_uu * a_vv - a_uv * a_uv
    with np.errstate(divide="ignore", invalid="ignore"):
        s_l = -(a_vv * pu - a_uv * pv) / (2.0 * np.pi * det)
        s_c = -(a_uu * pv - a_uv * pu) / (2.0 * np.pi * det)
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
    max_iter: int = 12,
    tol: float = 5e-3,
    backend: str = "auto",
) -> MatchResult:
    """Match points of band A in band B to sub-pixel accuracy.

    Parameters
    ----------
    image_a, image_b : ndarray, shape (lines, columns)
        The two bands (any radiometric unit: a gain and an offset between them
        are fitted per window). Non-finite pixels are no data.
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
        NCC peak over the integer search grid.
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
        A point stops once its update is below ``tol`` (px), or below a tenth
        of its own estimated standard deviation. The last update is applied
        and the secant steps converge superlinearly, so the error left is
        typically ten times smaller.
    backend : {"auto", "compiled", "numpy"}, keyword-only
        ``"compiled"`` runs the ``"ncc"`` method as a Numba kernel, one point
        per iteration of a parallel loop (:mod:`restore._ncc_kernel`);
        ``"numpy"`` runs the batched NumPy implementation, the reference the
        tests compare the kernel with. ``"auto"`` picks the kernel for
        ``"ncc"``; ``"phase"`` always runs in NumPy.

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
    searched integer grid: farther than the half-range from the grid centre
    (the rounded prediction), or than 0.5 px on an axis whose half-range is 0.
    """
    if method not in _METHODS:
        raise ValueError(f"method: expected one of {_METHODS}, got {method!r}")
    h, w = _check_window(window)
    sl, sc = _check_search(search)
    if not -1.0 <= float(min_quality) <= 1.0:
        raise ValueError(f"min_quality: must lie in [-1, 1], got {min_quality}")
    if max_std is not None and not float(max_std) > 0:
        raise ValueError(f"max_std: must be > 0, got {max_std}")
    if int(order) != order or order < 1:
        raise ValueError(f"order: must be an integer >= 1, got {order}")
    if int(max_iter) != max_iter or max_iter < 1:
        raise ValueError(f"max_iter: must be an integer >= 1, got {max_iter}")
    if not float(tol) > 0:
        raise ValueError(f"tol: must be > 0, got {tol}")
    if backend not in _BACKENDS:
        raise ValueError(f"backend: expected one of {_BACKENDS}, got {backend!r}")
    if backend == "compiled" and method != "ncc":
        raise ValueError(f"backend: the compiled kernel implements method 'ncc' only, got method {method!r}")
    images = []
    for name, img in (("image_a", image_a), ("image_b", image_b)):
        img = np.asarray(img)
        if img.ndim != 2:
            raise ValueError(f"{name}: expected a 2-D (line, column) array, got shape {img.shape}")
        if not (np.issubdtype(img.dtype, np.floating) or np.issubdtype(img.dtype, np.integer)):
            raise ValueError(f"{name}: expected a real-valued image, got dtype {img.dtype}")
        images.append(img)
    names = ("lines_a", "cols_a", "pred_lines_b", "pred_cols_b")
    pts = [np.atleast_1d(np.asarray(v, dtype=float)) for v in (lines_a, cols_a, pred_lines_b, pred_cols_b)]
    n = pts[0].shape[0]
    for name, v in zip(names, pts):
        if v.ndim != 1 or v.shape[0] != n:
            raise ValueError(f"{name}: expected shape ({n},), got {v.shape}")
        if not np.all(np.isfinite(v)):
            raise ValueError(f"{name}: must be finite")

    if n == 0:
        f, i = np.zeros(0), np.zeros(0, dtype=np.int64)
        return MatchResult(line_b=f, col_b=f.copy(), quality=f.copy(), valid=np.zeros(0, dtype=bool),
                           flags=i, std_line=f.copy(), std_col=f.copy())
    if method == "ncc" and backend != "numpy":
        return _match_compiled(*images, *pts, h=h, w=w, sl=sl, sc=sc, min_quality=float(min_quality),
                               max_std=max_std, order=int(order), max_iter=int(max_iter), tol=float(tol))
    opts = dict(h=h, w=w, sl=sl, sc=sc, method=method, min_quality=float(min_quality),
                max_std=max_std, order=int(order), max_iter=int(max_iter), tol=float(tol))
    parts = [_match_chunk(*images, *(v[i:i + _CHUNK] for v in pts), **opts) for i in range(0, n, _CHUNK)]
    return MatchResult(**{f.name: np.concatenate([p[f.name] for p in parts]) for f in fields(MatchResult)})


#: Numba's workqueue threading layer (its fallback where neither OpenMP nor TBB
#: is found) aborts on concurrent launches of a parallel kernel from several
#: Python threads (a threaded sweep): one launch at a time
_KERNEL_LOCK = threading.Lock()


def _match_compiled(image_a, image_b, la, ca, pl, pc, *, h, w, sl, sc, min_quality, max_std, order, max_iter,
                    tol) -> MatchResult:
    """:func:`match_points` ``"ncc"`` through the compiled kernel."""
    from ._ncc_kernel import match_ncc

    # the kernel is compiled for two C-ordered images of one type: float32 (products)
    # when both are, else float64 (each new combination of types would cost a compilation)
    both32 = image_a.dtype == np.float32 and image_b.dtype == np.float32
    dtype = np.float32 if both32 else np.float64
    image_a, image_b = (np.ascontiguousarray(img, dtype=dtype) for img in (image_a, image_b))
    with _KERNEL_LOCK:
        out = match_ncc(image_a, image_b, la, ca, pl, pc, h, w, sl, sc, order, max_iter, tol,
                        min_quality, -1.0 if max_std is None else float(max_std))
    flags = out[:, 3].astype(np.int64)
    return MatchResult(line_b=out[:, 0].copy(), col_b=out[:, 1].copy(), quality=out[:, 2].copy(), valid=flags == 0,
                       flags=flags, std_line=out[:, 4].copy(), std_col=out[:, 5].copy())


def _match_chunk(image_a, image_b, la, ca, pl, pc, *, h, w, sl, sc, method, min_quality, max_std,
                 order, max_iter, tol) -> dict:
    n = la.shape[0]
    npx = h * w
    hl, hc = h // 2, w // 2
    g = _G
    idx = np.arange(n)
    flags = np.zeros(n, dtype=np.int64)

    ra_l, ra_c = np.rint(la).astype(np.int64), np.rint(ca).astype(np.int64)
    # prediction for the rounded A point (local translation model)
    pr_l, pr_c = pl - (la - ra_l), pc - (ca - ra_c)
    c0_l, c0_c = np.rint(pr_l).astype(np.int64), np.rint(pr_c).astype(np.int64)

    # --- gather A (window + gradient support) and B (search + interpolation) -----
    a_patch, in_a = _gather(image_a, ra_l, ra_c, hl + g, hc + g)
    b_big, in_b = _gather(image_b, c0_l, c0_c, hl + sl + order, hc + sc + order)
    flags[~(in_a & in_b)] |= MatchFlag.OUT_OF_BOUNDS
    a_ref = a_patch.reshape(n, -1).mean(axis=1)
    b_ref = b_big.reshape(n, -1).mean(axis=1)
    no_data = ~(np.isfinite(a_ref) & np.isfinite(b_ref))  # a NaN or inf anywhere
    flags[no_data] |= MatchFlag.NO_DATA
    if no_data.any():
        a_patch = np.where(np.isfinite(a_patch), a_patch, 0.0)
        b_big = np.where(np.isfinite(b_big), b_big, 0.0)
        a_ref = np.where(no_data, 0.0, a_ref)
        b_ref = np.where(no_data, 0.0, b_ref)
    # remove a per-point level, then work in single precision
    a_patch = a_patch.astype(_F32, copy=False)  # gathered copies: ours to modify
    a_patch -= a_ref.astype(_F32)[:, None, None]
    b_big = b_big.astype(_F32, copy=False)
    b_big -= b_ref.astype(_F32)[:, None, None]
    a_win = a_patch[:, g:g + h, g:g + w]
    a_z = a_win - a_win.mean(axis=(1, 2), keepdims=True)
    a_norm2 = np.einsum("nij,nij->n", a_z, a_z).astype(np.float64)
    a_norm = np.sqrt(a_norm2)
    # flat: no texture, or texture below single precision w.r.t. the level
    flat_a = ~(a_norm > 1e-6 * np.sqrt(npx) * np.abs(a_ref))

    # --- integer search -----------------------------------------------------------
    region = b_big[:, order:order + h + 2 * sl, order:order + w + 2 * sc]
    surf = _integer_search(a_z, a_norm, region, h, w).reshape(n, -1)
    k = np.argmax(surf, axis=1)
    il, ic = np.divmod(k, 2 * sc + 1)
    flat_b = ~np.isfinite(surf[idx, k])
    hp, wp = h + 2 * order, w + 2 * order  # B patch on the integer peak + support
    patch = np.lib.stride_tricks.sliding_window_view(b_big, (hp, wp), axis=(1, 2))[idx, il, ic]

    # --- Gauss-Newton design: zero-mean [A, dA/dl, dA/dc], fixed -------------------
    jac = np.empty((n, 3, h, w), dtype=_F32)
    jac[:, 0] = a_z
    for ax, view in ((1, lambda t: a_patch[:, t:t + h, g:g + w]), (2, lambda t: a_patch[:, g:g + h, t:t + w])):
        # antisymmetric filter: sum_t D_t (a[+t] - a[-t]), t = 1 .. g
        out = jac[:, ax]
        np.subtract(view(g + 1), view(g - 1), out=out)
        out *= _F32(_GRADIENT[g + 1])
        for t in range(2, g + 1):
            out += _F32(_GRADIENT[g + t]) * (view(g + t) - view(g - t))
    # the columns must be orthogonal to a constant (the offset between the
    # bands): the gradients' means are removed in the normal matrix and in the
    # products with B below, not from the arrays
    jac = jac.reshape(n, 3, npx)
    jmean = jac.mean(axis=2, dtype=np.float64)
    jmean[:, 0] = 0.0  # a_z is zero-mean already
    normal = np.einsum("nqp,nrp->nqr", jac, jac).astype(np.float64) - npx * jmean[:, :, None] * jmean[:, None, :]
    dsc = np.sqrt(np.einsum("nii->ni", normal))
    with np.errstate(divide="ignore", invalid="ignore"):
        det_corr = _inv3(normal / (dsc[:, :, None] * dsc[:, None, :]))[1]
    singular = ~(det_corr > 1e-6) | flat_a | flat_b
    normal[singular] = np.eye(3)
    ninv = _inv3(normal)[0]
    # hopeless points are not refined: outside the image, no data, or an
    # integer peak far below the quality threshold (clouds, unrelated bands)
    peak = surf[idx, k].astype(np.float64)
    unusable = flags != 0
    hopeless = unusable | (peak < min_quality - 0.2)

    # --- sub-pixel iterations; the active set shrinks as points converge ---------
    # F(d), the shift the estimator still sees from d, has its root at the match
    # and a slope matrix S = -dF/dd that is the identity only for identical,
    # isotropic windows; S is learnt per point by Broyden's rank-one update
    # (coupled axes, cross-band contrast) and the step is S^-1 F, at most
    # _MAX_STEP px per axis.
    d = np.zeros((n, 2))  # shift from the integer peak (lines, columns), px
    stats = np.full((n, 4), np.nan)  # <a_z, B~>, <g_l, B~>, <g_c, B~>, |B~ - mean|^2
    slope = np.tile(np.eye(2), (n, 1, 1))
    prev = np.zeros((n, 4))  # previous (d_l, d_c, F_l, F_c)
    converged = singular | hopeless
    gave_up = np.zeros(n, dtype=bool)
    hist = np.full((n, 2), np.inf)  # step sizes of the two previous iterations, px
    swv = np.lib.stride_tricks.sliding_window_view
    if method == "phase":
        fa = np.fft.rfft2(a_z)
        grids = _phase_grids(h, w)
    lk = np.concatenate([ninv[:, 1:, :], normal[:, None, :, 0]], axis=1)  # (N, 3, 3) step operator
    inv_a2 = 1.0 / np.where(a_norm2 > 0, a_norm2, 1.0)
    ninv_d = np.stack([ninv[:, 1, 1], ninv[:, 2, 2]], axis=1)
    active = np.flatnonzero(~converged)
    for it in range(max_iter + 1):
        if active.size == 0:
            break
        # while most points are active, work on all of them (views, no copies)
        # and freeze the converged ones; then on the shrinking active subset
        full = active.size > (9 * n) // 10
        sel = slice(None) if full else active
        live = ~(converged | gave_up) if full else np.ones(active.size, dtype=bool)
        if it == 0:  # at the integer peak: no resampling
            b_res = patch[sel, order:order + h, order:order + w]
        else:
            wts = _lanczos_weights(d[sel], order).astype(_F32)  # (n, 2, taps)
            b_res = _resample(patch[sel], wts[:, 0], wts[:, 1])
        b_flat = b_res.reshape(-1, npx)
        b_sum = b_flat.sum(axis=1, dtype=np.float64)
        c = np.matmul(jac[sel], b_flat[:, :, None])[:, :, 0].astype(np.float64) - jmean[sel] * b_sum[:, None]
        sb = np.einsum("np,np->n", b_flat, b_flat).astype(np.float64) - b_sum * b_sum / npx
        st = np.concatenate([c, sb[:, None]], axis=1)
        if full:
            stats[live] = st[live]
        else:
            stats[sel] = st
        if it == max_iter:
            break
        gain = c[:, 0] * inv_a2[sel]
        if method == "ncc" or it == 0:
            # Gauss-Newton step with the gain projected out (variable projection)
            op = lk[sel]
            rhs = c - gain[:, None] * op[:, 2]
            safe = -1.0 / np.where(np.abs(gain) > 1e-12, gain, 1.0)
            f = np.stack([np.einsum("nj,nj->n", op[:, 0], rhs),
                          np.einsum("nj,nj->n", op[:, 1], rhs)], axis=1) * safe[:, None]
        ph = f
        if method == "phase":
            b_c = b_res - (b_sum / npx).astype(_F32)[:, None, None]
            ph = np.column_stack(_phase_shift(fa[sel], b_c, grids))
            f = ph if it > 0 else f  # the first move is the Lucas-Kanade step
        d_sel = d[sel]
        sm = slope[sel]
        pv = prev[sel]
        if it > 0:  # Broyden: S += (y - S s) s^T / s^T s, with y = F_prev - F, s = d - d_prev
            ds = d_sel - pv[:, :2]
            y = pv[:, 2:] - f
            ss = np.einsum("ni,ni->n", ds, ds)
            upd = (ss > 1e-8) & live
            corr = (y - np.einsum("nij,nj->ni", sm, ds)) / np.where(upd, ss, 1.0)[:, None]
            sm = sm + np.where(upd[:, None, None], corr[:, :, None] * ds[:, None, :], 0.0)
            det = sm[:, 0, 0] * sm[:, 1, 1] - sm[:, 0, 1] * sm[:, 1, 0]
            tr = sm[:, 0, 0] + sm[:, 1, 1]
            bad = ~((det > 0.04) & (tr > 0.4) & (tr < 6.0) & (np.abs(sm).max(axis=(1, 2)) < 4.0))
            sm[bad] = np.eye(2)
            slope[sel] = sm
        prev[sel] = np.where(live[:, None], np.concatenate([d_sel, ph], axis=1), pv)
        det = sm[:, 0, 0] * sm[:, 1, 1] - sm[:, 0, 1] * sm[:, 1, 0]
        step = np.stack([sm[:, 1, 1] * f[:, 0] - sm[:, 0, 1] * f[:, 1],
                         sm[:, 0, 0] * f[:, 1] - sm[:, 1, 0] * f[:, 0]], axis=1) / det[:, None]
        step = np.where(live[:, None], np.clip(step, -_MAX_STEP, _MAX_STEP), 0.0)
        d_new = d_sel + step
        # the match left the integer peak's cell: move the patch to the neighbour
        # (same interpolant, so F is continuous), within the search grid
        move = np.where(np.abs(d_new) > 0.75, np.sign(d_new), 0.0).astype(np.int64)
        if move.any():
            ids = np.arange(n)[sel]
            lim = np.array([2 * sl, 2 * sc])
            base = np.stack([il[ids], ic[ids]], axis=1)
            move = np.where((base + move >= 0) & (base + move <= lim), move, 0)
            mv = np.flatnonzero(move.any(axis=1))
            if mv.size:
                tgt = ids[mv]
                il[tgt] += move[mv, 0]
                ic[tgt] += move[mv, 1]
                patch[tgt] = swv(b_big, (hp, wp), axis=(1, 2))[tgt, il[tgt], ic[tgt]]
                d_new[mv] -= move[mv]
                pvm = prev[tgt]
                pvm[:, :2] -= move[mv]
                prev[tgt] = pvm
        d[sel] = np.clip(d_new, -0.999, 0.999)
        # converged: the step is below tol, or immaterial (a tenth of the
        # point's own standard deviation, e.g. across bands)
        small = (np.abs(step) < tol).all(axis=1)
        unsure = live & ~small
        if unsure.any():
            sig2 = np.maximum(sb - c[:, 0] * gain, 0.0) / max(npx - 4, 1)
            with np.errstate(divide="ignore", invalid="ignore"):
                noise_step = 0.1 * np.sqrt(sig2[:, None] * ninv_d[sel]) / np.abs(gain)[:, None]
            small |= (np.abs(step) < np.nan_to_num(noise_step)).all(axis=1)
        # stalled: late, and the step has not shrunk in two iterations (drift
        # along a flat direction, no root in reach): give up, NOT_CONVERGED
        norm = np.abs(step).max(axis=1)
        stalled = np.zeros_like(small)
        if it >= _STALL_IT:
            stalled = ~small & (norm > 0.8 * hist[sel, 1])
        hist[sel] = np.where(live[:, None], np.stack([norm, hist[sel, 0]], axis=1), hist[sel])
        stop = small | stalled
        if full:
            converged |= live & small
            gave_up |= live & stalled
            active = np.flatnonzero(~(converged | gave_up))
        else:
            converged[active[small]] = True
            gave_up[active[stalled]] = True
            active = active[~stop]

    # --- quality and a-posteriori precision --------------------------------------
    c0, sb = stats[:, 0], stats[:, 3]
    with np.errstate(divide="ignore", invalid="ignore"):
        quality = np.where(hopeless & ~singular, peak, c0 / (a_norm * np.sqrt(sb)))
        gain = c0 / a_norm2
        sigma2 = np.maximum(sb - c0 * gain, 0.0) / max(npx - 4, 1)
        std_l = np.sqrt(sigma2 * ninv[:, 1, 1]) / np.abs(gain)
        std_c = np.sqrt(sigma2 * ninv[:, 2, 2]) / np.abs(gain)

    off_l = (il - sl) + d[:, 0]
    off_c = (ic - sc) + d[:, 1]
    flags[singular] |= MatchFlag.FLAT
    lim_l, lim_c = (sl or 0.5), (sc or 0.5)
    flags[(np.abs(off_l) > lim_l) | (np.abs(off_c) > lim_c)] |= MatchFlag.SEARCH_BORDER
    flags[~converged | (np.any(np.abs(d) >= 0.99, axis=1) & ~hopeless)] |= MatchFlag.NOT_CONVERGED
    flags[~(quality >= min_quality)] |= MatchFlag.LOW_CORRELATION
    if max_std is not None:
        flags[~((std_l <= max_std) & (std_c <= max_std))] |= MatchFlag.IMPRECISE
    quality = np.where(singular | unusable, np.nan, quality)
    return {
        "line_b": c0_l + off_l + (la - ra_l), "col_b": c0_c + off_c + (ca - ra_c),
        "quality": quality, "valid": flags == 0, "flags": flags, "std_line": std_l, "std_col": std_c,
    }


def match_points_in_blocks(read_a, read_b, n_lines: tuple, lines_a, cols_a, pred_lines_b, pred_cols_b, *,
                           block_lines: int = 1024, **options) -> MatchResult:
    """:func:`match_points` on blocks of points, reading only the image lines each block needs.

    Parameters
    ----------
    read_a, read_b : callable
        ``read(slice) -> ndarray (lines, columns)``: those lines of band A / B.
    n_lines : (int, int)
        Number of lines of A and of B.
    lines_a, cols_a, pred_lines_b, pred_cols_b, **options
        As :func:`match_points`.
    block_lines : int, keyword-only
        Lines of A per block of points.

    Returns
    -------
    MatchResult
        The same as :func:`match_points` on the whole images: each block reads
        its points' lines plus the matcher's support margin and 8 more lines
        (the Gauss-Newton steps move the window by at most the search range,
        already in the margin), so no window sees a block edge that is not an
        image edge.
    """
    la = np.asarray(lines_a, dtype=np.float64)
    ca = np.asarray(cols_a, dtype=np.float64)
    pl = np.asarray(pred_lines_b, dtype=np.float64)
    pc = np.asarray(pred_cols_b, dtype=np.float64)
    n = la.size
    margin = support_margin(window=options.get("window", (3, 31)), search=options.get("search", (2, 2)),
                            order=options.get("order", 4))[0] + 8
    parts = []
    idx_all = np.arange(n)
    for a in range(0, int(n_lines[0]), block_lines):
        sel = idx_all[(np.rint(la) >= a) & (np.rint(la) < a + block_lines)]
        if sel.size == 0:
            continue
        a0, a1 = max(0, a - margin), min(int(n_lines[0]), a + block_lines + margin)
        fin = pl[sel][np.isfinite(pl[sel])]
        lo = int(np.floor(fin.min())) if fin.size else 0
        hi = int(np.ceil(fin.max())) if fin.size else 0
        b0, b1 = max(0, lo - margin), min(int(n_lines[1]), hi + margin + 1)
        if b1 - b0 < 1:
            b0, b1 = 0, min(int(n_lines[1]), 1)
        m = match_points(read_a(slice(a0, a1)), read_b(slice(b0, b1)), la[sel] - a0, ca[sel], pl[sel] - b0, pc[sel],
                         **options)
        parts.append((sel, m, b0))
    out = {}
    for k in (f.name for f in dataclasses.fields(MatchResult)):
        proto = getattr(parts[0][1], k) if parts else np.zeros(0)
        arr = np.zeros(n, dtype=np.asarray(proto).dtype)
        if arr.dtype.kind == "f":
            arr[:] = np.nan
        elif k == "flags":
            arr[:] = int(MatchFlag.OUT_OF_BOUNDS)  # a point on no image line
        for sel, m, b0 in parts:
            v = np.asarray(getattr(m, k))
            arr[sel] = v + b0 if k == "line_b" else v
        out[k] = arr
    return MatchResult(**out)
