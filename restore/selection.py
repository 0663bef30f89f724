"""Selection of characteristic points for band-to-band matching (patent step a).

Two stages, as in the CNES processing line (§3.3.1) and the Airbus patent:

1. An a-priori radiometric criterion, :func:`texture_mask`, rejects the areas
   where a match cannot be trusted: water and flat ground (no texture), clouds
   (bright, smooth, possibly saturated), no data. It rests on the local
   high-frequency gradient energy (Delon & Rougé 2007): the standard deviation
   of a match of two windows with noise ``sigma`` is, per axis,

   ``std_axis = sqrt(2) * sigma / sqrt(sum_window(d image / d axis) ** 2)``

   (px; ``sqrt(2)``: both bands are noisy), see :func:`expected_matching_std`.
2. One of the patent's three ways of choosing points:

   - :func:`double_gradient_points`: second derivative ("doble gradiente")
     above a threshold in at least two directions;
   - :func:`grid_points`: a predetermined grid, independent of the content
     (rejection on match quality comes after matching);
   - :func:`spread_quality_subset`: a subset that maximises the spatial
     spread and the quality (best point per column bin and line).

:func:`select_points` chains them and returns ``(line, column)`` candidates in
band A, aiming at ``per_line`` points per image line (CNES: 20 per line) where
texture allows, none on masked areas and none closer to the borders than the
matcher's support (window half-size + search + interpolation margin).

Images are ``(line, column)`` float arrays; pixel centres at integers.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy import ndimage

from .matching import support_margin

__all__ = [
    "estimate_image_noise",
    "NoiseLevel",
    "noise_level_function",
    "select_points_in_blocks",
    "gradient_energy",
    "expected_matching_std",
    "texture_mask",
    "double_gradient_points",
    "grid_points",
    "spread_quality_subset",
    "select_points",
    "SelectionMethod",
    "SELECTION_METHODS",
]

#: antisymmetric 5-point gradient (the matcher's), 1/px
_GRADIENT = np.array([1.0, -8.0, 0.0, 8.0, -1.0]) / 12.0
#: Immerkaer's noise mask: difference of two Laplacians, blind to planes
_IMMERKAER = np.array([[1.0, -2.0, 1.0], [-2.0, 4.0, -2.0], [1.0, -2.0, 1.0]])


def _as_image(image, name="image") -> np.ndarray:
    img = np.asarray(image, dtype=float)
    if img.ndim != 2 or min(img.shape) < 1:
        raise ValueError(f"{name}: expected a non-empty 2-D (line, column) array, got shape {img.shape}")
    return img


def _check_window(window) -> tuple[int, int]:
    try:
        h, w = (int(v) for v in window)
        ok = (h, w) == tuple(window) and h >= 1 and w >= 1 and h % 2 == 1 and w % 2 == 1
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise ValueError(f"window: expected two odd positive integers (lines, columns), got {window!r}")
    return h, w


def _box_sum(x: np.ndarray, window: tuple[int, int]) -> np.ndarray:
    """Sum over a centred ``window`` at every pixel (edges: reflected)."""
    return ndimage.uniform_filter(x, size=window, mode="reflect") * (window[0] * window[1])


def _dilate(mask: np.ndarray, window: tuple[int, int]) -> np.ndarray:
    """True where a centred ``window`` touches a True pixel."""
    return ndimage.maximum_filter(mask.astype(np.uint8), size=window, mode="constant", cval=0) > 0


#: pixels of an image over which :func:`estimate_image_noise` takes its median (larger images: evenly
#: spaced blocks of lines adding up to about this many; the median of 4 M values has a relative
#: standard error below 0.1 %)
NOISE_ESTIMATE_MAX_PIXELS = 4_000_000


def estimate_image_noise(image, *, max_pixels: int = NOISE_ESTIMATE_MAX_PIXELS) -> float:
    """Standard deviation of the white noise of an image (robust).

    Immerkaer's mask (a difference of two Laplacians, zero on planes) has a
    gain of 6 on white noise; the median of its absolute response over the
    image gives ``sigma = median(|L|) / (0.6745 * 6)``. Texture inflates the
    estimate; pass the known noise to the other functions when you have it.

    Parameters
    ----------
    image : ndarray, shape (lines, columns)
        Image, at least 3 x 3; non-finite pixels are ignored.
    max_pixels : int, keyword-only
        An image with more pixels is sampled in evenly spaced blocks of lines
        adding up to about ``max_pixels`` (the exact median of those); smaller
        images use every interior pixel.

    Returns
    -------
    float
        Noise standard deviation (image unit).
    """
    shape = np.shape(image)
    if len(shape) != 2 or min(shape) < 3:
        raise ValueError(f"image: need at least 3 x 3 pixels, got {shape}")
    if int(max_pixels) < 1:
        raise ValueError(f"max_pixels: must be >= 1, got {max_pixels!r}")
    starts = _noise_block_starts(shape, int(max_pixels))
    blocks = lambda: _immerkaer_blocks(image, starts=starts)  # noqa: E731 - re-run per pass, memory of one block
    med = _exact_median(blocks)
    return float(med / (0.6745 * 6.0))


def _noise_block_starts(shape, max_pixels: int, block_lines: int = 512):
    """First interior line of each block of lines the noise estimate reads (None: every block)."""
    n, c = shape
    all_starts = np.arange(1, n - 1, block_lines)
    if n * c <= max_pixels:
        return None
    keep = max(1, int(np.ceil(max_pixels / (block_lines * c))))
    if keep >= all_starts.size:
        return None
    pick = np.unique(np.round(np.linspace(0, all_starts.size - 1, keep)).astype(int))
    return all_starts[pick]


def _immerkaer_blocks(image, block_lines: int = 512, *, starts=None, with_level: bool = False):
    """|Immerkaer response| on the image interior, block of lines after block (finite values only).

    ``starts``: the first interior line of each block to read (default: every block). ``with_level``: yield
    ``(response, level)`` pairs, ``level`` the 3 × 3 mean of the image at the same pixels.
    """
    n = np.shape(image)[0]
    for a in (range(1, n - 1, block_lines) if starts is None else starts):
        a = int(a)
        b = min(n - 1, a + block_lines)
        sub = np.asarray(image[a - 1:b + 1], dtype=float)
        resp = ndimage.correlate(sub, _IMMERKAER, mode="nearest")[1:-1, 1:-1]
        ok = np.isfinite(resp)
        if with_level:
            # a finite response has a finite 3 × 3 neighbourhood: its mean is the level there
            level = ndimage.uniform_filter(np.where(np.isfinite(sub), sub, 0.0), size=3, mode="nearest")[1:-1, 1:-1]
            yield np.abs(resp[ok]), level[ok]
        else:
            yield np.abs(resp[ok])


def _exact_median(blocks, bins: int = 1 << 16) -> float:
    """``np.median`` of all values yielded by ``blocks()``, in three passes of bounded memory.

    Pass 1: count and range; pass 2: histogram, locating the bins of the middle
    order statistics; pass 3: those bins' values, sorted. Equal to
    ``np.median(np.concatenate(list(blocks())))``.
    """
    n, lo, hi = 0, np.inf, -np.inf
    for v in blocks():
        if v.size:
            n += v.size
            lo, hi = min(lo, float(v.min())), max(hi, float(v.max()))
    if n == 0:
        return float("nan")
    if hi == lo:
        return lo
    ranks = sorted({(n - 1) // 2, n // 2})
    edges = np.linspace(lo, hi, bins + 1)
    counts = np.zeros(bins, dtype=np.int64)
    for v in blocks():
        counts += np.histogram(v, bins=edges)[0]
    cum = np.cumsum(counts)
    chosen = sorted({int(np.searchsorted(cum, r, side="right")) for r in ranks})
    picked = []
    for v in blocks():
        idx = np.clip(np.searchsorted(edges, v, side="right") - 1, 0, bins - 1)  # np.histogram's binning
        picked.append(v[np.isin(idx, chosen)])
    vals = np.sort(np.concatenate(picked))
    below = {k: (int(cum[k - 1]) if k > 0 else 0) for k in chosen}
    out = []
    for r in ranks:
        k = int(np.searchsorted(cum, r, side="right"))
        offset = sum(int(counts[j]) for j in chosen if j < k)
        out.append(vals[offset + (r - below[k])])
    return float(np.mean(out))


#: intensity bins of :func:`noise_level_function` (quantiles of the local mean level)
NOISE_LEVEL_BINS = 16
#: fewest pixels per bin of :func:`noise_level_function` (fewer in all: a constant noise)
NOISE_LEVEL_MIN_PIXELS = 2000


@dataclass(frozen=True)
class NoiseLevel:
    """Signal-dependent noise of a band: variance ``read_var + shot_gain × level`` (image unit²).

    A detector's noise is the read noise and the photon (shot) noise, whose
    variance grows with the signal: in image units, ``σ² = a + b·μ`` for a
    pixel of mean level ``μ`` (the Poissonian–Gaussian model of Foi et al.
    2008, the photon-transfer curve). A single σ for the whole band is right
    at its median level only: too large in the shadows (a cloud's shadow in a
    dim scene: 2.97 measured there against 3.71 for the band, which rejects
    ~all of its windows as untextured), too small on bright ground.
    """

    read_var: float
    shot_gain: float

    @classmethod
    def from_radiometry(cls, radiometry) -> "NoiseLevel":
        """The noise a detector's calibration gives (:class:`simsat.instrument.Radiometry`): read noise and
        photon noise through the gain ``g`` [DN/e⁻], plus the quantisation's 1/12 DN²."""
        g = float(radiometry.gain_dn_per_e)
        if not getattr(radiometry, "enabled", True):
            return cls(read_var=1.0 / 12.0, shot_gain=0.0)
        return cls(read_var=(float(radiometry.read_noise_e) * g) ** 2 + 1.0 / 12.0, shot_gain=g)

    def std(self, level) -> np.ndarray:
        """Noise standard deviation at the mean level(s) ``level`` (image unit; a negative level counts as 0)."""
        lv = np.maximum(np.nan_to_num(np.asarray(level, dtype=np.float64)), 0.0)
        return np.sqrt(np.maximum(self.read_var + self.shot_gain * lv, 0.0))

    def local_std(self, image, window) -> np.ndarray:
        """Noise standard deviation of every pixel, at the mean level of the ``window`` centred on it."""
        img = _as_image(image)
        window = _check_window(window)
        work = np.where(np.isfinite(img), img, 0.0)
        return self.std(_box_sum(work, window) / (window[0] * window[1]))


