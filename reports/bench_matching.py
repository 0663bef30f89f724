"""Benchmark of the sub-pixel matcher against scikit-image and OpenCV.

Windows with known sub-pixel shifts are generated analytically: each pair of
patches samples a band-limited random texture (a sum of sinusoids below the
Nyquist frequency, with a ``1/f`` amplitude spectrum and a Gaussian MTF) at
exactly shifted coordinates, so the reference shift carries no interpolation
error. Two cases:

``same``
    Band B is band A shifted, each with its own white noise (and its own
    level: 10 and 7 texture standard deviations).
``cross``
    Bands A and B are different linear mixes of three independent texture
    components (spectral bands correlated but not identical: correlation
    0.85, gain 1.3), shifted, with noise.

Every method sees the same windows. Ours (``ncc`` and ``phase`` of
:func:`restore.matching.match_points`, one call for all points: ``ours-ncc``
is the compiled kernel on every thread Numba has, ``ours-ncc-1thread`` the
same on one thread, ``ours-ncc-numpy`` the batched NumPy reference) read band B around
the prediction (search area and interpolation support), as in the processing
line; ``skimage.registration.phase_cross_correlation(upsample_factor=100)``
and ``cv2.phaseCorrelate`` get, one call per point, the A window and the B
window of the same size at the predicted position (they have no search area).
Times include the window extraction, for all methods; images are float32, as
in products. Each method is timed ``repeat`` times, interleaved with the
others, and the best run is kept (the machine may be shared).

Run ``python -m reports.bench_matching`` to print the table.
"""
from __future__ import annotations

import time

import numpy as np

from reports.synthetic import CASES, synthetic_pairs
from restore.matching import match_points

__all__ = ["bench_matching", "format_table", "METHODS"]

METHODS = ("ours-ncc", "ours-ncc-1thread", "ours-ncc-numpy", "ours-phase", "skimage", "opencv")
#: how each of our methods calls :func:`restore.matching.match_points`: (method, backend, threads)
_OURS = {"ours-ncc": ("ncc", "compiled", None), "ours-ncc-1thread": ("ncc", "compiled", 1),
         "ours-ncc-numpy": ("ncc", "numpy", None), "ours-phase": ("phase", "numpy", None)}


def _run(method, data, window, search, repeat):
    """Estimated shifts (n, 2), valid mask and the best time over ``repeat`` runs (s).

    Every method gets the images and the point coordinates; the per-point
    baselines extract their windows (A at the point, B at the prediction)
    inside the timed loop, as the batched matcher does inside its call.
    """
    if method in _OURS:
        run = _run_ours
    elif method in _BASELINES:
        run = _BASELINES[method]
    else:
        raise ValueError(f"methods: unknown method {method!r}, expected a subset of {METHODS}")
    best, est, valid = np.inf, None, None
    for _ in range(repeat):
        t, est, valid = run(method, data, window, search)
        best = min(best, t)
    return est, valid, best


def _run_ours(method, data, window, search):
    """:func:`restore.matching.match_points` as :data:`_OURS` says: (seconds, shifts, valid)."""
    la, ca = data["lines"], data["cols"]
    meth, backend, threads = _OURS[method]
    with _numba_threads(threads):
        t0 = time.perf_counter()
        res = match_points(data["image_a"], data["image_b"], la, ca, la, ca, window=window, search=search,
                           method=meth, backend=backend)
        t = time.perf_counter() - t0
    return t, np.stack([res.line_b - la, res.col_b - ca], axis=1), res.valid


def _windows(data, window):
    """Per point: the window of A at the point and of B at the same place (the prediction)."""
    h2, w2 = window[0] // 2, window[1] // 2
    li, ci = np.rint(data["lines"]).astype(int), np.rint(data["cols"]).astype(int)
    for l, c in zip(li, ci):
        yield (data["image_a"][l - h2:l + h2 + 1, c - w2:c + w2 + 1],
               data["image_b"][l - h2:l + h2 + 1, c - w2:c + w2 + 1])


