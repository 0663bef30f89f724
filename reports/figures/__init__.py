"""Figures 7–14 of the founding patent (Airbus EP 1 843 295), recomputed.

What each figure shows (patent, section I "integración" and section III):

* **Fig. 7** – characteristics of the pseudo-inverse (Wiener) estimator
  ``H_k = conj(G) / (|G|² + k)``, ``G(ω) = e^{jωτ} − 1``, for τ = 7.44 ms
  (1/τ = 134.4 Hz), k = 0.1, line measurements above 100 Hz: the *gain*
  ``|H_k|`` (Δθ → θ̂), with the chain gain ``F_k = G·H_k`` (θ → θ̂) and the bare
  inverse filter ``1/|G|`` it regularises.  The filter cuts at every harmonic
  n/τ ("corta en todos los armónicos de frecuencia n·f_τ").
* **Fig. 8** – the *phase* of the same estimator, ``arg H_k = −π/2 − ωτ/2``
  plus π at each n/τ crossed, i.e. the sawtooth ``−90° − 180°·frac(fτ)``
  (wrapped), and of the chain, ``arg F_k = 0`` ("el estimador no introduce
  desfases").
* **Figs. 9, 10** – effect of the noise-attenuation coefficient k, other
  parameters as figs. 7–8: fig. 9 the estimator gain ``|H_k|`` (larger k → wider
  cut bands, lower peaks), fig. 10 the chain gain ``F_k`` ("el aumento de k
  disminuye además la ganancia de la cadena completa").
* **Figs. 11, 12** – "similar to figs. 9 and 10", effect of the delay τ: the cuts
  at n/τ on the estimator gain (fig. 11) and the same effect on the chain gain
  (fig. 12).
* **Fig. 13** – the pairs PAN/B2 (172.2 ms), B1/B2 (22.2 ms), B1/B0 (7.4 ms),
  B2/B0 (14.8 ms): each pair's chain gain and the combined one.  The patent
  defines the restorable band as the maximum of the elementary bands; the joint
  multi-pair Wiener estimator ``Σ|G_j|² / (Σ|G_j|² + k)`` is drawn too.
* **Fig. 14** – gain ``σ_est(t)/σ_meas`` (mean and maximum over the 6 s
  acquisition) of the least-squares estimator of a degree-5 polynomial (five
  coefficients θ1…θ5; θ0 is unobservable) versus τ, for 0.5 ms lines, one
  independent measurement every 10 lines, 12 000 lines.

Analytic curves are computed here from the formulas; Monte Carlo points are
measured by running the real :func:`restore.integration.integrate` on simulated
differentials, so each figure shows whether the code does what the formula says:
figs. 7–13 with ``method="inverse"`` (:data:`CONSTANT_K_METHOD`, the patent's
constant-k H_k; given several pairs it is the joint estimator of fig. 13 — in
that package ``method="wiener"`` is an adaptive MAP estimator without k), fig. 14
with ``method="polynomial", degree=5``.

Library layout: ``figNN_data(...)`` functions return :class:`FigureData` (a tidy
column table, also written as the CSV), ``draw_figNN(ax_or_fig, data)`` functions
draw it, and :func:`make_patent_figures` writes ``figNN_<name>.png`` / ``.csv``.

Conventions: Fourier convention ``x(t) = Re(X e^{jωt})`` (so θ(t+τ) → e^{jωτ}Θ,
as in the patent); frequencies in Hz, delays in s, phases in degrees; gains are
dimensionless (rad of θ per rad of Δθ for H_k, rad of θ̂ per rad of θ for F_k).
"""

from __future__ import annotations

import sys
import time
import warnings
from pathlib import Path
from typing import Callable

import numpy as np

from reports import plotting as P
from restore.integration.transfer import chain_gain

from .data import (
    CONSTANT_K_METHOD,
    FIG14_MC_TAUS_S,
    FIG14_TAUS_S,
    FUSION_MC_DT_S,
    FUSION_MC_FREQS_HZ,
    FUSION_MC_N,
    WIENER_MC_DT_S,
    WIENER_MC_N,
    fig07_data,
    fig08_data,
    fig09_data,
    fig10_data,
    fig11_data,
    fig12_data,
    fig13_data,
    fig14_data,
)
from .drawing import (
    _note_mc_unavailable,
    draw_fig07,
    draw_fig08,
    draw_fig09,
    draw_fig10,
    draw_fig11,
    draw_fig12,
    draw_fig13,
    draw_fig14,
)
from .formulas import (
    envelope_chain_gain,
    inverse_gain,
    joint_chain_gain,
    polynomial_gain,
    polynomial_sigma_ratio,
)
from .monte_carlo import (
    MIN_TONE_SPACING_BINS,
    _get_integrate,
    measure_polynomial_gain,
    measure_sinusoid_response,
)
from .parameters import (
    F_MAX_WIENER_HZ,
    F_RANGE_FIG13_HZ,
    FIG09_K_VALUES,
    FIG11_TAU_VALUES_S,
    FIG14_DEGREE,
    FIG14_LINE_PERIOD_S,
    FIG14_LINES_PER_MEASUREMENT,
    FIG14_N_LINES,
    FIGURE_NAMES,
    PATENT_K,
    PATENT_PAIRS,
    PATENT_TAU_S,
    FigureData,
)

