"""Restoration from a matrix detector's overlapping frames (EP1843295 fig. 1).

Frames k and k + 1, taken a frame period T apart, overlap. A grid of points of
frame k is located on the ground with the AOCS knowledge at t_k and predicted
in frame k + 1 with the knowledge at t_{k+1} (:mod:`simsat.frames`: a frame
has one time, so its inverse location is exact); the matcher measures where
they really are. With δθ_k the attitude the knowledge misses at t_k, a point's
measured minus predicted position is, to first order,

    ``r = J₁ δθ_{k+1} − J₀ δθ_k``

(``J₁``, ``J₀``: the sensitivities of its image position in frames k + 1 and k
to the attitude at those frames). Every pair of successive frames adds such
equations for two of the K unknown attitudes: one sparse least-squares
problem over the record, solved with a zero-mean gauge per axis (the constant
is unobservable from images), outliers rejected at ``n_sigma``. Unlike the
push-broom restoration, no high-pass by default: the attitude sampled at the
frame rate aliases jitter far above it (CMG lines at 50–150 Hz seen every 25
ms) onto every frequency, low ones included, and the frame differences measure
it there as well as anywhere (the random walk of their noise is what is left:
measured 0.007 px per difference); a numeric ``restoration.highpass_hz`` is
applied if set. Inside a frame every row is exposed at once: there is no
line-by-line distortion to undo (the patent: "this problem does not exist
with matrices").
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from simsat.frames import frame_direct_location, frame_inverse_location, frame_sensitivities
from simsat.units import AXES

from .errors import RestorationError
from .matching import match_points

__all__ = ["FrameRestoration", "restore_frames", "frame_pair_matches", "solve_frame_attitudes",
           "frames_restoration_dataset", "frames_restoration_from_dataset"]

#: point grid of a frame pair: one point every this many rows / columns, this far from the edges
_STEP = (8, 16)
_EDGE = 20
_WINDOW = (31, 31)
_SEARCH = (4, 4)


@dataclass
class FrameRestoration:
    """The attitude restored at the frame times, and what it came from."""

    time: np.ndarray
    restored: dict
    knowledge: dict
    correction: dict
    axes: tuple
    n_valid: np.ndarray          #: valid matches per frame pair
    n_points: np.ndarray         #: candidate points per frame pair
    residual_px: np.ndarray      #: RMS of the fit residual per frame pair [px]
    #: predicted 1-σ per restored axis and frame [rad]: the least squares' covariance with independent matching
    #: errors; the 31 × 31 windows of neighbouring points overlap, so it is optimistic (matrix_frames: actual /
    #: predicted 1.9 in roll, 1.5 in pitch)
    sigma: dict
    highpass_hz: float
    pixel_ifov_rad: float
    timings: dict = field(default_factory=dict)
    path: Path | None = None
    misregistration: dict = field(default_factory=dict)   #: no band pair to register: empty
    pairs: list = field(default_factory=list)
    settings: object = None

    @property
    def coverage(self) -> dict:
        """Fraction of frames restored per axis (every frame: the least squares ties them all)."""
        return {a: float(np.isfinite(self.restored[a]).mean()) for a in self.axes}

    def summary(self) -> str:
        ok = self.n_points > 0
        frac = float(self.n_valid[ok].sum() / max(self.n_points[ok].sum(), 1))
        corr = ", ".join(f"{a} {np.nanstd(self.correction[a]) / self.pixel_ifov_rad:.3f} px rms" for a in self.axes)
        cov = ", ".join(f"{a} {100 * v:.1f} %" for a, v in self.coverage.items())
        segs = frame_segments(pair_ties(self.n_valid, self.residual_px), self.time.size)
        broken = (f"; {len(segs)} runs of frames tied together (between them too few matches: each run keeps the "
                  f"knowledge's mean)" if len(segs) > 1 else "")
        return "\n".join([
            f"restoration from {self.time.size} frames ({self.time.size - 1} overlapping pairs, frame period "
            f"{1e3 * float(np.median(np.diff(self.time))):.2f} ms){broken}",
            f"  matches: {int(self.n_valid.sum())} / {int(self.n_points.sum())} valid ({100 * frac:.1f} %), fit "
            f"residual {float(np.sqrt(np.nanmean(self.residual_px ** 2))):.3f} px RMS",
            "  predicted error (1σ RMS, matching errors taken as independent: optimistic where windows overlap): "
            + ", ".join(
                f"{a} {float(np.sqrt(np.nanmean(self.sigma[a] ** 2))) / self.pixel_ifov_rad:.3f} px" for a in self.axes),
            f"  coverage (frames tied to a neighbour): {cov}",
            f"  correction applied: {corr}" + (f"; below {self.highpass_hz:g} Hz the knowledge is kept"
                                              if self.highpass_hz > 0 else ""),
            f"  time: {self.timings.get('total_s', float('nan')):.1f} s"])


def _grid(det, advance_rows: float):
    """Points of frame k whose homologues fall inside frame k + 1."""
    last = det.rows - 1 - int(np.ceil(max(advance_rows, 0.0))) - _EDGE
    rows = np.arange(_EDGE, max(last, _EDGE) + 1, _STEP[0], dtype=np.float64)
    cols = np.arange(_EDGE + 8, det.pixels - _EDGE - 8, _STEP[1], dtype=np.float64)
    rr, cc = np.meshgrid(rows, cols, indexing="ij")
    return rr.ravel(), cc.ravel()


def frame_pair_matches(product, k: int, frames_k: np.ndarray, frames_k1: np.ndarray, *, sm=None,
                       min_quality: float = 0.6):
    """Matches of frame k's point grid in frame k + 1 → (residual (N, 2), J₁ (N, 2, 3), J₀ (N, 2, 3), valid (N,)).

    ``residual`` is measured minus knowledge-predicted (row, column) in frame k + 1 [px].
    """
    det = product.instrument.detectors[0]
    sm = sm or product.sensor_model()
    t = product.time
    adv = float(product.ds.attrs["frame_period_s"]) * product.platform.ground_speed_m_s / (
        product.platform.altitude_m * det.pitch_m / product.instrument.focal_length_m)
    rows, cols = _grid(det, adv)
    g = frame_direct_location(sm, det, t[k], rows, cols)
    pr, pc = frame_inverse_location(sm, det, t[k + 1], g)
    m = match_points(frames_k, frames_k1, rows, cols, pr, pc, window=_WINDOW, search=_SEARCH,
                     min_quality=min_quality)
    inside = np.isfinite(pr) & (pr > _EDGE) & (pr < det.rows - 1 - _EDGE)
    valid = m.valid & inside & np.isfinite(g[:, 0])
    res = np.stack([m.line_b - pr, m.col_b - pc], axis=1)
    j1 = frame_sensitivities(sm, det, t[k + 1], g)
    j0 = frame_sensitivities(sm, det, t[k], g)
    return res, j1, j0, valid


#: fewest kept matches that tie two successive frames, and the largest standard error of their mean shift [px]:
#: a pair bridging clouds with a handful of poor matches on their edges does not tie its frames
MIN_POINTS_PER_PAIR = 8
MAX_PAIR_SHIFT_STD_PX = 0.03


def pair_ties(kept_per_pair, residual_px=None) -> np.ndarray:
    """Whether each pair's kept matches tie its two frames: at least :data:`MIN_POINTS_PER_PAIR` of them and,
    when the pairs' fit residuals [px] are known, a standard error ``residual / √kept`` within
    :data:`MAX_PAIR_SHIFT_STD_PX`."""
    kept = np.asarray(kept_per_pair, dtype=float)
    tied = kept >= MIN_POINTS_PER_PAIR
    if residual_px is not None:
        r = np.asarray(residual_px, dtype=float)
        with np.errstate(invalid="ignore", divide="ignore"):
            tied &= ~(r / np.sqrt(np.maximum(kept, 1)) > MAX_PAIR_SHIFT_STD_PX)  # NaN residual: no evidence against
    return tied


def frame_segments(ties, n_frames: int) -> list:
    """Runs of frames tied by successive pairs (``ties[k]``: frames k and k + 1 tied) → list of index arrays."""
    out, start = [], 0
    for k, tied in enumerate(ties):
        if not tied:
            out.append(np.arange(start, k + 1))
            start = k + 1
    out.append(np.arange(start, n_frames))
    return out


def solve_frame_attitudes(pairs: list, n_frames: int, axes_idx: list, *, n_sigma: float = 3.0):
    """Least-squares attitudes δθ (n_frames, len(axes_idx)) [rad] from the pairs' equations, zero mean per axis
    over each run of frames the matches tie together (:func:`frame_segments`; a frame with no valid match
    to either neighbour keeps the knowledge).

    ``pairs[k] = (residual, J1, J0, valid)`` of frames (k, k + 1). Returns the
    solution, the per-pair residual RMS [px], the per-pair count of the
    points kept and the predicted 1-σ of the solution [rad] (the normal
    matrix's inverse scaled by the residual variance: independent matching
    errors assumed).
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.linalg import lsqr

    na = len(axes_idx)
    keep = [p[3].copy() for p in pairs]
    x = np.zeros((n_frames, na))
    res_rms = None
    for _ in range(4):  # solve, reject outliers at n_sigma of the robust residual, re-judge the ties, solve again
        rows_i, cols_i, vals, rhs = [], [], [], []
        eq = 0
        ties = pair_ties([int(k.sum()) for k in keep], res_rms)
        segments = frame_segments(ties, n_frames)
        for k, (res, j1, j0, _) in enumerate(pairs):
            ok = keep[k]
            n = int(ok.sum())
            if not ties[k]:  # too few to tie frames k and k + 1: a break between segments
                continue
            for c in range(2):
                e = eq + np.arange(n)
                for a, ai in enumerate(axes_idx):
                    rows_i += [e, e]
                    cols_i += [np.full(n, (k + 1) * na + a), np.full(n, k * na + a)]
                    vals += [j1[ok, c, ai], -j0[ok, c, ai]]
                rhs.append(res[ok, c])
                eq += n
        if eq == 0:
            raise RestorationError("no valid match between successive frames: nothing to restore")
        n_measured = eq
        # gauge: zero mean per axis over each segment of tied frames (weighted like many equations): the offset
        # between segments is unobservable from images, each keeps the knowledge's mean
        scale = float(np.sqrt(np.mean(np.concatenate(vals) ** 2))) * 10.0
        for seg in segments:
            for a in range(na):
                rows_i.append(np.full(seg.size, eq))
                cols_i.append(seg * na + a)
                vals.append(np.full(seg.size, scale / seg.size))
                rhs.append(np.zeros(1))
                eq += 1
        A = coo_matrix((np.concatenate(vals), (np.concatenate(rows_i), np.concatenate(cols_i))),
                       shape=(eq, n_frames * na)).tocsr()
        b = np.concatenate(rhs)
        x = lsqr(A, b, atol=1e-12, btol=1e-12, iter_lim=20000)[0].reshape(n_frames, na)
        changed = False
        res_rms = np.full(len(pairs), np.nan)
        for k, (res, j1, j0, valid) in enumerate(pairs):
            if not valid.any():
                continue
            pred = np.einsum("nca,a->nc", j1[:, :, axes_idx], x[k + 1]) - np.einsum("nca,a->nc", j0[:, :, axes_idx], x[k])
            d = res - pred
            if not ties[k]:  # frames in different runs: their offset is arbitrary, judge the scatter about it
                d = d - np.median(d[valid], axis=0)
            r = np.linalg.norm(d, axis=1)
            med = np.median(r[valid])
            sig = 1.4826 * np.median(np.abs(r[valid] - med)) + 1e-6
            new = valid & (r <= med + n_sigma * sig)
            changed |= bool((new != keep[k]).any())
            keep[k] = new
            res_rms[k] = float(np.sqrt(np.mean(d[new] ** 2))) if new.any() else np.nan
        changed |= bool((pair_ties([int(k.sum()) for k in keep], res_rms) != ties).any())
        if not changed:
            break
    # predicted 1-σ of each frame's attitude: (AᵀA)⁻¹ scaled by the residual variance of the kept equations
    used = [int(k.sum()) if tied else 0 for k, tied in zip(keep, ties)]
    n_eq = 2 * sum(used)
    r2 = np.nansum([(rr ** 2) * 2 * n for rr, n in zip(res_rms, used) if n])
    s2 = r2 / max(n_eq - n_frames * na, 1)
    a_meas = A[:n_measured]  # the measurements only: their pseudo-inverse is the covariance in the zero-mean gauge
    normal = (a_meas.T @ a_meas).toarray()
    sigma = np.sqrt(np.clip(np.diag(np.linalg.pinv(normal, rcond=1e-12, hermitian=True)), 0, None) * s2
                    ).reshape(n_frames, na)
    return x, res_rms, np.array([int(k.sum()) for k in keep]), sigma


