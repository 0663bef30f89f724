"""Compiled (Numba) kernel of the ``"ncc"`` matcher of :mod:`restore.matching`.

The same algorithm as the batched NumPy implementation (integer NCC search,
Gauss-Newton / Lucas-Kanade refinement with the gain projected out, Broyden
slope update, bounded steps, moves of the integer base, stall detection,
Delon-Rouge precision), written per point and compiled with Numba, so that
one point's whole life stays in registers and cache. Points are independent:
they are spread over threads in fixed blocks, and the result of each point
does not depend on the thread count (same bytes on any number of cores).

It is an implementation detail of :func:`restore.matching.match_points`
(``backend="compiled"``); the NumPy path stays the reference that the tests
compare it with.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

# flag bits, as restore.matching.MatchFlag
_OUT_OF_BOUNDS = 1
_NO_DATA = 2
_FLAT = 4
_SEARCH_BORDER = 8
_LOW_CORRELATION = 16
_NOT_CONVERGED = 32
_IMPRECISE = 64

#: antisymmetric gradient filter taps D_1, D_2 of [1, -8, 0, 8, -1] / 12
_D1 = 8.0 / 12.0
_D2 = -1.0 / 12.0
_G = 2
_MAX_STEP = 0.5
_STALL_IT = 8
#: points per block of the parallel loop (each block owns its scratch buffers)
_BLOCK = 64


@njit(cache=True, error_model="numpy", inline="always")
def _lanczos(d, order, sk, ck, corr, out):
    """Normalised Lanczos weights of taps -order..order for a shift d in (-1, 1), exact for polynomials
    up to the degree of ``corr`` (:func:`restore.matching.lanczos_weights`).

    ``sinc(x) sinc(x / a)`` with ``x = k - d`` is ``-a sin(pi d) (-1)^k
    sin(pi x / a) / (pi x)^2``; by angle addition it needs the tables
    ``sk = (-1)^k sin(pi k / a)``, ``ck = (-1)^k cos(pi k / a)`` and two sines of
    ``d`` (the factor common to all taps cancels in the normalisation).
    """
    n = 2 * order + 1
    if d == 0.0:  # integer position: the sample itself
        for t in range(n):
            out[t] = 0.0
        out[order] = 1.0
        return
    s = math.sin(math.pi / order * d)
    c = math.cos(math.pi / order * d)
    tot = 0.0
    for t in range(n):
        x = (t - order) - d
        v = 0.0
        if abs(x) < order:
            v = (sk[t] * c - ck[t] * s) / (x * x)
        out[t] = v
        tot += v
    for t in range(n):
        out[t] /= tot
    # the smallest change that makes the weights exact for powers of d up to corr's degree
    # (restore.matching.polynomial_correction, its row for the sign of d)
    row = 0 if d > 0.0 else 1
    deg = corr.shape[2]
    for p in range(deg):
        m = 0.0
        for t in range(n):
            m += out[t] * float(t - order) ** p
        r = d ** p - m
        for t in range(n):
            out[t] += corr[row, t, p] * r


@njit(cache=True, error_model="numpy", inline="always")
def _patch_sum(image, s_l, s_c, n_l, n_c, colacc):
    """Sum of ``image[s_l:s_l + n_l, s_c:s_c + n_c]`` (column partial sums in ``colacc``)."""
    for j in range(n_c):
        colacc[j] = 0.0
    for i in range(n_l):
        src = image[s_l + i, s_c:s_c + n_c]  # a row slice: the inner loop indexes from 0
        for j in range(n_c):
            colacc[j] += src[j]
    return _sum4(colacc, n_c)


@njit(cache=True, error_model="numpy", inline="always")
def _sum4(x, n):
    """``x[:n].sum()`` with four interleaved accumulators (a fixed order: same bytes everywhere)."""
    s0 = s1 = s2 = s3 = 0.0
    m = n - n % 4
    for j in range(0, m, 4):
        s0 += x[j]
        s1 += x[j + 1]
        s2 += x[j + 2]
        s3 += x[j + 3]
    for j in range(m, n):
        s0 += x[j]
    return (s0 + s1) + (s2 + s3)


@njit(cache=True, error_model="numpy", inline="always")
def _gather_level(image, s_l, s_c, n_l, n_c, ref, dst):
    """``dst[:n_l, :n_c] = image[s_l:s_l + n_l, s_c:s_c + n_c] - ref``."""
    for i in range(n_l):
        src = image[s_l + i, s_c:s_c + n_c]
        row = dst[i]
        for j in range(n_c):
            row[j] = src[j] - ref


@njit(cache=True, error_model="numpy", inline="always")
def _a_design(a_patch, h, w, jac):
    """Gauss-Newton design of the A window, written into ``jac`` (3, h, w).

    ``jac[0]`` is the zero-mean window, ``jac[1]``, ``jac[2]`` its line and
    column gradients (antisymmetric filter ``_D1``, ``_D2``; their means are
    kept in the array and removed in the products). Returns
    ``(sum(a_z**2), mean(dA/dl), mean(dA/dc))``.
    """
    g = _G
    npx = h * w
    a_mean = 0.0
    for i in range(h):
        for j in range(w):
            a_mean += a_patch[g + i, g + j]
    a_mean /= npx
    a_norm2 = 0.0
    m1 = 0.0
    m2 = 0.0
    for i in range(h):
        for j in range(w):
            v = a_patch[g + i, g + j] - a_mean
            jac[0, i, j] = v
            a_norm2 += v * v
            gl = _D1 * (a_patch[g + i + 1, g + j] - a_patch[g + i - 1, g + j]) + \
                _D2 * (a_patch[g + i + 2, g + j] - a_patch[g + i - 2, g + j])
            gc = _D1 * (a_patch[g + i, g + j + 1] - a_patch[g + i, g + j - 1]) + \
                _D2 * (a_patch[g + i, g + j + 2] - a_patch[g + i, g + j - 2])
            jac[1, i, j] = gl
            jac[2, i, j] = gc
            m1 += gl
            m2 += gc
    return a_norm2, m1 / npx, m2 / npx


@njit(cache=True, error_model="numpy", inline="always")
def _integer_search(b_big, jac, a_norm, h, w, sl, sc, order, colacc, colsq, prod):
    """NCC of the A window (``jac[0]``) at every integer offset of the search grid.

    Returns ``(best, il, ic)``: the peak NCC (``-inf`` where B is flat at every
    offset) and its offset in the grid (``sl``, ``sc`` is the centre).
    """
    npx = h * w
    kl, kc = 2 * sl + 1, 2 * sc + 1
    best = -np.inf
    il = 0
    ic = 0
    wb = w + 2 * sc  # columns of the search region
    for ol in range(kl):
        # line sums of B and B**2 per column over the window's lines
        for j in range(wb):
            colacc[j] = 0.0
            colsq[j] = 0.0
        for i in range(h):
            src = b_big[order + ol + i, order:order + wb]
            for j in range(wb):
                b = src[j]
                colacc[j] += b
                colsq[j] += b * b
        for oc in range(kc):
            # numerator: products summed over lines per column, then over columns
            for j in range(w):
                prod[j] = 0.0
            for i in range(h):
                arow = jac[0, i]
                brow = b_big[order + ol + i, order + oc:order + oc + w]
                for j in range(w):
                    prod[j] += arow[j] * brow[j]
            v_num = _sum4(prod, w)
            s1 = _sum4(colacc[oc:oc + w], w)
            s2 = _sum4(colsq[oc:oc + w], w)
            den = math.sqrt(max(s2 - s1 * s1 / npx, 0.0)) * a_norm
            if den > 0:
                v = v_num / den
                if v > best:
                    best = v
                    il = ol
                    ic = oc
    return best, il, ic


@njit(cache=True, error_model="numpy", inline="always")
def _normal_matrix(jac, h, w, a_norm2, m1, m2):
    """Upper triangle ``(n00, n01, n02, n11, n12, n22)`` of the normal matrix of
    ``[a_z, dA/dl, dA/dc]``, the gradients' means removed."""
    npx = h * w
    n01 = 0.0
    n02 = 0.0
    n11 = 0.0
    n12 = 0.0
    n22 = 0.0
    for i in range(h):
        for j in range(w):
            a0 = jac[0, i, j]
            a1 = jac[1, i, j]
            a2 = jac[2, i, j]
            n01 += a0 * a1
            n02 += a0 * a2
            n11 += a1 * a1
            n12 += a1 * a2
            n22 += a2 * a2
    n11 -= npx * m1 * m1
    n12 -= npx * m1 * m2
    n22 -= npx * m2 * m2
    return a_norm2, n01, n02, n11, n12, n22