__all__ = ["chain_gain", "PATENT_TAU_S", "PATENT_K", "PATENT_PAIRS", "FIG09_K_VALUES", "FIG11_TAU_VALUES_S", "FIG14_LINE_PERIOD_S", "FIG14_LINES_PER_MEASUREMENT", "FIG14_N_LINES", "FIG14_DEGREE", "F_MAX_WIENER_HZ", "F_RANGE_FIG13_HZ", "FIGURE_NAMES", "FigureData", "inverse_gain", "joint_chain_gain", "envelope_chain_gain", "polynomial_sigma_ratio", "polynomial_gain", "MIN_TONE_SPACING_BINS", "measure_sinusoid_response", "measure_polynomial_gain", "CONSTANT_K_METHOD", "WIENER_MC_DT_S", "WIENER_MC_N", "fig07_data", "fig08_data", "fig09_data", "fig10_data", "fig11_data", "fig12_data", "FUSION_MC_DT_S", "FUSION_MC_N", "FUSION_MC_FREQS_HZ", "fig13_data", "FIG14_TAUS_S", "FIG14_MC_TAUS_S", "fig14_data", "draw_fig07", "draw_fig08", "draw_fig09", "draw_fig10", "draw_fig11", "draw_fig12", "draw_fig13", "draw_fig14", "method_unavailable", "make_patent_figures"]


def method_unavailable(method: str, integrate: Callable | None = None, **options) -> str | None:
    """Why ``integrate(method=method)`` cannot be used for Monte Carlo, or None if it can.

    Probes the method on a tiny gap-free record.  Missing package/module or an
    unknown method name count as unavailable; any other error propagates (it is
    a bug to see, not to hide).
    """
    try:
        integrate = integrate or _get_integrate()
    except Exception as exc:  # ImportError or a half-written package
        return f"restore.integration not importable ({type(exc).__name__}: {exc})"
    dt, tau, n = 1e-3, 5e-3, 400
    t = np.arange(n) * dt
    d = np.sin(2 * np.pi * 3.0 * (t + tau)) - np.sin(2 * np.pi * 3.0 * t)
    try:
        integrate([d], [tau], dt, method=method, **options)
    except (ImportError, NotImplementedError) as exc:
        return f"integrate(method={method!r}) unavailable: {exc}"
    except ValueError as exc:
        if "method" in str(exc).split(":")[0]:
            return f"integrate(method={method!r}): {exc}"
        raise
    return None


def make_patent_figures(out_dir, *, monte_carlo: bool = True, seed: int = 0, progress: bool = False) -> list[Path]:
    """Write figs. 7–14 as ``figNN_<name>.png`` and ``.csv`` in ``out_dir``.

    Parameters
    ----------
    out_dir : path
        Output folder (created if needed).  Files are written atomically.
    monte_carlo : bool
        Add points measured through :func:`restore.integration.integrate`.  If the
        package or a method cannot be used (see :func:`method_unavailable`), a
        ``RuntimeWarning`` is issued and the figures concerned are drawn without
        them, with a note saying why.
    seed : int
        Seed of every Monte Carlo draw.
    progress : bool
        Say each figure on stderr as it starts (the Monte Carlo takes tens of seconds).

    Returns
    -------
    list of Path
        The files written, PNG and CSV per figure, in figure order.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    why_k = why_poly = None
    if monte_carlo:
        why_k = method_unavailable(CONSTANT_K_METHOD, k=PATENT_K)
        why_poly = method_unavailable("polynomial", degree=FIG14_DEGREE)
        for why in {why_k, why_poly} - {None}:
            warnings.warn(f"{why}; figures drawn without these Monte Carlo points",
                          RuntimeWarning, stacklevel=2)
    cache: dict = {}
    kk = dict(monte_carlo=monte_carlo and why_k is None, seed=seed)
    kp = dict(monte_carlo=monte_carlo and why_poly is None, seed=seed)
    makers = [
        (lambda: fig07_data(mc_cache=cache, **kk), draw_fig07, why_k),
        (lambda: fig08_data(mc_cache=cache, **kk), draw_fig08, why_k),
        (lambda: fig09_data(mc_cache=cache, **kk), draw_fig09, why_k),
        (lambda: fig10_data(mc_cache=cache, **kk), draw_fig10, why_k),
        (lambda: fig11_data(mc_cache=cache, **kk), draw_fig11, why_k),
        (lambda: fig12_data(mc_cache=cache, **kk), draw_fig12, why_k),
        (lambda: fig13_data(**kk), draw_fig13, why_k),
        (lambda: fig14_data(**kp), draw_fig14, why_poly),
    ]
    written: list[Path] = []
    t0 = time.perf_counter()
    for i, (make, draw, why) in enumerate(makers):
        if progress:
            print(f"figures: fig. {7 + i} ({i + 1}/{len(makers)}, {time.perf_counter() - t0:.0f} s)",
                  file=sys.stderr, flush=True)
        data = make()
        if why:
            data.meta["mc_unavailable"] = why
        _note_mc_unavailable(data)
        if data.number == 13:
            fig, axes = P.new_axes_grid(len(data.meta["pairs"]) + 1, figsize=(11.0, 10.0),
                                        height_ratios=[1, 1, 1, 1, 1.5])
            draw(axes, data)
        else:
            fig, ax = P.new_axes(figsize=(9.0, 5.6))
            draw(ax, data)
        written.append(P.save_figure(fig, out_dir / f"{data.name}.png"))
        written.append(P.write_table_csv(out_dir / f"{data.name}.csv", data.table))
    return written