def noise_level_function(image, *, bins: int = NOISE_LEVEL_BINS, max_pixels: int = NOISE_ESTIMATE_MAX_PIXELS
                         ) -> NoiseLevel:
    """The band's noise as a function of its level (:class:`NoiseLevel`), estimated from the image alone.

    Immerkaer's response (zero on planes) is binned by the 3 × 3 mean level
    of its pixel into ``bins`` quantile bins; in each, the robust noise
    estimate of :func:`estimate_image_noise` (``median |L| / (0.6745 × 6)``);
    then ``σ² = a + b μ`` is fitted to the bins by non-negative least
    squares. Texture inflates every bin's estimate a little, as it does the
    global one. With too few pixels (fewer than ``NOISE_LEVEL_MIN_PIXELS``
    per bin) or no spread of levels, the constant noise of
    :func:`estimate_image_noise` (``b = 0``).
    """
    from scipy.optimize import nnls

    shape = np.shape(image)
    if len(shape) != 2 or min(shape) < 3:
        raise ValueError(f"image: need at least 3 x 3 pixels, got {shape}")
    if int(bins) < 2:
        raise ValueError(f"bins: must be >= 2, got {bins!r}")
    blocks = list(_immerkaer_blocks(image, starts=_noise_block_starts(shape, int(max_pixels)), with_level=True))
    resp, level = np.concatenate([r for r, _ in blocks]), np.concatenate([m for _, m in blocks])
    constant = estimate_image_noise(image, max_pixels=max_pixels)
    if resp.size < int(bins) * NOISE_LEVEL_MIN_PIXELS or not np.ptp(level) > 0:
        return NoiseLevel(read_var=constant ** 2, shot_gain=0.0)
    edges = np.quantile(level, np.linspace(0.0, 1.0, int(bins) + 1))
    idx = np.clip(np.searchsorted(edges, level, side="right") - 1, 0, int(bins) - 1)
    mu, var = [], []
    for k in range(int(bins)):
        sel = idx == k
        if sel.sum() >= NOISE_LEVEL_MIN_PIXELS:
            mu.append(float(np.median(level[sel])))
            var.append((float(np.median(resp[sel])) / (0.6745 * 6.0)) ** 2)
    if len(mu) < 2 or not np.ptp(mu) > 0:
        return NoiseLevel(read_var=constant ** 2, shot_gain=0.0)
    (a, b), _ = nnls(np.c_[np.ones(len(mu)), np.maximum(mu, 0.0)], np.asarray(var))
    return NoiseLevel(read_var=float(a), shot_gain=float(b))


