"""Synthetic textures with known shifts: the shared test and benchmark fixtures of the matcher.

Band-limited random textures are sums of sinusoids (a Gaussian MTF and a
``1/f`` amplitude spectrum), so a shifted copy is exact at any sub-pixel
shift: :func:`synthetic_pairs` gives patches of band A and band B with known
shifts, in one band ("same") or across two correlated bands ("cross").
"""
from __future__ import annotations

import numpy as np

from restore.matching import support_margin

__all__ = ["texture_terms", "sum_of_sinusoids", "textured_image", "synthetic_pairs", "CASES"]

CASES = ("same", "cross")
_PAD = 3  # extra margin of each synthetic patch (px)


def texture_terms(rng, n, n_terms, mtf_nyquist, corner):
    """Random frequencies (cycles/px), phases and amplitudes, shape (n, n_terms)."""
    f = rng.uniform(-0.5, 0.5, size=(n, n_terms, 2))
    fr = np.hypot(f[..., 0], f[..., 1])
    mtf = mtf_nyquist ** ((fr / 0.5) ** 2)
    amp = mtf / np.hypot(fr, corner)
    phase = rng.uniform(0.0, 2.0 * np.pi, size=(n, n_terms))
    return f, phase, amp


def sum_of_sinusoids(f, phase, amp, lines, cols):
    """Sum of sinusoids on the grid ``lines x cols`` (per pair): (n, L, C).

    ``cos(2 pi (u l + v c) + p) = cos(2 pi u l + p) cos(2 pi v c) - sin(2 pi u l + p) sin(2 pi v c)``,
    evaluated as a batched matrix product.
    """
    arg_l = 2 * np.pi * f[:, None, :, 0] * lines[:, :, None] + phase[:, None, :]  # (n, L, K)
    arg_c = 2 * np.pi * f[:, None, :, 1] * cols[:, :, None]  # (n, C, K)
    left = np.concatenate([np.cos(arg_l) * amp[:, None, :], -np.sin(arg_l) * amp[:, None, :]], axis=2)
    right = np.concatenate([np.cos(arg_c), np.sin(arg_c)], axis=2)
    return np.matmul(left, right.transpose(0, 2, 1))


def synthetic_pairs(*, seed=0, n=2000, window=(3, 31), search=(2, 2), max_shift=1.5, case="same",
                    noise=0.02, n_terms=64, mtf_nyquist=0.3, corner=0.02, band_correlation=0.85,
                    dtype=np.float32):
    """Pairs of analytic band-limited patches with known sub-pixel shifts.

    Parameters
    ----------
    seed : int, keyword-only
        Seed of every random draw.
    n : int, keyword-only
        Number of pairs.
    window, search : (int, int), keyword-only
        Matching window and search half-range (px) the patches must support.
    max_shift : float, keyword-only
        Shifts are uniform in ``[-max_shift, max_shift]`` on each axis (px).
    case : {"same", "cross"}, keyword-only
        Identical bands, or two different mixes of three texture components.
    noise : float, keyword-only
        White-noise standard deviation, relative to the texture's.
    n_terms : int, keyword-only
        Sinusoids per texture component.
    mtf_nyquist : float, keyword-only
        MTF at the Nyquist frequency (Gaussian MTF).
    corner : float, keyword-only
        Corner frequency of the ``1/f`` amplitude spectrum (cycles/px).
    band_correlation : float, keyword-only
        Cross-band case: correlation of the two mixes (0..1).
    dtype : numpy dtype, keyword-only
        Type of the images (products store float32 bands).

    Returns
    -------
    dict
        ``image_a``, ``image_b``: patches stacked along the lines (float
        arrays); ``lines``, ``cols``: point centres (px); ``shift_lines``,
        ``shift_cols``: true shifts, so that the point is at
        ``(lines + shift_lines, cols + shift_cols)`` in B (px);
        ``patch_shape``.
    """
    if case not in CASES:
        raise ValueError(f"case: expected one of {CASES}, got {case!r}")
    if int(n) != n or n < 1:
        raise ValueError(f"n: must be an integer >= 1, got {n}")
    if not 0 <= max_shift <= min(search):
        raise ValueError(f"max_shift: must lie in [0, min(search)={min(search)}], got {max_shift}")
    if noise < 0:
        raise ValueError(f"noise: must be >= 0, got {noise}")
    if not 0 < band_correlation <= 1:
        raise ValueError(f"band_correlation: must lie in (0, 1], got {band_correlation}")
    rng = np.random.default_rng(seed)
    ml, mc = support_margin(window=window, search=search)
    ml, mc = ml + _PAD, mc + _PAD
    pl, pc = 2 * ml + 1, 2 * mc + 1
    shift = rng.uniform(-max_shift, max_shift, size=(n, 2))
    grid_l = np.arange(pl, dtype=float) - ml
    grid_c = np.arange(pc, dtype=float) - mc
    n_comp = 1 if case == "same" else 3
    if case == "same":
        mix_a = mix_b = np.array([1.0])
    else:
        # a shared component plus one of its own for each band: correlation
        # cos(t)**2 = band_correlation; band B has another gain
        t = np.arccos(np.sqrt(band_correlation))
        mix_a = np.array([np.cos(t), np.sin(t), 0.0])
        mix_b = 1.3 * np.array([np.cos(t), 0.0, np.sin(t)])
    img_a = np.zeros((n, pl, pc))
    img_b = np.zeros((n, pl, pc))
    for j in range(n_comp):  # a handful of texture components
        f, ph, amp = texture_terms(rng, n, n_terms, mtf_nyquist, corner)
        amp = amp / np.sqrt(0.5 * np.sum(amp**2, axis=1, keepdims=True))  # unit std
        ones = np.ones((n, 1))
        comp_a = sum_of_sinusoids(f, ph, amp, ones * grid_l, ones * grid_c)
        comp_b = sum_of_sinusoids(f, ph, amp, grid_l - shift[:, :1], grid_c - shift[:, 1:])
        img_a += mix_a[j] * comp_a
        img_b += mix_b[j] * comp_b
    img_a += noise * np.linalg.norm(mix_a) * rng.standard_normal(img_a.shape) + 10.0
    img_b += noise * np.linalg.norm(mix_b) * rng.standard_normal(img_b.shape) + 7.0
    lines = ml + pl * np.arange(n, dtype=float)
    cols = np.full(n, float(mc))
    return {
        "image_a": img_a.reshape(n * pl, pc).astype(dtype), "image_b": img_b.reshape(n * pl, pc).astype(dtype),
        "lines": lines, "cols": cols, "shift_lines": shift[:, 0], "shift_cols": shift[:, 1],
        "patch_shape": (pl, pc),
    }


def textured_image(shape, *, seed: int = 0, n_terms: int = 300, mtf_nyquist: float = 0.3, corner: float = 0.02,
                   rng=None) -> np.ndarray:
    """One band-limited random texture of unit standard deviation (float64, ``shape`` = (lines, columns))."""
    rng = np.random.default_rng(seed) if rng is None else rng
    f, ph, amp = texture_terms(rng, 1, n_terms, mtf_nyquist, corner)
    amp = amp / np.sqrt(0.5 * np.sum(amp ** 2))
    lines = np.arange(shape[0], dtype=float)[None]
    cols = np.arange(shape[1], dtype=float)[None]
    return sum_of_sinusoids(f, ph, amp, lines, cols)[0]
