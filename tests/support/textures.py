"""Analytic textures for matching tests: sampled exactly at any position (no interpolation)."""
import numpy as np


def band_limited_texture(lines, cols, *, max_cycles=0.35, width=None, seed=3, n=300):
    """Sum of ``n`` random cosines below ``max_cycles`` cycle/px, Gaussian-weighted (σ ``width``, default
    0.43 × the limit)."""
    width = 0.43 * max_cycles if width is None else width
    rng = np.random.default_rng(seed)
    kl, kc = rng.uniform(-max_cycles, max_cycles, n), rng.uniform(-max_cycles, max_cycles, n)
    ph = rng.uniform(0, 2 * np.pi, n)
    amp = np.exp(-(kl ** 2 + kc ** 2) / width ** 2) * rng.standard_normal(n)
    out = np.zeros(np.broadcast(lines, cols).shape)
    for i in range(n):
        out += amp[i] * np.cos(2 * np.pi * (kl[i] * lines + kc[i] * cols) + ph[i])
    return 100 + 20 * out