def gradient_energy(image, *, window=(3, 31)) -> tuple[np.ndarray, np.ndarray]:
    """Local gradient energy per axis, summed over a window.

    Parameters
    ----------
    image : ndarray, shape (lines, columns)
        Image.
    window : (int, int), keyword-only
        Window (lines, columns), odd, centred on each pixel.

    Returns
    -------
    e_line, e_col : ndarray, shape of ``image``
        ``sum_window (d image / d line)**2`` and the same across columns
        (image unit**2 / px**2), with the matcher's 5-point gradient. Non-finite
        where the window or the gradient support touches no data.
    """
    img = _as_image(image)
    window = _check_window(window)
    g_l = ndimage.correlate1d(img, _GRADIENT, axis=0, mode="reflect")
    g_c = ndimage.correlate1d(img, _GRADIENT, axis=1, mode="reflect")
    return _box_sum(g_l * g_l, window), _box_sum(g_c * g_c, window)


def expected_matching_std(image, *, window=(3, 31), noise_std=None) -> tuple[np.ndarray, np.ndarray]:
    """A-priori standard deviation of a match centred on each pixel (Delon & Rougé).

    Parameters
    ----------
    image : ndarray, shape (lines, columns)
        Band A.
    window : (int, int), keyword-only
        Matching window (lines, columns), odd.
    noise_std : float, NoiseLevel or None, keyword-only
        Noise standard deviation of each band (image unit); a
        :class:`NoiseLevel` gives each window the noise of its mean level;
        estimated by :func:`estimate_image_noise` when None.

    Returns
    -------
    std_line, std_col : ndarray, shape of ``image``
        ``sqrt(2) * noise_std / sqrt(signal gradient energy)`` per axis (px),
        where the signal gradient energy is the window's gradient energy less
        its expected noise part (``window size * sum(filter**2) * noise_std**2``);
        ``inf`` where nothing is left (flat ground, water: pure noise).
    """
    img = _as_image(image)
    window = _check_window(window)
    sigma = _noise_std_map(img, window, noise_std)
    e_l, e_c = gradient_energy(img, window=window)
    e_noise = window[0] * window[1] * float(np.sum(_GRADIENT**2)) * sigma**2
    with np.errstate(divide="ignore", invalid="ignore"):
        k = np.sqrt(2.0) * sigma
        return (k / np.sqrt(np.maximum(e_l - e_noise, 0.0)),
                k / np.sqrt(np.maximum(e_c - e_noise, 0.0)))


