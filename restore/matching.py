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
Lanczos kernel (order 4 by default), corrected to reproduce cubics exactly (no
pull towards whole pixels on smooth texture: :func:`lanczos_weights`), from
the lines and columns around the window: the window itself may be only 3
lines high.

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
from typing import Callable

import numpy as np

__all__ = [
    "MATCHING_METHODS",
    "MatchingMethod",
    "match_points_in_blocks",
    "MatchFlag",
    "MatchResult",
    "match_points",
    "support_margin",
    "lanczos_weights",
    "polynomial_correction",
    "EXACT_DEGREE",
    "exact_degree_for",
    "resample_windows",
]

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
    corr_line_col : ndarray of float, shape (N,)
        Correlation of the line and column errors, from the same normal
        matrix (its inverse, the gain projected out): near ±1 on an edge or
        an oriented texture, where a slide along the edge moves both
        coordinates together (the aperture problem); 0 where the normal
        matrix is singular. A weighted fit that takes it (the 2 × 2
        covariance of each point) does not read an along-edge slide as
        two independent measurements.
    """

    line_b: np.ndarray
    col_b: np.ndarray
    quality: np.ndarray
    valid: np.ndarray
    flags: np.ndarray
    std_line: np.ndarray
    std_col: np.ndarray
    corr_line_col: np.ndarray

    def __len__(self) -> int:
        return int(self.line_b.shape[0])


# ---------------------------------------------------------------------------
# interpolation


#: the matcher's interpolation weights reproduce every polynomial up to this degree (:func:`lanczos_weights`;
#: at most ``2 order - 1``, :func:`exact_degree_for`)
EXACT_DEGREE = 3


def exact_degree_for(order: int) -> int:
    """The matcher's :data:`EXACT_DEGREE` for an interpolation ``order``: ``2 order`` taps fit at most degree
    ``2 order - 1``."""
    return min(EXACT_DEGREE, 2 * int(order) - 1)


def lanczos_weights(shift, *, order: int = 4, exact_degree: int = 0) -> np.ndarray:
    """Weights of a normalised Lanczos kernel for a fractional shift, optionally made exact for polynomials.

    Parameters
    ----------
    shift : array_like of float, shape (N,)
        Position to interpolate, relative to the central tap (px), in
        ``(-1, 1)`` so that every non-zero weight falls on a tap.
    order : int, keyword-only
        Lanczos order ``a`` (half-width of the kernel, px).
    exact_degree : int, keyword-only
        The weights are corrected, by the smallest change (least squares over
        the ``2 order`` taps of the support), to reproduce every polynomial up
        to this degree exactly; 0: the normalised kernel itself. The matcher
        uses :data:`EXACT_DEGREE`.

    Returns
    -------
    ndarray of float64, shape (N, 2 * order + 1)
        Weights of taps ``k = -order .. order``: ``f(shift) ~ sum_k w_k f[k]``.
        They sum to 1 (the kernel preserves a constant).

    Notes
    -----
    ``sinc(x) sinc(x / a)`` with ``x = k - shift`` is evaluated with two sines
    per point (angle addition) rather than two per tap.

    The normalised kernel does not reproduce a ramp: order 4 interpolates at
    0.2 px the value at 0.214 px, a phase error of 0.014 px on slowly varying
    texture. The matcher converges where the resampled B looks like A, so its
    estimates lock towards whole pixels: −0.008 px at 0.2 px on a texture
    band-limited below 0.2 cycle/px, a slope of −6 % near a whole pixel and
    +5 % near a half, by which a pair's differentials took a gain set by the
    fractional part of its delay. Exact up to cubics, it locks by 0.0001 px
    there, and on the 1/f test texture (MTF 0.3 at Nyquist) by 0.0018 /
    0.0010 px instead of 0.0029 / 0.0022 (exact for ramps only: 0.0049;
    quintics: 0.0037; Lagrange through the 8 taps, exact to degree 7 but with
    a gain of 0.65–0.83 at 0.4 cycle/px: 0.008).
    """
    if int(order) != order or order < 1:
        raise ValueError(f"order: must be an integer >= 1, got {order}")
    if int(exact_degree) != exact_degree or not 0 <= exact_degree < 2 * order:
        raise ValueError(f"exact_degree: must be an integer from 0 to {2 * order - 1}, got {exact_degree}")
    d = np.atleast_1d(np.asarray(shift, dtype=float))
    if d.ndim != 1:
        raise ValueError(f"shift: expected a 1-D array, got shape {d.shape}")
    if d.size and not np.all(np.abs(d) < 1.0):
        raise ValueError("shift: must lie in (-1, 1)")
    return _lanczos_weights(d, order, int(exact_degree))


def polynomial_correction(order: int, degree: int) -> np.ndarray:
    """``P = Vᵀ (V Vᵀ)⁻¹`` of the ``2 order`` taps a positive (row 0) and a negative (row 1) shift uses, with
    ``V[p, t] = k_t ** p`` (p ≤ ``degree``): ``w + P (d^p − V w)`` is the smallest change of ``w`` that
    reproduces the powers of ``d`` up to ``degree``. Shape (2, 2 order + 1, degree + 1), zero rows
    off the support."""
    k = np.arange(-order, order + 1, dtype=float)
    out = np.zeros((2, k.size, degree + 1))
    for row, sup in enumerate((k > -order, k < order)):
        v = np.vstack([k[sup] ** p for p in range(degree + 1)])
        out[row, sup] = v.T @ np.linalg.inv(v @ v.T)
    return out


def _lanczos_weights(d: np.ndarray, order: int, exact_degree: int | None = None) -> np.ndarray:
    """:func:`lanczos_weights` without checks, for any shape of ``d`` (taps last); ``exact_degree`` None: the
    matcher's (:func:`exact_degree_for`)."""
    if exact_degree is None:
        exact_degree = exact_degree_for(order)
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
    if exact_degree and not np.all(on_tap):
        powers = np.arange(exact_degree + 1)
        resid = d[..., None] ** powers - np.einsum("...t,tp->...p", w, k[:, None] ** powers)
        corr = polynomial_correction(order, exact_degree)[np.where(d > 0, 0, 1)]  # (..., taps, degree + 1)
        w = np.where(on_tap[..., None], w, w + np.einsum("...tp,...p->...t", corr, resid))
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
    wl = lanczos_weights(shift_lines, order=order, exact_degree=exact_degree_for(order)).astype(dtype)
    wc = lanczos_weights(shift_cols, order=order, exact_degree=exact_degree_for(order)).astype(dtype)
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
    if method not in MATCHING_METHODS:
        raise ValueError(f"method: expected one of {tuple(MATCHING_METHODS)}, got {method!r}")
    spec = MATCHING_METHODS[method]
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
    if backend == "compiled" and not spec.compiled:
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
                           flags=i, std_line=f.copy(), std_col=f.copy(), corr_line_col=f.copy())
    if spec.compiled and backend != "numpy":
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
                        min_quality, -1.0 if max_std is None else float(max_std),
                        polynomial_correction(order, exact_degree_for(order)))
    flags = out[:, 3].astype(np.int64)
    return MatchResult(line_b=out[:, 0].copy(), col_b=out[:, 1].copy(), quality=out[:, 2].copy(), valid=flags == 0,
                       flags=flags, std_line=out[:, 4].copy(), std_col=out[:, 5].copy(),
                       corr_line_col=out[:, 6].copy())


