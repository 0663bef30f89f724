"""Data preparation, figs. 7–12 (single pair); Fig. 13 (pairs) and fig. 14 (polynomial) (see :mod:`reports.figures`)."""
from __future__ import annotations

from typing import Callable, Mapping, Sequence

import numpy as np

from restore.integration.transfer import chain_gain, wiener_gain

from .formulas import (
    envelope_chain_gain,
    inverse_gain,
    joint_chain_gain,
    polynomial_gain,
)
from .monte_carlo import measure_polynomial_gain, measure_sinusoid_response
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
from .tables import _block, _concat, _freq_grid, _label_k, _label_tau, _mc_freqs

__all__ = ['CONSTANT_K_METHOD', 'WIENER_MC_DT_S', 'WIENER_MC_N', 'fig07_data', 'fig08_data', 'fig09_data', 'fig10_data', 'fig11_data', 'fig12_data', 'FUSION_MC_DT_S', 'FUSION_MC_N', 'FUSION_MC_FREQS_HZ', 'fig13_data', 'FIG14_TAUS_S', 'FIG14_MC_TAUS_S', 'fig14_data']

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