def _run_skimage(method, data, window, search):
    """``skimage.registration.phase_cross_correlation`` per point (upsampled ×100)."""
    from skimage.registration import phase_cross_correlation  # optional baseline

    est = np.empty((data["lines"].size, 2))
    t0 = time.perf_counter()
    for i, (wa, wb) in enumerate(_windows(data, window)):
        est[i] = -phase_cross_correlation(wa, wb, upsample_factor=100)[0]  # the shift that registers B onto A
    return time.perf_counter() - t0, est, np.ones(est.shape[0], dtype=bool)


def _run_opencv(method, data, window, search):
    """``cv2.phaseCorrelate`` per point."""
    import cv2  # optional baseline

    est = np.empty((data["lines"].size, 2))
    t0 = time.perf_counter()
    for i, (wa, wb) in enumerate(_windows(data, window)):
        (x, y), _ = cv2.phaseCorrelate(wa, wb)
        est[i] = (y, x)
    return time.perf_counter() - t0, est, np.ones(est.shape[0], dtype=bool)


#: the other libraries' matchers the bench compares ours with: name → runner
_BASELINES = {"skimage": _run_skimage, "opencv": _run_opencv}


class _numba_threads:
    """Context manager: run the compiled kernel on ``n`` threads (``None``: all)."""

    def __init__(self, n):
        self.n = n

    def __enter__(self):
        if self.n is not None:
            import numba

            self.prev = numba.get_num_threads()
            numba.set_num_threads(self.n)

    def __exit__(self, *exc):
        if self.n is not None:
            import numba

            numba.set_num_threads(self.prev)


def compile_seconds(window=(3, 31), search=(2, 2)) -> float:
    """Time of the first call of the compiled matcher in this process (s): JIT or cache load."""
    data = synthetic_pairs(seed=0, n=4, window=window, search=search)
    t0 = time.perf_counter()
    match_points(data["image_a"], data["image_b"], data["lines"], data["cols"], data["lines"], data["cols"],
                 window=window, search=search, backend="compiled")
    return time.perf_counter() - t0


def _stats(err, valid, shift, n_bins=10):
    e = err[valid]
    frac = (shift[valid] + 0.5) % 1.0
    bins = np.minimum((frac * n_bins).astype(int), n_bins - 1)
    means = [np.mean(e[bins == b]) for b in range(n_bins) if np.any(bins == b)]
    return {
        "bias": float(np.mean(e)), "std": float(np.std(e)),
        "rmse": float(np.sqrt(np.mean(e**2))),
        # pixel-locking: worst mean error over fractional-shift bins
        "locking": float(np.max(np.abs(means))) if means else float("nan"),
    }


