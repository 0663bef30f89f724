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
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Mapping, Sequence

import numpy as np

from reports import plotting as P
from restore.integration.transfer import chain_gain, fused_chain_gain, pair_transfer, wiener_gain

__all__ = [
    "PATENT_TAU_S",
    "PATENT_K",
    "PATENT_PAIRS",
    "FIG14_LINE_PERIOD_S",
    "FIG14_LINES_PER_MEASUREMENT",
    "FIG14_N_LINES",
    "FIG14_DEGREE",
    "FIGURE_NAMES",
    "FigureData",
    "chain_gain",
    "inverse_gain",
    "joint_chain_gain",
    "envelope_chain_gain",
    "polynomial_sigma_ratio",
    "polynomial_gain",
    "measure_sinusoid_response",
    "measure_polynomial_gain",
    "fig07_data", "fig08_data", "fig09_data", "fig10_data",
    "fig11_data", "fig12_data", "fig13_data", "fig14_data",
    "draw_fig07", "draw_fig08", "draw_fig09", "draw_fig10",
    "draw_fig11", "draw_fig12", "draw_fig13", "draw_fig14",
    "make_patent_figures",
    "method_unavailable",
    "CONSTANT_K_METHOD",
]

# ---------------------------------------------------------------------------
# Patent parameters
# ---------------------------------------------------------------------------

#: Delay of figs. 7–8 (s): 7.44 ms, i.e. 1/τ = 134.4 Hz.
PATENT_TAU_S: float = 7.44e-3
#: Noise-attenuation coefficient of figs. 7–8.
PATENT_K: float = 0.1
#: Band pairs and delays (s) of fig. 13.
PATENT_PAIRS: dict[str, float] = {
    "PAN/B2": 172.2e-3,
    "B1/B2": 22.2e-3,
    "B1/B0": 7.4e-3,
    "B2/B0": 14.8e-3,
}
#: Values of k for fig. 9/10 and of τ (s) for figs. 11/12.
FIG09_K_VALUES: tuple[float, ...] = (0.01, 0.1, 1.0)
FIG11_TAU_VALUES_S: tuple[float, ...] = (3.72e-3, 7.44e-3, 14.88e-3)
#: Fig. 14 acquisition: line period (s), lines per independent measurement,
#: number of lines (12 000 × 0.5 ms = 6 s, hence 1 200 measurements), degree.
FIG14_LINE_PERIOD_S: float = 0.5e-3
FIG14_LINES_PER_MEASUREMENT: int = 10
FIG14_N_LINES: int = 12_000
FIG14_DEGREE: int = 5

#: Frequency span (Hz) of figs. 7–12 and of fig. 13.
F_MAX_WIENER_HZ: float = 600.0
F_RANGE_FIG13_HZ: tuple[float, float] = (0.05, 500.0)

FIGURE_NAMES: dict[int, str] = {
    7: "fig07_wiener_gain",
    8: "fig08_wiener_phase",
    9: "fig09_k_estimator_gain",
    10: "fig10_k_chain_gain",
    11: "fig11_tau_estimator_gain",
    12: "fig12_tau_chain_gain",
    13: "fig13_pairs_fusion",
    14: "fig14_polynomial_gain",
}


@dataclass
class FigureData:
    """Data of one figure.

    Attributes
    ----------
    number : int
        Patent figure number.
    name : str
        File stem, e.g. ``"fig07_wiener_gain"``.
    table : dict of str → ndarray
        Tidy table, one row per point, written verbatim as the CSV.  Columns:
        ``source`` (``analytic`` / ``monte_carlo``), ``quantity``, ``series``,
        ``unit`` and numeric columns (``freq_hz``, ``tau_s``, ``k``, ``value``,
        ``stderr``, ``n_trials`` …; NaN where not applicable).
    meta : dict
        Parameters and notes (not in the CSV).
    """

    number: int
    name: str
    table: dict[str, np.ndarray]
    meta: dict = field(default_factory=dict)

    def select(self, *, source: str | None = None, quantity: str | None = None,
               series: str | None = None) -> dict[str, np.ndarray]:
        """Rows matching the given labels, as a dict of columns."""
        m = np.ones(len(self.table["source"]), dtype=bool)
        for col, want in (("source", source), ("quantity", quantity), ("series", series)):
            if want is not None:
                m &= self.table[col] == want
        return {c: v[m] for c, v in self.table.items()}

    def series_names(self, *, source: str, quantity: str) -> list[str]:
        """Distinct series of ``quantity`` from ``source``, in table order."""
        sel = self.select(source=source, quantity=quantity)["series"]
        return list(dict.fromkeys(sel.tolist()))


# ---------------------------------------------------------------------------
# Analytic transfer functions: restore.integration.transfer's (the tests hold an independent oracle)
# ---------------------------------------------------------------------------

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


# ---------------------------------------------------------------------------
# Monte Carlo through restore.integration
# ---------------------------------------------------------------------------

def _get_integrate() -> Callable:
    from restore.integration import integrate  # noqa: WPS433 (lazy: package in progress)

    return integrate


