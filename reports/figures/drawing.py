"""Drawing (see :mod:`reports.figures`)."""
from __future__ import annotations

import numpy as np

from reports import plotting as P

from .data import CONSTANT_K_METHOD
from .parameters import FigureData

__all__ = ['draw_fig07', 'draw_fig08', 'draw_fig09', 'draw_fig10', 'draw_fig11', 'draw_fig12', 'draw_fig13', 'draw_fig14']

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