@njit(cache=True, error_model="numpy", inline="always")
def _ill_conditioned(n00, n01, n02, n11, n12, n22):
    """Whether the correlation matrix of the design has a determinant <= 1e-6 (or a null column)."""
    d0, d1, d2 = math.sqrt(n00), math.sqrt(n11), math.sqrt(n22)
    if d0 > 0 and d1 > 0 and d2 > 0:
        r01, r02, r12 = n01 / (d0 * d1), n02 / (d0 * d2), n12 / (d1 * d2)
        det_corr = 1.0 + 2.0 * r01 * r02 * r12 - r01 * r01 - r02 * r02 - r12 * r12
        return not (det_corr > 1e-6)
    return True


@njit(cache=True, error_model="numpy", inline="always")
def _inverse_rows(n00, n01, n02, n11, n12, n22):
    """Rows 1 and 2 ``(i10, i11, i12, i20, i21, i22)`` of the inverse of the symmetric normal matrix."""
    c00, c01, c02 = n11 * n22 - n12 * n12, n02 * n12 - n01 * n22, n01 * n12 - n02 * n11
    c11, c12, c22 = n00 * n22 - n02 * n02, n01 * n02 - n00 * n12, n00 * n11 - n01 * n01
    det = n00 * c00 + n01 * c01 + n02 * c02
    return c01 / det, c11 / det, c12 / det, c02 / det, c12 / det, c22 / det


