"""Run report data: spectra and transfer functions (see :mod:`reports.report_data`)."""
from __future__ import annotations

import time as _time
from typing import Callable, Sequence

import numpy as np
from scipy.signal import csd, get_window, welch

from restore.integration.methods import integration_method
from restore.integration.transfer import chain_gain, fused_chain_gain, fused_snr
from simsat.units import AXES

from .budget import axis_integration
from .headline import attitude_table, restored_axes
from .loading import RunData
from .series import longest_finite_run

__all__ = ['welch_settings', 'spectra', 'frozen_chain_gain', 'probe_window_gain', 'integration_probe', 'measured_transfer', 'analytic_chain_gain', 'analytic_joint_gain', 'regularisation_k']


def welch_settings(n: int) -> dict:
    """Welch parameters used everywhere in the report for a record of ``n`` samples.

    Hann window, segments of ``nperseg`` = largest power of two ≤ n/4
    (64 … 8192; the whole record when n < 64), 50 % overlap, constant detrend,
    one-sided density.
    """
    if n < 64:
        nps = max(int(n), 1)
    else:
        nps = int(2 ** np.floor(np.log2(max(n / 4.0, 64))))
        nps = int(min(max(nps, 64), 8192))
    return {"window": "hann", "nperseg": nps, "noverlap": nps // 2, "detrend": "constant",
            "scaling": "density", "return_onesided": True}


def spectra(run: RunData) -> dict:
    """Welch PSDs [rad²/Hz] per axis over the longest fully estimated stretch.

    Returns
    -------
    dict
        ``freq_hz`` (common frequency grid); per axis ``psd_delta_<a>``
        (true − knowledge), ``psd_correction_<a>``, ``psd_error_<a>`` (restored −
        true) — only those that exist —, ``span_<a>`` (first line, stop line),
        ``fs_hz``, ``nperseg``.
    """
    att = attitude_table(run)
    fs = 1.0 / run.line_period_s
    out: dict = {"fs_hz": fs}
    have_truth = run.truth is not None
    have_rest = run.restoration is not None
    series_all = {}
    for a in AXES:
        s = {}
        if have_truth:
            s["delta"] = att[f"delta_{a}"]
        if have_rest:
            s["correction"] = att[f"correction_{a}"]
            if have_truth:
                s["error"] = att[f"restored_{a}"] - att[f"true_{a}"]
        if have_rest:
            s = {k: np.where(np.isfinite(att[f"restored_{a}"]), v, np.nan) for k, v in s.items()}
        series_all[a] = s
    # one common span (shortest over axes) so that all PSDs share a frequency grid
    spans = {a: longest_finite_run(*series_all[a].values()) if series_all[a] else slice(0, 0) for a in AXES}
    n = min((sl.stop - sl.start) for sl in spans.values()) if spans else 0
    if n < 16:
        out["freq_hz"] = np.zeros(0)
        out["nperseg"] = 0
        return out
    ws = welch_settings(n)
    out["nperseg"] = ws["nperseg"]
    for a in AXES:
        sl = spans[a]
        out[f"span_{a}"] = (sl.start, sl.stop)
        for k, v in series_all[a].items():
            f, p = welch(np.asarray(v[sl], dtype=np.float64), fs=fs, **ws)
            out["freq_hz"] = f
            out[f"psd_{k}_{a}"] = p
    return out


def _band_limited_probe(n: int, te: float, taus: Sequence[float], rng) -> tuple:
    """Band-limited random θ (periodic over n samples) and its exact differentials θ(t+τ) − θ(t)."""
    nf = n // 2 + 1
    x = rng.standard_normal(nf) + 1j * rng.standard_normal(nf)
    x[0] = 0.0
    if n % 2 == 0:
        x[-1] = 0.0  # Nyquist bin: a fractional delay of it is ambiguous
    f = np.fft.rfftfreq(n, te)
    theta = np.fft.irfft(x, n)
    diffs = [np.fft.irfft(x * (np.exp(2j * np.pi * f * tau) - 1.0), n) for tau in taus]
    return theta, diffs