def _highpass(x: np.ndarray, fs: float, cutoff: float) -> np.ndarray:
    """Remove the components below ``cutoff`` (zero-phase Butterworth, order 2); unchanged if it cannot apply."""
    from scipy.signal import butter, sosfiltfilt

    if cutoff <= 0 or cutoff >= 0.45 * fs or x.shape[0] < 16:
        return x
    sos = butter(2, cutoff, btype="highpass", fs=fs, output="sos")
    return sosfiltfilt(sos, x, axis=0, padtype="odd", padlen=min(x.shape[0] - 1, int(3 * fs / cutoff)))


def restore_frames(product, settings, *, progress: bool = False) -> FrameRestoration:
    """Restore the attitude at every frame time of a matrix product (module docstring)."""
    import time as _time

    from .stages import highpass_from_product

    t_all = _time.perf_counter()
    det = product.instrument.detectors[0]
    n = product.time.size
    if n < 3:
        raise RestorationError(f"{product.path}: {n} frames; the restoration needs at least 3")
    sm = product.sensor_model()
    bar = None
    if progress:
        import sys

        from tqdm import tqdm
        bar = tqdm(total=n - 1, unit="pair", desc="restore (frames)", file=sys.stderr, dynamic_ncols=True)
    pairs = []
    prev = product.image(det.name, lines=slice(0, 1))[0]
    try:
        for k in range(n - 1):
            cur = product.image(det.name, lines=slice(k + 1, k + 2))[0]
            pairs.append(frame_pair_matches(product, k, prev, cur, sm=sm, min_quality=settings.min_quality))
            prev = cur
            if bar is not None:
                bar.update(1)
    finally:
        if bar is not None:
            bar.close()
    axes = tuple(settings.axes)
    axes_idx = [AXES.index(a) for a in axes]
    x, res_rms, kept, sig = solve_frame_attitudes(pairs, n, axes_idx, n_sigma=settings.n_sigma)
    hp = 0.0 if settings.highpass_hz == "auto" else float(highpass_from_product(settings.highpass_hz, product))
    fs = 1.0 / float(np.median(np.diff(product.time)))
    x = _highpass(x, fs, hp)
    x = x - x.mean(axis=0)
    knowledge = dict(zip(AXES, product.knowledge.at(product.time)))
    # a frame tied to neither neighbour (clouds, water, no texture) is not restored: NaN, not the knowledge
    alone = np.zeros(n, bool)
    for seg in frame_segments(pair_ties(kept, res_rms), n):
        alone[seg] = seg.size < 2
    correction = {a: np.zeros(n) for a in AXES}
    sigma = {}
    for i, a in enumerate(axes):
        correction[a] = np.where(alone, np.nan, x[:, i])
        sigma[a] = np.where(alone, np.nan, sig[:, i])
    restored = {a: knowledge[a] + correction[a] for a in AXES}
    n_points = np.array([p[3].size for p in pairs])
    return FrameRestoration(time=product.time, restored=restored, knowledge=knowledge, correction=correction,
                            axes=axes, n_valid=kept, n_points=n_points, residual_px=res_rms, sigma=sigma,
                            highpass_hz=hp,
                            pixel_ifov_rad=product.pixel_ifov_rad, settings=settings,
                            timings={"total_s": _time.perf_counter() - t_all,
                                     "lines_per_s": n / max(_time.perf_counter() - t_all, 1e-9)})


