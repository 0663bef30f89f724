"""Tidy tables (see :mod:`reports.figures`)."""
from __future__ import annotations

from typing import Sequence

import numpy as np

__all__ = []

_STR_COLS = ("source", "quantity", "series", "unit")


def _block(source: str, quantity: str, series: str, unit: str, **cols) -> dict[str, np.ndarray]:
    n = max(np.size(v) for v in cols.values())
    out = {"source": np.full(n, source, dtype=object), "quantity": np.full(n, quantity, dtype=object),
           "series": np.full(n, series, dtype=object), "unit": np.full(n, unit, dtype=object)}
    for c, v in cols.items():
        out[c] = np.broadcast_to(np.asarray(v, dtype=float), (n,)).copy()
    return out


def _concat(blocks: Sequence[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    names: list[str] = list(_STR_COLS)
    for b in blocks:
        names += [c for c in b if c not in names]
    out = {}
    for c in names:
        parts = []
        for b in blocks:
            n = len(b["source"])
            if c in b:
                parts.append(b[c])
            else:
                parts.append(np.full(n, "" if c in _STR_COLS else np.nan,
                                     dtype=object if c in _STR_COLS else float))
        out[c] = np.concatenate(parts)
    return out


def _freq_grid(f_max_hz: float, taus_s: Sequence[float], step_hz: float = 0.2) -> np.ndarray:
    """Uniform grid plus the exact blind frequencies n/τ (so the nulls are drawn)."""
    f = np.arange(0.0, f_max_hz + step_hz / 2, step_hz)
    extra = [np.arange(1, int(f_max_hz * t) + 1) / t for t in taus_s]
    return np.unique(np.concatenate([f, *extra]))


def _mc_freqs(tau_s: float, f_max_hz: float,
              fractions: Sequence[float] = (0.06, 0.15, 0.3, 0.45, 0.7, 0.85, 0.94)) -> np.ndarray:
    """Test frequencies (n + u)/τ below f_max, never on a blind frequency."""
    f = np.array([(n + u) / tau_s for n in range(int(f_max_hz * tau_s) + 1) for u in fractions])
    return f[f <= f_max_hz]


def _label_tau(tau_s: float) -> str:
    return f"τ = {tau_s * 1e3:g} ms"


def _label_k(k: float) -> str:
    return f"k = {k:g}"