def _matvec(a: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``a @ x`` without BLAS: multi-threaded BLAS on these thin products is
    slower, and erratic on a loaded machine, than einsum's single-thread loop."""
    return np.einsum("ij,j->i", a, x)


def _blackman_harris(n: int) -> np.ndarray:
    """4-term Blackman–Harris window (side lobes −92 dB, main lobe ±4 bins)."""
    x = 2.0 * np.pi * np.arange(n) / (n - 1)
    return 0.35875 - 0.48829 * np.cos(x) + 0.14128 * np.cos(2 * x) - 0.01168 * np.cos(3 * x)


#: Minimum spacing of the Monte Carlo tones, and distance from DC, in
#: resolution bins (1 / window duration) of the Blackman–Harris window.
MIN_TONE_SPACING_BINS: float = 5.0


def measure_sinusoid_response(freqs_hz, taus_s: Sequence[float], *, method: str,
                              options: Mapping | None = None, dt_s: float, n_samples: int,
                              n_trials: int = 8, noise_std: float = 0.05,
                              amplitude: float = 1.0, seed: int = 0,
                              integrate: Callable | None = None) -> dict[str, np.ndarray]:
    """Measure the transfer of ``integrate`` with sinusoids plus white measurement noise.

    Each trial injects all the test tones at once (a multi-tone signal; the
    estimators under test are linear):
    θ(t) = A Σ_i sin(2π f_i t + φ_i) with random phases,
    ``diffs[j][n] = θ(n·dt + τ_j) − θ(n·dt) + b`` (exact differences, b white
    with std ``noise_std``·A, independent per pair),
    ``θ̂ = integrate(diffs, taus, dt, method=method, **options)``.
    The complex amplitude of each tone is taken by a Blackman–Harris-weighted
    projection over the central half of the record (away from the ends, where
    any estimator lacks data); the tones are at least
    :data:`MIN_TONE_SPACING_BINS` resolution bins apart (and from DC), so that
    leakage between them is below 1e-4.  The *chain* response is ``F = Θ̂/Θ``
    and, for a single pair, the *estimator* response ``H = Θ̂/ΔΘ`` (ΔΘ = clean
    differential), Fourier convention ``x = Re(X e^{jωt})``.

    Returns
    -------
    dict
        ``freq_hz``; ``chain_gain``, ``chain_gain_se``, ``chain_phase_deg``,
        ``chain_phase_se_deg``; for one pair also ``estimator_gain``,
        ``estimator_gain_se``, ``estimator_phase_deg``, ``estimator_phase_se_deg``
        (NaN at a blind frequency, where ΔΘ = 0); ``n_trials``; ``seconds``.
        Standard errors are the standard deviation over trials / √n_trials.
    """
    integrate = integrate or _get_integrate()
    options = dict(options or {})
    freqs = np.atleast_1d(np.asarray(freqs_hz, dtype=float))
    taus = [float(t) for t in taus_s]
    if n_trials < 2:
        raise ValueError(f"n_trials must be >= 2 (error bars), got {n_trials}")
    lo, hi = n_samples // 4, n_samples - n_samples // 4
    bin_hz = 1.0 / ((hi - lo) * dt_s)
    spacing = np.diff(np.concatenate([[0.0], np.sort(freqs)]))
    if spacing.min() < MIN_TONE_SPACING_BINS * bin_hz:
        raise ValueError(f"freqs_hz: tones closer than {MIN_TONE_SPACING_BINS} bins "
                         f"({MIN_TONE_SPACING_BINS * bin_hz:.3g} Hz) to each other or to 0 Hz; "
                         "increase n_samples")
    if freqs.max() >= 0.5 / dt_s:
        raise ValueError("freqs_hz: a tone is above the Nyquist frequency of dt_s")
    rng = np.random.default_rng(seed)
    t = np.arange(n_samples) * dt_s
    w = _blackman_harris(hi - lo)
    proj = (2.0 / w.sum()) * w[None, :] * np.exp(-2j * np.pi * freqs[:, None] * t[None, lo:hi])
    # Tone basis [sin ω_i t | cos ω_i t] (N × 2F): every signal below is basis @ coefficients,
    # sin(ωt + φ) = cos φ · sin ωt + sin φ · cos ωt.
    basis = np.hstack([np.sin(2 * np.pi * freqs[None, :] * t[:, None]),
                       np.cos(2 * np.pi * freqs[None, :] * t[:, None])])
    proj_basis = np.einsum("fn,nk->fk", proj, basis[lo:hi])  # basis projections, F × 2F
    single = len(taus) == 1
    chain = np.empty((freqs.size, n_trials), dtype=complex)
    est = np.full((freqs.size, n_trials), np.nan + 0j)
    t0 = time.perf_counter()
    for r in range(n_trials):
        phi = rng.uniform(0.0, 2.0 * np.pi, freqs.size)
        cp, sp = np.cos(phi), np.sin(phi)
        coef_theta = amplitude * np.concatenate([cp, sp])
        coef_clean = []
        for tau in taus:
            # sin(ωt + φ + ωτ) − sin(ωt + φ) in the same basis
            cw, sw = np.cos(2 * np.pi * freqs * tau) - 1.0, np.sin(2 * np.pi * freqs * tau)
            coef_clean.append(amplitude * np.concatenate([cw * cp - sw * sp, cw * sp + sw * cp]))
        diffs = [_matvec(basis, c) + noise_std * amplitude * rng.standard_normal(n_samples)
                 for c in coef_clean]
        out = np.asarray(integrate(diffs, taus, dt_s, method=method, **options), dtype=float)
        if out.shape != (n_samples,):
            raise RuntimeError(f"integrate returned shape {out.shape}, expected ({n_samples},)")
        if not np.all(np.isfinite(out[lo:hi])):
            raise RuntimeError(f"integrate(method={method!r}) returned NaN in the central half "
                               "of a gap-free record")
        c_out = _matvec(proj, out[lo:hi])
        chain[:, r] = c_out / (proj_basis @ coef_theta)
        if single:
            c_d = proj_basis @ coef_clean[0]
            ok = np.abs(c_d) > 1e-6 * amplitude
            est[ok, r] = c_out[ok] / c_d[ok]
    res = {"freq_hz": freqs, "n_trials": np.full(freqs.size, n_trials)}
    res.update(_gain_phase_stats("chain", chain))
    if single:
        res.update(_gain_phase_stats("estimator", est))
    res["seconds"] = time.perf_counter() - t0
    return res


def _gain_phase_stats(prefix: str, z: np.ndarray) -> dict[str, np.ndarray]:
    """Gain and phase of complex per-trial ratios ``z`` (frequency × trial).

    The ratios are averaged coherently (complex mean; the noise term has random
    phase from trial to trial, so the mean is unbiased, unlike the mean of |z|,
    which is biased up where the true gain is 0).  Standard errors: the scatter
    of the in-phase (gain) and quadrature (phase) components over trials / √n.
    """
    n = np.sum(np.isfinite(z), axis=1)
    zm = np.nanmean(z, axis=1)
    rot = z * np.exp(-1j * np.angle(zm))[:, None]
    gain = np.abs(zm)
    gain_se = np.nanstd(rot.real, axis=1, ddof=1) / np.sqrt(n)
    with np.errstate(divide="ignore", invalid="ignore"):
        phase_se = np.nanstd(rot.imag, axis=1, ddof=1) / np.sqrt(n) / gain
    return {
        f"{prefix}_gain": gain,
        f"{prefix}_gain_se": gain_se,
        f"{prefix}_phase_deg": np.degrees(np.angle(zm)),
        f"{prefix}_phase_se_deg": np.degrees(phase_se),
    }


def measure_polynomial_gain(taus_s, *, degree: int = FIG14_DEGREE,
                            line_period_s: float = FIG14_LINE_PERIOD_S,
                            lines_per_measurement: int = FIG14_LINES_PER_MEASUREMENT,
                            n_lines: int = FIG14_N_LINES, n_trials: int = 200,
                            n_boot: int = 200, seed: int = 0,
                            options: Mapping | None = None,
                            integrate: Callable | None = None) -> dict[str, np.ndarray]:
    """Measure σ_est/σ_meas of ``integrate(method="polynomial")`` by Monte Carlo (fig. 14).

    Each trial: a random degree-``degree`` polynomial θ(t) (to check it is
    restored exactly) plus unit white noise on one line in
    ``lines_per_measurement`` (NaN on the others), ``dt`` = line period,
    ``n_lines`` samples.  Error e(t) = (θ̂(t) − θ̂(0)) − (θ(t) − θ(0)) (the
    patent's origin convention, θ0 unobservable).  σ(t) = RMS of e(t) over
    trials; reported: mean_t σ(t) and max_t σ(t), with standard errors from a
    bootstrap over trials.  The statistics run over the lines where
    ``integrate`` returns an estimate (it declines to extrapolate past the last
    observed line, e.g. the last 9 lines when one line in 10 is measured);
    ``coverage`` gives that fraction.  θ̂(0) must exist (line 0 is measured).

    Returns
    -------
    dict
        ``tau_s``, ``mean``, ``mean_se``, ``max``, ``max_se``, ``coverage``,
        ``n_trials``, ``seconds``.
    """
    integrate = integrate or _get_integrate()
    opts = {"degree": degree}
    opts.update(options or {})
    taus = np.atleast_1d(np.asarray(taus_s, dtype=float))
    rng = np.random.default_rng(seed)
    t = np.arange(n_lines) * line_period_s
    t_acq = n_lines * line_period_s
    meas = np.zeros(n_lines, dtype=bool)
    meas[::lines_per_measurement] = True
    n_meas = int(meas.sum())
    out = {k: np.empty(taus.size) for k in ("mean", "mean_se", "max", "max_se", "coverage")}
    t0 = time.perf_counter()
    b0 = _scaled_poly_basis(t, degree, t_acq)  # θ(t) − θ(0) = b0 @ c  (b0[0] = 0)
    for i, tau in enumerate(taus):
        b_diff = _scaled_poly_basis(t + tau, degree, t_acq) - b0
        err = np.empty((n_trials, n_lines))
        d = np.full(n_lines, np.nan)
        for r in range(n_trials):
            c = rng.standard_normal(degree)  # θ(t) = Σ c_p (t/T)^p, ~1 rad
            d[meas] = b_diff[meas] @ c + rng.standard_normal(n_meas)
            est = np.asarray(integrate([d.copy()], [float(tau)], line_period_s,
                                       method="polynomial", **opts), dtype=float)
            if est.shape != (n_lines,) or not np.isfinite(est[0]):
                raise RuntimeError("integrate(method='polynomial') gave no estimate at line 0 "
                                   f"(tau = {tau} s)")
            err[r] = (est - est[0]) - b0 @ c
        covered = np.all(np.isfinite(err), axis=0)
        out["coverage"][i] = covered.mean()
        err = err[:, covered]
        sig = np.sqrt(np.mean(err ** 2, axis=0))
        out["mean"][i], out["max"][i] = sig.mean(), sig.max()
        # bootstrap over trials (on every 5th line, plus the line of the max: the
        # statistics are smooth in t, and this keeps it cheap)
        sub = np.unique(np.concatenate([np.arange(0, err.shape[1], 5), [np.argmax(sig)]]))
        e2 = err[:, sub] ** 2
        boot = rng.integers(0, n_trials, size=(n_boot, n_trials))
        bm = np.empty(n_boot)
        bx = np.empty(n_boot)
        for b in range(n_boot):
            s = np.sqrt(e2[boot[b]].mean(axis=0))
            bm[b], bx[b] = s.mean(), s.max()
        out["mean_se"][i], out["max_se"][i] = bm.std(ddof=1), bx.std(ddof=1)
    out["tau_s"] = taus
    out["n_trials"] = np.full(taus.size, n_trials)
    out["seconds"] = time.perf_counter() - t0
    return out


# ---------------------------------------------------------------------------
# Tidy tables
# ---------------------------------------------------------------------------

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


# ---------------------------------------------------------------------------
# Data preparation, figs. 7–12 (single pair)
# ---------------------------------------------------------------------------

#: Name of the ``restore.integration`` method implementing the patent's
#: constant-k pseudo-inverse ``H_k = conj(G)/(|G|² + k)`` (multi-pair:
#: ``conj(G_j)/(Σ|G_i|² + k)``).  In that package ``method="wiener"`` is an
#: adaptive MAP estimator with a data-estimated PSD prior and takes no ``k``.
CONSTANT_K_METHOD: str = "inverse"

#: Monte Carlo settings of the single-pair figures: dt such that every τ of
#: figs. 7–12 is a whole number of samples (7.44 ms = 62 × 0.12 ms).
WIENER_MC_DT_S: float = 0.12e-3
WIENER_MC_N: int = 2 ** 15


def _wiener_mc(freqs, tau_s, k, *, n_trials, seed, integrate=None):
    return measure_sinusoid_response(freqs, [tau_s], method=CONSTANT_K_METHOD, options={"k": k},
                                     dt_s=WIENER_MC_DT_S, n_samples=WIENER_MC_N,
                                     n_trials=n_trials, seed=seed, integrate=integrate)


def _single_pair_data(number: int, configs: Sequence[tuple[float, float]], quantities: Sequence[str],
                      *, vary: str, f_max_hz: float, monte_carlo: bool, n_trials: int, seed: int,
                      mc_cache: dict | None, integrate=None, mc_fractions=None) -> FigureData:
    """Shared builder: ``configs`` = [(tau_s, k)], ``quantities`` ⊂
    {estimator_gain, chain_gain, inverse_gain, estimator_phase, chain_phase}."""
    f = _freq_grid(f_max_hz, sorted({tau for tau, _ in configs}))
    blocks = []
    for tau, k in configs:
        series = _label_k(k) if vary == "k" else _label_tau(tau)
        h = wiener_gain(f, tau, k)
        values = {
            "estimator_gain": (np.abs(h), "1"),
            "chain_gain": (chain_gain(f, tau, k), "1"),
            "inverse_gain": (inverse_gain(f, tau), "1"),
            "estimator_phase": (np.degrees(np.angle(h)), "deg"),
            "chain_phase": (np.zeros_like(f), "deg"),
        }
        for q in quantities:
            v, unit = values[q]
            blocks.append(_block("analytic", q, series, unit, tau_s=tau, k=k if q != "inverse_gain" else np.nan,
                                 freq_hz=f, value=v, stderr=np.nan, n_trials=np.nan))
    meta = {"f_max_hz": f_max_hz, "configs": list(configs), "monte_carlo": False}
    if monte_carlo:
        meta["monte_carlo"] = True
        meta["mc"] = {"dt_s": WIENER_MC_DT_S, "n_samples": WIENER_MC_N, "n_trials": n_trials,
                      "method": CONSTANT_K_METHOD, "noise_std": 0.05}
        for ci, (tau, k) in enumerate(configs):
            series = _label_k(k) if vary == "k" else _label_tau(tau)
            key = ("wiener", tau, k, n_trials, seed, tuple(mc_fractions or ()))
            if mc_cache is not None and key in mc_cache:
                mc = mc_cache[key]
            else:
                fr = _mc_freqs(tau, f_max_hz, **({"fractions": mc_fractions} if mc_fractions else {}))
                mc = _wiener_mc(fr, tau, k, n_trials=n_trials, seed=seed + 1000 * ci,
                                integrate=integrate)
                if mc_cache is not None:
                    mc_cache[key] = mc
            for q in quantities:
                if q == "inverse_gain":
                    continue
                kind, what = q.split("_")
                col = f"{kind}_{what}" + ("_deg" if what == "phase" else "")
                se = f"{kind}_{what}_se" + ("_deg" if what == "phase" else "")
                unit = "deg" if what == "phase" else "1"
                blocks.append(_block("monte_carlo", q, series, unit, tau_s=tau, k=k,
                                     freq_hz=mc["freq_hz"], value=mc[col], stderr=mc[se],
                                     n_trials=mc["n_trials"]))
    return FigureData(number, FIGURE_NAMES[number], _concat(blocks), meta)


def fig07_data(*, tau_s: float = PATENT_TAU_S, k: float = PATENT_K,
               f_max_hz: float = F_MAX_WIENER_HZ, monte_carlo: bool = True,
               n_trials: int = 8, seed: int = 0, mc_cache: dict | None = None,
               integrate: Callable | None = None) -> FigureData:
    """Fig. 7: gain of the Wiener estimator |H_k|, chain gain F_k and inverse 1/|G|."""
    return _single_pair_data(7, [(tau_s, k)], ["estimator_gain", "chain_gain", "inverse_gain"],
                             vary="none", f_max_hz=f_max_hz, monte_carlo=monte_carlo,
                             n_trials=n_trials, seed=seed, mc_cache=mc_cache, integrate=integrate)


def fig08_data(*, tau_s: float = PATENT_TAU_S, k: float = PATENT_K,
               f_max_hz: float = F_MAX_WIENER_HZ, monte_carlo: bool = True,
               n_trials: int = 8, seed: int = 0, mc_cache: dict | None = None,
               integrate: Callable | None = None) -> FigureData:
    """Fig. 8: phase of the Wiener estimator arg H_k and of the chain arg F_k (= 0), deg."""
    return _single_pair_data(8, [(tau_s, k)], ["estimator_phase", "chain_phase"],
                             vary="none", f_max_hz=f_max_hz, monte_carlo=monte_carlo,
                             n_trials=n_trials, seed=seed, mc_cache=mc_cache, integrate=integrate)


def fig09_data(*, tau_s: float = PATENT_TAU_S, k_values: Sequence[float] = FIG09_K_VALUES,
               f_max_hz: float = F_MAX_WIENER_HZ, monte_carlo: bool = True,
               n_trials: int = 8, seed: int = 0, mc_cache: dict | None = None,
               integrate: Callable | None = None) -> FigureData:
    """Fig. 9: effect of k on the estimator gain |H_k| (τ = 7.44 ms)."""
    return _single_pair_data(9, [(tau_s, k) for k in k_values], ["estimator_gain"], vary="k",
                             f_max_hz=f_max_hz, monte_carlo=monte_carlo, n_trials=n_trials,
                             seed=seed, mc_cache=mc_cache, integrate=integrate,
                             mc_fractions=(0.1, 0.3, 0.5, 0.7, 0.9))


def fig10_data(*, tau_s: float = PATENT_TAU_S, k_values: Sequence[float] = FIG09_K_VALUES,
               f_max_hz: float = F_MAX_WIENER_HZ, monte_carlo: bool = True,
               n_trials: int = 8, seed: int = 0, mc_cache: dict | None = None,
               integrate: Callable | None = None) -> FigureData:
    """Fig. 10: effect of k on the chain gain F_k (τ = 7.44 ms)."""
    return _single_pair_data(10, [(tau_s, k) for k in k_values], ["chain_gain"], vary="k",
                             f_max_hz=f_max_hz, monte_carlo=monte_carlo, n_trials=n_trials,
                             seed=seed, mc_cache=mc_cache, integrate=integrate,
                             mc_fractions=(0.1, 0.3, 0.5, 0.7, 0.9))


def fig11_data(*, tau_values_s: Sequence[float] = FIG11_TAU_VALUES_S, k: float = PATENT_K,
               f_max_hz: float = F_MAX_WIENER_HZ, monte_carlo: bool = True,
               n_trials: int = 8, seed: int = 0, mc_cache: dict | None = None,
               integrate: Callable | None = None) -> FigureData:
    """Fig. 11: effect of τ on the estimator gain |H_k| (k = 0.1)."""
    return _single_pair_data(11, [(t, k) for t in tau_values_s], ["estimator_gain"], vary="tau",
                             f_max_hz=f_max_hz, monte_carlo=monte_carlo, n_trials=n_trials,
                             seed=seed, mc_cache=mc_cache, integrate=integrate,
                             mc_fractions=(0.1, 0.3, 0.5, 0.7, 0.9))


def fig12_data(*, tau_values_s: Sequence[float] = FIG11_TAU_VALUES_S, k: float = PATENT_K,
               f_max_hz: float = F_MAX_WIENER_HZ, monte_carlo: bool = True,
               n_trials: int = 8, seed: int = 0, mc_cache: dict | None = None,
               integrate: Callable | None = None) -> FigureData:
    """Fig. 12: effect of τ on the chain gain F_k (k = 0.1)."""
    return _single_pair_data(12, [(t, k) for t in tau_values_s], ["chain_gain"], vary="tau",
                             f_max_hz=f_max_hz, monte_carlo=monte_carlo, n_trials=n_trials,
                             seed=seed, mc_cache=mc_cache, integrate=integrate,
                             mc_fractions=(0.1, 0.3, 0.5, 0.7, 0.9))


# ---------------------------------------------------------------------------
# Fig. 13 (pairs) and fig. 14 (polynomial)
# ---------------------------------------------------------------------------

#: dt of the fig. 13 Monte Carlo: 0.2 ms makes all four delays whole numbers of
#: samples (861, 111, 37, 74).
FUSION_MC_DT_S: float = 0.2e-3
FUSION_MC_N: int = 2 ** 17
FUSION_MC_FREQS_HZ: tuple[float, ...] = (0.4, 0.8, 1.5, 2.9, 5.81, 11.0, 22.5, 45.05,
                                         67.57, 100.0, 135.14, 200.0, 270.27, 400.0)


def _fig13_grid(f_lo: float, f_hi: float, taus: Sequence[float], n_log: int = 1500) -> np.ndarray:
    f = [np.geomspace(f_lo, f_hi, n_log)]
    offs = np.array([-0.2, -0.1, -0.05, -0.02, -0.005, 0.0, 0.005, 0.02, 0.05, 0.1, 0.2, 0.5])
    for tau in taus:
        n = np.arange(1, int(f_hi * tau) + 1)
        f.append(((n[:, None] + offs[None, :]) / tau).ravel())
    f = np.unique(np.concatenate(f))
    return f[(f >= f_lo) & (f <= f_hi)]


def fig13_data(*, pairs: Mapping[str, float] = PATENT_PAIRS, k: float = PATENT_K,
               f_range_hz: tuple[float, float] = F_RANGE_FIG13_HZ, monte_carlo: bool = True,
               n_trials: int = 8, seed: int = 0, fusion_method: str | None = None,
               mc_freqs_hz: Sequence[float] = FUSION_MC_FREQS_HZ,
               integrate: Callable | None = None) -> FigureData:
    """Fig. 13: chain gain of each pair, the patent's envelope (max over pairs) and
    the joint Wiener fusion, k = 0.1.  Monte Carlo: ``integrate`` with
    :data:`CONSTANT_K_METHOD` per pair, and with ``fusion_method`` (default the
    same method, given all four pairs at once) for the combination."""
    fusion_method = fusion_method or CONSTANT_K_METHOD
    taus = list(pairs.values())
    f = _fig13_grid(*f_range_hz, taus)
    blocks = [_block("analytic", "chain_gain", name, "1", tau_s=tau, k=k, freq_hz=f,
                     value=chain_gain(f, tau, k), stderr=np.nan, n_trials=np.nan)
              for name, tau in pairs.items()]
    blocks.append(_block("analytic", "envelope_chain_gain", "max over pairs", "1", tau_s=np.nan,
                         k=k, freq_hz=f, value=envelope_chain_gain(f, taus, k), stderr=np.nan,
                         n_trials=np.nan))
    blocks.append(_block("analytic", "joint_chain_gain", "joint Wiener, all pairs", "1",
                         tau_s=np.nan, k=k, freq_hz=f, value=joint_chain_gain(f, taus, k),
                         stderr=np.nan, n_trials=np.nan))
    meta = {"pairs": dict(pairs), "k": k, "f_range_hz": f_range_hz, "monte_carlo": False}
    if monte_carlo:
        fr = np.array([x for x in mc_freqs_hz if f_range_hz[0] <= x <= f_range_hz[1]])
        common = dict(dt_s=FUSION_MC_DT_S, n_samples=FUSION_MC_N, n_trials=n_trials,
                      integrate=integrate)
        for j, (name, tau) in enumerate(pairs.items()):
            mc = measure_sinusoid_response(fr, [tau], method=CONSTANT_K_METHOD, options={"k": k},
                                           seed=seed + 100 + j, **common)
            blocks.append(_block("monte_carlo", "chain_gain", name, "1", tau_s=tau, k=k,
                                 freq_hz=fr, value=mc["chain_gain"], stderr=mc["chain_gain_se"],
                                 n_trials=n_trials))
        mc = measure_sinusoid_response(fr, taus, method=fusion_method, options={"k": k},
                                       seed=seed + 200, **common)
        blocks.append(_block("monte_carlo", "joint_chain_gain", "joint Wiener, all pairs", "1",
                             tau_s=np.nan, k=k, freq_hz=fr, value=mc["chain_gain"],
                             stderr=mc["chain_gain_se"], n_trials=n_trials))
        meta["monte_carlo"] = True
        meta["mc"] = {"dt_s": FUSION_MC_DT_S, "n_samples": FUSION_MC_N, "n_trials": n_trials,
                      "method": CONSTANT_K_METHOD, "fusion_method": fusion_method}
    return FigureData(13, FIGURE_NAMES[13], _concat(blocks), meta)


#: Delays (s) of the fig. 14 curve and of its Monte Carlo points.
FIG14_TAUS_S: np.ndarray = np.geomspace(1e-3, 6.0, 121)
FIG14_MC_TAUS_S: tuple[float, ...] = (0.005, 0.02, 0.1, 0.5, 2.0, 5.0)


def fig14_data(*, taus_s=FIG14_TAUS_S, degree: int = FIG14_DEGREE,
               line_period_s: float = FIG14_LINE_PERIOD_S,
               lines_per_measurement: int = FIG14_LINES_PER_MEASUREMENT,
               n_lines: int = FIG14_N_LINES, monte_carlo: bool = True,
               mc_taus_s: Sequence[float] = FIG14_MC_TAUS_S, n_trials: int = 200,
               seed: int = 0, integrate: Callable | None = None) -> FigureData:
    """Fig. 14: mean and max over the acquisition of σ_est/σ_meas versus τ,
    least-squares polynomial of degree 5."""
    kw = dict(degree=degree, line_period_s=line_period_s,
              lines_per_measurement=lines_per_measurement, n_lines=n_lines)
    g = polynomial_gain(taus_s, **kw)
    common = dict(degree=degree, line_period_s=line_period_s,
                  lines_per_measurement=lines_per_measurement, n_lines=n_lines)
    blocks = [_block("analytic", f"sigma_ratio_{s}", s, "1", tau_s=g["tau_s"], value=g[s],
                     stderr=np.nan, n_trials=np.nan, **common) for s in ("mean", "max")]
    meta = {**kw, "monte_carlo": False}
    if monte_carlo:
        mc = measure_polynomial_gain(mc_taus_s, n_trials=n_trials, seed=seed + 300,
                                     integrate=integrate, **kw)
        for s in ("mean", "max"):
            blocks.append(_block("monte_carlo", f"sigma_ratio_{s}", s, "1", tau_s=mc["tau_s"],
                                 value=mc[s], stderr=mc[f"{s}_se"], n_trials=mc["n_trials"],
                                 coverage=mc["coverage"], **common))
        meta["monte_carlo"] = True
        meta["mc"] = {"n_trials": n_trials, "seconds": mc["seconds"]}
    return FigureData(14, FIGURE_NAMES[14], _concat(blocks), meta)


# ---------------------------------------------------------------------------
# Drawing
# ---------------------------------------------------------------------------

_MC_NOTE = (r"Monte Carlo, integrate(method='%s') ($\pm 2\sigma$ bars)" % CONSTANT_K_METHOD)
_H = r"$|H_k|$"
_F = r"$F_k$"


def _curve(data: FigureData, quantity: str, series: str, source: str = "analytic"):
    d = data.select(source=source, quantity=quantity, series=series)
    return d["freq_hz"], d["value"], d.get("stderr")


def _has_mc(data: FigureData, quantity: str) -> bool:
    return bool(np.any((data.table["source"] == "monte_carlo") & (data.table["quantity"] == quantity)))


def _note_mc_unavailable(data: FigureData) -> None:
    """Remember, for the legend, why a figure has no Monte Carlo points."""
    why = data.meta.get("mc_unavailable")
    import textwrap

    data.meta["mc_note"] = (textwrap.fill(f"no Monte Carlo points — {why}"[:120], 48)
                            if why else None)


def _legend_note(ax, data: FigureData) -> None:
    if data.meta.get("mc_note"):
        ax.plot([], [], " ", label=data.meta["mc_note"])


def _blind_legend(tau: float) -> str:
    return rf"blind frequencies $n/\tau$ ($n \times$ {1 / tau:.1f} Hz)"


def draw_fig07(ax, data: FigureData):
    """Estimator gain |H_k|, chain gain F_k, inverse 1/|G| (fig. 7). Returns the figure."""
    (tau, k), = data.meta["configs"]
    s = data.series_names(source="analytic", quantity="estimator_gain")[0]
    c_h, c_f = P.SERIES_COLORS[0], P.SERIES_COLORS[1]
    f, v, _ = _curve(data, "inverse_gain", s)
    ax.plot(f, v, color="0.6", lw=1.0, ls="--", label=r"inverse filter $1/|G|$ ($k = 0$)")
    f, v, _ = _curve(data, "estimator_gain", s)
    ax.plot(f, v, color=c_h, label=rf"estimator gain {_H} ($\Delta\theta \to \hat\theta$), $k$ = {k:g}")
    f, v, _ = _curve(data, "chain_gain", s)
    ax.plot(f, v, color=c_f, label=rf"chain gain {_F} $= G H_k$ ($\theta \to \hat\theta$), $k$ = {k:g}")
    for q, c in (("estimator_gain", c_h), ("chain_gain", c_f)):
        if _has_mc(data, q):
            fm, vm, em = _curve(data, q, s, "monte_carlo")
            P.plot_mc_points(ax, fm, vm, em, color=c, label=_MC_NOTE if q == "estimator_gain" else None)
    fmax = data.meta["f_max_hz"]
    P.mark_blind_frequencies(ax, tau, f_max_hz=fmax, legend_label=_blind_legend(tau))
    ax.set_xlim(0, fmax)
    ax.set_ylim(0, 2.2)
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel("gain (rad/rad, dimensionless)")
    ax.set_title(rf"Fig. 7 — Wiener estimator gain, $\tau$ = {tau * 1e3:g} ms "
                 rf"($1/\tau$ = {1 / tau:.1f} Hz), $k$ = {k:g}")
    _legend_note(ax, data)
    P.legend_below(ax, ncols=2)
    return ax.figure


def draw_fig08(ax, data: FigureData):
    """Phase of H_k and of the chain (fig. 8). Returns the figure."""
    (tau, k), = data.meta["configs"]
    s = data.series_names(source="analytic", quantity="estimator_phase")[0]
    c_h, c_f = P.SERIES_COLORS[0], P.SERIES_COLORS[1]
    f, v, _ = _curve(data, "estimator_phase", s)
    v = v.copy()
    v[np.abs(np.diff(v, prepend=v[0])) > 90] = np.nan  # do not draw the ±180° wraps as lines
    ax.plot(f, v, color=c_h,
            label=rf"estimator: arg $H_k = -90° - 180°\cdot\mathrm{{frac}}(f\tau)$, $k$ = {k:g}")
    f, v, _ = _curve(data, "chain_phase", s)
    ax.plot(f, v, color=c_f, label=r"chain: arg $F_k = 0$ (no phase shift)")
    for q, c in (("estimator_phase", c_h), ("chain_phase", c_f)):
        if _has_mc(data, q):
            fm, vm, em = _curve(data, q, s, "monte_carlo")
            P.plot_mc_points(ax, fm, vm, em, color=c, label=_MC_NOTE if q == "estimator_phase" else None)
    fmax = data.meta["f_max_hz"]
    P.mark_blind_frequencies(ax, tau, f_max_hz=fmax, legend_label=_blind_legend(tau))
    ax.set_xlim(0, fmax)
    ax.set_ylim(-200, 215)
    ax.set_yticks(np.arange(-180, 181, 45))
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel("phase (deg)")
    ax.set_title(rf"Fig. 8 — Wiener estimator phase, $\tau$ = {tau * 1e3:g} ms, $k$ = {k:g}")
    _legend_note(ax, data)
    P.legend_below(ax, ncols=2)
    return ax.figure


def _draw_family(ax, data: FigureData, quantity: str, *, title: str, ylabel: str, ylim, vary: str):
    configs = data.meta["configs"]
    names = data.series_names(source="analytic", quantity=quantity)
    fmax = data.meta["f_max_hz"]
    taus = sorted({t for t, _ in configs})
    styles = ("-", "-", "-", "--")
    for i, (s, (tau, k)) in enumerate(zip(names, configs)):
        c = P.SERIES_COLORS[i]
        f, v, _ = _curve(data, quantity, s)
        if vary == "k":
            label = rf"$k$ = {k:g}"
        else:
            label = rf"$\tau$ = {tau * 1e3:g} ms ($1/\tau$ = {1 / tau:.1f} Hz)"
        ax.plot(f, v, color=c, ls=styles[i % len(styles)], lw=1.3, label=label)
        if _has_mc(data, quantity):
            fm, vm, em = _curve(data, quantity, s, "monte_carlo")
            P.plot_mc_points(ax, fm, vm, em, color=c, label=_MC_NOTE if i == len(names) - 1 else None)
        if len(taus) > 1:
            P.rug_blind_frequencies(ax, tau, f_max_hz=fmax, color=c, y_axes=0.975 - 0.04 * i,
                                    label=r"blind frequencies $n/\tau$ (triangles, colour of $\tau$)"
                                    if i == len(names) - 1 else None)
    if len(taus) == 1:
        P.mark_blind_frequencies(ax, taus[0], f_max_hz=fmax, legend_label=_blind_legend(taus[0]))
    ax.set_xlim(0, fmax)
    ax.set_ylim(*ylim)
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    _legend_note(ax, data)
    P.legend_below(ax, ncols=3 if vary == "k" else 2)
    return ax.figure


def draw_fig09(ax, data: FigureData):
    """Estimator gain |H_k| for several k (fig. 9). Returns the figure."""
    tau = data.meta["configs"][0][0]
    return _draw_family(ax, data, "estimator_gain", vary="k",
                        ylabel=rf"estimator gain {_H} (rad/rad)",
                        title=rf"Fig. 9 — effect of $k$ on the estimator gain {_H}, "
                              rf"$\tau$ = {tau * 1e3:g} ms ($1/\tau$ = {1 / tau:.1f} Hz)",
                        ylim=(0, 5.4))


def draw_fig10(ax, data: FigureData):
    """Chain gain F_k for several k (fig. 10). Returns the figure."""
    tau = data.meta["configs"][0][0]
    return _draw_family(ax, data, "chain_gain", vary="k",
                        ylabel=rf"chain gain {_F} $= \hat\theta/\theta$ (rad/rad)",
                        title=rf"Fig. 10 — effect of $k$ on the chain gain {_F}, "
                              rf"$\tau$ = {tau * 1e3:g} ms ($1/\tau$ = {1 / tau:.1f} Hz)",
                        ylim=(0, 1.1))


def draw_fig11(ax, data: FigureData):
    """Estimator gain |H_k| for several τ (fig. 11). Returns the figure."""
    k = data.meta["configs"][0][1]
    return _draw_family(ax, data, "estimator_gain", vary="tau",
                        ylabel=rf"estimator gain {_H} (rad/rad)",
                        title=rf"Fig. 11 — effect of $\tau$ on the estimator gain {_H}, $k$ = {k:g}",
                        ylim=(0, 1.95))


def draw_fig12(ax, data: FigureData):
    """Chain gain F_k for several τ (fig. 12). Returns the figure."""
    k = data.meta["configs"][0][1]
    return _draw_family(ax, data, "chain_gain", vary="tau",
                        ylabel=rf"chain gain {_F} $= \hat\theta/\theta$ (rad/rad)",
                        title=rf"Fig. 12 — effect of $\tau$ on the chain gain {_F}, $k$ = {k:g}",
                        ylim=(0, 1.2))


def draw_fig13(axes, data: FigureData):
    """Each pair's chain gain (one panel each) and the combined gain (bottom panel).

    ``axes``: sequence of ``len(pairs) + 1`` axes sharing x.  Returns the figure.
    """
    pairs = data.meta["pairs"]
    k = data.meta["k"]
    f_lo, f_hi = data.meta["f_range_hz"]
    axes = list(axes)
    for i, (name, tau) in enumerate(pairs.items()):
        ax = axes[i]
        c = P.SERIES_COLORS[i]
        f, v, _ = _curve(data, "chain_gain", name)
        ax.plot(f, v, color=c, lw=0.9, label=rf"{name}: $\tau$ = {tau * 1e3:g} ms, $k$ = {k:g}")
        if _has_mc(data, "chain_gain"):
            fm, vm, em = _curve(data, "chain_gain", name, "monte_carlo")
            P.plot_mc_points(ax, fm, vm, em, color="k",
                             label=f"Monte Carlo, integrate(method='{CONSTANT_K_METHOD}')\n(bars: ±2σ)"
                             if i == 0 else None)
        P.rug_blind_frequencies(ax, tau, f_max_hz=f_hi, f_min_hz=f_lo, color=c, size=4,
                                label=rf"blind $n/\tau$ ($n \times$ {1 / tau:.2f} Hz)")
        ax.set_ylim(0, 1.1)
        ax.set_yticks([0, 0.5, 1])
        ax.set_ylabel(rf"{_F} (rad/rad)")
        P.legend_right(ax, fontsize=8)
    ax = axes[-1]
    f, v, _ = _curve(data, "envelope_chain_gain", "max over pairs")
    ax.plot(f, v, color="0.6", lw=2.4, label="max over the 4 pairs\n(patent: restorable band)")
    f, v, _ = _curve(data, "joint_chain_gain", "joint Wiener, all pairs")
    ax.plot(f, v, color="k", lw=1.0,
            label="joint Wiener, all pairs:\n" + r"$\Sigma_j|G_j|^2 / (\Sigma_j|G_j|^2 + k)$, " + f"$k$ = {k:g}")
    if _has_mc(data, "joint_chain_gain"):
        fm, vm, em = _curve(data, "joint_chain_gain", "joint Wiener, all pairs", "monte_carlo")
        meth = data.meta.get("mc", {}).get("fusion_method", CONSTANT_K_METHOD)
        P.plot_mc_points(ax, fm, vm, em, color=P.SERIES_COLORS[1],
                         label=f"Monte Carlo, integrate(method='{meth}')\n(bars: ±2σ)")
    ax.set_ylim(0, 1.1)
    ax.set_yticks([0, 0.25, 0.5, 0.75, 1])
    ax.set_ylabel("combined chain gain\n(rad/rad)")
    _legend_note(ax, data)
    P.legend_right(ax, fontsize=8)
    ax.set_xscale("log")
    ax.set_xlim(f_lo, f_hi)
    ax.set_xlabel("frequency (Hz)")
    fig = axes[0].figure
    fig.suptitle("Fig. 13 — pairs PAN/B2, B1/B2, B1/B0, B2/B0 fill each other's blind frequencies "
                 rf"(chain gain $F_k$, $k$ = {k:g})", fontsize=11)
    return fig


def draw_fig14(ax, data: FigureData):
    """σ_est/σ_meas (mean and max over the acquisition) versus τ (fig. 14). Returns the figure."""
    m = data.meta
    dur = m["n_lines"] * m["line_period_s"]
    styles = {"mean": (P.SERIES_COLORS[0], "-"), "max": (P.SERIES_COLORS[1], "--")}
    for s in ("mean", "max"):
        d = data.select(source="analytic", quantity=f"sigma_ratio_{s}")
        c, ls = styles[s]
        ax.plot(d["tau_s"], d["value"], color=c, ls=ls,
                label=f"{'mean' if s == 'mean' else 'maximum'} over the {dur:g} s acquisition, "
                      r"$\sqrt{T(t)(M^TM)^{-1}T(t)^T}$")
    for s in ("mean", "max"):
        d = data.select(source="monte_carlo", quantity=f"sigma_ratio_{s}")
        if d["value"].size:
            P.plot_mc_points(ax, d["tau_s"], d["value"], d["stderr"], color=styles[s][0],
                             label=f"Monte Carlo {s}, integrate(method='polynomial') (bars: ±2σ)",
                             marker="o" if s == "mean" else "s")
    d = data.select(source="analytic", quantity="sigma_ratio_mean")
    i = int(np.searchsorted(d["tau_s"], 0.01))
    ref = d["value"][i] * d["tau_s"][i] / d["tau_s"]
    ax.plot(d["tau_s"], ref, color="0.55", lw=0.9, ls=":", label=r"$\propto 1/\tau$ (reference slope)")
    ax.axhline(10, color="0.3", lw=0.9, ls="-.",
               label="gain 10 (patent's limit: 0.1 px correlation → 1 px attitude)")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlim(d["tau_s"][0], d["tau_s"][-1])
    ax.set_ylim(0.05, 300)
    ax.set_xlabel(r"delay $\tau$ between the two acquisitions (s)")
    ax.set_ylabel(r"gain $\sigma_{est}/\sigma_{meas}$ (dimensionless)")
    ax.set_title(f"Fig. 14 — least-squares polynomial estimator (degree {m['degree']}, $\\theta_0$ unobservable): "
                 f"{m['line_period_s'] * 1e3:g} ms lines,\n1 independent measurement every "
                 f"{m['lines_per_measurement']} lines, {m['n_lines']} lines ({dur:g} s)", fontsize=10.5)
    _legend_note(ax, data)
    P.legend_below(ax, ncols=2, fontsize=8)
    return ax.figure


# ---------------------------------------------------------------------------
# Top level
# ---------------------------------------------------------------------------

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