@njit(cache=True, error_model="numpy", inline="always")
def _sample_b(b_big, il, ic, d_l, d_c, at_peak, h, w, order, sk, ck, corr, wl, wc, rows, bres):
    """B at the current position into ``bres`` (h, w): the window on the integer
    base ``(il, ic)`` if ``at_peak``, else resampled at ``(d_l, d_c)`` from it."""
    if at_peak:
        for i in range(h):
            src = b_big[order + il + i, order + ic:order + ic + w]
            br = bres[i]
            for j in range(w):
                br[j] = src[j]
        return
    _lanczos(d_l, order, sk, ck, corr, wl)
    _lanczos(d_c, order, sk, ck, corr, wc)
    taps = 2 * order + 1
    wcol = w + 2 * order
    # separable resampling; the tap loops are outside, so the
    # inner loops run over independent outputs (vectorised)
    for i in range(h):
        rw = rows[i]
        for j in range(wcol):
            rw[j] = 0.0
        for t in range(taps):
            wt = wl[t]
            src = b_big[il + i + t, ic:ic + wcol]
            for j in range(wcol):
                rw[j] += wt * src[j]
        br = bres[i]
        for j in range(w):
            br[j] = 0.0
        for t in range(taps):
            wt = wc[t]
            src = rw[t:t + w]
            for j in range(w):
                br[j] += wt * src[j]


@njit(cache=True, error_model="numpy", inline="always")
def _b_products(bres, jac, h, w, m1, m2):
    """Products of B with the design: ``(sum B, <a_z, B>, <g_l, B>, <g_c, B>, |B - mean|^2)``,
    the gradients' means removed."""
    npx = h * w
    b_sum = 0.0
    q0 = 0.0
    q1 = 0.0
    q2 = 0.0
    sb = 0.0
    for i in range(h):
        for j in range(w):
            b = bres[i, j]
            b_sum += b
            q0 += jac[0, i, j] * b
            q1 += jac[1, i, j] * b
            q2 += jac[2, i, j] * b
            sb += b * b
    q1 -= m1 * b_sum
    q2 -= m2 * b_sum
    sb -= b_sum * b_sum / npx
    return b_sum, q0, q1, q2, sb