def _transfer_estimate(x, y, fs, ws) -> tuple:
    """Cross-spectral transfer estimate Y/X: (freq, Pxy, Pxx, Pyy) over the longest common finite run."""
    sl = longest_finite_run(x, y)
    xs, ys = np.asarray(x[sl], float), np.asarray(y[sl], float)
    if xs.size < ws["nperseg"]:
        ws = welch_settings(xs.size)
    f, pxy = csd(xs, ys, fs=fs, **ws)
    _, pxx = welch(xs, fs=fs, **ws)
    _, pyy = welch(ys, fs=fs, **ws)
    return f, pxy, pxx, pyy


def _options_for_pairs(options: dict, idx: Sequence[int], n_pairs: int) -> dict:
    """Options restricted to the pairs ``idx`` (per-pair sequences such as ``noise_std`` are sliced), without
    those the axis's integration reads or records rather than the method (a transient's windows, the notches
    raised: :data:`restore.axis_integration.AXIS_OPTIONS`)."""
    from restore.axis_integration import AXIS_OPTIONS

    out = {k: v for k, v in options.items() if k not in AXIS_OPTIONS}
    for key in ("noise_std",):
        v = out.get(key)
        if v is not None and np.ndim(v) == 1 and len(v) == n_pairs:
            out[key] = np.asarray(v, dtype=np.float64)[list(idx)]
    w = out.get("weights")
    if w is not None and len(w) == n_pairs:  # one array per pair
        out["weights"] = [w[i] for i in idx]
    return out


def frozen_chain_gain(freq_hz, taus: Sequence[float], spectrum: dict, te: float) -> np.ndarray:
    """Analytic chain gain of the multi-pair Wiener filter with a frozen prior.

    ``F = SNR / (1 + SNR)``, ``SNR = Σ_j |G_j|² S/N_j`` (:func:`restore.integration.transfer.fused_snr`),
    ``S`` the (two-sided) PSD prior of θ and ``N_j = σ_j² Δt`` the PSD of the white noise of pair j.
    """
    f = np.asarray(freq_hz, dtype=np.float64)
    s = np.interp(np.abs(f), spectrum["freq"], spectrum["psd"], left=0.0, right=0.0)
    snr = fused_snr(f, s, spectrum["noise_std"], list(taus), te)
    return snr / (1.0 + snr)


def probe_window_gain(freq_hz, taus: Sequence[float], spectrum: dict, te: float, n: int, *,
                      oversample: int = 16) -> np.ndarray:
    """:func:`frozen_chain_gain` as :func:`integration_probe` sees it: averaged over its spectral window.

    The probe estimates the gain by Welch cross-spectra (Hann segments of
    ``welch_settings(2 n)["nperseg"]`` samples), i.e. the filter's gain
    averaged over the Hann window's spectral kernel |W(ν)|² (a main lobe of
    ± 2 bins). A prior estimated from quasi-harmonic jitter has lines
    narrower than that, where the point formula jumps between 0 and 1 and the
    probe cannot: comparing like with like needs the same averaging.
    """
    f = np.asarray(freq_hz, dtype=np.float64)
    nps = welch_settings(2 * n)["nperseg"]
    fs = 1.0 / te
    w = get_window("hann", nps)
    kern = np.abs(np.fft.fft(w, nps * oversample)) ** 2
    kern /= kern.sum()
    off = np.fft.fftfreq(nps * oversample, te)
    keep = kern > kern.max() * 1e-6
    kern, off = kern[keep] / kern[keep].sum(), off[keep]
    fine = np.arange(0.0, fs / 2 + fs / (nps * oversample), fs / (nps * oversample))
    g = frozen_chain_gain(fine, taus, spectrum, te)
    return np.array([np.sum(kern * np.interp(np.abs(fi - off), fine, g)) for fi in f])


