"""One study point (design, seed) at either level, returned as one row of the tidy table.

``differential`` — the fast level. No image is rendered: the true attitude
and the AOCS knowledge come from the scenario's own models (same seed, same
series as a render), the pairs and their delays τ from its focal plane and
viewing geometry, and each pair's per-line differential of the part the
images restore, ``e(t + τ) − e(t)`` with ``e = θ − knowledge``, gets white
matching noise of ``σ`` px per line (one per axis). It is integrated by the restoration's
own integration step (:func:`restore.axis_integration.integrate_axis`, with
the scenario's method and options, the "auto" high-pass and the knowledge
prior) and scored with the accuracy metric.

The noise ``σ`` is calibrated on a rendered run of the base scenario
(:func:`calibrate_noise`): the per-line noise the Wiener integration
estimated there from the measured differentials (median over pairs, per
axis). What this level leaves out: matching failures (gaps, outliers) and the
synthesis's model errors, which grow at large amplitude and off nadir.

``rendered`` — the full chain: render, restore, score, in a run directory of
the study that is removed afterwards (simsat wrote all of it).
"""
from __future__ import annotations

import shutil
import time as _time
import traceback
from pathlib import Path

import numpy as np

from reports.metrics import attitude_errors
from restore.axis_integration import integrate_axis
from restore.knowledge_prior import knowledge_psd_ceiling
from restore.observability import observability
from restore.settings import restoration_settings
from restore.stages import HIGHPASS_FRACTION_OF_KNOWLEDGE, visible_pairs
from simsat.attitude import KNOWLEDGE_FILTER_ORDER
from simsat.scenario import load_scenario
from simsat.units import RAD_PER_URAD

__all__ = ["evaluate_point", "differential_point", "rendered_point", "calibrate_noise", "scenario_pairs"]

AXES_RESTORED = ("roll", "pitch")


def scenario_pairs(sc) -> list[tuple[str, str, float]]:
    """(ahead, behind, τ [s]) of the pairs the restoration uses by default (:func:`restore.stages.visible_pairs`)."""
    return [(a, b, float(sc.delay_s(a, b))) for a, b in visible_pairs(sc.instrument.detectors)]


def _stats(err: np.ndarray, ifov: float) -> tuple[float, float]:
    e = err[np.isfinite(err)]
    if not e.size:
        return float("nan"), float("nan")
    e = e - e.mean()
    return float(np.sqrt(np.mean(e ** 2)) / ifov), float(np.percentile(np.abs(e), 99.7) / ifov)


def differential_point(base: str, overrides: dict, *, noise_px: float | dict, seed: int) -> dict:
    """Figures of one point at the differential level (see the module's docstring).

    ``noise_px``: per-line matching noise [px], one number or one per axis (``{"roll": .., "pitch": ..}``).
    """
    t0 = _time.perf_counter()
    sc = load_scenario(base, overrides=overrides)
    settings = restoration_settings(sc.section("restoration"))
    t = sc.line_times
    dt = sc.instrument.line_period_s
    ifov = sc.instrument.ifov_rad(sc.acquisition.reference_detector)
    model = sc.attitude_model()
    kn = model.knowledge_series()
    pairs = scenario_pairs(sc)
    taus = [p[2] for p in pairs]
    kc = model.knowledge
    hp = settings.highpass_hz if settings.highpass_hz != "auto" else HIGHPASS_FRACTION_OF_KNOWLEDGE * kc.cutoff_hz
    rng = np.random.default_rng([int(seed), 0x5D1F])
    row: dict = {"pairs": ",".join(f"{a}/{b}" for a, b, _ in pairs), "taus_ms": ",".join(f"{x * 1e3:.3f}" for x in taus)}
    truth = dict(zip(("roll", "pitch", "yaw"), model.evaluate(t)))
    know = dict(zip(("roll", "pitch", "yaw"), kn.at(t)))
    # what the images restore, e = attitude − knowledge, at t + τ of every pair (all axes at once)
    later = [np.asarray(model.evaluate(t + tau)) - np.asarray(kn.at(np.clip(t + tau, kn.time[0], kn.time[-1])))
             for tau in taus]
    for axis in AXES_RESTORED:
        k = ("roll", "pitch", "yaw").index(axis)
        e_now = truth[axis] - know[axis]
        sigma = float(noise_px[axis]) if isinstance(noise_px, dict) else float(noise_px)
        diffs = [(e_later[k] - e_now) + sigma * ifov * rng.standard_normal(t.size) for e_later in later]
        ceiling = knowledge_psd_ceiling(know[axis], dt, cutoff_hz=kc.cutoff_hz, order=KNOWLEDGE_FILTER_ORDER,
                                        rate_hz=kc.rate_hz, noise_rad=kc.noise_urad * RAD_PER_URAD) \
            if settings.knowledge_prior else None
        res = integrate_axis(diffs, taus, dt, method=settings.method, options=settings.integration_options,
                             highpass_hz=hp, psd_ceiling=ceiling, transient_factor=settings.transient_factor)
        err = res.theta - e_now
        row[f"{axis}_rms_px"], row[f"{axis}_p997_px"] = _stats(err, ifov)
        row[f"{axis}_knowledge_rms_px"], _ = _stats(e_now, ifov)
        row[f"{axis}_coverage"] = float(np.mean(np.isfinite(res.theta)))
        if res.spectrum is not None:
            obs = observability(res.spectrum.freq, res.spectrum.psd, res.spectrum.noise_std, taus, dt, highpass_hz=hp)
            row[f"{axis}_unobservable_px"] = obs.unobservable_rms_rad / ifov
            row[f"{axis}_floor_px"] = obs.floor_rms_rad / ifov
    for axis in AXES_RESTORED:
        row[f"{axis}_noise_px"] = float(noise_px[axis]) if isinstance(noise_px, dict) else float(noise_px)
    row["evaluate_s"] = _time.perf_counter() - t0
    return row