@njit(cache=True, error_model="numpy", inline="always")
def _broyden(s00, s01, s10, s11, ds_l, ds_c, y_l, y_c):
    """Broyden update ``S += (y - S s) s^T / s^T s`` of the 2 x 2 slope matrix,
    reset to the identity when it leaves a plausible range."""
    ss = ds_l * ds_l + ds_c * ds_c
    if ss > 1e-8:
        e_l = (y_l - (s00 * ds_l + s01 * ds_c)) / ss
        e_c = (y_c - (s10 * ds_l + s11 * ds_c)) / ss
        s00 += e_l * ds_l
        s01 += e_l * ds_c
        s10 += e_c * ds_l
        s11 += e_c * ds_c
    dt = s00 * s11 - s01 * s10
    tr = s00 + s11
    mx = max(max(abs(s00), abs(s01)), max(abs(s10), abs(s11)))
    if not ((dt > 0.04) and (tr > 0.4) and (tr < 6.0) and (mx < 4.0)):
        return 1.0, 0.0, 0.0, 1.0
    return s00, s01, s10, s11


@njit(cache=True, error_model="numpy", inline="always")
def _cell_move(nd, base, top):
    """Move (-1, 0, 1) of the integer base when the match ``nd`` left its cell
    (``|nd| > 0.75``), kept inside the grid ``0 .. top``."""
    if abs(nd) > 0.75:
        mv = 1 if nd > 0 else -1
        if base + mv < 0 or base + mv > top:
            return 0
        return mv
    return 0


@njit(cache=True, error_model="numpy", inline="always")
def _small_step(st_l, st_c, tol, sb, q0, gain, npx, i11, i22):
    """Converged: the step is below ``tol``, or below a tenth of the point's own
    standard deviation (immaterial, e.g. across bands)."""
    if abs(st_l) < tol and abs(st_c) < tol:
        return True
    sig2 = max(sb - q0 * gain, 0.0) / max(npx - 4, 1)
    ns_l = 0.1 * math.sqrt(sig2 * i11) / abs(gain)
    ns_c = 0.1 * math.sqrt(sig2 * i22) / abs(gain)
    if math.isnan(ns_l):
        ns_l = 0.0
    if math.isnan(ns_c):
        ns_c = 0.0
    return abs(st_l) < ns_l and abs(st_c) < ns_c


@njit(cache=True, error_model="numpy", inline="always")
def _refine(b_big, jac, il, ic, h, w, sl, sc, order, max_iter, tol, m1, m2, inv_a2, n00, n01, n02,
            i10, i11, i12, i20, i21, i22, sk, ck, corr, wl, wc, rows, bres):
    """Sub-pixel Gauss-Newton / Broyden iterations of one point from its integer peak.

    Returns ``(il, ic, d_l, d_c, st0, st3, converged, gave_up)``: the final
    integer base and shift from it (px), ``<a_z, B>`` and ``|B - mean|^2`` at the
    final position, and how the iterations ended.
    """
    npx = h * w
    d_l = 0.0
    d_c = 0.0
    s00, s01, s10, s11 = 1.0, 0.0, 0.0, 1.0  # Broyden slope matrix
    p_dl = p_dc = p_fl = p_fc = 0.0  # previous position and F
    hist0 = np.inf
    hist1 = np.inf
    st0 = np.nan
    st3 = np.nan
    converged = False
    gave_up = False
    for it in range(max_iter + 1):
        _sample_b(b_big, il, ic, d_l, d_c, it == 0, h, w, order, sk, ck, corr, wl, wc, rows, bres)
        b_sum, q0, q1, q2, sb = _b_products(bres, jac, h, w, m1, m2)
        st0 = q0
        st3 = sb
        if it == max_iter:
            break
        gain = q0 * inv_a2
        # Gauss-Newton step with the gain projected out (variable projection)
        r0 = q0 - gain * n00
        r1 = q1 - gain * n01
        r2 = q2 - gain * n02
        safe = -1.0 / gain if abs(gain) > 1e-12 else -1.0
        f_l = (i10 * r0 + i11 * r1 + i12 * r2) * safe
        f_c = (i20 * r0 + i21 * r1 + i22 * r2) * safe
        if it > 0:
            s00, s01, s10, s11 = _broyden(s00, s01, s10, s11, d_l - p_dl, d_c - p_dc, p_fl - f_l, p_fc - f_c)
        p_dl, p_dc, p_fl, p_fc = d_l, d_c, f_l, f_c
        dt = s00 * s11 - s01 * s10
        st_l = min(max((s11 * f_l - s01 * f_c) / dt, -_MAX_STEP), _MAX_STEP)
        st_c = min(max((s00 * f_c - s10 * f_l) / dt, -_MAX_STEP), _MAX_STEP)
        nd_l = d_l + st_l
        nd_c = d_c + st_c
        # the match left the integer peak's cell: move to the neighbour
        mv_l = _cell_move(nd_l, il, 2 * sl)
        mv_c = _cell_move(nd_c, ic, 2 * sc)
        if mv_l != 0 or mv_c != 0:
            il += mv_l
            ic += mv_c
            nd_l -= mv_l
            nd_c -= mv_c
            p_dl -= mv_l
            p_dc -= mv_c
        d_l = min(max(nd_l, -0.999), 0.999)
        d_c = min(max(nd_c, -0.999), 0.999)
        if _small_step(st_l, st_c, tol, sb, q0, gain, npx, i11, i22):
            converged = True
            break
        norm = max(abs(st_l), abs(st_c))
        if it >= _STALL_IT and norm > 0.8 * hist1:  # the step stopped shrinking: no root in reach
            gave_up = True
            break
        hist1 = hist0
        hist0 = norm
    return il, ic, d_l, d_c, st0, st3, converged, gave_up


