"""``simsat optimise``: the detector layout that minimises the predicted restored error for a jitter spectrum.

Three bands A, B, C on the focal plane give the pairs A/B, B/C and A/C with
delays ``τ1``, ``τ2`` and ``τ1 + τ2``; the layout is ``(τ1, τ2)`` under a
constraint on the spread ``τ1 + τ2`` (the focal-plane height). For each
layout:

1. *screening* — the Wiener floor of each restored axis
   (:func:`restore.observability.observability`) for the spectrum of what the
   images must restore (the scenario's attitude minus its AOCS knowledge,
   averaged over seeds) and the per-line matching noise; cheap, evaluated on
   a grid of every line-period multiple;
2. *ranking* — the best few layouts of the screen, and the reference layout
   of the scenario (PHR: 7.4 / 14.8 / 22.2 ms), evaluated at the differential
   level of the studies (:func:`reports.study.evaluate.differential_point`:
   finite record, the restoration's own integration), mean over seeds: the
   *predicted restored error*;
3. *confirmation* — the best and the reference layout rendered, restored and
   scored (one seed each), against their prediction.
"""
from __future__ import annotations

import io
import sys
import time as _time
from pathlib import Path

import numpy as np
from scipy.signal import welch

from restore.observability import observability
from restore.stages import HIGHPASS_FRACTION_OF_KNOWLEDGE
from simsat.product import atomic_write_bytes, atomic_write_json
from simsat.scenario import load_scenario

from .study.evaluate import differential_point, rendered_point, scenario_pairs

__all__ = ["jitter_psd", "layout_overrides", "screen_layouts", "screen_strip_lines", "optimise_layout"]

AXES_RESTORED = ("roll", "pitch")


def jitter_psd(base: str, *, seeds=(0, 1, 2), overrides: dict | None = None) -> dict:
    """Two-sided PSD [rad²/Hz] of what the images restore (attitude − AOCS knowledge), per axis, mean over seeds.

    Returns ``{"freq": f, "roll": S, "pitch": S, "dt": line period, "ifov": rad, "highpass_hz": ...}``.
    """
    out: dict = {}
    for seed in seeds:
        sc = load_scenario(base, overrides={**(overrides or {}), "scenario": {"seed": int(seed)}})
        t = sc.line_times
        dt = sc.instrument.line_period_s
        model = sc.attitude_model()
        kn = model.knowledge_series()
        truth = dict(zip(("roll", "pitch", "yaw"), model.evaluate(t)))
        know = dict(zip(("roll", "pitch", "yaw"), kn.at(t)))
        for a in AXES_RESTORED:
            f, p = welch(truth[a] - know[a], fs=1 / dt, nperseg=min(t.size, 2048), detrend="linear")
            out.setdefault(a, []).append(p / 2.0)  # one-sided → two-sided
        out["freq"], out["dt"] = f, dt
        out["ifov"] = sc.instrument.ifov_rad(sc.acquisition.reference_detector)
        out["highpass_hz"] = HIGHPASS_FRACTION_OF_KNOWLEDGE * model.knowledge.cutoff_hz
    for a in AXES_RESTORED:
        out[a] = np.mean(out[a], axis=0)
    return out


def _tau_per_mm(sc) -> tuple[float, list]:
    """Delay per mm of along-track separation [s/mm] (flat ground, the scenario's geometry), and the three bands."""
    pairs = scenario_pairs(sc)
    if len(pairs) < 3:
        raise ValueError("the base scenario needs three visible bands at different along-track positions")
    names = sorted({n for a, b, _ in pairs for n in (a, b)},
                   key=lambda n: -sc.instrument.detector(n).along_m)[:3]
    a, b = names[0], names[1]
    sep_mm = (sc.instrument.detector(a).along_m - sc.instrument.detector(b).along_m) * 1e3
    return sc.delay_s(a, b) / sep_mm, names