def integration_probe(taus: Sequence[float], te: float, n: int, *, integrate: Callable, method: str | None,
                      options: dict | None = None, pair_names: Sequence[str] | None = None,
                      n_realisations: int = 1, seed: int = 0, amplitude_rad: float = 1e-6) -> dict:
    """Transfer θ → θ̂ of the integration actually used, measured by re-running it.

    A band-limited random attitude θ (flat spectrum up to Nyquist) and its exact
    differentials for every pair are integrated with ``integrate`` (all pairs:
    *fused*; each pair alone: *per pair*); the transfer is the Welch
    cross-spectrum θ̂·θ* over the θ PSD (Welch segments of the largest power of
    two ≤ n/2: the probe has no noise, resolution matters more than averaging),
    averaged over ``n_realisations``. ``options`` are those of the run, frozen
    where the method adapts to its data (:func:`freeze_integration`); per-pair
    options (``noise_std`` as a sequence) are sliced for the single pairs. The
    probe has a physical size (RMS ``amplitude_rad``): iterative solvers stop on
    tolerances that are not scale-free, and a 1-rad probe is not integrated like
    µrad jitter.

    Returns
    -------
    dict
        ``freq_hz``, ``gain_fused``, ``phase_fused_deg``, ``gain_<pair>`` (NaN
        if integrating that pair alone failed), ``errors`` {label: message},
        ``seconds``.
    """
    t0 = _time.perf_counter()
    opts = dict(options or {})
    names = list(pair_names) if pair_names is not None else [f"pair{j}" for j in range(len(taus))]
    rng = np.random.default_rng(seed)
    fs = 1.0 / te
    # the probe is noise-free: longer segments (n/2) for frequency resolution, 3 of them with the overlap
    ws = welch_settings(2 * n)
    acc: dict = {}
    errors: dict = {}
    freq = None
    cases = [("fused", list(range(len(taus))))]
    if len(taus) > 1:
        cases += [(names[j], [j]) for j in range(len(taus))]
    else:
        cases += [(names[0], [0])]
    for _ in range(n_realisations):
        theta, diffs = _band_limited_probe(n, te, taus, rng)
        scale = float(amplitude_rad) / max(float(np.std(theta)), 1e-300)
        theta = theta * scale
        diffs = [d * scale for d in diffs]
        for label, idx in cases:
            if label in errors:
                continue
            if label != "fused" and len(taus) == 1 and "fused" in acc:
                acc[label] = acc["fused"]
                continue
            try:
                est = integrate([diffs[j] for j in idx], [float(taus[j]) for j in idx], te, method=method,
                                **_options_for_pairs(opts, idx, len(taus)))
                est = np.asarray(est, dtype=np.float64)
                if est.shape != theta.shape:
                    raise ValueError(f"integrate returned shape {est.shape}, expected {theta.shape}")
                f, pxy, pxx, _ = _transfer_estimate(theta, est, fs, ws)
            except Exception as e:  # one case failing must not sink the report
                errors[label] = f"{type(e).__name__}: {e}"
                continue
            freq = f if freq is None else freq
            if f.shape != freq.shape:
                errors[label] = "estimated span too short"
                continue
            s = acc.setdefault(label, [0.0, 0.0])
            s[0] = s[0] + pxy
            s[1] = s[1] + pxx
    out: dict = {"freq_hz": freq if freq is not None else np.zeros(0), "errors": errors}
    for label, _ in cases:
        key = "fused" if label == "fused" else label
        if label in acc and label not in errors:
            h = acc[label][0] / acc[label][1]
            out[f"gain_{key}"] = np.abs(h)
            out[f"phase_{key}_deg"] = np.degrees(np.angle(h))
        else:
            n_f = 0 if freq is None else freq.size
            out[f"gain_{key}"] = np.full(n_f, np.nan)
            out[f"phase_{key}_deg"] = np.full(n_f, np.nan)
    out["seconds"] = _time.perf_counter() - t0
    return out