@njit(cache=True, error_model="numpy", inline="always")
def _quality_std(st0, st3, peak, a_norm, a_norm2, i11, i22, npx, hopeless, singular):
    """Final NCC and Delon-Rouge standard deviations ``(quality, std_l, std_c)``."""
    if hopeless and not singular:
        quality = peak
    else:
        quality = st0 / (a_norm * math.sqrt(st3))
    gain = st0 / a_norm2
    sigma2 = max(st3 - st0 * gain, 0.0) / max(npx - 4, 1)
    if math.isnan(st3):
        sigma2 = np.nan
    return quality, math.sqrt(sigma2 * i11) / abs(gain), math.sqrt(sigma2 * i22) / abs(gain)


@njit(cache=True, error_model="numpy", inline="always")
def _final_flags(off_l, off_c, d_l, d_c, sl, sc, quality, std_l, std_c, singular, hopeless, converged, gave_up,
                 min_quality, max_std):
    """Rejection bits of a refined (or given up) point, as ``MatchFlag``."""
    flags = 0
    if singular:
        flags |= _FLAT
    lim_l = sl if sl > 0 else 0.5
    lim_c = sc if sc > 0 else 0.5
    if abs(off_l) > lim_l or abs(off_c) > lim_c:
        flags |= _SEARCH_BORDER
    if (not converged) or gave_up or ((abs(d_l) >= 0.99 or abs(d_c) >= 0.99) and not hopeless):
        flags |= _NOT_CONVERGED
    if not (quality >= min_quality):
        flags |= _LOW_CORRELATION
    if max_std > 0 and not (std_l <= max_std and std_c <= max_std):
        flags |= _IMPRECISE
    return flags