def layout_overrides(sc, tau1_s: float, tau2_s: float) -> dict:
    """Overrides placing the three visible bands ``τ1`` and ``τ1 + τ2`` behind the first one, centred on the
    focal plane."""
    k, names = _tau_per_mm(sc)
    dets = [d.name for d in sc.instrument.detectors]
    top = 0.5 * (tau1_s + tau2_s) / k
    pos = {names[0]: top, names[1]: top - tau1_s / k, names[2]: top - (tau1_s + tau2_s) / k}
    return {"instrument": {"detectors": {dets.index(n): {"along_track_mm": float(v)} for n, v in pos.items()}}}


def screen_layouts(psd: dict, *, noise_px: float, max_spread_s: float, min_tau_lines: int = 2,
                   max_grid: int = 80) -> dict:
    """The worst-axis Wiener floor [px] of every layout (τ1, τ2) on a grid of line-period multiples
    (every one, or every k-th so that each axis has at most ``max_grid`` values), τ1 + τ2 ≤ max spread."""
    dt, ifov = psd["dt"], psd["ifov"]
    n_max = int(np.floor(max_spread_s / dt))
    step = max(1, int(np.ceil((n_max - min_tau_lines) / max_grid)))
    grid = np.arange(min_tau_lines, n_max + 1, step)
    floor = np.full((grid.size, grid.size), np.nan)
    for i, n1 in enumerate(grid):
        for j, n2 in enumerate(grid):
            if n1 + n2 > n_max:
                continue
            taus = [n1 * dt, n2 * dt, (n1 + n2) * dt]
            floor[i, j] = max(observability(psd["freq"], psd[a], noise_px * ifov, taus, dt,
                                            highpass_hz=psd["highpass_hz"]).floor_rms_rad / ifov
                              for a in AXES_RESTORED)
    return {"tau_lines": grid, "floor_px": floor, "dt": dt}


def screen_strip_lines(psd: dict, *, noise_px: float, strip_lines: int) -> dict:
    """Claims 22–23: one strip detector, two of its lines used as the pair — the worst-axis Wiener floor [px]
    of each line separation ``k = 1 .. strip_lines − 1`` (one pair, ``τ = k`` line periods), and the best ``k``.

    Returns ``{"separation_lines": k, "tau_s": k dt, "floor_px": floor, "best_lines": k*}``.
    """
    dt, ifov = psd["dt"], psd["ifov"]
    if int(strip_lines) < 2:
        raise ValueError(f"strip_lines: a strip needs at least 2 lines, got {strip_lines}")
    k = np.arange(1, int(strip_lines))
    floor = np.array([max(observability(psd["freq"], psd[a], noise_px * ifov, [n * dt], dt,
                                        highpass_hz=psd["highpass_hz"]).floor_rms_rad / ifov
                          for a in AXES_RESTORED) for n in k])
    return {"separation_lines": k, "tau_s": k * dt, "floor_px": floor, "best_lines": int(k[np.argmin(floor)])}


def _predicted(base, over, *, noise_px, seeds) -> dict:
    rows = [differential_point(base, {**over, "scenario": {"seed": int(s)}}, noise_px=noise_px, seed=int(s))
            for s in seeds]
    return {a: float(np.mean([r[f"{a}_rms_px"] for r in rows])) for a in AXES_RESTORED} | \
        {f"{a}_spread": float(np.std([r[f"{a}_rms_px"] for r in rows])) for a in AXES_RESTORED}