def _noise_std_map(img: np.ndarray, window: tuple, noise_std):
    """The noise σ the texture criterion uses: a float, or per pixel (a :class:`NoiseLevel` at each window's
    mean level); :func:`estimate_image_noise` when None."""
    if isinstance(noise_std, NoiseLevel):
        return noise_std.local_std(img, window)
    sigma = estimate_image_noise(img) if noise_std is None else float(noise_std)
    if not sigma >= 0:
        raise ValueError(f"noise_std: must be >= 0, got {noise_std}")
    return sigma


def _typical_noise_std(img: np.ndarray, noise_std) -> float:
    """One σ for what needs a scalar (the double-gradient threshold): a :class:`NoiseLevel` at the image's
    median level."""
    if isinstance(noise_std, NoiseLevel):
        finite = img[np.isfinite(img)]
        return float(noise_std.std(np.median(finite) if finite.size else 0.0))
    return float(noise_std)


def texture_mask(image, *, window=(3, 31), noise_std=None, max_std=0.2, min_contrast=0.0,
                 saturation=None, max_level=None) -> np.ndarray:
    """Pixels where a window centred on them has enough texture to be matched.

    Parameters
    ----------
    image : ndarray, shape (lines, columns)
        Band A. Non-finite pixels are no data.
    window : (int, int), keyword-only
        Matching window (lines, columns), odd.
    noise_std : float, NoiseLevel or None, keyword-only
        Noise standard deviation (image unit), or the band's
        :class:`NoiseLevel` (each window at its mean level); estimated when None.
    max_std : float, keyword-only
        Largest acceptable a-priori matching standard deviation on either axis
        (px, :func:`expected_matching_std`; CNES quotes 0.17 px of correlation
        noise across XS bands). Rejects water, flat ground and the smooth
        inside of clouds: their gradient energy is that of the noise.
    min_contrast : float, keyword-only
        Smallest acceptable local contrast, standard deviation over mean level
        of the window (dimensionless; 0 disables). Rejects bright, smooth areas
        (clouds) whose gradient energy is dominated by photon noise.
    saturation : float or None, keyword-only
        Level at or above which a pixel is saturated (image unit); windows
        touching a saturated pixel are rejected. None disables.
    max_level : float or None, keyword-only
        Windows whose mean level exceeds this (image unit: a cloud threshold)
        are rejected. None disables.

    Returns
    -------
    ndarray of bool, shape of ``image``
        True where the texture is good enough to match.
    """
    return _texture(image, window=window, noise_std=noise_std, max_std=max_std, min_contrast=min_contrast,
                    saturation=saturation, max_level=max_level)[0]


def _texture(image, *, window, noise_std, max_std, min_contrast, saturation, max_level):
    """:func:`texture_mask` and the a-priori standard deviations it rests on."""
    img = _as_image(image)
    window = _check_window(window)
    if not max_std > 0:
        raise ValueError(f"max_std: must be > 0, got {max_std}")
    if not min_contrast >= 0:
        raise ValueError(f"min_contrast: must be >= 0, got {min_contrast}")
    nodata = ~np.isfinite(img)
    work = np.where(nodata, 0.0, img) if nodata.any() else img
    # estimated on the image (no data ignored), not on ``work``; validated by expected_matching_std
    sigma = estimate_image_noise(img) if noise_std is None else noise_std
    std_l, std_c = expected_matching_std(work, window=window, noise_std=sigma)
    ok = (std_l <= max_std) & (std_c <= max_std)
    if min_contrast > 0 or max_level is not None:
        npx = window[0] * window[1]
        mean = _box_sum(work, window) / npx
        if min_contrast > 0:
            var = np.maximum(_box_sum(work * work, window) / npx - mean * mean, 0.0)
            with np.errstate(divide="ignore", invalid="ignore"):
                ok &= np.sqrt(var) >= min_contrast * np.abs(mean)
        if max_level is not None:
            ok &= mean <= max_level
    bad = nodata
    if saturation is not None:
        bad = bad | (np.where(nodata, -np.inf, img) >= saturation)
    # the gradient reads 2 pixels beyond the window
    if bad.any():
        ok &= ~_dilate(bad, (window[0] + 4, window[1] + 4))
    return ok, std_l, std_c


