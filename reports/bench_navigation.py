"""``simsat bench navigation``: the aided INS over the default and the degraded scenario.

Measured, and written to ``bench/navigation.json``:

* accuracy over ≥ 20 Monte Carlo seeds (IMU and initial errors; the frames
  depend on the true flight only and are rendered once): final horizontal
  error (median, 95th percentile, max), the unaided INS's, the improvement,
  and the filter's consistency (share of updates whose mean NEES over seeds
  lies inside its 95 % χ² bounds);
* the degraded scenario: every update inside a desert or fog stretch must be
  "no aiding"; a *wrong fix* is an update after which the horizontal error
  exceeds 3 × the filter's horizontal σ (counted everywhere);
* segment detection + tracking time per frame, on the rendered frames of the
  run (640 × 480 on this machine's cores), apart from rendering.

The runs and their reports are written to ``bench/navigation/<scenario>/``.
"""
from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np

from navigation.io import navigation_dataset, summarise, write_navigation
from navigation.run import NavigationRun
from navigation.scenario import load_navigation_scenario
from navigation.segments import SegmentExtractor
from navigation.tracking import track_sequence
from navigation.measurement import ground_plane_homographies

__all__ = ["bench_navigation", "wrong_fixes", "degraded_flags", "detection_tracking_ms"]


def wrong_fixes(ds) -> dict:
    """Updates with a fix after which the horizontal error exceeds 3 σ of the filter."""
    err = np.hypot(ds.update_error.values[..., 0], ds.update_error.values[..., 1])
    sig = np.hypot(ds.update_sigma.values[..., 0], ds.update_sigma.values[..., 1])
    ok = ds.update_status.values == "ok"
    wrong = ok & (err > 3 * sig)
    return {"fixes": int(ok.sum()), "wrong": int(wrong.sum()), "wrong_fraction": float(wrong.sum() / max(ok.sum(), 1))}


def degraded_flags(ds, sc) -> dict:
    """How the updates that see only the scenario's degraded stretches were flagged."""
    d = ds.update_distance_m.values
    inside = np.zeros(len(d), bool)
    for s in sc.degraded:
        # fog surrounds the vehicle; a desert is seen only once the camera's range lies inside it
        end = s.to_m if s.kind == "fog" else s.to_m - sc.sensor.max_range_m
        inside |= (d >= s.from_m) & (d <= end)
    st = ds.update_status.values[:, inside]
    return {"updates_inside": int(inside.sum()), "fixes_inside": int((st == "ok").sum()),
            "flagged_no_aiding_fraction": float((st != "ok").mean()) if st.size else 1.0,
            "sigma_growth_m": _sigma_growth(ds, inside)}


def _sigma_growth(ds, inside) -> float:
    """Median over seeds of the filter's horizontal σ at the end of the longest degraded run minus at its start."""
    if not inside.any():
        return 0.0
    idx = np.flatnonzero(inside)
    sig = np.hypot(ds.update_sigma.values[..., 0], ds.update_sigma.values[..., 1])
    a, b = max(idx[0] - 1, 0), idx[-1]
    return float(np.median(sig[:, b] - sig[:, a]))


