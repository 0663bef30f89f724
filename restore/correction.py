"""Image correction with the restored attitude, and band-to-band misregistration.

Each band is resampled to the geometry it would have had under the smooth
*knowledge* attitude: output pixel (l, c) shows the ground point
``G = direct_location(band, l, c, knowledge)``, read in the raw image at
``inverse_location(band, G, restored)``. After correction, bands are related by
the knowledge geometry alone, so matching them at knowledge predictions
measures what misregistration is left.
"""
from __future__ import annotations

import numpy as np

from simsat.product import clamped_attitude
from simsat.sensor_model import tdi_mean_attitude
from simsat.sensor_model import SensorModel

from .matching import match_points_in_blocks
from .settings import CORRECTED_COMPRESSION

__all__ = ["resampling_grid", "resampling_nodes", "correct_bands", "correct_band_block", "correct_band_block_nodes", "SPLINE_MARGIN_LINES", "misregistration", "weak_band_misregistration", "per_line_shift_rms", "rank_within_line", "line_median"]


def resampling_grid(product, band: str, restored, *, column_step: int = 16, lines: slice | None = None,
                    exact: bool = False, line_step: int = 32):
    """Raw-image coordinates (lines, cols) of every pixel of the corrected band.

    Output pixel (l, c) shows the ground point ``G`` the band sees there under
    the knowledge; its raw-image position is ``inverse_location(G)`` under the
    restored attitude. The mapping is computed on every line and every
    ``column_step``-th column, and interpolated linearly in between (it is
    smooth across the field). ``lines`` limits it to a range of output lines
    (default: all).

    With ``exact`` every grid node is located by the sensor model (direct
    location of the node, inverse location under the restored attitude).
    Otherwise (default, ≈ 10× cheaper) the mapping is first order about the
    knowledge attitude of the output line, ``θ_k(t_l)``, held constant:
    ``line = l + S_l·(θ_r(t(line)) − θ_k(t_l))``, ``col = c + S_c·(θ_r(t(line))
    − θ_k(t_l))``, where ``S = ∂(line, col)/∂(roll, pitch, yaw)`` is the sensor
    model's sensitivity under that constant attitude
    (:meth:`~simsat.sensor_model.SensorModel.sensitivities`; it depends on the
    geometry only, so it is computed every ``line_step`` lines and interpolated
    linearly in between), and the implicit time ``t(line)`` (the attitude moves
    during the shift) is solved by Newton iterations on ``θ_r`` sampled 32
    times per line. The neglected terms are second order in the attitude
    change (a few µrad) and the relief's change of ``S`` between nodes
    (relative ``Δh / H``): below 1e-3 px for shifts of several pixels (tested
    against ``exact``).
    """
    det = product.instrument.detector(band)
    rl, rc, cols = resampling_nodes(product, band, restored, column_step=column_step, lines=lines, exact=exact,
                                    line_step=line_step)
    return _interpolate_columns(rl, rc, cols, det.pixels)


def resampling_nodes(product, band: str, restored, *, column_step: int = 16, lines: slice | None = None,
                     exact: bool = False, line_step: int = 32, tdi_mean: bool = True):
    """:func:`resampling_grid` at its grid columns only → ``(rl, rc, cols)``.

    ``rl``, ``rc`` have shape (lines, len(cols)); ``cols`` are every
    ``column_step``-th column and the last one. Interpolating them linearly
    across columns gives :func:`resampling_grid`.

    A TDI band (``tdi_stages`` N > 1) shows the attitude averaged over its N
    stages, its lines dated at the last one: with ``tdi_mean`` (the default)
    the raw image is located with :func:`simsat.sensor_model.tdi_mean_attitude`
    of ``restored``; ``tdi_mean=False`` uses the attitude at the date (about
    (N − 1) Te / 2 too late: the error CNES §3.3.4 warns about).
    """
    det = product.instrument.detector(band)
    n_lines = product.time.size
    sl = slice(0, n_lines) if lines is None else slice(*lines.indices(n_lines)[:2])
    cols = np.unique(np.r_[np.arange(0, det.pixels, column_step), det.pixels - 1]).astype(np.float64)
    sm_k = product.sensor_model()
    att_r = clamped_attitude(restored)
    if tdi_mean and det.tdi_stages > 1:
        att_r = tdi_mean_attitude(att_r, det.tdi_stages, product.instrument.line_period_s)
    if exact:
        sm_r = product.sensor_model(attitude=att_r)
        L, C = np.meshgrid(np.arange(sl.start, sl.stop, dtype=np.float64), cols, indexing="ij")
        g = sm_k.direct_location(band, L, C)
        rl, rc = sm_r.inverse_location(band, g)
    else:
        rl, rc = _linearised_grid(sm_k, att_r, band, np.arange(sl.start, sl.stop, dtype=np.float64), cols,
                                  n_lines=n_lines, line_step=line_step)
    return rl, rc, cols