@njit(cache=True, error_model="numpy")
def _match_one(image_a, image_b, la, ca, pl, pc, h, w, sl, sc, order, max_iter, tol, min_quality, max_std,
               a_patch, b_big, jac, rows, bres, wl, wc, sk, ck, corr, prod, colacc, colsq, out):
    """Match one point; writes line_b, col_b, quality, flags, std_l, std_c into ``out``.

    Structure: the steps of :func:`restore.matching._match_chunk`, per point,
    each an ``@njit(inline="always")`` helper that Numba inlines here (one
    function after compilation, same machine code as the former single body):

    1. geometry: rounded point in A, centre of the search grid in B, bounds
       (``OUT_OF_BOUNDS``: reported at the prediction);
    2. levels (:func:`_patch_sum`, ``NO_DATA`` if not finite) and gathering of
       the A patch and the B search area, levels removed
       (:func:`_gather_level`);
    3. A design ``[a_z, dA/dl, dA/dc]`` (:func:`_a_design`), flatness of A;
    4. integer NCC search (:func:`_integer_search`), flatness of B;
    5. normal matrix (:func:`_normal_matrix`), conditioning
       (:func:`_ill_conditioned`), inverse (:func:`_inverse_rows`);
    6. sub-pixel iterations unless singular or hopeless (:func:`_refine`:
       :func:`_sample_b`, :func:`_b_products`, :func:`_broyden`,
       :func:`_cell_move`, :func:`_small_step`);
    7. quality and precision (:func:`_quality_std`), flags
       (:func:`_final_flags`).

    The helpers are inlined at Numba IR level (``inline="always"``): compiled as
    separate functions (LLVM's choice) they cost 7-8 % per match. Splitting
    the former 305-line body this way kept the outputs bit for bit and costs
    2-6 % per match on one thread, about 3.5 % on average (six interleaved A/B
    runs on a shared 2-core machine, 20000 points, best of 20-30 calls each:
    e.g. 5.04 -> 5.20 µs "same", 5.21 -> 5.41 µs "cross"), at the edge of
    the timing noise of ``simsat bench matching``.
    """
    nla, nca = image_a.shape
    nlb, ncb = image_b.shape
    npx = h * w
    g = _G
    hl, hc = h // 2, w // 2

    # --- 1. geometry --------------------------------------------------------------
    ra_l = np.rint(la)
    ra_c = np.rint(ca)
    fr_l = la - ra_l
    fr_c = ca - ra_c
    c0_l = np.rint(pl - fr_l)
    c0_c = np.rint(pc - fr_c)
    pa_l, pa_c = h + 2 * g, w + 2 * g
    pb_l, pb_c = h + 2 * sl + 2 * order, w + 2 * sc + 2 * order
    sa_l, sa_c = int(ra_l) - hl - g, int(ra_c) - hc - g
    sb_l, sb_c = int(c0_l) - hl - sl - order, int(c0_c) - hc - sc - order
    inside = (sa_l >= 0 and sa_l + pa_l <= nla and sa_c >= 0 and sa_c + pa_c <= nca and
              sb_l >= 0 and sb_l + pb_l <= nlb and sb_c >= 0 and sb_c + pb_c <= ncb)
    # points that cannot be matched are reported at their prediction
    out[0] = c0_l + fr_l
    out[1] = c0_c + fr_c
    out[2] = np.nan
    out[4] = np.nan
    out[5] = np.nan
    if not inside:
        out[3] = _OUT_OF_BOUNDS | _LOW_CORRELATION
        return
    # --- 2. levels and gathering ----------------------------------------------------
    # (single precision levels as in the NumPy path are not needed here: every
    # sum below is accumulated in double precision; the levels need no
    # particular summation order, only finiteness)
    a_ref = _patch_sum(image_a, sa_l, sa_c, pa_l, pa_c, colacc)
    b_ref = _patch_sum(image_b, sb_l, sb_c, pb_l, pb_c, colacc)
    if not (math.isfinite(a_ref) and math.isfinite(b_ref)):
        out[3] = _NO_DATA | _LOW_CORRELATION
        return
    a_ref /= pa_l * pa_c
    b_ref /= pb_l * pb_c
    _gather_level(image_a, sa_l, sa_c, pa_l, pa_c, a_ref, a_patch)
    _gather_level(image_b, sb_l, sb_c, pb_l, pb_c, b_ref, b_big)
    # --- 3.-5. design, integer search, normal matrix ------------------------------
    a_norm2, m1, m2 = _a_design(a_patch, h, w, jac)
    a_norm = math.sqrt(a_norm2)
    flat_a = not (a_norm > 1e-6 * math.sqrt(npx) * abs(a_ref))
    peak, il, ic = _integer_search(b_big, jac, a_norm, h, w, sl, sc, order, colacc, colsq, prod)
    flat_b = not math.isfinite(peak)
    n00, n01, n02, n11, n12, n22 = _normal_matrix(jac, h, w, a_norm2, m1, m2)
    singular = flat_a or flat_b
    if not singular:
        singular = _ill_conditioned(n00, n01, n02, n11, n12, n22)
    if singular:
        n00, n01, n02, n11, n12, n22 = 1.0, 0.0, 0.0, 1.0, 0.0, 1.0
    i10, i11, i12, i20, i21, i22 = _inverse_rows(n00, n01, n02, n11, n12, n22)
    hopeless = peak < min_quality - 0.2
    # --- 6. sub-pixel iterations ----------------------------------------------------
    converged = singular or hopeless
    gave_up = False
    d_l = 0.0
    d_c = 0.0
    st0 = np.nan
    st3 = np.nan
    if not converged:
        inv_a2 = 1.0 / a_norm2 if a_norm2 > 0 else 1.0
        il, ic, d_l, d_c, st0, st3, converged, gave_up = _refine(
            b_big, jac, il, ic, h, w, sl, sc, order, max_iter, tol, m1, m2, inv_a2, n00, n01, n02,
            i10, i11, i12, i20, i21, i22, sk, ck, corr, wl, wc, rows, bres)
    # --- 7. quality, precision and flags ------------------------------------------
    quality, std_l, std_c = _quality_std(st0, st3, peak, a_norm, a_norm2, i11, i22, npx, hopeless, singular)
    off_l = (il - sl) + d_l
    off_c = (ic - sc) + d_c
    flags = _final_flags(off_l, off_c, d_l, d_c, sl, sc, quality, std_l, std_c, singular, hopeless, converged,
                         gave_up, min_quality, max_std)
    out[0] = c0_l + off_l + fr_l
    out[1] = c0_c + off_c + fr_c
    out[2] = np.nan if singular else quality
    out[3] = flags
    out[4] = std_l
    out[5] = std_c
    # correlation of the line and column errors: the normal matrix's inverse, gain projected out (an
    # oriented texture, an edge, couples them: the aperture problem)
    out[6] = 0.0 if singular or not (i11 > 0 and i22 > 0) else i12 / math.sqrt(i11 * i22)