def detection_tracking_ms(run: NavigationRun, *, frames: int = 80) -> dict:
    """Segment detection and tracking time per frame on re-rendered sample sequences (ms)."""
    from navigation.frames import FrameRenderer

    sc, f = run.sc, run.flight
    renderer = FrameRenderer(run.world, run.dem, sc.camera, sc.sensor)
    ext = SegmentExtractor()
    det = trk = 0.0
    n = 0
    for idx in run.sequence_indices()[::max(len(run.sequence_indices()) // max(frames // sc.frames, 1), 1)]:
        poses = [sc.camera.pose(f.p[i], f.R[i]) for i in idx]
        renderer.prepare(poses)
        imgs = [renderer.render(p, rng=np.random.default_rng(int(i))) for p, i in zip(poses, idx)]
        t0 = time.perf_counter()
        segs = [ext(im) for im in imgs]
        t1 = time.perf_counter()
        track_sequence(segs, ground_plane_homographies(sc.camera, poses, run.dem), width=sc.camera.width,
                       height=sc.camera.height)
        t2 = time.perf_counter()
        det += t1 - t0
        trk += t2 - t1
        n += len(imgs)
        if n >= frames:
            break
    return {"frames": n, "detection_ms": 1e3 * det / n, "tracking_ms": 1e3 * trk / n,
            "total_ms": 1e3 * (det + trk) / n, "cores": os.cpu_count(),
            "size": [sc.camera.width, sc.camera.height]}


def _one(name: str, seeds: int | None, workers: int | None, progress: bool, out_dir: Path | None) -> tuple:
    """One scenario: the same seeds as ``simsat navigate`` (unless ``seeds`` is given); its run and report
    written to ``out_dir`` so that the figures behind the numbers can be looked at."""
    sc = load_navigation_scenario(name)
    run = NavigationRun(sc, progress=progress)
    res = run.run(seeds=None if not seeds else list(range(sc.seed * 1000, sc.seed * 1000 + seeds)), workers=workers)
    if out_dir is not None:
        from .navigation_report import make_navigation_report

        write_navigation(res, out_dir / sc.name)
        make_navigation_report(out_dir / sc.name)
    return sc, run, navigation_dataset(res), res.timings


def bench_navigation(*, scenario: str | None = None, degraded: str | None = "nav_degraded", seeds: int | None = None,
                     workers: int | None = None, progress: bool = True, out_dir: str | Path | None = "bench/navigation"
                     ) -> dict:
    """Run the navigation benchmark (see the module docstring) and return its result.

    The runs (``navigation.nc`` and the report) are written under ``out_dir`` (None: not written).
    """
    out_dir = Path(out_dir) if out_dir is not None else None
    sc, run, ds, timings = _one(scenario or "nav_default", seeds, workers, progress, out_dir)
    s = summarise(ds)
    req = sc.requirement
    out = {"scenario": sc.name, "summary": s, "wrong_fixes": wrong_fixes(ds), "timings": timings,
           "detection_tracking": detection_tracking_ms(run),
           "requirement": req,
           "passed": {"final_horizontal": s["final_horizontal_m"]["p95"] <= req["final_horizontal_m"],
                      "improvement": s["improvement_median"] >= req["improvement"],
                      "nees": s["nees_inside_fraction"] >= req["nees_inside"]}}
    out["passed"]["detection_tracking_20ms"] = out["detection_tracking"]["total_ms"] <= 20.0
    if degraded:
        dsc, _, dds, _ = _one(degraded, seeds, workers, progress, out_dir)
        out["degraded"] = {"scenario": dsc.name, "summary": summarise(dds), "flags": degraded_flags(dds, dsc),
                           "wrong_fixes": wrong_fixes(dds)}
    return out


def format_navigation(r: dict) -> list[str]:
    s = r["summary"]
    f = s["final_horizontal_m"]
    lines = [f"navigation on {r['scenario']}: {s['seeds']} seeds, {s['distance_km']:.0f} km, {s['updates']} updates",
             f"  final horizontal error: median {f['median']:.1f} m, p95 {f['p95']:.1f} m, max {f['max']:.1f} m "
             f"(requirement ≤ {r['requirement']['final_horizontal_m']:g} m)",
             f"  unaided INS: median {s['unaided_final_horizontal_m']['median']:.0f} m; improvement "
             f"{s['improvement_median']:.0f}× (median of ratios)",
             f"  NEES inside the χ²₃ 95 % interval on {100 * s['nees_inside_fraction']:.0f} % of (seed, update), "
             f"mean NEES {s['nees_mean']:.2f} (3 ideal; mean over seeds inside its bounds on "
             f"{100 * s['nees_mean_inside_fraction']:.0f} % of updates); fixes on "
             f"{100 * s['fixes_fraction']:.0f} % of (seed, update); wrong fixes {r['wrong_fixes']['wrong']}",
             f"  detection + tracking {r['detection_tracking']['total_ms']:.1f} ms per "
             f"{r['detection_tracking']['size'][0]}×{r['detection_tracking']['size'][1]} frame "
             f"(detection {r['detection_tracking']['detection_ms']:.1f}, tracking "
             f"{r['detection_tracking']['tracking_ms']:.1f}; {r['detection_tracking']['cores']} cores)"]
    d = r.get("degraded")
    if d:
        fl = d["flags"]
        lines.append(f"  degraded ({d['scenario']}): {fl['updates_inside']} updates inside desert/fog, "
                     f"{fl['fixes_inside']} fixes there ({100 * fl['flagged_no_aiding_fraction']:.0f} % flagged "
                     f"no aiding), σ grew {fl['sigma_growth_m']:.1f} m; wrong fixes {d['wrong_fixes']['wrong']}; "
                     f"final p95 {d['summary']['final_horizontal_m']['p95']:.1f} m")
    lines.append("  passed: " + ", ".join(f"{k} {'yes' if v else 'NO'}" for k, v in r["passed"].items()))
    return lines