def _interpolate_columns(rl, rc, cols, pixels: int):
    """Linear interpolation of grid columns ``cols`` to every column, vectorised over lines."""
    full_c = np.arange(pixels, dtype=np.float64)
    idx = np.clip(np.searchsorted(cols, full_c, side="right") - 1, 0, len(cols) - 2)
    w = (full_c - cols[idx]) / (cols[idx + 1] - cols[idx])
    out_l = rl[:, idx] * (1 - w) + rl[:, idx + 1] * w
    out_c = rc[:, idx] * (1 - w) + rc[:, idx + 1] * w
    return out_l, out_c


#: samples of the restored attitude per line period in the linearised resampling grid (linear
#: interpolation between them: relative error (2π f Te / 32)² / 8, 1e-4 at 200 Hz)
_DELTA_SAMPLES_PER_LINE = 32


def _linearised_grid(sm_k, att_r, band: str, out_lines: np.ndarray, cols: np.ndarray, *, n_lines: int,
                     line_step: int, tol_px: float = 1e-6, max_iter: int = 20):
    """:func:`resampling_grid`'s first-order mapping on ``out_lines`` × ``cols`` → (rl, rc)."""
    a0, a1 = float(out_lines[0]), float(out_lines[-1])
    nodes = np.unique(np.r_[np.arange(a0, a1, line_step), a1])
    t_nodes = sm_k.line_time(nodes)
    th_nodes = np.stack(sm_k.attitude(t_nodes))  # (3, nodes): the knowledge, frozen at each node
    mids = 0.5 * (t_nodes[1:] + t_nodes[:-1])

    def frozen(t):  # the attitude of the nearest node, constant around it (inverse location stays near it)
        k = np.searchsorted(mids, np.asarray(t, dtype=np.float64))
        return th_nodes[0][k], th_nodes[1][k], th_nodes[2][k]

    Ln, Cn = np.meshgrid(nodes, cols, indexing="ij")
    g = sm_k.direct_location(band, Ln, Cn)
    sens = sm_k.sensitivities(band, g, attitude=frozen)  # (nodes, cols, 2, 3) px/rad
    if nodes.size > 1:
        j = np.clip(np.searchsorted(nodes, out_lines, side="right") - 1, 0, nodes.size - 2)
        w = ((out_lines - nodes[j]) / (nodes[j + 1] - nodes[j]))[:, None, None, None]
        S = sens[j] * (1 - w) + sens[j + 1] * w
    else:
        S = np.broadcast_to(sens, (out_lines.size,) + sens.shape[1:])
    Sl, Sc = S[:, :, 0, :], S[:, :, 1, :]
    th_k = np.stack(sm_k.attitude(sm_k.line_time(out_lines)))[:, :, None]  # (3, L, 1) θ_k(t_l)

    # θ_r on a fine grid of fractional lines covering the shifts (first guess: at the output line)
    L0 = np.broadcast_to(out_lines[:, None], (out_lines.size, cols.size))
    d0 = np.stack(att_r(sm_k.line_time(out_lines)))[:, :, None] - th_k
    first = L0 + np.einsum("lck,klc->lc", Sl, np.broadcast_to(d0, (3,) + L0.shape))
    ok = np.isfinite(first)
    if not ok.any():
        return np.full(L0.shape, np.nan), np.full(L0.shape, np.nan)
    margin = 8.0 + 3.0 * float(np.max(np.abs(first[ok] - L0[ok])))
    g0 = max(0.0, np.floor(a0 - margin))
    g1 = max(g0 + 1.0, min(float(n_lines - 1), np.ceil(a1 + margin)))
    m = _DELTA_SAMPLES_PER_LINE
    grid = g0 + np.arange(int(round((g1 - g0) * m)) + 1) / m
    th_r = np.stack(att_r(sm_k.line_time(grid)))  # (3, G)

    def attitude_and_slope(x):
        u = np.clip((x - g0) * m, 0.0, grid.size - 1.000001)
        i = np.floor(u).astype(np.int64)
        f = u - i
        lo, hi = th_r[:, i], th_r[:, i + 1]
        return lo + (hi - lo) * f, (hi - lo) * m  # (3, L, C) rad and rad per line

    def residual(x):
        th, slope = attitude_and_slope(x)
        return x - L0 - np.einsum("lck,klc->lc", Sl, th - th_k), 1.0 - np.einsum("lck,klc->lc", Sl, slope)

    Sl_flat = Sl.reshape(-1, 3)
    th_k_flat = np.broadcast_to(th_k, (3,) + L0.shape).reshape(3, -1)
    L0_flat = L0.ravel()

    def residual_at(x, idx):  # the residual and its slope at the flat nodes ``idx`` only
        th, slope = attitude_and_slope(x)
        S = Sl_flat[idx]
        return (x - L0_flat[idx] - np.einsum("nk,kn->n", S, th - th_k_flat[:, idx]),
                1.0 - np.einsum("nk,kn->n", S, slope))

    # safeguarded Newton inside a bracket (rtsafe): the shift is bounded by Σ_k |S_k| max_t |θ_r,k(t) −
    # θ_k,k(t_l)| over the sampled span, so the root lies in [l − bound, l + bound]; a Newton step that
    # leaves the bracket, or a slope <= 0 (the attitude moving faster than the line sweeps: fast jitter
    # of several pixels), is replaced by bisection. Only the nodes whose |residual| (in lines) still
    # exceeds ``tol_px`` are iterated (a converged node's Newton step rounds to nothing and would
    # otherwise read as leaving the bracket).
    dev = np.maximum(np.abs(th_r.max(axis=1)[:, None] - th_k[:, :, 0]),
                     np.abs(th_r.min(axis=1)[:, None] - th_k[:, :, 0]))  # (3, L)
    bound = 1.0 + np.einsum("lck,kl->lc", np.abs(Sl), dev)
    lo = np.maximum(L0 - bound, g0)
    hi = np.minimum(L0 + bound, g1)
    g_lo, _ = residual(lo)
    g_hi, _ = residual(hi)
    bracketed = ok & (g_lo <= 0) & (g_hi >= 0)
    x = np.where(ok, np.clip(first, lo, hi), L0)
    x_flat, lo_flat, hi_flat = x.ravel().copy(), lo.ravel().copy(), hi.ravel().copy()
    _bracketed_newton(residual_at, x_flat, lo_flat, hi_flat, np.flatnonzero(bracketed.ravel()), tol=tol_px,
                      max_iter=max_iter)
    x = x_flat.reshape(L0.shape)
    th, _ = attitude_and_slope(x)
    rc = Cn[:1] + np.einsum("lck,klc->lc", Sc, th - th_k)
    x[~ok] = np.nan
    rc[~ok] = np.nan
    miss = ok & ~bracketed  # the root is not inside the sampled span: the sensor model locates these nodes
    if miss.any():
        sm_r = SensorModel(platform=sm_k.platform, instrument=sm_k.instrument, dem=sm_k.dem, attitude=att_r,
                           t0_s=sm_k.t0_s)
        x[miss], rc[miss] = sm_r.inverse_location(band, sm_k.direct_location(band, L0[miss], Cn[:1].repeat(
            L0.shape[0], axis=0)[miss]))
    return x, rc