def optimise_layout(base: str, out_dir: str | Path, *, noise_px: float, max_spread_s: float | None = None,
                    seeds=(0, 1, 2, 3, 4), top: int = 5, confirm: bool = True, progress: bool = True) -> dict:
    """Screen, rank and confirm (see the module's docstring); writes ``optimise.json`` and ``optimise.png``."""
    def say(msg):
        if progress:
            print(f"optimise: {msg}", file=sys.stderr, flush=True)

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    sc = load_scenario(base)
    k, names = _tau_per_mm(sc)
    ref_taus = sorted(p[2] for p in scenario_pairs(sc))
    ref = (ref_taus[0], ref_taus[-1] - ref_taus[0])
    spread = max_spread_s if max_spread_s is not None else 0.98 * sc.instrument.focal_plane_height_m * 1e3 * k
    say(f"jitter spectrum of {sc.name} (attitude − AOCS knowledge, {len(seeds[:3])} seeds)")
    psd = jitter_psd(base, seeds=seeds[:3])
    t0 = _time.perf_counter()
    scr = screen_layouts(psd, noise_px=noise_px, max_spread_s=spread)
    say(f"screened {int(np.isfinite(scr['floor_px']).sum())} layouts in {_time.perf_counter() - t0:.1f} s")
    order = np.argsort(np.where(np.isfinite(scr["floor_px"]), scr["floor_px"], np.inf), axis=None)[:top]
    cands = [(float(scr["tau_lines"][i] * scr["dt"]), float(scr["tau_lines"][j] * scr["dt"]))
             for i, j in (np.unravel_index(o, scr["floor_px"].shape) for o in order)]
    rows = []
    for tau1, tau2 in [ref] + cands:
        over = layout_overrides(sc, tau1, tau2)
        pred = _predicted(base, over, noise_px=noise_px, seeds=seeds)
        rows.append({"tau_ms": [tau1 * 1e3, tau2 * 1e3, (tau1 + tau2) * 1e3], "predicted_px": pred,
                     "worst_px": max(pred[a] for a in AXES_RESTORED), "reference": (tau1, tau2) == ref,
                     "overrides": over})
        say(f"τ = {tau1 * 1e3:.1f} / {tau2 * 1e3:.1f} / {(tau1 + tau2) * 1e3:.1f} ms: predicted "
            + " / ".join(f"{pred[a]:.4f}" for a in AXES_RESTORED) + " px" + (" (reference)" if rows[-1]["reference"]
                                                                              else ""))
    best = min(rows, key=lambda r: r["worst_px"])
    reference = rows[0]
    result = {"scenario": sc.name, "noise_px": noise_px, "max_spread_ms": spread * 1e3, "seeds": list(seeds),
              "candidates": rows, "best": best, "reference": reference}
    if confirm:
        for tag, r in (("best", best), ("reference", reference)):
            say(f"rendering the {tag} layout to confirm ...")
            rr = rendered_point(base, r["overrides"], run_dir=out / f"confirm_{tag}")
            r["rendered_px"] = {a: rr[f"{a}_rms_px"] for a in AXES_RESTORED}
            r["rendered_over_predicted"] = {a: rr[f"{a}_rms_px"] / r["predicted_px"][a] for a in AXES_RESTORED}
    atomic_write_json(result, out / "optimise.json")
    _plot(scr, result, out / "optimise.png")
    result["_paths"] = [str(out / "optimise.json"), str(out / "optimise.png")]
    return result


def _plot(scr: dict, result: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    fig = Figure(figsize=(6.4, 5.0), layout="constrained")
    ax = fig.subplots()
    ms = scr["tau_lines"] * scr["dt"] * 1e3
    im = ax.pcolormesh(ms, ms, scr["floor_px"].T, shading="nearest", cmap="viridis_r",
                       norm=matplotlib.colors.LogNorm())
    fig.colorbar(im, ax=ax, label="Wiener floor, worst axis [px]")
    for r, marker, label in ((result["reference"], "s", "reference"), (result["best"], "*", "best")):
        ax.plot(r["tau_ms"][0], r["tau_ms"][1], marker=marker, color="red", ms=12 if marker == "*" else 8,
                ls="none", label=f"{label}: {r['worst_px']:.4f} px predicted (differential level, worst axis)")
    ax.set_xlabel("τ1 (first to second band) [ms]")
    ax.set_ylabel("τ2 (second to third band) [ms]")
    ax.set_title(f"{result['scenario']}: detector layouts, noise {result['noise_px']:.3f} px per line", fontsize=9)
    ax.legend(fontsize=8, loc="upper right")
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    atomic_write_bytes(buf.getvalue(), path)
