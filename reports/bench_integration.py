"""Differential-level benchmark of the integration methods on the CNES / Pleiades case.

The case (CNES paper §3.2.3 and §4; docs/design.md "reference numbers"):

* jitter: the ``cmg`` model of :mod:`simsat.attitude` — 4 exciters, harmonics
  ``[1, 2]`` (8 lines), main lines in 50–80 Hz, main-line amplitude
  ``amplitude_px`` (1 px by default; 1 px = 4 µrad), non-linear frequency drift
  of 0.2–1.1 % over the acquisition, small frequency noise (0.1 %), amplitude
  noise (5 %), random phases;
* three pairs ``tau = 7.4 / 14.8 / 22.2 ms``, sampling ``dt = 0.4 ms`` (lags of
  18.5 / 37 / 55.5 samples: not multiples of dt);
* measurement noise: 0.17 px (1 sigma) per matched point with 20 points per
  line, hence a per-line differential noise of ``0.17 / sqrt(20) = 0.038 px``
  (white, independent between pairs);
* optional gaps: NaN blocks (clouds: the same lines missing in every pair).

Metric (docs/design.md): ``error = estimate - truth`` over the estimated samples,
mean removed; RMS and 99.7th percentile of ``|error|`` in px and µrad, coverage
(fraction of samples estimated) and run time.  CNES reports 0.013 px RMS and
0.04 px at 99.7 %.

Run ``python -m reports.bench_integration`` for the table.
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from restore.integration import DEFAULT_METHOD, METHODS, integrate
from simsat.attitude import AttitudeModel
from simsat.config import Section

__all__ = ["cnes_case", "error_stats", "bench_integration", "format_table", "CNES_RMS_PX",
           "CNES_P997_PX"]

CNES_RMS_PX = 0.013   #: CNES result, RMS (px)
CNES_P997_PX = 0.04   #: CNES result, 99.7th percentile (px)
_STREAM_NOISE = 0xBE7C
_STREAM_GAPS = 0x6A95


def cnes_case(*, seed: int = 0, duration_s: float = 4.0, dt_s: float = 0.4e-3,
              taus_s=(7.4e-3, 14.8e-3, 22.2e-3), px_urad: float = 4.0, amplitude_px: float = 1.0,
              exciter_frequencies_hz=(51.2, 54.9, 73.3, 77.6), harmonics=(1, 2),
              exciter_amplitude_ratios=(0.5, 1.0, 1.0, 0.5), harmonic_amplitude_ratios=(1.0, 0.3),
              drift_percent=(0.2, 1.1), frequency_noise_percent: float = 0.1,
              amplitude_noise_percent: float = 5.0, point_noise_px: float = 0.17,
              points_per_line: int = 20, gap_fraction: float = 0.0,
              gap_length_s=(0.02, 0.2), extra_jitter: list | None = None) -> dict:
    """Build the CNES differential case.

    Parameters
    ----------
    seed : int
        Scenario seed (jitter draws, measurement noise and gaps derive from it).
    duration_s, dt_s : float
        Record length and sampling step (s).
    taus_s : sequence of float
        Lags of the pairs (s).
    px_urad : float
        Size of one pixel (µrad).
    amplitude_px : float
        Amplitude of the main lines (px).
    exciter_frequencies_hz, harmonics, exciter_amplitude_ratios, harmonic_amplitude_ratios,
    drift_percent, frequency_noise_percent, amplitude_noise_percent
        ``cmg`` jitter settings (see :class:`simsat.attitude.CMGJitter`).
    point_noise_px : float
        Matching noise per point (px, 1 sigma).
    points_per_line : int
        Matched points per line; the per-line differential noise is
        ``point_noise_px / sqrt(points_per_line)``.
    gap_fraction : float
        Fraction of lines to blank (NaN blocks common to all pairs), in [0, 0.9].
    gap_length_s : (float, float)
        Range of gap block lengths (s).
    extra_jitter : list of dict, optional
        Further ``[[attitude.jitter]]`` tables (on ``"roll"``) added to the CMG.

    Returns
    -------
    dict
        ``diffs`` (list of arrays, rad), ``taus`` (s), ``dt`` (s), ``time`` (s),
        ``truth`` (rad, at ``time``), ``noise_std`` (rad per line), ``px`` (rad),
        ``model`` (:class:`~simsat.attitude.AttitudeModel`).
    """
    if not 0 <= gap_fraction <= 0.9:
        raise ValueError(f"gap_fraction: must be in [0, 0.9], got {gap_fraction}")
    if not points_per_line >= 1:
        raise ValueError(f"points_per_line: must be >= 1, got {points_per_line}")
    px = px_urad * 1e-6
    jitter = [{
        "kind": "cmg", "axis": "roll",
        "exciter_frequencies_hz": list(exciter_frequencies_hz), "harmonics": list(harmonics),
        "amplitude_urad": amplitude_px * px_urad,
        "exciter_amplitude_ratios": list(exciter_amplitude_ratios),
        "harmonic_amplitude_ratios": list(harmonic_amplitude_ratios),
        "drift_percent": list(drift_percent),
        "frequency_noise_percent": frequency_noise_percent,
        "amplitude_noise_percent": amplitude_noise_percent,
    }]
    jitter += [dict(j, axis="roll") for j in (extra_jitter or [])]
    model = AttitudeModel.from_config(Section({"jitter": jitter}, "attitude"), seed=seed,
                                      t_start=0.0, t_end=duration_s)
    n = int(round(duration_s / dt_s))
    t = np.arange(n) * dt_s
    taus = [float(x) for x in taus_s]
    truth = model.evaluate_axis("roll", t)
    sigma = point_noise_px / np.sqrt(points_per_line) * px
    rng = np.random.default_rng(np.random.SeedSequence([seed, _STREAM_NOISE]))
    diffs = [model.evaluate_axis("roll", t + tau) - truth + sigma * rng.standard_normal(n)
             for tau in taus]
    if gap_fraction > 0:
        grng = np.random.default_rng(np.random.SeedSequence([seed, _STREAM_GAPS]))
        keep = np.ones(n, dtype=bool)
        lo, hi = (max(1, int(round(g / dt_s))) for g in gap_length_s)
        while (~keep).mean() < gap_fraction:
            a = int(grng.integers(0, n))
            keep[a:a + int(grng.integers(lo, hi + 1))] = False
        diffs = [np.where(keep, d, np.nan) for d in diffs]
    return {"diffs": diffs, "taus": taus, "dt": dt_s, "time": t, "truth": truth,
            "noise_std": sigma, "px": px, "model": model}


def error_stats(estimate, truth, px: float) -> dict:
    """RMS and 99.7th percentile of ``|estimate - truth|`` (mean removed) over estimated samples."""
    est = np.asarray(estimate, dtype=np.float64)
    ok = np.isfinite(est)
    if not ok.any():
        return {"rms_px": np.nan, "p997_px": np.nan, "rms_urad": np.nan, "p997_urad": np.nan,
                "coverage": 0.0}
    e = est[ok] - np.asarray(truth)[ok]
    e = e - e.mean()
    rms = float(np.sqrt(np.mean(e**2)))
    p997 = float(np.percentile(np.abs(e), 99.7))
    return {"rms_px": rms / px, "p997_px": p997 / px, "rms_urad": rms * 1e6,
            "p997_urad": p997 * 1e6, "coverage": float(ok.mean())}


def bench_integration(*, seed: int = 0, methods=None, duration_s: float = 4.0,
                      gap_fraction: float = 0.0, method_options: dict | None = None,
                      **case_options) -> dict:
    """Run the integration methods on the CNES case.

    Parameters
    ----------
    seed : int, keyword-only
        Scenario seed.
    methods : sequence of str, keyword-only
        Methods to run (default: all of :data:`restore.integration.METHODS`).
    duration_s : float, keyword-only
        Record length (s).
    gap_fraction : float, keyword-only
        Fraction of lines blanked by NaN blocks.
    method_options : dict, keyword-only
        ``{method: {option: value}}`` passed to :func:`restore.integration.integrate`.
    **case_options
        Further keywords of :func:`cnes_case`.

    Returns
    -------
    dict
        ``{"case": {...settings...}, "uncorrected": stats, "methods": {name: stats}}``
        where stats holds ``rms_px``, ``p997_px``, ``rms_urad``, ``p997_urad``,
        ``coverage`` and ``time_s``; ``"default"`` names the default method.
    """
    case = cnes_case(seed=seed, duration_s=duration_s, gap_fraction=gap_fraction, **case_options)
    names = list(METHODS) if methods is None else list(methods)
    for name in names:
        if name not in METHODS:
            raise ValueError(f"methods: unknown method {name!r}; known: {', '.join(METHODS)}")
    opts = method_options or {}
    px = case["px"]
    out = {}
    for name in names:
        t0 = time.perf_counter()
        est = integrate(case["diffs"], case["taus"], case["dt"], method=name, **opts.get(name, {}))
        elapsed = time.perf_counter() - t0
        out[name] = dict(error_stats(est, case["truth"], px), time_s=elapsed)
    unc = error_stats(np.zeros_like(case["truth"]), case["truth"], px)
    return {
        "case": {"seed": seed, "duration_s": duration_s, "gap_fraction": gap_fraction,
                 "taus_s": case["taus"], "dt_s": case["dt"],
                 "noise_px_per_line": case["noise_std"] / px, **case_options},
        "uncorrected": unc,
        "methods": out,
        "default": DEFAULT_METHOD,
    }


def format_table(result: dict) -> str:
    """A plain-text table of :func:`bench_integration`'s result."""
    lines = [f"{'method':<12} {'RMS px':>9} {'99.7% px':>9} {'RMS urad':>9} "
             f"{'99.7% urad':>10} {'coverage':>8} {'time s':>7}"]
    rows = list(result["methods"].items()) + [("uncorrected", dict(result["uncorrected"], time_s=0))]
    for name, s in rows:
        tag = "*" if name == result.get("default") else " "
        lines.append(f"{name + tag:<12} {s['rms_px']:9.4f} {s['p997_px']:9.4f} {s['rms_urad']:9.4f} "
                     f"{s['p997_urad']:10.4f} {s['coverage']:8.3f} {s['time_s']:7.2f}")
    lines.append(f"CNES reference: {CNES_RMS_PX} px RMS, {CNES_P997_PX} px at 99.7 %   (* default)")
    return "\n".join(lines)


def main(argv=None) -> None:  # pragma: no cover - CLI
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--duration", type=float, default=4.0)
    ap.add_argument("--gaps", type=float, default=0.0, help="gap fraction")
    ap.add_argument("--methods", nargs="*", default=None)
    args = ap.parse_args(argv)
    res = bench_integration(seed=args.seed, duration_s=args.duration, gap_fraction=args.gaps,
                            methods=args.methods)
    print(format_table(res))


if __name__ == "__main__":  # pragma: no cover
    main()