# ---------------------------------------------------------------------------
# batched NumPy implementation, one chunk of points


def _match_chunk(image_a, image_b, la, ca, pl, pc, *, h, w, sl, sc, method, min_quality, max_std,
                 order, max_iter, tol) -> dict:
    """Match one chunk of points with the batched NumPy implementation.

    Runs the steps in turn: window extraction, integer NCC search,
    Gauss-Newton design, sub-pixel refinement with the residual of
    ``method``, then quality, precision and flags.

    Parameters
    ----------
    image_a, image_b : ndarray, shape (lines, columns)
        The two bands, checked by :func:`match_points`.
    la, ca, pl, pc : ndarray of float, shape (N,)
        Points in A and their predicted positions in B (px).
    h, w, sl, sc, method, min_quality, max_std, order, max_iter, tol
        Options of :func:`match_points` (window, search half-range, ...).

    Returns
    -------
    dict
        The fields of :class:`MatchResult`, one entry per point.
    """
    win = _extract_windows(image_a, image_b, la, ca, pl, pc, h=h, w=w, sl=sl, sc=sc, order=order)
    a_z, a_norm2, a_norm, flat_a = _a_window_stats(win.a_patch, win.a_ref, h, w)
    il, ic, peak, flat_b, patch = _ncc_integer_peak(a_z, a_norm, win.b_big, h=h, w=w, sl=sl, sc=sc, order=order)
    jac, jmean, normal = _gauss_newton_design(win.a_patch, a_z, h, w)
    singular, ninv = _normal_inverse(normal, flat_a | flat_b)
    # hopeless points are not refined: outside the image, no data, or an
    # integer peak far below the quality threshold (clouds, unrelated bands)
    flags = win.flags
    unusable = flags != 0
    hopeless = unusable | (peak < min_quality - 0.2)

    ctx = _RefineContext(
        b_big=win.b_big, jac=jac, jmean=jmean,
        lk=np.concatenate([ninv[:, 1:, :], normal[:, None, :, 0]], axis=1),  # (N, 3, 3) step operator
        inv_a2=1.0 / np.where(a_norm2 > 0, a_norm2, 1.0), ninv_d=np.stack([ninv[:, 1, 1], ninv[:, 2, 2]], axis=1),
        h=h, w=w, sl=sl, sc=sc, order=order,
        fa=np.fft.rfft2(a_z) if MATCHING_METHODS[method].needs_spectrum else None,
        grids=_phase_grids(h, w) if MATCHING_METHODS[method].needs_spectrum else None)
    state = _RefineState.start(il, ic, patch, converged=singular | hopeless)
    _refine(ctx, state, method=method, max_iter=max_iter, tol=tol)

    quality, std_l, std_c = _quality_and_std(state.stats, peak, a_norm, a_norm2, ninv, hopeless=hopeless,
                                             singular=singular, npx=h * w)
    d = state.d
    off_l = (state.il - sl) + d[:, 0]
    off_c = (state.ic - sc) + d[:, 1]
    _final_flags(flags, off_l, off_c, d, quality, std_l, std_c, singular=singular, converged=state.converged,
                 hopeless=hopeless, sl=sl, sc=sc, min_quality=min_quality, max_std=max_std)
    quality = np.where(singular | unusable, np.nan, quality)
    return {
        "line_b": win.c0_l + off_l + (la - win.ra_l), "col_b": win.c0_c + off_c + (ca - win.ra_c),
        "quality": quality, "valid": flags == 0, "flags": flags, "std_line": std_l, "std_col": std_c,
        "corr_line_col": _line_col_correlation(ninv, singular),
    }