@njit(cache=True, error_model="numpy", parallel=True)
def match_ncc(image_a, image_b, la, ca, pl, pc, h, w, sl, sc, order, max_iter, tol, min_quality, max_std, corr):
    """Match every point; returns an (N, 7) array of line_b, col_b, quality, flags, std_l, std_c, corr_lc.

    ``corr``: :func:`restore.matching.polynomial_correction` of ``order`` (B's interpolation weights).

    ``max_std <= 0`` means no precision requirement.
    """
    n = la.shape[0]
    out = np.empty((n, 7))
    n_blocks = (n + _BLOCK - 1) // _BLOCK
    g = _G
    sk = np.empty(2 * order + 1)  # Lanczos tap tables
    ck = np.empty(2 * order + 1)
    for t in range(2 * order + 1):
        k = t - order
        sgn = 1.0 if k % 2 == 0 else -1.0
        sk[t] = sgn * math.sin(math.pi * k / order)
        ck[t] = sgn * math.cos(math.pi * k / order)
    for blk in prange(n_blocks):
        a_patch = np.empty((h + 2 * g, w + 2 * g))
        b_big = np.empty((h + 2 * sl + 2 * order, w + 2 * sc + 2 * order))
        jac = np.empty((3, h, w))
        rows = np.empty((h, w + 2 * order))
        bres = np.empty((h, w))
        wl = np.empty(2 * order + 1)
        wc = np.empty(2 * order + 1)
        prod = np.empty(w)
        wide = max(w + 2 * sc + 2 * order, w + 2 * g)
        colacc = np.empty(wide)
        colsq = np.empty(wide)
        for p in range(blk * _BLOCK, min(n, (blk + 1) * _BLOCK)):
            _match_one(image_a, image_b, la[p], ca[p], pl[p], pc[p], h, w, sl, sc, order, max_iter, tol,
                       min_quality, max_std, a_patch, b_big, jac, rows, bres, wl, wc, sk, ck, corr, prod, colacc, colsq, out[p])
    return out