def frames_restoration_dataset(res: FrameRestoration):
    """``restoration.nc`` of a frames product (one time per frame)."""
    import xarray as xr

    data = {}
    for a in AXES:
        data[a] = ("time", res.restored[a], {"units": "rad", "long_name": f"restored {a} at the frame times"})
        data[f"knowledge_{a}"] = ("time", res.knowledge[a], {"units": "rad"})
        data[f"correction_{a}"] = ("time", res.correction[a], {"units": "rad"})
        if a in res.sigma:
            data[f"sigma_{a}"] = ("time", res.sigma[a], {"units": "rad", "long_name": f"predicted 1-sigma of {a}"})
    data["pair_valid_matches"] = ("pair", res.n_valid.astype(np.int32))
    data["pair_points"] = ("pair", res.n_points.astype(np.int32))
    data["pair_residual_px"] = ("pair", res.residual_px, {"units": "px"})
    return xr.Dataset(data, coords={"time": ("time", res.time, {"units": "s", "long_name": "frame time"})},
                      attrs={"title": "simsat restoration (frames)", "acquisition": "frames",
                             "method": "frames_lsq", "axes": ",".join(res.axes), "highpass_hz": res.highpass_hz,
                             "pixel_ifov_rad": res.pixel_ifov_rad, "total_s": res.timings.get("total_s", 0.0)})