def _line_col_correlation(ninv, singular) -> np.ndarray:
    """Correlation of the line and column errors from the inverse normal matrices (N, 3, 3); 0 where singular."""
    i11, i22, i12 = ninv[:, 1, 1], ninv[:, 2, 2], ninv[:, 1, 2]
    ok = ~np.asarray(singular, dtype=bool) & (i11 > 0) & (i22 > 0)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(ok, i12 / np.sqrt(np.where(ok, i11 * i22, 1.0)), 0.0)


@dataclass
class _Windows:
    """Gathered windows of a chunk (see :func:`_extract_windows`)."""

    ra_l: np.ndarray  #: rounded points in A (int64)
    ra_c: np.ndarray
    c0_l: np.ndarray  #: centre of the search grid in B (int64)
    c0_c: np.ndarray
    a_patch: np.ndarray  #: A window + gradient support, level removed (float32)
    b_big: np.ndarray  #: B search area + interpolation support, level removed (float32)
    a_ref: np.ndarray  #: level removed from each A patch (float64)
    flags: np.ndarray  #: OUT_OF_BOUNDS and NO_DATA so far (int64)


def _extract_windows(image_a, image_b, la, ca, pl, pc, *, h, w, sl, sc, order) -> _Windows:
    """Gather the A and B patches of every point, with their levels removed.

    Parameters
    ----------
    image_a, image_b : ndarray, shape (lines, columns)
        The two bands.
    la, ca, pl, pc : ndarray of float, shape (N,)
        Points in A and predicted positions in B (px).
    h, w, sl, sc, order : int, keyword-only
        Window size, search half-range and Lanczos order.

    Returns
    -------
    _Windows
        A patches of ``(h + 2 _G, w + 2 _G)`` around the rounded points, B
        patches of ``(h + 2 (sl + order), w + 2 (sc + order))`` around the
        rounded prediction of the rounded point (local translation), both in
        float32 with a per-point level removed and non-finite pixels zeroed,
        and the ``OUT_OF_BOUNDS`` / ``NO_DATA`` flags.
    """
    n = la.shape[0]
    g = _G
    hl, hc = h // 2, w // 2
    flags = np.zeros(n, dtype=np.int64)
    ra_l, ra_c = np.rint(la).astype(np.int64), np.rint(ca).astype(np.int64)
    # prediction for the rounded A point (local translation model)
    pr_l, pr_c = pl - (la - ra_l), pc - (ca - ra_c)
    c0_l, c0_c = np.rint(pr_l).astype(np.int64), np.rint(pr_c).astype(np.int64)
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
    return _Windows(ra_l=ra_l, ra_c=ra_c, c0_l=c0_l, c0_c=c0_c, a_patch=a_patch, b_big=b_big, a_ref=a_ref,
                    flags=flags)