def measured_transfer(run: RunData) -> dict:
    """Measured transfer of the whole chain, per axis: correction vs (true − knowledge).

    ``H(f) = P_{δ,c}(f) / P_{δ,δ}(f)`` (Welch cross-spectrum of the part to
    restore δ = true − knowledge and the restored correction c, over the δ
    PSD), with the coherence ``γ² = |P_{δc}|² / (P_δδ P_cc)``. ``significant``
    marks the bins where the ratio means something: δ has power there (PSD
    ≥ 1e-4 of its maximum above DC) and more than ten times the part of the
    correction that is not correlated with it, ``P_cc (1 − γ²)`` (so a blind
    frequency, where the correlated part vanishes, still shows if δ has power).

    Returns
    -------
    dict
        ``freq_hz``; per axis ``gain_<a>``, ``phase_<a>_deg``, ``coherence_<a>``,
        ``psd_delta_<a>``, ``significant_<a>`` (bool). Empty without truth or
        restoration.
    """
    if run.truth is None or run.restoration is None:
        return {}
    att = attitude_table(run)
    fs = 1.0 / run.line_period_s
    out: dict = {}
    spans = {}
    for a in restored_axes(run):
        m = np.isfinite(att[f"restored_{a}"])
        spans[a] = longest_finite_run(np.where(m, att[f"delta_{a}"], np.nan), att[f"correction_{a}"])
    if not spans:
        return {}
    n = min(sl.stop - sl.start for sl in spans.values())
    if n < 16:
        return {}
    ws = welch_settings(n)
    for a, sl in spans.items():
        x = att[f"delta_{a}"][sl]
        y = att[f"correction_{a}"][sl]
        f, pxy, pxx, pyy = _transfer_estimate(x, y, fs, ws)
        with np.errstate(divide="ignore", invalid="ignore"):
            h = pxy / pxx
            coh = np.abs(pxy) ** 2 / (pxx * pyy)
        out["freq_hz"] = f
        out[f"gain_{a}"] = np.abs(h)
        out[f"phase_{a}_deg"] = np.degrees(np.angle(h))
        out[f"coherence_{a}"] = coh
        out[f"psd_delta_{a}"] = pxx
        peak = np.max(pxx[1:]) if pxx.size > 1 else np.inf
        with np.errstate(invalid="ignore"):
            uncorrelated = pyy * np.clip(1.0 - coh, 0.0, 1.0)
            sig = (pxx >= 1e-4 * peak) & (pxx >= 10.0 * uncorrelated) & np.isfinite(h)
        sig[0] = False
        out[f"significant_{a}"] = sig
    return out


def analytic_chain_gain(freq_hz, tau_s: float, k: float) -> np.ndarray:
    """Single-pair Wiener chain gain ``F_k = 2(1−cos ωτ) / (2(1−cos ωτ) + k)`` (:func:`restore.integration.transfer.chain_gain`)."""
    return np.asarray(chain_gain(np.asarray(freq_hz, float), float(tau_s), float(k)), dtype=np.float64)


def analytic_joint_gain(freq_hz, taus: Sequence[float], k: float) -> np.ndarray:
    """Joint multi-pair Wiener chain gain ``Σ|G_j|² / (Σ|G_j|² + k)``, ``G_j = e^{jωτ_j} − 1``."""
    return fused_chain_gain(np.asarray(freq_hz, float), list(taus), k=k)


def regularisation_k(method: str | None, options: dict) -> float | None:
    """The fixed regularisation k of a method that is the stationary filter Σ|G|²/(Σ|G|² + k), if it has one."""
    try:
        key = integration_method(method or None).gain_option
    except ValueError:
        return None
    v = (options or {}).get(key) if key else None
    if key and v is None:
        v = integration_method(method or None).options().get(key)
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) and v > 0 else None


def _frozen_analytic(probe: dict, taus, names, spectrum: dict, te: float, n: int) -> dict:
    """The frozen Wiener filter's analytic gains (fused and per pair) at the probe's resolution."""
    f = probe["freq_hz"]
    an = {"freq_hz": f, "label": "Wiener with the frozen PSD prior and noise (probe's resolution)",
          "gain_joint": probe_window_gain(f, taus, spectrum, te, n)}
    sig = np.broadcast_to(np.atleast_1d(spectrum["noise_std"]), (len(taus),))
    for j, nm in enumerate(names):
        an[f"gain_{nm}"] = probe_window_gain(f, [taus[j]], {**spectrum, "noise_std": sig[j:j + 1]}, te, n)
    return an


