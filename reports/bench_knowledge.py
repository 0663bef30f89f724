"""Benchmark of the causal AOCS knowledge's record ends: the dephased and advanced knowledge against ``|F| θ``.

A causal knowledge's phase is taken out by an all-pass, and a latency by an
advance (:mod:`restore.knowledge_dephasing`); both need the knowledge past the
record's ends, which the restoration predicts (:func:`restore.knowledge_dephasing.predicted_tail`).
This benchmark measures what that prediction leaves, with no rendering: for
draws of the stress scenarios' attitudes under a causal knowledge of several
cut-offs and a known latency, the knowledge samples (as product.nc records
them) are dephased and advanced by the true latency exactly as the restoration
does, and compared with what a perfect dephasing gives, the attitude through
the zero-phase filter of gain ``|F|`` (computed on a grid a few seconds wider
than the record, so that it has no ends of its own). The knowledge's bias and
drift are a straight line: it is taken out. Reported per scenario and cut-off:
the RMS of that difference below 1 Hz (a Gaussian low-pass: what the
restoration takes from the knowledge below its high-pass) over the record and
over its last 0.3 s, for the predicted ends and, for comparison, the point
reflection alone.

Run ``simsat bench knowledge`` (or ``python -m reports.bench_knowledge``).
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from restore.knowledge_dephasing import advance_samples, dephase_samples, prediction_memory_s
from simsat.scenario import SCENARIO_DIR, load_scenario

__all__ = ["SCENARIOS", "CUTOFFS_HZ", "LATENCY_MS", "knowledge_end_errors", "bench_knowledge", "format_table"]

#: the stress scenarios whose attitudes are drawn (lines at 2.2 / 5.5 / 9 Hz, lines at 3–8 Hz, a chirp, CMG lines
#: far above the knowledge — phr_cmg's attitude, so real_aocs' too: its own knowledge errors are replaced here —
#: and broadband jitter)
SCENARIOS = ("causal_knowledge", "low_frequencies", "damped_chirp", "large_amplitude", "broadband")
#: the causal knowledge's cut-offs [Hz]
CUTOFFS_HZ = (2.0, 4.0, 8.0)
#: the knowledge's latency, known here (the restoration measures it) [ms]
LATENCY_MS = 15.0
#: the low-pass the error is read through [Hz] and the record's end it is also read over [s]
LOWPASS_HZ = 1.0
END_S = 0.3
_PAD_S = 4.0
_FS = 2000.0


def _gaussian_lowpass(x: np.ndarray, dt: float, cutoff_hz: float) -> np.ndarray:
    from scipy.ndimage import gaussian_filter1d

    return gaussian_filter1d(x, 1.0 / (2 * np.pi * cutoff_hz) / dt, mode="nearest")


@lru_cache(maxsize=4)
def _draw(scenario: str, seed: int, cutoff_hz: float, latency_ms: float):
    """One draw's knowledge samples (the scenario's, made causal at ``cutoff_hz`` and ``latency_ms`` late),
    ``{axis: |F| θ at their times}`` and which of them lie in the record; kept for the second variant of
    :func:`knowledge_end_errors` on the same draw."""
    sc = load_scenario(scenario, overrides={"scenario": {"seed": seed}, "attitude": {"knowledge": {
        "filter": "causal", "delay_ms": latency_ms, "cutoff_hz": cutoff_hz}}})
    model = sc.attitude_model()
    kn = model.knowledge_series()
    tk = np.asarray(kn.time, dtype=np.float64)
    grid = np.arange(tk[0] - _PAD_S, tk[-1] + _PAD_S, 1.0 / _FS)
    f = np.fft.rfftfreq(grid.size, 1.0 / _FS)
    gain = 1.0 / np.sqrt(1.0 + (f / cutoff_hz) ** 8)               # |F| of the 4th-order Butterworth
    ideal = {a: np.interp(tk, grid, np.fft.irfft(np.fft.rfft(model.evaluate_axis(a, grid)) * gain, grid.size))
             for a in ("roll", "pitch")}
    return kn, ideal, (tk >= sc.t0_s) & (tk <= sc.t_end_s)


def knowledge_end_errors(scenario, *, seed: int, cutoff_hz: float, latency_ms: float = LATENCY_MS,
                         predicted: bool = True) -> dict:
    """``{axis: (rms, rms_end)}`` [rad]: the dephased and advanced knowledge less ``|F| θ`` below
    :data:`LOWPASS_HZ`, over the record and its last :data:`END_S` (module docstring), for one draw.

    Parameters
    ----------
    scenario : str or Path
        A scenario (its attitude and knowledge settings are used; the knowledge made causal at ``cutoff_hz``,
        ``latency_ms`` late).
    seed : int
        The scenario seed of the draw.
    predicted : bool
        The restoration's ends (linear prediction); False: the point reflection alone.
    """
    kn, ideal, inside = _draw(str(scenario), int(seed), float(cutoff_hz), float(latency_ms))
    tk = np.asarray(kn.time, dtype=np.float64)
    dt = float(np.median(np.diff(tk)))
    line = np.vstack([np.ones(np.count_nonzero(inside)), tk[inside]]).T
    memory = prediction_memory_s(cutoff_hz) if predicted else None
    n_end = max(1, int(round(END_S / dt)))
    out = {}
    for axis in ("roll", "pitch"):
        v = dephase_samples(getattr(kn, axis), dt, cutoff_hz=cutoff_hz, order=4, kind="butterworth_causal",
                            predicted_ends=predicted)
        v = advance_samples(v, dt, latency_ms * 1e-3, memory_s=memory)
        e = (v - ideal[axis])[inside]
        e = e - line @ np.linalg.lstsq(line, e, rcond=None)[0]
        low = _gaussian_lowpass(e, dt, LOWPASS_HZ)
        out[axis] = (float(np.sqrt(np.mean(low ** 2))), float(np.sqrt(np.mean(low[-n_end:] ** 2))))
    return out


def bench_knowledge(*, seeds: int = 30, scenarios=SCENARIOS, cutoffs=CUTOFFS_HZ, first_seed: int = 0,
                    progress=None) -> dict:
    """Per scenario and cut-off, the RMS over ``seeds`` draws and both axes of :func:`knowledge_end_errors`
    [px of the scenario's reference band], with the ends predicted and reflected. ``progress``: called with a
    line per scenario and cut-off."""
    rows = []
    for name in scenarios:
        path = SCENARIO_DIR / "stress" / f"{name}.toml"
        sc = load_scenario(path)
        ifov = sc.instrument.ifov_rad(sc.acquisition.reference_detector)
        for fc in cutoffs:
            row = {"scenario": name, "cutoff_hz": float(fc)}
            draws = {key: [] for key in ("predicted", "reflected")}
            for s in range(first_seed, first_seed + seeds):    # both variants on a draw, one after the other
                for key in draws:
                    e = knowledge_end_errors(path, seed=s, cutoff_hz=fc, predicted=key == "predicted")
                    draws[key].append([e[a] for a in ("roll", "pitch")])
            for key, errs in draws.items():
                errs = np.array(errs)
                row[key] = {"rms_px": float(np.sqrt(np.mean(errs[..., 0] ** 2)) / ifov),
                            "end_rms_px": float(np.sqrt(np.mean(errs[..., 1] ** 2)) / ifov),
                            "max_px": float(np.max(errs[..., 0]) / ifov)}
            rows.append(row)
            if progress is not None:
                progress(f"{name} {fc:g} Hz: {row['predicted']['rms_px']:.4f} px predicted, "
                         f"{row['reflected']['rms_px']:.4f} reflected")
    return {"seeds": int(seeds), "latency_ms": LATENCY_MS, "lowpass_hz": LOWPASS_HZ, "end_s": END_S, "rows": rows}


def format_table(result: dict) -> str:
    """The benchmark's rows as a text table."""
    lines = [f"causal AOCS knowledge's ends, {result['seeds']} draws per row, {result['latency_ms']:g} ms late: "
             f"dephased and advanced less |F| θ below {result['lowpass_hz']:g} Hz (px RMS; last "
             f"{result['end_s']:g} s; worst draw)",
             f"  {'scenario':18s} {'cut-off':>8s} {'predicted':>10s} {'end':>7s} {'worst':>7s} {'reflected':>10s} "
             f"{'end':>7s} {'worst':>7s}"]
    for r in result["rows"]:
        p, q = r["predicted"], r["reflected"]
        lines.append(f"  {r['scenario']:18s} {r['cutoff_hz']:6.1f}Hz {p['rms_px']:10.4f} {p['end_rms_px']:7.4f} "
                     f"{p['max_px']:7.4f} {q['rms_px']:10.4f} {q['end_rms_px']:7.4f} {q['max_px']:7.4f}")
    return "\n".join(lines)


if __name__ == "__main__":
    print(format_table(bench_knowledge(progress=print)))