def _a_window_stats(a_patch: np.ndarray, a_ref: np.ndarray, h: int, w: int):
    """Zero-mean A windows, their energy and flatness.

    Parameters
    ----------
    a_patch : ndarray of float32, shape (N, h + 2 _G, w + 2 _G)
        A patches, level removed.
    a_ref : ndarray of float, shape (N,)
        The level removed (flatness is judged relative to it).
    h, w : int
        Window size.

    Returns
    -------
    a_z : ndarray of float32, shape (N, h, w)
        Zero-mean windows.
    a_norm2, a_norm : ndarray of float64, shape (N,)
        ``sum(a_z**2)`` and its square root.
    flat_a : ndarray of bool, shape (N,)
        No texture, or texture below single precision w.r.t. the level.
    """
    g = _G
    a_win = a_patch[:, g:g + h, g:g + w]
    a_z = a_win - a_win.mean(axis=(1, 2), keepdims=True)
    a_norm2 = np.einsum("nij,nij->n", a_z, a_z).astype(np.float64)
    a_norm = np.sqrt(a_norm2)
    flat_a = ~(a_norm > 1e-6 * np.sqrt(h * w) * np.abs(a_ref))
    return a_z, a_norm2, a_norm, flat_a


def _ncc_integer_peak(a_z, a_norm, b_big, *, h, w, sl, sc, order):
    """Integer NCC peak of each A window over its search grid in B.

    Parameters
    ----------
    a_z : ndarray of float32, shape (N, h, w)
        Zero-mean A windows.
    a_norm : ndarray of float64, shape (N,)
        Their norms.
    b_big : ndarray of float32, shape (N, h + 2 (sl + order), w + 2 (sc + order))
        B search areas with the interpolation support.
    h, w, sl, sc, order : int, keyword-only
        Window size, search half-range and Lanczos order.

    Returns
    -------
    il, ic : ndarray of int64, shape (N,)
        Peak offset in the search grid (``sl``, ``sc`` is its centre).
    peak : ndarray of float64, shape (N,)
        NCC at the peak (``-inf`` where B is flat everywhere).
    flat_b : ndarray of bool, shape (N,)
        B flat at every offset.
    patch : ndarray of float32, shape (N, h + 2 order, w + 2 order)
        B window on the peak with its interpolation support (a copy).
    """
    n = a_z.shape[0]
    idx = np.arange(n)
    region = b_big[:, order:order + h + 2 * sl, order:order + w + 2 * sc]
    surf = _integer_search(a_z, a_norm, region, h, w).reshape(n, -1)
    k = np.argmax(surf, axis=1)
    il, ic = np.divmod(k, 2 * sc + 1)
    flat_b = ~np.isfinite(surf[idx, k])
    hp, wp = h + 2 * order, w + 2 * order  # B patch on the integer peak + support
    patch = np.lib.stride_tricks.sliding_window_view(b_big, (hp, wp), axis=(1, 2))[idx, il, ic]
    return il, ic, surf[idx, k].astype(np.float64), flat_b, patch


def _gauss_newton_design(a_patch, a_z, h, w):
    """Fixed Gauss-Newton design ``[a_z, dA/dl, dA/dc]`` and its normal matrix.

    Parameters
    ----------
    a_patch : ndarray of float32, shape (N, h + 2 _G, w + 2 _G)
        A patches (the gradient filter reads ``_G`` pixels around the window).
    a_z : ndarray of float32, shape (N, h, w)
        Zero-mean A windows.
    h, w : int
        Window size.

    Returns
    -------
    jac : ndarray of float32, shape (N, 3, h * w)
        Design columns; the gradients keep their means.
    jmean : ndarray of float64, shape (N, 3)
        Means of the columns (0 for ``a_z``), removed in every product.
    normal : ndarray of float64, shape (N, 3, 3)
        Normal matrix of the zero-mean columns.
    """
    n, npx, g = a_z.shape[0], h * w, _G
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
    # products with B, not from the arrays
    jac = jac.reshape(n, 3, npx)
    jmean = jac.mean(axis=2, dtype=np.float64)
    jmean[:, 0] = 0.0  # a_z is zero-mean already
    normal = np.einsum("nqp,nrp->nqr", jac, jac).astype(np.float64) - npx * jmean[:, :, None] * jmean[:, None, :]
    return jac, jmean, normal