def _bracketed_newton(residual_at, x, lo, hi, act, *, tol: float, max_iter: int) -> None:
    """Solve ``g(x) = 0`` in place at the flat nodes ``act``, each inside its bracket ``[lo, hi]``.

    ``residual_at(x_sub, idx) -> (g, g')``; a Newton step that leaves the
    bracket or meets a slope <= 0 is replaced by bisection; only nodes with
    ``|g| > tol`` are iterated.
    """
    gx, gp = residual_at(x[act], act)
    for _ in range(max_iter):
        keep = np.abs(gx) > tol
        act, gx, gp = act[keep], gx[keep], gp[keep]
        if act.size == 0:
            return
        xa = x[act]
        lo_a = np.where(gx < 0, xa, lo[act])
        hi_a = np.where(gx >= 0, xa, hi[act])
        lo[act], hi[act] = lo_a, hi_a
        newton = xa - gx / np.where(gp > 0, gp, 1.0)
        xa = np.where((gp > 0) & (newton >= lo_a) & (newton <= hi_a), newton, 0.5 * (lo_a + hi_a))
        x[act] = xa
        gx, gp = residual_at(xa, act)


#: lines of raw image read beyond a block's resampling coordinates: the cubic spline prefilter's
#: influence decays as 0.268^n, so 16 lines make the block-wise result equal the whole-image one
#: to ~1e-9 of the signal
SPLINE_MARGIN_LINES = 16


