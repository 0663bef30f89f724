"""Transfer functions of differential measurement and integration (patent step c).

A pair of detectors seeing the same ground ``tau`` seconds apart measures
``d(t) = theta(t + tau) - theta(t)``, i.e. ``D(f) = G(f) Theta(f)`` with

* ``G(f) = exp(j w tau) - 1`` (``w = 2 pi f``), blind (``G = 0``) at ``f = n / tau``;
* the pseudo-inverse (Wiener with constant ``k``) ``H_k = conj(G) / (|G|² + k)``;
* the chain gain ``F_k = G H_k = 2 (1 - cos w tau) / (2 (1 - cos w tau) + k)``
  (real: the estimator introduces no phase shift).

Several pairs fill each other's blind frequencies.  With a signal PSD ``S`` and
noise PSDs ``N_j`` the fused (multi-pair Wiener) estimator is
``Theta = sum_j H_j D_j`` with ``H_j = conj(G_j) S / N_j / (1 + S sum_i |G_i|² / N_i)``;
with ``S / N_j = 1 / k`` for all pairs this is ``conj(G_j) / (sum_i |G_i|² + k)``.
Frequencies in Hz, lags in s.
"""
from __future__ import annotations

import numpy as np

__all__ = ["pair_transfer", "wiener_gain", "chain_gain", "blind_frequencies", "fused_gains", "pair_snr", "fused_snr",
           "fused_chain_gain", "noise_gain"]


def _check_tau(tau) -> np.ndarray:
    t = np.asarray(tau, dtype=np.float64)
    if not np.all(np.isfinite(t)) or np.any(t <= 0):
        raise ValueError(f"tau_s: must be finite and > 0, got {t.tolist()}")
    return t


def _check_k(k) -> float:
    k = float(k)
    if not k >= 0:
        raise ValueError(f"k: must be >= 0, got {k}")
    return k


def pair_transfer(freq_hz, tau_s) -> np.ndarray:
    """Differential transfer ``G(f) = exp(2 pi j f tau) - 1`` (complex, dimensionless)."""
    tau = _check_tau(tau_s)
    return np.exp(2j * np.pi * np.asarray(freq_hz, dtype=np.float64) * tau) - 1


def wiener_gain(freq_hz, tau_s, k) -> np.ndarray:
    """Pseudo-inverse (Wiener, constant ``k``) ``H_k = conj(G) / (|G|² + k)`` (complex)."""
    k = _check_k(k)
    g = pair_transfer(freq_hz, tau_s)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.conj(g) / (np.abs(g) ** 2 + k)


def chain_gain(freq_hz, tau_s, k) -> np.ndarray:
    """Chain gain ``F_k = 2 (1 - cos w tau) / (2 (1 - cos w tau) + k)`` (real, in [0, 1])."""
    k = _check_k(k)
    tau = _check_tau(tau_s)
    g2 = 2 * (1 - np.cos(2 * np.pi * np.asarray(freq_hz, dtype=np.float64) * tau))
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(g2 + k > 0, g2 / (g2 + k), 0.0)


def blind_frequencies(tau_s, f_max_hz: float) -> np.ndarray:
    """Blind frequencies ``n / tau`` (Hz), ``n = 0, 1, ...``, up to ``f_max_hz``."""
    tau = float(_check_tau(tau_s))
    if not f_max_hz >= 0:
        raise ValueError(f"f_max_hz: must be >= 0, got {f_max_hz}")
    return np.arange(0, int(np.floor(f_max_hz * tau * (1 + 1e-12))) + 1) / tau


def fused_gains(freq_hz, taus_s, *, k: float | None = None, signal_psd=None,
                noise_psd=None) -> np.ndarray:
    """Per-pair gains ``H_j(f)`` of the multi-pair Wiener estimator.

    Parameters
    ----------
    freq_hz : array_like
        Frequencies (Hz), shape (F,).
    taus_s : sequence of float
        Lags (s), one per pair.
    k : float, optional
        Constant regularisation (noise-to-signal PSD ratio, same for all pairs):
        ``H_j = conj(G_j) / (sum_i |G_i|² + k)``.
    signal_psd, noise_psd : array_like, optional
        ``S(f)`` (shape (F,)) and ``N_j`` (shape (p,) or (p, F)) in the same
        units; used when ``k`` is None.

    Returns
    -------
    ndarray, complex, shape (p, F)
    """
    f = np.atleast_1d(np.asarray(freq_hz, dtype=np.float64))
    taus = _check_tau(np.atleast_1d(taus_s))
    g = np.exp(2j * np.pi * f[None, :] * taus[:, None]) - 1
    if k is not None:
        k = _check_k(k)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.conj(g) / ((np.abs(g) ** 2).sum(0) + k)
    if signal_psd is None or noise_psd is None:
        raise ValueError("k: give k, or both signal_psd and noise_psd")
    s = np.broadcast_to(np.asarray(signal_psd, dtype=np.float64), f.shape)
    n = np.asarray(noise_psd, dtype=np.float64)
    n = n[:, None] if n.ndim == 1 else n
    n = np.broadcast_to(n, g.shape)
    if np.any(n <= 0):
        raise ValueError("noise_psd: must be > 0")
    snr = s[None, :] / n
    return np.conj(g) * snr / (1 + (np.abs(g) ** 2 * snr).sum(0))


def fused_chain_gain(freq_hz, taus_s, **kwargs) -> np.ndarray:
    """Chain gain ``sum_j H_j G_j`` of :func:`fused_gains` (real, in [0, 1])."""
    f = np.atleast_1d(np.asarray(freq_hz, dtype=np.float64))
    taus = _check_tau(np.atleast_1d(taus_s))
    h = fused_gains(f, taus, **kwargs)
    g = np.exp(2j * np.pi * f[None, :] * taus[:, None]) - 1
    return np.real((h * g).sum(0))


def noise_gain(freq_hz, taus_s, **kwargs) -> np.ndarray:
    """Noise power gain ``sum_j |H_j|²`` of :func:`fused_gains` (white noise of unit PSD)."""
    h = fused_gains(freq_hz, taus_s, **kwargs)
    return (np.abs(h) ** 2).sum(0)


def pair_snr(freq, psd, noise_std, taus, dt: float) -> np.ndarray:
    """``|G_j(f)|² S(f) / (σ_j² Δt)`` per pair (pair, freq) on ``freq`` [Hz] (``psd`` two-sided [rad²/Hz],
    σ_j [rad/line])."""
    f = np.asarray(freq, dtype=np.float64)
    s = np.asarray(psd, dtype=np.float64)
    sig = np.broadcast_to(np.asarray(noise_std, dtype=np.float64), (len(taus),))
    out = np.empty((len(taus),) + f.shape)
    for j, (tau, sj) in enumerate(zip(taus, sig)):
        g2 = 2.0 * (1.0 - np.cos(2.0 * np.pi * f * tau))
        out[j] = g2 * s / max(sj * sj * dt, 1e-300)
    return out


def fused_snr(freq, psd, noise_std, taus, dt: float) -> np.ndarray:
    """``Σ_j |G_j(f)|² S(f) / (σ_j² Δt)`` on ``freq`` [Hz] (:func:`pair_snr` summed over the pairs)."""
    return pair_snr(freq, psd, noise_std, taus, dt).sum(0)