def _normal_inverse(normal, degenerate):
    """Singular designs and the inverse normal matrices.

    Parameters
    ----------
    normal : ndarray of float64, shape (N, 3, 3)
        Normal matrices; those of singular points are set to the identity,
        in place.
    degenerate : ndarray of bool, shape (N,)
        Points already known to be flat (A or B).

    Returns
    -------
    singular : ndarray of bool, shape (N,)
        ``degenerate``, or a correlation matrix of determinant <= 1e-6.
    ninv : ndarray of float64, shape (N, 3, 3)
        Inverse normal matrices.
    """
    dsc = np.sqrt(np.einsum("nii->ni", normal))
    with np.errstate(divide="ignore", invalid="ignore"):
        det_corr = _inv3(normal / (dsc[:, :, None] * dsc[:, None, :]))[1]
    singular = ~(det_corr > 1e-6) | degenerate
    normal[singular] = np.eye(3)
    return singular, _inv3(normal)[0]


@dataclass
class _RefineContext:
    """What the sub-pixel iterations read and never change."""

    b_big: np.ndarray  #: B search areas + support (N, ...), float32
    jac: np.ndarray  #: design (N, 3, h w), float32
    jmean: np.ndarray  #: column means (N, 3)
    lk: np.ndarray  #: Gauss-Newton step operator (N, 3, 3): rows 1, 2 of N^-1, then column 0 of N
    inv_a2: np.ndarray  #: 1 / sum(a_z**2) (N,)
    ninv_d: np.ndarray  #: diagonal (1, 1), (2, 2) of N^-1 (N, 2)
    h: int
    w: int
    sl: int
    sc: int
    order: int
    fa: np.ndarray | None  #: rfft2 of the A windows ("phase" only)
    grids: tuple | None  #: :func:`_phase_grids` ("phase" only)

    @property
    def npx(self) -> int:
        return self.h * self.w


@dataclass
class _RefineState:
    """Per-point state of the sub-pixel iterations, updated in place."""

    il: np.ndarray  #: integer base in the search grid (int64)
    ic: np.ndarray
    patch: np.ndarray  #: B window + support on the base (N, h + 2 order, w + 2 order)
    d: np.ndarray  #: shift from the base (N, 2), px
    stats: np.ndarray  #: <a_z, B~>, <g_l, B~>, <g_c, B~>, |B~ - mean|^2 at the last sample (N, 4)
    slope: np.ndarray  #: Broyden slope matrices (N, 2, 2)
    prev: np.ndarray  #: previous (d_l, d_c, F_l, F_c) (N, 4)
    converged: np.ndarray  #: (N,) bool
    gave_up: np.ndarray  #: (N,) bool, stalled
    hist: np.ndarray  #: step sizes of the two previous iterations (N, 2), px

    @classmethod
    def start(cls, il, ic, patch, *, converged) -> "_RefineState":
        """State at the integer peak; points already ``converged`` are not refined."""
        n = il.shape[0]
        return cls(il=il, ic=ic, patch=patch, d=np.zeros((n, 2)), stats=np.full((n, 4), np.nan),
                   slope=np.tile(np.eye(2), (n, 1, 1)), prev=np.zeros((n, 4)), converged=converged,
                   gave_up=np.zeros(n, dtype=bool), hist=np.full((n, 2), np.inf))