def correct_band_block(img, rl: np.ndarray, rc: np.ndarray, *, n_lines: int | None = None) -> np.ndarray:
    """Resample raw image rows at (rl, rc) by cubic splines, reading only the rows they need.

    Parameters
    ----------
    img : ndarray (L, C), or callable
        The whole raw band (float32 DN), or ``read(slice) -> rows`` of it
        (then ``n_lines`` is required).
    rl, rc : ndarray (l, C)
        Raw-image coordinates [px] of a block of output pixels.
    n_lines : int, optional
        Lines of the raw band when ``img`` is a reader.

    Returns
    -------
    ndarray (l, C) float32
        The resampled block, NaN where the coordinates fall outside the raw image.
    """
    from ._spline_kernel import cubic_spline_resample  # compiled: equal to map_coordinates(order=3, "nearest")

    if callable(img):
        read, total = img, int(n_lines)
    else:
        read, total = (lambda s: img[s]), img.shape[0]
    span = _raw_rows(rl, total)
    if span is None:
        return np.full(rl.shape, np.nan, np.float32)
    r0, r1 = span
    sub = np.asarray(read(slice(r0, r1)), dtype=np.float64)
    n_cols = sub.shape[1]
    inside = (rl >= 0) & (rl <= total - 1) & (rc >= 0) & (rc <= n_cols - 1)
    out = cubic_spline_resample(sub, np.nan_to_num(rl) - r0, np.nan_to_num(rc)).astype(np.float32)
    out[~inside] = np.nan
    return out


def _raw_rows(rl: np.ndarray, total: int) -> tuple[int, int] | None:
    """First and end raw line a block with raw line coordinates ``rl`` reads (None: no finite one)."""
    finite_l = rl[np.isfinite(rl)]
    if finite_l.size == 0:
        return None
    r0 = int(max(0, np.floor(finite_l.min()) - SPLINE_MARGIN_LINES))
    r1 = int(min(total, np.ceil(finite_l.max()) + SPLINE_MARGIN_LINES + 1))
    if r1 - r0 < 2:
        r0, r1 = max(0, min(r0, total - 2)), min(total, max(r0, 0) + 2)
    return r0, r1


def correct_band_block_nodes(read, rl: np.ndarray, rc: np.ndarray, cols: np.ndarray, *, pixels: int,
                             n_lines: int) -> np.ndarray:
    """:func:`correct_band_block` with the coordinates at grid columns ``cols`` (:func:`resampling_nodes`).

    The coordinates are interpolated across columns inside the compiled
    sampler (no full-resolution coordinate arrays): equal to
    ``correct_band_block(read, *interpolated)``. ``read(slice) -> rows`` reads
    raw lines of the band (``n_lines`` of them, ``pixels`` wide output).
    """
    from ._spline_kernel import cubic_spline_resample_nodes

    span = _raw_rows(rl, int(n_lines))
    if span is None:
        return np.full((rl.shape[0], int(pixels)), np.nan, np.float32)
    r0, r1 = span
    sub = np.asarray(read(slice(r0, r1)), dtype=np.float64)
    return cubic_spline_resample_nodes(sub, r0, int(n_lines), rl, rc, cols, int(pixels))


def correct_bands(product, *, restored, valid=None, column_step: int = 16, bands=None, path=None, compression="zlib",
                  attrs: dict | None = None, block_lines: int = 512, tdi_mean: bool = True):
    """Bands resampled to the knowledge geometry (cubic spline interpolation), block by block.

    Parameters
    ----------
    product : simsat.product.Product
    restored : AttitudeSeries
        The attitude to correct with.
    valid : ndarray of bool, optional
        Lines where the attitude is restored (others are NaN in the output).
    column_step : int
        The resampling grid is exact every ``column_step`` columns.
    bands : sequence of str, optional
        Band names to correct (default: all).
    path : path, optional
        Write the images into this NetCDF file block by block (memory bounded
        by one band and one block) and return it opened lazily; default: an
        in-memory dataset.
    compression : {"zlib", "lz4", "none"}
        Compression of the images written to ``path``
        (:data:`restore.settings.CORRECTED_COMPRESSION`).
    attrs : dict, optional
        Global attributes of the result.
    block_lines : int
        Lines per block.
    tdi_mean : bool
        Locate TDI bands with the attitude averaged over their stages (:func:`resampling_nodes`).

    Returns
    -------
    xarray.Dataset
        ``image_<band>`` float32 (NaN outside the raw image or where the
        attitude was not restored), ``time`` per line.
    """
    import xarray as xr

    names = [n for n in product.band_names if bands is None or n in bands]
    same = len({d.pixels for d in product.instrument.detectors}) == 1
    n_lines = product.time.size
    if compression not in CORRECTED_COMPRESSION:
        raise ValueError(f"compression: must be one of {', '.join(CORRECTED_COMPRESSION)}, got {compression!r}")
    attrs = {"title": "simsat corrected images", **(attrs or {})}
    valid = None if valid is None else np.asarray(valid, bool)
    nc = None
    data = {}
    if path is not None:
        import netCDF4

        xr.Dataset(coords={"time": ("line", product.time, {"units": "s"})}, attrs=attrs).to_netcdf(
            path, engine="netcdf4")
        nc = netCDF4.Dataset(str(path), "a")
    try:
        for name in names:
            det = product.instrument.detector(name)
            dims = ("line", "column") if same else ("line", f"column_{name}")
            long_name = f"{name} resampled to the knowledge geometry with the restored attitude"
            if nc is not None:
                if dims[1] not in nc.dimensions:
                    nc.createDimension(dims[1], det.pixels)
                var = nc.createVariable(f"image_{name}", "f4", dims, **CORRECTED_COMPRESSION[compression],
                                        chunksizes=(min(block_lines, n_lines), det.pixels), fill_value=np.nan)
                var.setncatts({"units": "DN", "long_name": long_name})
            else:
                var = np.empty((n_lines, det.pixels), np.float32)
            def read(rows, name=name):
                return product.image(name, lines=rows)  # only the raw lines this block needs

            for a in range(0, n_lines, block_lines):
                sl = slice(a, min(n_lines, a + block_lines))
                rl, rc, cols = resampling_nodes(product, name, restored, column_step=column_step, lines=sl,
                                                tdi_mean=tdi_mean)
                out = correct_band_block_nodes(read, rl, rc, cols, pixels=det.pixels, n_lines=n_lines)
                if valid is not None:
                    out[~valid[sl]] = np.nan
                var[sl] = out
            if nc is None:
                data[f"image_{name}"] = (dims, var, {"units": "DN", "long_name": long_name})
    finally:
        if nc is not None:
            nc.close()
    if path is not None:
        return xr.open_dataset(path, engine="netcdf4", cache=False)  # read band by band, never all held
    return xr.Dataset(data, coords={"time": ("line", product.time, {"units": "s"})}, attrs=attrs)


