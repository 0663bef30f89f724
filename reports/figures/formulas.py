"""Analytic transfer functions: restore.integration.transfer's (the tests hold an independent oracle) (see :mod:`reports.figures`)."""
from __future__ import annotations

from typing import Sequence

import numpy as np

from restore.integration.transfer import chain_gain, fused_chain_gain, pair_transfer

from .parameters import (
    FIG14_DEGREE,
    FIG14_LINE_PERIOD_S,
    FIG14_LINES_PER_MEASUREMENT,
    FIG14_N_LINES,
)

__all__ = ['inverse_gain', 'joint_chain_gain', 'envelope_chain_gain', 'polynomial_sigma_ratio', 'polynomial_gain']

def inverse_gain(freq_hz, tau_s: float) -> np.ndarray:
    """Gain ``1/|G|`` of the bare inverse filter (inf at the blind frequencies)."""
    with np.errstate(divide="ignore"):
        return 1.0 / np.abs(pair_transfer(freq_hz, tau_s))


def joint_chain_gain(freq_hz, taus_s: Sequence[float], k: float) -> np.ndarray:
    """Chain gain of the joint multi-pair Wiener estimator ``Σ_j |G_j|² / (Σ_j |G_j|² + k)``.

    Minimising ``Σ_j |Δ_j − G_j Θ|² + k|Θ|²`` gives
    ``Θ̂ = Σ_j conj(G_j) Δ_j / (Σ_j |G_j|² + k)``: blind only where *all* pairs are blind.
    """
    return fused_chain_gain(freq_hz, list(taus_s), k=k)


def envelope_chain_gain(freq_hz, taus_s: Sequence[float], k: float) -> np.ndarray:
    """Patent's restorable band: the maximum over pairs of the elementary chain gains."""
    return np.max([chain_gain(freq_hz, t, k) for t in taus_s], axis=0)


def _scaled_poly_basis(t: np.ndarray, degree: int, t_scale: float) -> np.ndarray:
    """Columns ``(t/t_scale)^p``, p = 1…degree (the constant is unobservable)."""
    u = np.asarray(t, dtype=float)[:, None] / t_scale
    return u ** np.arange(1, degree + 1)[None, :]


def polynomial_sigma_ratio(tau_s: float, *, degree: int = FIG14_DEGREE,
                           line_period_s: float = FIG14_LINE_PERIOD_S,
                           lines_per_measurement: int = FIG14_LINES_PER_MEASUREMENT,
                           n_lines: int = FIG14_N_LINES) -> dict[str, np.ndarray]:
    """σ_est(t)/σ_meas of the least-squares polynomial estimator, for one delay.

    Model (patent §III, "Método de mínimos cuadrados"):
    θ(t) = θ0 + Σ_{p=1..n} θ_p t^p, measurement Δθ_i = θ(t_i+τ) − θ(t_i) + b_i,
    b_i independent with std σ_meas.  Design matrix rows
    ``M_i = ((t_i+τ)^p − t_i^p)_{p=1..n}``; the estimate is
    ``Θ̂ = (MᵀM)⁻¹MᵀΔ`` and ``θ̂(t) − θ̂(0) = T(t)·Θ̂`` with ``T(t) = (t^p)_p``,
    a linear function of the noise, so

        σ_est²(t) = σ_meas² · T(t) (MᵀM)⁻¹ T(t)ᵀ.

    The origin t = 0 is the first line (σ_est(0) = 0: the error there is absorbed
    by the unobservable θ0).  Measurements at t_i = i·lines_per_measurement·Te,
    i = 0 … n_lines/lines_per_measurement − 1; σ_est evaluated at every line
    t = m·Te, m = 0 … n_lines − 1.  Computed in scaled time u = t/T_acq (the ratio
    is invariant under any rescaling of the basis) with a QR factorisation:
    ``M = QR`` → ``T (MᵀM)⁻¹ Tᵀ = ‖R⁻ᵀ Tᵀ‖²``.

    Returns
    -------
    dict
        ``t_s`` (line times, s), ``ratio`` (σ_est/σ_meas at each line),
        ``t_meas_s`` (measurement times, s).
    """
    if tau_s <= 0:
        raise ValueError(f"tau_s must be > 0, got {tau_s!r}")
    if n_lines % lines_per_measurement:
        raise ValueError("n_lines must be a multiple of lines_per_measurement")
    t_acq = n_lines * line_period_s
    t_line = np.arange(n_lines) * line_period_s
    t_meas = t_line[::lines_per_measurement]
    m = (_scaled_poly_basis(t_meas + tau_s, degree, t_acq)
         - _scaled_poly_basis(t_meas, degree, t_acq))
    a = _scaled_poly_basis(t_line, degree, t_acq)
    _, r = np.linalg.qr(m, mode="reduced")
    z = np.linalg.solve(r.T, a.T)  # R⁻ᵀ Aᵀ, shape (degree, n_lines)
    ratio = np.sqrt(np.sum(z * z, axis=0))
    return {"t_s": t_line, "ratio": ratio, "t_meas_s": t_meas}


def polynomial_gain(taus_s, **kwargs) -> dict[str, np.ndarray]:
    """Mean and maximum over the acquisition of σ_est(t)/σ_meas for each τ (fig. 14).

    Keyword arguments are those of :func:`polynomial_sigma_ratio`.
    Returns ``tau_s``, ``mean``, ``max`` arrays.
    """
    taus = np.atleast_1d(np.asarray(taus_s, dtype=float))
    mean = np.empty(taus.size)
    mx = np.empty(taus.size)
    for i, tau in enumerate(taus):
        r = polynomial_sigma_ratio(float(tau), **kwargs)["ratio"]
        mean[i], mx[i] = r.mean(), r.max()
    return {"tau_s": taus, "mean": mean, "max": mx}