def _refine(ctx: _RefineContext, s: _RefineState, *, method, max_iter, tol) -> None:
    """Sub-pixel iterations, shared by both methods; updates ``s`` in place.

    ``F(d)``, the shift the estimator (:func:`_ncc_residual` or
    :func:`_phase_residual`) still sees from ``d``, has its root at the match
    and a slope matrix ``S = -dF/dd`` that is the identity only for identical,
    isotropic windows; ``S`` is learnt per point by Broyden's rank-one update
    and the step is ``S^-1 F``, at most ``_MAX_STEP`` px per axis
    (:func:`_secant_step`). The active set shrinks as points converge or stall.

    Parameters
    ----------
    ctx : _RefineContext
        Fixed inputs.
    s : _RefineState
        State, updated in place; ``s.stats`` ends at the final positions.
    method : {"ncc", "phase"}, keyword-only
        Residual estimator.
    max_iter : int, keyword-only
        Maximum number of steps.
    tol : float, keyword-only
        Convergence threshold on the step (px).
    """
    residual = MATCHING_METHODS[method].residual
    n = s.d.shape[0]
    active = np.flatnonzero(~s.converged)
    for it in range(max_iter + 1):
        if active.size == 0:
            break
        # while most points are active, work on all of them (views, no copies)
        # and freeze the converged ones; then on the shrinking active subset
        full = active.size > (9 * n) // 10
        sel = slice(None) if full else active
        live = ~(s.converged | s.gave_up) if full else np.ones(active.size, dtype=bool)
        b_res, b_sum, c, sb = _sample_b(ctx, s, sel, it)
        st = np.concatenate([c, sb[:, None]], axis=1)
        if full:
            s.stats[live] = st[live]
        else:
            s.stats[sel] = st
        if it == max_iter:
            break
        gain = c[:, 0] * ctx.inv_a2[sel]
        f, ph = residual(ctx, sel, it, b_res, b_sum, c, gain)
        step = _secant_step(s, sel, live, it, f, ph)
        _advance(ctx, s, sel, step)
        small = _small_step(ctx, sel, live, step, c, sb, gain, tol)
        active = _retire(s, sel, live, active, full=full, it=it, step=step, small=small)


def _sample_b(ctx: _RefineContext, s: _RefineState, sel, it: int):
    """B at the current positions of the points ``sel`` and its products with the design.

    Returns
    -------
    b_res : ndarray of float32, shape (n, h, w)
        B on the base (iteration 0), else resampled at ``s.d``.
    b_sum : ndarray of float64, shape (n,)
        Its sums.
    c : ndarray of float64, shape (n, 3)
        Products with the zero-mean design columns.
    sb : ndarray of float64, shape (n,)
        ``|B~ - mean|^2``.
    """
    h, w, o, npx = ctx.h, ctx.w, ctx.order, ctx.npx
    if it == 0:  # at the integer peak: no resampling
        b_res = s.patch[sel, o:o + h, o:o + w]
    else:
        wts = _lanczos_weights(s.d[sel], o).astype(_F32)  # (n, 2, taps)
        b_res = _resample(s.patch[sel], wts[:, 0], wts[:, 1])
    b_flat = b_res.reshape(-1, npx)
    b_sum = b_flat.sum(axis=1, dtype=np.float64)
    c = np.matmul(ctx.jac[sel], b_flat[:, :, None])[:, :, 0].astype(np.float64) - ctx.jmean[sel] * b_sum[:, None]
    sb = np.einsum("np,np->n", b_flat, b_flat).astype(np.float64) - b_sum * b_sum / npx
    return b_res, b_sum, c, sb


def _ncc_residual(ctx: _RefineContext, sel, c, gain):
    """``"ncc"`` residual shift: Gauss-Newton step with the gain projected out.

    Parameters
    ----------
    ctx : _RefineContext
        Fixed inputs (``lk``, the step operator).
    sel : slice or ndarray of int
        Points worked on.
    c : ndarray of float64, shape (n, 3)
        Products of B with the design (:func:`_sample_b`).
    gain : ndarray of float64, shape (n,)
        Gain between the bands, ``c[:, 0] / |a_z|^2``.

    Returns
    -------
    ndarray of float64, shape (n, 2)
        ``F`` (lines, columns), px (variable projection).
    """
    op = ctx.lk[sel]
    rhs = c - gain[:, None] * op[:, 2]
    safe = -1.0 / np.where(np.abs(gain) > 1e-12, gain, 1.0)
    return np.stack([np.einsum("nj,nj->n", op[:, 0], rhs),
                     np.einsum("nj,nj->n", op[:, 1], rhs)], axis=1) * safe[:, None]


def _phase_residual(ctx: _RefineContext, sel, it: int, b_res, b_sum, c, gain):
    """``"phase"`` residual shift from the phase plane of the cross-power spectrum.

    Parameters
    ----------
    ctx : _RefineContext
        Fixed inputs (``fa``, ``grids``).
    sel : slice or ndarray of int
        Points worked on.
    it : int
        Iteration number: the first move (``it == 0``) is the Lucas-Kanade
        step, the phase of a 3-line window says little about a larger shift.
    b_res, b_sum, c, gain
        B sampled at the current positions, its sums and products with the
        design (:func:`_sample_b`), the gain between the bands.

    Returns
    -------
    f : ndarray of float64, shape (n, 2)
        ``F`` that drives the step (px).
    ph : ndarray of float64, shape (n, 2)
        Phase-plane shift, the ``F`` the Broyden update remembers.
    """
    b_c = b_res - (b_sum / ctx.npx).astype(_F32)[:, None, None]
    ph = np.column_stack(_phase_shift(ctx.fa[sel], b_c, ctx.grids))
    if it == 0:
        return _ncc_residual(ctx, sel, c, gain), ph
    return ph, ph