def per_line_shift_rms(lines, res_l, res_c, n_lines: int, *, cols=None, weights_l=None, weights_c=None,
                       min_points: int = 5) -> dict:
    """Misregistration series of a pair: RMS over lines of the per-line mean shift, px.

    Parameters
    ----------
    lines : array_like of int
        Line of each matched point.
    res_l, res_c : array_like of float
        Measured minus expected position of each point (lines, columns), px.
    n_lines : int
        Lines of the image.
    cols : array_like of float, optional
        Column of each point: the points of a line are split into two
        interleaved halves (every other point by column) for the noise-free
        estimate below. Without it, the halves follow the input order.
    weights_l, weights_c : array_like of float, optional
        Inverse variances of the points (e.g. ``1 / std**2`` from the
        matcher): per-line means are weighted. Default equal weights.
    min_points : int, keyword-only
        Lines with fewer points are left out.

    Returns
    -------
    dict
        Per axis ``line`` / ``col`` and for the 2-D shift ``total``:

        ``<axis>_px``
            RMS over lines of the (weighted) per-line mean, its mean over the
            lines removed: the misregistration as measured, with the matching
            noise of a per-line mean in it;
        ``<axis>_noise_px``
            that noise, from the scatter of the points within their line;
        ``<axis>_signal_px``
            the misregistration without matching noise: ``sqrt(mean(m1 m2))``
            where ``m1``, ``m2`` are the per-line means of two interleaved
            halves of each line's points, whose noises are independent (the
            product's expectation is the variance of the common signal); 0
            when the estimate is negative (signal below the noise).

        Also ``net_px`` (``sqrt(total² − noise²)``, kept for comparison),
        ``noise_px`` (2-D) and ``lines``.
    """
    lines = np.asarray(lines, dtype=np.int64)
    res_l = np.asarray(res_l, dtype=np.float64)
    res_c = np.asarray(res_c, dtype=np.float64)
    wts = []
    for w in (weights_l, weights_c):
        w = np.ones(lines.size) if w is None else np.asarray(w, dtype=np.float64)
        if w.shape != lines.shape:
            raise ValueError(f"weights: expected shape {lines.shape}, got {w.shape}")
        wts.append(w)
    ok = np.isfinite(res_l) & np.isfinite(res_c) & np.isfinite(wts[0]) & np.isfinite(wts[1]) & \
        (wts[0] > 0) & (wts[1] > 0) & (lines >= 0) & (lines < n_lines)
    nan = float("nan")
    empty = {f"{a}_{k}": nan for a in ("line", "col", "total") for k in ("px", "noise_px", "signal_px")}
    empty.update(net_px=nan, noise_px=nan, lines=0)
    if not ok.any():
        return empty
    lines, res_l, res_c = lines[ok], res_l[ok], res_c[ok]
    w_l, w_c = wts[0][ok], wts[1][ok]
    cols = np.arange(lines.size, dtype=np.float64) if cols is None else np.asarray(cols, dtype=np.float64)[ok]
    # two interleaved halves of each line's points (rank by column, odd / even)
    half = rank_within_line(lines, cols)[0] % 2
    # mismatches are not misregistration: reject points beyond 3 robust σ of the
    # residuals around the median of their line (the rule of the instant
    # synthesis), taken per half so that the halves' noises stay independent
    key = 2 * lines + half
    keep = np.ones(lines.size, dtype=bool)
    for r in (res_l, res_c):
        med = line_median(key, r, keep, 2 * n_lines)
        dev = r - med[key]
        s = 1.4826 * np.nanmedian(np.abs(dev[keep]))
        keep &= np.abs(dev) <= 3 * max(s, 1e-3)
    lines, res_l, res_c, w_l, w_c, half = (x[keep] for x in (lines, res_l, res_c, w_l, w_c, half))
    n = np.bincount(lines, minlength=n_lines)
    n_h = [np.bincount(lines[half == k], minlength=n_lines) for k in (0, 1)]
    m = (n >= min_points) & (n_h[0] >= 2) & (n_h[1] >= 2)
    if not m.any():
        return empty
    out = {"lines": int(m.sum())}
    var_sum = sig_sum = tot_sum = 0.0
    for name, r, w in (("line", res_l, w_l), ("col", res_c, w_c)):
        sw = np.bincount(lines, w, minlength=n_lines)
        mean = np.bincount(lines, w * r, minlength=n_lines) / np.where(sw > 0, sw, 1.0)
        # variance of a weighted mean from the scatter within the line
        dev = r - mean[lines]
        var = np.bincount(lines, w * w * dev * dev, minlength=n_lines) / np.where(sw > 0, sw, 1.0) ** 2 * \
            n / np.maximum(n - 1, 1)
        ml = mean[m] - mean[m].mean()
        halves = []
        for k in (0, 1):
            s = half == k
            swk = np.bincount(lines[s], w[s], minlength=n_lines)
            mk = np.bincount(lines[s], w[s] * r[s], minlength=n_lines)[m] / swk[m]
            halves.append(mk - mk.mean())
        cov = float(np.mean(halves[0] * halves[1]))
        tot2 = float(np.mean(ml ** 2))
        out[f"{name}_px"] = float(np.sqrt(tot2))
        out[f"{name}_noise_px"] = float(np.sqrt(np.mean(var[m])))
        out[f"{name}_signal_px"] = float(np.sqrt(max(cov, 0.0)))
        tot_sum += tot2
        var_sum += float(np.mean(var[m]))
        sig_sum += max(cov, 0.0)
    out["total_px"] = float(np.sqrt(tot_sum))
    out["total_noise_px"] = out["noise_px"] = float(np.sqrt(var_sum))
    out["total_signal_px"] = float(np.sqrt(sig_sum))
    out["net_px"] = float(np.sqrt(max(tot_sum - var_sum, 0.0)))
    return out