def frames_restoration_from_dataset(ds, path=None) -> FrameRestoration:
    """A :class:`FrameRestoration` read back from its ``restoration.nc`` (:func:`frames_restoration_dataset`).

    Raises
    ------
    ProductError
        Naming the file and the variable or attribute missing.
    """
    from simsat.product import ProductError

    where = str(path) if path is not None else "restoration.nc"
    required = ["time", "pair_valid_matches", "pair_points", "pair_residual_px"] + \
        [v for a in AXES for v in (a, f"knowledge_{a}", f"correction_{a}")]
    for name in required:
        if name not in ds.variables:
            raise ProductError(f"{where}: no variable {name!r} (a truncated or foreign frames restoration); "
                               f"run `simsat restore` again")
    for name in ("axes", "pixel_ifov_rad"):
        if name not in ds.attrs:
            raise ProductError(f"{where}: no global attribute {name!r}; run `simsat restore` again")
    axes = tuple(a for a in str(ds.attrs["axes"]).split(",") if a)
    unknown = [a for a in axes if a not in AXES]
    if unknown:
        raise ProductError(f"{where}: attribute 'axes' names {', '.join(map(repr, unknown))} "
                           f"(axes: {', '.join(AXES)})")

    def values(name):
        return np.asarray(ds[name].values, dtype=np.float64)

    return FrameRestoration(
        time=values("time"), restored={a: values(a) for a in AXES}, knowledge={a: values(f"knowledge_{a}") for a in AXES},
        correction={a: values(f"correction_{a}") for a in AXES}, axes=axes,
        n_valid=np.asarray(ds["pair_valid_matches"].values, dtype=np.int64),
        n_points=np.asarray(ds["pair_points"].values, dtype=np.int64), residual_px=values("pair_residual_px"),
        sigma={a: values(f"sigma_{a}") for a in AXES if f"sigma_{a}" in ds.variables},
        highpass_hz=float(ds.attrs.get("highpass_hz", 0.0)), pixel_ifov_rad=float(ds.attrs["pixel_ifov_rad"]),
        timings={"total_s": float(ds.attrs.get("total_s", float("nan")))},
        path=Path(path) if path is not None else None)