def _constant_k_analytic(freq_hz, taus, names, k: float | None) -> dict:
    """The constant-k Wiener chain gains (the method's k, or k = 0.1 as an illustration)."""
    kk = k if k is not None else 0.1
    an = {"freq_hz": freq_hz, "label": f"Wiener k = {kk:g}" + ("" if k is not None else ", illustration"),
          "gain_joint": analytic_joint_gain(freq_hz, taus, kk)}
    for j, nm in enumerate(names):
        an[f"gain_{nm}"] = analytic_chain_gain(freq_hz, taus[j], kk)
    return an


def transfer_curves(run, taus, names, axes, *, method: str, options: dict, integrate, f_max: float | None) -> dict:
    """The integration's transfer per restored axis: probed by re-running it, and analytic references.

    Each axis's integration is probed with its recorded options (a
    data-adaptive prior frozen: :func:`reports.report_data.axis_integration`);
    axes whose filter does not depend on the data share one probe. The
    analytic reference is the frozen Wiener filter where there is one, else
    the constant-k chain gain. ``integrate`` None: analytic curves only.

    Returns
    -------
    dict
        ``probes`` {axis: :func:`integration_probe` output}, ``analytic`` {axis:
        {freq_hz, label, gain_joint, gain_<pair>}}, ``frozen`` (bool), ``gaps``
        (analytic − probed deviations, text), ``notes`` (what failed).
    """
    te, n = run.line_period_s, run.time.size
    probes: dict = {}
    analytic: dict = {}
    notes: list = []
    gaps: list = []
    frozen = False
    shared: dict = {}  # method → the probe of a filter that does not depend on the data
    for a in (axes if integrate is not None else ()):
        fz = axis_integration(run, a)
        if fz["error"]:
            notes.append(f"{a}: re-running the integration failed: {fz['error']}")
            continue
        # the method this axis ran (restoration.method = "auto" chooses per axis)
        used = fz["record"].method if fz["record"] is not None else (method or None)
        if not fz["frozen"] and used in shared:
            probes[a] = shared[used]
        else:
            corr = np.asarray(run.restoration[f"correction_{a}"].values, dtype=np.float64)
            amp = float(np.nanstd(corr)) if np.isfinite(corr).any() and np.nanstd(corr) > 0 else 1e-6
            probes[a] = integration_probe(taus, te, n, integrate=integrate, method=used,
                                          options=fz["options"], pair_names=names, amplitude_rad=amp)
            if not fz["frozen"]:
                shared[used] = probes[a]
            notes += [f"{a}: integrating {'all pairs' if label == 'fused' else label + ' alone'} failed: {msg}"
                      for label, msg in probes[a]["errors"].items()]
        if fz["frozen"]:
            frozen = True
            analytic[a] = an = _frozen_analytic(probes[a], taus, names, fz["spectrum"], te, n)
            f = an["freq_hz"]
            band = (f >= 1.0) & (f <= (f_max or f[-1])) & np.isfinite(probes[a]["gain_fused"])
            if band.any():
                dev = np.abs(an["gain_joint"][band] - probes[a]["gain_fused"][band])
                gaps.append(f"{a}: median {np.median(dev):.3f}, largest {np.max(dev):.2f}")
    k = regularisation_k(method or None, options)
    for a in axes:
        if a in analytic or (a in probes and k is None):
            continue
        f = probes[a]["freq_hz"] if a in probes and probes[a]["freq_hz"].size else np.fft.rfftfreq(max(n, 4096), te)
        analytic[a] = _constant_k_analytic(f, taus, names, k)
    return {"probes": probes, "analytic": analytic, "frozen": frozen, "gaps": gaps, "notes": notes}
