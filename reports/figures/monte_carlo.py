"""Monte Carlo through restore.integration (see :mod:`reports.figures`)."""
from __future__ import annotations

import time
from typing import Callable, Mapping, Sequence

import numpy as np

from restore.integration import integrate

from .formulas import _scaled_poly_basis
from .parameters import (
    FIG14_DEGREE,
    FIG14_LINE_PERIOD_S,
    FIG14_LINES_PER_MEASUREMENT,
    FIG14_N_LINES,
)

__all__ = ['MIN_TONE_SPACING_BINS', 'measure_sinusoid_response', 'measure_polynomial_gain']

def _get_integrate() -> Callable:
    """The integration the Monte Carlo points run (restore's)."""
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