def _hessian_score(img: np.ndarray, sigma: float) -> np.ndarray:
    """Smaller absolute eigenvalue of the Hessian (second differences, 4 directions)."""
    if sigma > 0:
        img = ndimage.gaussian_filter(img, sigma, mode="nearest")
    p = np.pad(img, 1, mode="edge")
    c = p[1:-1, 1:-1]
    d_ll = p[2:, 1:-1] - 2 * c + p[:-2, 1:-1]                # along lines
    d_cc = p[1:-1, 2:] - 2 * c + p[1:-1, :-2]                # along columns
    d_1 = 0.5 * (p[2:, 2:] - 2 * c + p[:-2, :-2])            # diagonals: distance sqrt(2)
    d_2 = 0.5 * (p[2:, :-2] - 2 * c + p[:-2, 2:])
    h_lc = 0.5 * (d_1 - d_2)                                 # mixed derivative
    mean = 0.5 * (d_ll + d_cc)
    rad = np.hypot(0.5 * (d_ll - d_cc), h_lc)
    return np.minimum(np.abs(mean + rad), np.abs(mean - rad))


def _second_difference_gain(sigma: float) -> float:
    """White-noise gain of the (smoothed) second difference along one axis."""
    size = 2 * int(np.ceil(4 * sigma)) + 5
    delta = np.zeros((size, size))
    delta[size // 2, size // 2] = 1.0
    if sigma > 0:
        delta = ndimage.gaussian_filter(delta, sigma, mode="constant")
    d2 = delta[2:, 1:-1] - 2 * delta[1:-1, 1:-1] + delta[:-2, 1:-1]
    return float(np.sqrt(np.sum(d2 * d2)))


def double_gradient_points(image, *, threshold=None, n_sigma=4.0, noise_std=None, sigma=1.5,
                           min_distance=8, mask=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points whose second derivative exceeds a threshold in two directions.

    The patent's "doble gradiente": the second derivative with respect to
    distance, taken along lines, columns and both diagonals (after a light
    Gaussian smoothing), gives the Hessian at each pixel; the second
    derivative exceeds the threshold in two orthogonal directions when both
    eigenvalues of the Hessian do. The score is the smaller absolute
    eigenvalue: high on spots, corners and saddles, zero on straight edges
    and ridges (which cannot be matched along them). Points are kept where
    the score reaches the threshold and is a local maximum along their line
    within ``min_distance`` columns.

    Parameters
    ----------
    image : ndarray, shape (lines, columns)
        Band A.
    threshold : float or None, keyword-only
        Threshold on the second derivative (image unit / px**2). None:
        ``n_sigma`` times the noise standard deviation of the (smoothed)
        second difference.
    n_sigma : float, keyword-only
        Threshold in noise standard deviations when ``threshold`` is None.
    noise_std : float or None, keyword-only
        Noise standard deviation (image unit); estimated when None.
    sigma : float, keyword-only
        Standard deviation of the Gaussian smoothing (px); 0 disables it.
        Smoothing raises the signal-to-noise ratio of second derivatives on
        images whose MTF leaves little energy near Nyquist.
    min_distance : int, keyword-only
        Non-maximum suppression half-width along the line (px).
    mask : ndarray of bool or None, keyword-only
        True where points are not allowed.

    Returns
    -------
    lines, cols : ndarray of float, shape (N,)
        Points (px), sorted by line then column.
    score : ndarray of float, shape (N,)
        Smaller absolute eigenvalue of the Hessian (image unit / px**2).
    """
    img = _as_image(image)
    if int(min_distance) != min_distance or min_distance < 0:
        raise ValueError(f"min_distance: must be an integer >= 0, got {min_distance}")
    if not sigma >= 0:
        raise ValueError(f"sigma: must be >= 0, got {sigma}")
    if threshold is None:
        if not n_sigma > 0:
            raise ValueError(f"n_sigma: must be > 0, got {n_sigma}")
        noise = estimate_image_noise(img) if noise_std is None else float(noise_std)
        if not noise >= 0:
            raise ValueError(f"noise_std: must be >= 0, got {noise_std}")
        threshold = n_sigma * _second_difference_gain(sigma) * noise
    elif not threshold >= 0:
        raise ValueError(f"threshold: must be >= 0, got {threshold}")
    nodata = ~np.isfinite(img)
    score = _hessian_score(np.where(nodata, 0.0, img), sigma)
    if nodata.any():
        score[_dilate(nodata, (2 * int(np.ceil(3 * sigma)) + 3,) * 2)] = -np.inf
    keep = score >= threshold
    if min_distance > 0:
        keep &= score >= ndimage.maximum_filter1d(score, 2 * int(min_distance) + 1, axis=1, mode="nearest")
    if mask is not None:
        mask = np.asarray(mask, dtype=bool)
        if mask.shape != img.shape:
            raise ValueError(f"mask: expected shape {img.shape}, got {mask.shape}")
        keep &= ~mask
    li, ci = np.nonzero(keep)
    return li.astype(float), ci.astype(float), score[li, ci]


def grid_points(shape, *, step_lines=1, step_columns=32, margin=(0, 0), offset=(0, 0)):
    """A predetermined grid of points, independent of the image content.

    Parameters
    ----------
    shape : (int, int)
        Image shape (lines, columns).
    step_lines, step_columns : int, keyword-only
        Grid steps (px).
    margin : (int, int), keyword-only
        No point closer than this to the borders (lines, columns), px.
    offset : (int, int), keyword-only
        Position of the first node after the margin (px).

    Returns
    -------
    lines, cols : ndarray of float, shape (N,)
        Nodes (px), sorted by line then column.
    """
    try:
        n_lines, n_cols = (int(v) for v in shape)
    except (TypeError, ValueError):
        raise ValueError(f"shape: expected (lines, columns), got {shape!r}") from None
    for name, v in (("step_lines", step_lines), ("step_columns", step_columns)):
        if int(v) != v or v < 1:
            raise ValueError(f"{name}: must be an integer >= 1, got {v}")
    ml, mc = (int(v) for v in margin)
    if ml < 0 or mc < 0:
        raise ValueError(f"margin: must be >= 0, got {margin!r}")
    ol, oc = (int(v) for v in offset)
    lines = np.arange(ml + ol, n_lines - ml, int(step_lines), dtype=float)
    cols = np.arange(mc + oc, n_cols - mc, int(step_columns), dtype=float)
    ll, cc = np.meshgrid(lines, cols, indexing="ij")
    return ll.ravel(), cc.ravel()


def spread_quality_subset(lines, columns, quality, *, per_line, column_range=None, min_quality=None):
    """Indices of the best point per column bin and line: spread and quality.

    The column range is cut into ``per_line`` equal bins; on each line
    (rounded), the point of highest quality in each bin is kept. Use it on
    candidates before matching (a-priori quality) or after (match quality).

    Parameters
    ----------
    lines, columns, quality : array_like of float, shape (N,)
        Candidate points (px) and their quality (higher is better); points
        with a non-finite quality are never kept.
    per_line : int, keyword-only
        Number of column bins, i.e. the most points kept per line.
    column_range : (float, float) or None, keyword-only
        Columns spanned by the bins (px); the candidates' range when None.
    min_quality : float or None, keyword-only
        Points below this quality are never kept.

    Returns
    -------
    ndarray of int
        Indices into the inputs, sorted by line then column.
    """
    li = np.asarray(lines, dtype=float)
    co = np.asarray(columns, dtype=float)
    q = np.asarray(quality, dtype=float)
    if li.ndim != 1 or co.shape != li.shape or q.shape != li.shape:
        raise ValueError(f"lines, columns, quality: expected three arrays of one shape (N,), got "
                         f"{li.shape}, {co.shape}, {q.shape}")
    if int(per_line) != per_line or per_line < 1:
        raise ValueError(f"per_line: must be an integer >= 1, got {per_line}")
    ok = np.isfinite(q) & np.isfinite(li) & np.isfinite(co)
    if min_quality is not None:
        ok &= q >= min_quality
    idx = np.flatnonzero(ok)
    if idx.size == 0:
        return idx
    if column_range is None:
        c0, c1 = co[idx].min(), co[idx].max()
    else:
        c0, c1 = (float(v) for v in column_range)
        if not c1 >= c0:
            raise ValueError(f"column_range: expected (low, high) with high >= low, got {column_range!r}")
        idx = idx[(co[idx] >= c0) & (co[idx] <= c1)]
    width = max(c1 - c0, 1e-9) * (1 + 1e-12)
    b = np.minimum(((co[idx] - c0) / width * per_line).astype(np.int64), per_line - 1)
    ln = np.rint(li[idx]).astype(np.int64)
    order = np.lexsort((-q[idx], b, ln))  # by line, bin, then best quality first
    ln, b = ln[order], b[order]
    first = np.ones(order.size, dtype=bool)
    first[1:] = (ln[1:] != ln[:-1]) | (b[1:] != b[:-1])
    kept = idx[order[first]]
    return kept[np.lexsort((co[kept], li[kept]))]


def select_points(image, *, method="grid", per_line=20, window=(3, 31), search=(2, 2), margin=None,
                  mask=None, line_mask=None, line_step=1, noise_std=None, max_std=0.2, min_contrast=0.0,
                  saturation=None, max_level=None, threshold=None):
    """Candidate points of band A for matching.

    Parameters
    ----------
    image : ndarray, shape (lines, columns)
        Band A.
    method : {"grid", "double_gradient", "spread"}, keyword-only
        ``grid``: ``per_line`` evenly spaced columns on every selected line,
        kept where the texture criterion passes; ``double_gradient``: points
        of :func:`double_gradient_points`, thinned to the best per column bin;
        ``spread``: on every line, the pixel of smallest a-priori matching
        standard deviation in each of ``per_line`` column bins.
    per_line : int, keyword-only
        Points wanted per line (CNES: 20).
    window, search : (int, int), keyword-only
        Matching window (lines, columns) and search half-range (px): they fix
        the border margin.
    margin : (int, int) or None, keyword-only
        Border margin (lines, columns), px; :func:`restore.matching.support_margin`
        (window half-size + search + interpolation support) when None.
    mask : ndarray of bool or None, keyword-only
        True where the image must not be used (clouds, water, no data known
        beforehand); no window touches it.
    line_mask : ndarray of bool or None, keyword-only
        Per line, True where points may be taken (e.g. lines whose homologues
        fall inside band B).
    line_step : int, keyword-only
        Take points every ``line_step`` lines.
    noise_std, max_std, min_contrast, saturation, max_level : keyword-only
        Texture criterion, see :func:`texture_mask`.
    threshold : float or None, keyword-only
        Double-gradient threshold, see :func:`double_gradient_points`.

    Returns
    -------
    lines, cols : ndarray of float, shape (N,)
        Points (px, pixel centres), sorted by line then column.
    """
    if method not in SELECTION_METHODS:
        raise ValueError(f"method: expected one of {tuple(SELECTION_METHODS)}, got {method!r}")
    img = _as_image(image)
    n_lines, n_cols = img.shape
    window = _check_window(window)
    if int(per_line) != per_line or per_line < 1:
        raise ValueError(f"per_line: must be an integer >= 1, got {per_line}")
    if int(line_step) != line_step or line_step < 1:
        raise ValueError(f"line_step: must be an integer >= 1, got {line_step}")
    if margin is None:
        margin = support_margin(window=window, search=search)
    try:
        ml, mc = (int(v) for v in margin)
    except (TypeError, ValueError):
        raise ValueError(f"margin: expected (lines, columns), got {margin!r}") from None
    if ml < 0 or mc < 0:
        raise ValueError(f"margin: must be >= 0, got {margin!r}")
    ml = max(ml, window[0] // 2)
    mc = max(mc, window[1] // 2)
    empty = (np.zeros(0), np.zeros(0))
    if n_lines <= 2 * ml or n_cols <= 2 * mc:
        return empty

    if noise_std is None:
        noise_std = estimate_image_noise(img)
    usable, std_l, std_c = _texture(img, window=window, noise_std=noise_std, max_std=max_std,
                                    min_contrast=min_contrast, saturation=saturation, max_level=max_level)
    if mask is not None:
        mask = np.asarray(mask, dtype=bool)
        if mask.shape != img.shape:
            raise ValueError(f"mask: expected shape {img.shape}, got {mask.shape}")
        usable &= ~_dilate(mask, window)
    rows = np.zeros(n_lines, dtype=bool)
    rows[ml:n_lines - ml:int(line_step)] = True
    if line_mask is not None:
        line_mask = np.asarray(line_mask, dtype=bool)
        if line_mask.shape != (n_lines,):
            raise ValueError(f"line_mask: expected shape ({n_lines},), got {line_mask.shape}")
        rows &= line_mask
    usable[~rows] = False
    usable[:, :mc] = False
    usable[:, n_cols - mc:] = False
    c_lo, c_hi = mc, n_cols - 1 - mc

    area = _Area(img=img, usable=usable, rows=rows, std_l=std_l, std_c=std_c, c_lo=c_lo, c_hi=c_hi,
                 per_line=int(per_line), noise_std=_typical_noise_std(img, noise_std), threshold=threshold)
    return SELECTION_METHODS[method].pick(area)


@dataclass
class _Area:
    """What a selection method picks from: the usable windows of the image and the column range."""

    img: np.ndarray
    usable: np.ndarray
    rows: np.ndarray
    std_l: np.ndarray
    std_c: np.ndarray
    c_lo: int
    c_hi: int
    per_line: int
    noise_std: float
    threshold: float | None


def _grid_points(area: _Area) -> tuple[np.ndarray, np.ndarray]:
    """``grid``: fixed columns, evenly spread, on every usable line."""
    cols = np.unique(np.rint(np.linspace(area.c_lo, area.c_hi, area.per_line)))
    li = np.flatnonzero(area.rows)
    ll, cc = np.meshgrid(li, cols.astype(np.int64), indexing="ij")
    keep = area.usable[ll, cc]
    return ll[keep].astype(float), cc[keep].astype(float)


def _double_gradient_points(area: _Area) -> tuple[np.ndarray, np.ndarray]:
    """``double_gradient``: corners (patent's double-gradient criterion), the best spread along each line."""
    li, ci, score = double_gradient_points(area.img, threshold=area.threshold, noise_std=area.noise_std,
                                           min_distance=max(1, (area.c_hi - area.c_lo) // (4 * area.per_line)),
                                           mask=~area.usable)
    keep = spread_quality_subset(li, ci, score, per_line=area.per_line, column_range=(area.c_lo, area.c_hi))
    return li[keep], ci[keep]


def _spread_points(area: _Area) -> tuple[np.ndarray, np.ndarray]:
    """``spread``: the best a-priori precision in each column bin of each line."""
    quality = np.where(area.usable, -np.maximum(area.std_l, area.std_c), -np.inf)
    li = np.flatnonzero(area.rows)
    c_lo, c_hi = area.c_lo, area.c_hi
    span = c_hi - c_lo + 1
    nb = min(area.per_line, span)
    bw = -(-span // nb)  # ceil
    q = np.full((li.size, nb * bw), -np.inf)
    q[:, :span] = quality[li, c_lo:c_hi + 1]
    q = q.reshape(li.size, nb, bw)
    best = np.argmax(q, axis=2)
    ok = np.isfinite(np.take_along_axis(q, best[:, :, None], axis=2)[:, :, 0])
    cols = c_lo + np.arange(nb)[None, :] * bw + best
    ll = np.broadcast_to(li[:, None], cols.shape)
    return ll[ok].astype(float), cols[ok].astype(float)


@dataclass(frozen=True)
class SelectionMethod:
    """A point-selection method: how it picks, and how many lines of context a block needs around it."""

    name: str
    description: str
    pick: Callable
    context_lines: Callable = lambda n_cols, per_line: 32


#: ``restoration.selection`` → method
SELECTION_METHODS: dict[str, SelectionMethod] = {m.name: m for m in (
    SelectionMethod("grid", "fixed, evenly spread columns on every usable line", _grid_points),
    SelectionMethod("double_gradient", "corners by the double-gradient criterion, spread along the line",
                    _double_gradient_points,
                    context_lines=lambda n_cols, per_line: max(32, n_cols // (2 * int(per_line)) + 16)),
    SelectionMethod("spread", "best a-priori precision in each column bin", _spread_points),
)}


def select_points_in_blocks(image, *, block_lines: int = 512, noise_std=None, line_mask=None, mask=None,
                            method="grid", per_line=20, **options):
    """:func:`select_points` run on blocks of lines, with the same result and bounded memory.

    The texture maps of :func:`select_points` cost several float64 copies of
    the image; here they are computed one block at a time, each with enough
    lines of context around it (filter supports, the double-gradient peak
    spacing) that the points equal the whole-image ones (exactly for ``grid``
    and ``double_gradient`` in the tests; ``spread`` may move a tie by one
    column, from the rounding of the texture maps). The noise is estimated
    once on the image (exact median of evenly spaced blocks of lines, bounded
    memory: :func:`estimate_image_noise`).

    Parameters
    ----------
    image : ndarray (lines, columns)
    block_lines : int, keyword-only
        Lines per block.
    noise_std, line_mask, mask, method, per_line, **options
        As :func:`select_points`.
    """
    n_lines, n_cols = np.shape(image)
    if noise_std is None:
        noise_std = estimate_image_noise(image)
    if method not in SELECTION_METHODS:
        raise ValueError(f"method: expected one of {tuple(SELECTION_METHODS)}, got {method!r}")
    context = SELECTION_METHODS[method].context_lines(n_cols, per_line)
    if n_lines <= block_lines + 2 * context:
        return select_points(image, noise_std=noise_std, line_mask=line_mask, mask=mask, method=method,
                             per_line=per_line, **options)
    full_mask = np.ones(n_lines, bool) if line_mask is None else np.asarray(line_mask, bool)
    if full_mask.shape != (n_lines,):
        raise ValueError(f"line_mask: expected shape ({n_lines},), got {full_mask.shape}")
    out_l, out_c = [], []
    for a in range(0, n_lines, block_lines):
        b = min(n_lines, a + block_lines)
        a0, b0 = max(0, a - context), min(n_lines, b + context)
        lm = np.zeros(b0 - a0, bool)
        lm[a - a0:b - a0] = full_mask[a:b]
        if not lm.any():
            continue
        li, ci = select_points(np.asarray(image[a0:b0]), noise_std=noise_std, line_mask=lm,
                               mask=None if mask is None else np.asarray(mask)[a0:b0], method=method,
                               per_line=per_line, **options)
        out_l.append(li + a0)
        out_c.append(ci)
    if not out_l:
        return np.zeros(0), np.zeros(0)
    return np.concatenate(out_l), np.concatenate(out_c)