def _secant_step(s: _RefineState, sel, live, it: int, f, ph):
    """Broyden update of the slope matrices, then the bounded step ``S^-1 F``.

    Parameters
    ----------
    s : _RefineState
        ``slope`` and ``prev`` are updated in place for the points ``sel``.
    sel : slice or ndarray of int
        Points worked on.
    live : ndarray of bool, shape (n,)
        Points of ``sel`` still iterating (the others are frozen).
    it : int
        Iteration number (no update at 0).
    f, ph : ndarray of float64, shape (n, 2)
        Residual driving the step, and the one remembered for the next update.

    Returns
    -------
    ndarray of float64, shape (n, 2)
        Step (px), clipped to ``_MAX_STEP``; 0 for frozen points.
    """
    d_sel = s.d[sel]
    sm = s.slope[sel]
    pv = s.prev[sel]
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
        s.slope[sel] = sm
    s.prev[sel] = np.where(live[:, None], np.concatenate([d_sel, ph], axis=1), pv)
    det = sm[:, 0, 0] * sm[:, 1, 1] - sm[:, 0, 1] * sm[:, 1, 0]
    step = np.stack([sm[:, 1, 1] * f[:, 0] - sm[:, 0, 1] * f[:, 1],
                     sm[:, 0, 0] * f[:, 1] - sm[:, 1, 0] * f[:, 0]], axis=1) / det[:, None]
    return np.where(live[:, None], np.clip(step, -_MAX_STEP, _MAX_STEP), 0.0)


def _advance(ctx: _RefineContext, s: _RefineState, sel, step) -> None:
    """Apply ``step`` to the points ``sel``, moving the integer base when needed.

    A match that leaves its integer cell (``|d| > 0.75``) moves its base to the
    neighbour inside the search grid (same interpolant, so ``F`` stays
    continuous); ``s.il``, ``s.ic``, ``s.patch``, ``s.prev`` and ``s.d`` are
    updated in place, ``d`` clipped to ``(-1, 1)``.
    """
    d_new = s.d[sel] + step
    move = np.where(np.abs(d_new) > 0.75, np.sign(d_new), 0.0).astype(np.int64)
    if move.any():
        ids = np.arange(s.d.shape[0])[sel]
        lim = np.array([2 * ctx.sl, 2 * ctx.sc])
        base = np.stack([s.il[ids], s.ic[ids]], axis=1)
        move = np.where((base + move >= 0) & (base + move <= lim), move, 0)
        mv = np.flatnonzero(move.any(axis=1))
        if mv.size:
            tgt = ids[mv]
            s.il[tgt] += move[mv, 0]
            s.ic[tgt] += move[mv, 1]
            hp, wp = ctx.h + 2 * ctx.order, ctx.w + 2 * ctx.order
            swv = np.lib.stride_tricks.sliding_window_view
            s.patch[tgt] = swv(ctx.b_big, (hp, wp), axis=(1, 2))[tgt, s.il[tgt], s.ic[tgt]]
            d_new[mv] -= move[mv]
            pvm = s.prev[tgt]
            pvm[:, :2] -= move[mv]
            s.prev[tgt] = pvm
    s.d[sel] = np.clip(d_new, -0.999, 0.999)


def _small_step(ctx: _RefineContext, sel, live, step, c, sb, gain, tol):
    """Converged points: the step is below ``tol``, or immaterial.

    Immaterial: below a tenth of the point's own standard deviation (e.g.
    across bands), from the fit residual ``sb - c[:, 0] * gain``.

    Returns
    -------
    ndarray of bool, shape (n,)
    """
    small = (np.abs(step) < tol).all(axis=1)
    unsure = live & ~small
    if unsure.any():
        sig2 = np.maximum(sb - c[:, 0] * gain, 0.0) / max(ctx.npx - 4, 1)
        with np.errstate(divide="ignore", invalid="ignore"):
            noise_step = 0.1 * np.sqrt(sig2[:, None] * ctx.ninv_d[sel]) / np.abs(gain)[:, None]
        small |= (np.abs(step) < np.nan_to_num(noise_step)).all(axis=1)
    return small