def bench_matching(*, seed=0, n=2000, window=(3, 31), search=(2, 2), max_shift=1.5, noise=0.02,
                   methods=METHODS, cases=CASES, skimage_n=300, repeat=3):
    """Accuracy and speed of the matchers on analytic shifted windows.

    Parameters
    ----------
    seed : int, keyword-only
        Seed of the synthetic data.
    n : int, keyword-only
        Pairs per case.
    window : (int, int), keyword-only
        Matching window (lines, columns), odd.
    search : (int, int), keyword-only
        Search half-range of our matcher (px).
    max_shift : float, keyword-only
        True shifts uniform in ``[-max_shift, max_shift]`` px per axis.
    noise : float, keyword-only
        Noise standard deviation relative to the texture's.
    methods : sequence of str, keyword-only
        Subset of :data:`METHODS`.
    cases : sequence of str, keyword-only
        Subset of ``("same", "cross")``.
    skimage_n : int, keyword-only
        scikit-image is slow (~ms per call): at most this many pairs are given
        to it (the first ones, same windows as the others).
    repeat : int, keyword-only
        Each method is timed this many times, interleaved with the others;
        the best time is kept (the machine may be shared).

    Returns
    -------
    dict
        ``{"config": {...}, "results": {case: {method: {...}}}}``; each method
        entry holds ``n`` (pairs), ``valid`` (fraction), ``us_per_match``
        (µs), and per axis (``line``, ``col``) ``bias``, ``std``, ``rmse``
        and ``locking`` (px; worst mean error over 10 bins of the fractional
        shift, i.e. the pixel-locking amplitude). Errors are over valid
        matches only.
    """
    for m in methods:
        if m not in METHODS:
            raise ValueError(f"methods: unknown method {m!r}, expected a subset of {METHODS}")
    for c in cases:
        if c not in CASES:
            raise ValueError(f"cases: unknown case {c!r}, expected a subset of {CASES}")
    if int(repeat) != repeat or repeat < 1:
        raise ValueError(f"repeat: must be an integer >= 1, got {repeat}")
    if int(skimage_n) != skimage_n or skimage_n < 1:
        raise ValueError(f"skimage_n: must be an integer >= 1, got {skimage_n}")
    window, search = tuple(window), tuple(search)
    import numba

    out = {"config": {"seed": seed, "n": n, "window": window, "search": search,
                      "max_shift": max_shift, "noise": noise, "repeat": repeat,
                      "threads": numba.get_num_threads(),
                      # first call of the compiled kernel: JIT compilation, or loading it from numba's cache
                      "compile_s": compile_seconds(window, search)}, "results": {}}
    for case in cases:
        data = synthetic_pairs(seed=seed, n=n, window=window, search=search, max_shift=max_shift,
                               case=case, noise=noise)
        truth = np.stack([data["shift_lines"], data["shift_cols"]], axis=1)
        runs = {}
        for _ in range(repeat):  # interleaved, so that all methods see the same load
            for m in methods:
                sub = data
                if m == "skimage" and n > skimage_n:
                    sub = dict(data, lines=data["lines"][:skimage_n], cols=data["cols"][:skimage_n])
                est, valid, dt = _run(m, sub, window, search, 1)
                best = runs[m][2] if m in runs else np.inf
                runs[m] = (est, valid, min(dt, best))
        res = {}
        for m, (est, valid, dt) in runs.items():
            k = est.shape[0]
            err = est - truth[:k]
            res[m] = {"n": k, "valid": float(np.mean(valid)), "us_per_match": 1e6 * dt / k,
                      "line": _stats(err[:, 0], valid, truth[:k, 0]),
                      "col": _stats(err[:, 1], valid, truth[:k, 1])}
        out["results"][case] = res
    return out


def format_table(result) -> str:
    """Plain-text table of a :func:`bench_matching` result."""
    cfg = result["config"]
    head = (f"window {cfg['window'][0]}x{cfg['window'][1]}, shifts U(±{cfg['max_shift']}) px, "
            f"noise {cfg['noise']} of texture std, n={cfg['n']}, seed={cfg['seed']}; "
            f"compiled kernel on {cfg.get('threads', '?')} threads (first call {cfg.get('compile_s', float('nan')):.1f} s)")
    cols = ("case", "method", "valid", "µs/match", "bias_l", "std_l", "lock_l", "bias_c", "std_c", "lock_c")
    rows = [head, "  ".join(f"{c:>16}" if c == "method" else f"{c:>10}" for c in cols)]
    for case, res in result["results"].items():
        for m, r in res.items():
            vals = [case, m, f"{r['valid']:.3f}", f"{r['us_per_match']:.1f}",
                    f"{r['line']['bias']:+.4f}", f"{r['line']['std']:.4f}", f"{r['line']['locking']:.4f}",
                    f"{r['col']['bias']:+.4f}", f"{r['col']['std']:.4f}", f"{r['col']['locking']:.4f}"]
            rows.append("  ".join(f"{v:>16}" if i == 1 else f"{v:>10}" for i, v in enumerate(vals)))
    return "\n".join(rows)


if __name__ == "__main__":  # pragma: no cover
    print(format_table(bench_matching()))