def rendered_point(base: str, overrides: dict, *, run_dir: Path, keep: bool = False) -> dict:
    """Figures of one point at the rendered level: render, restore, score (the run removed unless ``keep``)."""
    from restore.pipeline import restore_run
    from restore.restoration_io import open_restoration
    from simsat.product import read_truth
    from simsat.render.texture_bake import enable_bake
    from simsat.simulate import simulate

    enable_bake()  # the points of a study mostly share their ground: its texture is synthesised once per worker
    t0 = _time.perf_counter()
    sc = load_scenario(base, overrides=overrides)
    simulate(sc, run_dir, progress=False)
    t1 = _time.perf_counter()
    res = restore_run(run_dir, progress=False, overrides={"correct_images": False})  # a study scores the attitude
    t2 = _time.perf_counter()
    errs = attitude_errors(open_restoration(run_dir / "restoration.nc"), read_truth(run_dir))
    row: dict = {"pairs": ",".join(p.name for p in res.pairs),
                 "taus_ms": ",".join(f"{p.tau_s * 1e3:.3f}" for p in res.pairs)}
    for axis in AXES_RESTORED:
        if axis not in errs:
            continue
        e = errs[axis]
        row[f"{axis}_rms_px"], row[f"{axis}_p997_px"] = e["rms_px"], e["p997_px"]
        row[f"{axis}_knowledge_rms_px"] = e["knowledge_rms_px"]
        row[f"{axis}_coverage"] = e["coverage"]
        rec = res.integration.get(axis)
        if rec is not None:
            row[f"{axis}_unobservable_px"] = rec.unobservable_rms_rad / res.pixel_ifov_rad
            row[f"{axis}_floor_px"] = rec.floor_rms_rad / res.pixel_ifov_rad
            if rec.spectrum is not None:
                row[f"{axis}_noise_px"] = float(np.median(rec.spectrum.noise_std)) / res.pixel_ifov_rad
    row["render_s"], row["restore_s"] = t1 - t0, t2 - t1
    row["evaluate_s"] = _time.perf_counter() - t0
    if not keep:
        shutil.rmtree(run_dir, ignore_errors=True)
    return row


def calibrate_noise(base: str, overrides: dict, run_dir: Path) -> dict:
    """Per-line differential noise [px] of a rendered run of ``base``: the Wiener estimate, median over pairs/axes."""
    row = rendered_point(base, overrides, run_dir=run_dir)
    vals = [row[f"{a}_noise_px"] for a in AXES_RESTORED if f"{a}_noise_px" in row]
    if not vals:
        raise RuntimeError(f"calibration run of {base} gave no noise estimate (no data-adaptive integration)")
    return {"noise_px": float(np.median(vals)), "per_axis": {a: row.get(f"{a}_noise_px") for a in AXES_RESTORED},
            "rms_px": {a: row.get(f"{a}_rms_px") for a in AXES_RESTORED}, "overrides": overrides}


def evaluate_point(level: str, base: str, point: dict, *, noise_px: float | dict | None, work_dir: str) -> dict:
    """One row: the point's key, design, seed, figures and timings, or its error (a failed point does not stop
    the study). Runs on a Dask worker."""
    row = {"key": point["key"], "seed": point["seed"], **{f"design.{k}": _scalar(v) for k, v in point["design"].items()}}
    t0 = _time.perf_counter()
    try:
        if level == "differential":
            row.update(differential_point(base, point["overrides"], noise_px=noise_px, seed=point["seed"]))
        else:
            row.update(rendered_point(base, point["overrides"], run_dir=Path(work_dir) / "runs" / point["key"]))
        row["error"] = ""
    except Exception as e:  # recorded in the row: the study goes on
        row["error"] = f"{type(e).__name__}: {e}"
        row["traceback"] = traceback.format_exc(limit=3)
    row["wall_s"] = _time.perf_counter() - t0
    return row


def _scalar(v):
    return ",".join(str(x) for x in v) if isinstance(v, (list, tuple)) else v