def _retire(s: _RefineState, sel, live, active, *, full, it, step, small):
    """Mark converged and stalled points; return the new active set.

    Stalled: from iteration ``_STALL_IT`` on, the step has not shrunk in two
    iterations (drift along a flat direction, no root in reach): the point is
    given up (``NOT_CONVERGED``). Updates ``s.hist``, ``s.converged`` and
    ``s.gave_up`` in place.
    """
    norm = np.abs(step).max(axis=1)
    stalled = np.zeros_like(small)
    if it >= _STALL_IT:
        stalled = ~small & (norm > 0.8 * s.hist[sel, 1])
    s.hist[sel] = np.where(live[:, None], np.stack([norm, s.hist[sel, 0]], axis=1), s.hist[sel])
    if full:
        s.converged |= live & small
        s.gave_up |= live & stalled
        return np.flatnonzero(~(s.converged | s.gave_up))
    s.converged[active[small]] = True
    s.gave_up[active[stalled]] = True
    return active[~(small | stalled)]


def _quality_and_std(stats, peak, a_norm, a_norm2, ninv, *, hopeless, singular, npx):
    """Final NCC and a-posteriori standard deviations (Delon & Rouge).

    Parameters
    ----------
    stats : ndarray of float64, shape (N, 4)
        ``_RefineState.stats`` at the final positions.
    peak : ndarray of float64, shape (N,)
        Integer NCC peak, the quality of points not refined.
    a_norm, a_norm2 : ndarray of float64, shape (N,)
        Norms of the zero-mean A windows.
    ninv : ndarray of float64, shape (N, 3, 3)
        Inverse normal matrices.
    hopeless, singular : ndarray of bool, shape (N,), keyword-only
        Points not refined, degenerate designs.
    npx : int, keyword-only
        Pixels per window.

    Returns
    -------
    quality, std_l, std_c : ndarray of float64, shape (N,)
    """
    c0, sb = stats[:, 0], stats[:, 3]
    with np.errstate(divide="ignore", invalid="ignore"):
        quality = np.where(hopeless & ~singular, peak, c0 / (a_norm * np.sqrt(sb)))
        gain = c0 / a_norm2
        sigma2 = np.maximum(sb - c0 * gain, 0.0) / max(npx - 4, 1)
        std_l = np.sqrt(sigma2 * ninv[:, 1, 1]) / np.abs(gain)
        std_c = np.sqrt(sigma2 * ninv[:, 2, 2]) / np.abs(gain)
    return quality, std_l, std_c


def _final_flags(flags, off_l, off_c, d, quality, std_l, std_c, *, singular, converged, hopeless, sl, sc,
                 min_quality, max_std) -> None:
    """Add the ``FLAT``, ``SEARCH_BORDER``, ``NOT_CONVERGED``, ``LOW_CORRELATION``
    and ``IMPRECISE`` bits to ``flags``, in place.

    ``off_l``, ``off_c`` are the match offsets from the search grid centre
    (px), ``d`` the final shifts from the integer base; see
    :func:`match_points` for the rules.
    """
    flags[singular] |= MatchFlag.FLAT
    lim_l, lim_c = (sl or 0.5), (sc or 0.5)
    flags[(np.abs(off_l) > lim_l) | (np.abs(off_c) > lim_c)] |= MatchFlag.SEARCH_BORDER
    flags[~converged | (np.any(np.abs(d) >= 0.99, axis=1) & ~hopeless)] |= MatchFlag.NOT_CONVERGED
    flags[~(quality >= min_quality)] |= MatchFlag.LOW_CORRELATION
    if max_std is not None:
        flags[~((std_l <= max_std) & (std_c <= max_std))] |= MatchFlag.IMPRECISE


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


def _ncc_step(ctx: _RefineContext, sel, it: int, b_res, b_sum, c, gain):
    """``"ncc"``: the Gauss-Newton residual drives the step and is what the Broyden update remembers."""
    f = _ncc_residual(ctx, sel, c, gain)
    return f, f


@dataclass(frozen=True)
class MatchingMethod:
    """A sub-pixel matching method: its residual shift, whether it needs A's spectrum, whether it is compiled."""

    name: str
    description: str
    residual: Callable
    needs_spectrum: bool = False
    compiled: bool = False


#: ``restoration.match_method`` → method
MATCHING_METHODS: dict[str, MatchingMethod] = {m.name: m for m in (
    MatchingMethod("ncc", "normalised cross-correlation, Gauss-Newton with the gain projected out (compiled kernel)",
                   _ncc_step, compiled=True),
    MatchingMethod("phase", "phase plane of the cross-power spectrum (NumPy)", _phase_residual, needs_spectrum=True),
)}