def rank_within_line(lines, cols):
    """Rank of each point among the points of its line, by column; and its line's point count."""
    lines = np.asarray(lines)
    order = np.lexsort((np.asarray(cols), lines))
    srt = lines[order]
    starts = np.r_[0, np.flatnonzero(srt[1:] != srt[:-1]) + 1]
    counts = np.diff(np.r_[starts, srt.size])
    rank = np.empty(lines.size, dtype=np.int64)
    count = np.empty(lines.size, dtype=np.int64)
    rank[order] = np.arange(srt.size) - np.repeat(starts, counts)
    count[order] = np.repeat(counts, counts)
    return rank, count


def line_median(lines, values, ok, n_lines):
    """Median of ``values`` per line (NaN where a line has no value)."""
    med = np.full(n_lines, np.nan)
    li = lines[ok]
    v = values[ok]
    if li.size == 0:
        return med
    order = np.lexsort((v, li))
    li, v = li[order], v[order]
    starts = np.flatnonzero(np.r_[True, li[1:] != li[:-1]])
    ends = np.r_[starts[1:], li.size]
    mid_lo = v[(starts + ends - 1) // 2]
    mid_hi = v[(starts + ends) // 2]
    med[li[starts]] = 0.5 * (mid_lo + mid_hi)
    return med


def _inverse_variance(std, floor: float = 0.02):
    """Weights ``1 / (std² + floor²)`` of matched points (NaN std → NaN weight: point left out)."""
    std = np.asarray(std, dtype=np.float64) if std is not None else None
    return None if std is None else 1.0 / (std ** 2 + floor ** 2)


_MISREG_BLOCK = 1024  #: lines of corrected band read at a time by the misregistration measurement


def misregistration(product, corrected, pairs, settings) -> dict:
    """Band-to-band misregistration of each pair before and after correction.

    Both are measured with the same points and the same matcher: raw bands
    against knowledge predictions (before), corrected bands against the same
    predictions (after). Each figure is the RMS over lines of the per-line
    mean shift, weighted by the matcher's inverse variances (the
    jitter-induced misregistration; per-point matching noise is averaged
    within each line). After correction the misregistration is comparable to
    the matching noise of a per-line mean of cross-band 3-line windows, so
    :func:`per_line_shift_rms` also gives that noise and the noise-free
    (split-half) estimate: ``after_signal_px`` is the figure to compare with
    a requirement, ``after_px`` includes the measurement noise.
    """
    sm = product.sensor_model()
    out = {}
    n_lines = product.time.size
    for p in pairs:
        v = p.valid & np.isfinite(p.meas_line_b)
        la, ca = p.line_a[v], p.col_a[v]
        if la.size == 0:
            continue
        g = sm.direct_location(p.ahead, la, ca)
        pl, pc = sm.inverse_location(p.behind, g)
        before = per_line_shift_rms(np.rint(la), p.meas_line_b[v] - pl, p.meas_col_b[v] - pc, n_lines, cols=ca,
                                    weights_l=_inverse_variance(None if p.std_line is None else p.std_line[v]),
                                    weights_c=_inverse_variance(None if p.std_col is None else p.std_col[v]))
        # the corrected bands are read block by block (from corrected.nc when it is a file): memory
        # bounded by a block of lines, whatever the image length
        var_a, var_b = corrected[f"image_{p.ahead}"], corrected[f"image_{p.behind}"]
        n_a, n_b = int(var_a.shape[0]), int(var_b.shape[0])
        li = np.clip(np.rint(la).astype(int), 0, n_a - 1)
        ci = np.clip(np.rint(ca).astype(int), 0, int(var_a.shape[1]) - 1)
        ok = np.zeros(la.size, dtype=bool)
        for a0 in range(0, n_a, _MISREG_BLOCK):
            sel = (li >= a0) & (li < a0 + _MISREG_BLOCK)
            if sel.any():
                rows = np.asarray(var_a[a0:a0 + _MISREG_BLOCK].values)
                ok[sel] = np.isfinite(rows[li[sel] - a0, ci[sel]])

        def reader(var):
            return lambda s: np.nan_to_num(np.asarray(var[s].values, dtype=np.float32))

        m = match_points_in_blocks(reader(var_a), reader(var_b), (n_a, n_b), la[ok], ca[ok], pl[ok], pc[ok],
                                   block_lines=_MISREG_BLOCK, window=settings.window, search=settings.search,
                                   method=settings.match_method, min_quality=settings.min_quality)
        good = np.asarray(m.valid, bool)
        after = per_line_shift_rms(np.rint(la[ok][good]), m.line_b[good] - pl[ok][good], m.col_b[good] - pc[ok][good],
                                   n_lines, cols=ca[ok][good], weights_l=_inverse_variance(m.std_line[good]),
                                   weights_c=_inverse_variance(m.std_col[good]))
        row = {"before_px": before["total_px"], "after_px": after["total_px"],
               "after_noise_px": after["noise_px"], "after_net_px": after["net_px"],
               "after_signal_px": after["total_signal_px"], "lines": after["lines"]}
        for ax in ("line", "col"):
            row[f"before_{ax}_px"] = before[f"{ax}_px"]
            row[f"after_{ax}_px"] = after[f"{ax}_px"]
            row[f"after_{ax}_noise_px"] = after[f"{ax}_noise_px"]
            row[f"after_{ax}_signal_px"] = after[f"{ax}_signal_px"]
        out[p.name] = row
    return out


def _gradient_reader(read, total: int):
    """``read(slice) -> rows`` of a band → the same rows of its gradient magnitude (Sobel), exactly as on
    the whole band (one more line is read on each side)."""
    from scipy import ndimage

    def grad(s: slice):
        a, b = max(0, s.start - 1), min(total, s.stop + 1)
        rows = np.nan_to_num(np.asarray(read(slice(a, b)), dtype=np.float32))
        g = np.hypot(ndimage.sobel(rows, axis=0, mode="nearest"), ndimage.sobel(rows, axis=1, mode="nearest"))
        return g[s.start - a:s.start - a + (s.stop - s.start)]
    return grad


def weak_band_misregistration(product, corrected, pairs, settings, *, line_step: int = 2,
                              max_lines: int = 2 * _MISREG_BLOCK) -> dict:
    """Misregistration of the bands no pair uses (weakly correlated: near infrared) before / after correction.

    The patent (EP1843295, claims 9–11) corrects a band that correlates poorly
    with the others (the near infrared against the visible) with the line of
    sight restored from the well-correlated pairs. Each band outside every
    restoration pair is measured here against the pair band nearest to it on
    the focal plane (the shortest delay): points on a regular grid of that
    band (``settings.points_per_line`` columns every ``line_step`` lines) are
    matched on **gradient-magnitude** images (edges coincide even where the
    radiometry is inverted, vegetation bright in the near infrared and dark
    in the red), raw bands against the knowledge prediction (before), and
    corrected bands (after), as :func:`misregistration` does. A record longer
    than ``max_lines`` is measured on evenly spaced (centred) blocks of
    :data:`_MISREG_BLOCK` lines adding up to about ``max_lines`` (the blocks
    the matcher reads: the cost of a long record stays that of ``max_lines``).

    Returns
    -------
    dict
        ``{"REF/WEAK" or "WEAK/REF" (ahead/behind): row}`` with the keys of
        :func:`misregistration` plus ``weakly_correlated`` (True), ``tau_s``
        and ``valid_fraction`` (matched points / points, after).
    """
    used = {n for p in pairs for n in (p.ahead, p.behind)}
    dets = product.instrument.detectors
    weak = [d for d in dets if d.name not in used]
    ref_dets = [d for d in dets if d.name in used]
    if not weak or not ref_dets:
        return {}
    sm = product.sensor_model()
    n_lines = product.time.size
    out = {}
    for w in weak:
        r = min(ref_dets, key=lambda d: abs(d.along_m - w.along_m))
        if r.along_m == w.along_m:
            continue
        ahead, behind = (r, w) if r.along_m > w.along_m else (w, r)
        tau = float(product.delay_s(ahead.name, behind.name))
        margin = settings.window[1] // 2 + settings.search[1] + 8
        cols = np.linspace(margin, r.pixels - 1 - margin, settings.points_per_line)
        lines = np.arange(margin, n_lines - margin, line_step, dtype=np.float64)
        n_blocks = -(-n_lines // _MISREG_BLOCK)
        keep = max(1, -(-int(max_lines) // _MISREG_BLOCK))
        if keep < n_blocks:
            pick = ((np.arange(keep) + 0.5) * n_blocks / keep).astype(int)  # centred: not the record's ends
            lines = lines[np.isin(lines.astype(int) // _MISREG_BLOCK, pick)]
        L, C = np.meshgrid(lines, np.rint(cols), indexing="ij")
        la, ca = L.ravel(), C.ravel()
        pl, pc = sm.inverse_location(w.name, sm.direct_location(r.name, la, ca))
        ok = np.isfinite(pl) & np.isfinite(pc)
        la, ca, pl, pc = la[ok], ca[ok], pl[ok], pc[ok]
        opts = dict(block_lines=_MISREG_BLOCK, window=settings.window, search=settings.search,
                    method=settings.match_method, min_quality=settings.min_quality)
        rows = {}
        for when, read_r, read_w in (
                ("before", lambda s: product.image(r.name, lines=s), lambda s: product.image(w.name, lines=s)),
                ("after", lambda s: np.asarray(corrected[f"image_{r.name}"][s].values),
                 lambda s: np.asarray(corrected[f"image_{w.name}"][s].values))):
            m = match_points_in_blocks(_gradient_reader(read_r, n_lines), _gradient_reader(read_w, n_lines),
                                       (n_lines, n_lines), la, ca, pl, pc, **opts)
            good = np.asarray(m.valid, bool)
            rows[when] = per_line_shift_rms(np.rint(la[good]), m.line_b[good] - pl[good], m.col_b[good] - pc[good],
                                            n_lines, cols=ca[good], weights_l=_inverse_variance(m.std_line[good]),
                                            weights_c=_inverse_variance(m.std_col[good]))
            rows[when]["valid_fraction"] = float(good.mean()) if good.size else 0.0
        b, a = rows["before"], rows["after"]
        row = {"before_px": b["total_px"], "after_px": a["total_px"], "after_noise_px": a["noise_px"],
               "after_net_px": a["net_px"], "after_signal_px": a["total_signal_px"], "lines": a["lines"],
               "weakly_correlated": True, "reference_band": r.name, "tau_s": tau,
               "valid_fraction": a["valid_fraction"]}
        for ax in ("line", "col"):
            row[f"before_{ax}_px"] = b[f"{ax}_px"]
            row[f"after_{ax}_px"] = a[f"{ax}_px"]
            row[f"after_{ax}_noise_px"] = a[f"{ax}_noise_px"]
            row[f"after_{ax}_signal_px"] = a[f"{ax}_signal_px"]
        out[f"{ahead.name}/{behind.name}"] = row
    return out
