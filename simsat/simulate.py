"""Scenario → rendered multi-band product + exact truth (the `simsat render` command)."""
from __future__ import annotations

import math
import platform as _pyplatform
import shutil
import sys
import time as _time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from . import __version__, terrain
from .product import (
    atomic_write_dataset,
    atomic_write_json,
    make_tmp_dir,
    netcdf_encoding,
    product_dataset,
)
from .rundir import RunLock, content_id, install_files, prepare_output_dir
from .scenario import Scenario, load_scenario

__all__ = ["simulate", "apply_radiometry", "SimulationResult", "build_world"]


@dataclass
class SimulationResult:
    out_dir: Path
    timings: dict = field(default_factory=dict)
    render_stats: dict = field(default_factory=dict)
    #: simsat's outputs of a previous run in ``out_dir`` that were replaced or removed
    replaced: list = field(default_factory=list)


def _seed_seq(seed: int, *keys: int) -> np.random.SeedSequence:
    return np.random.SeedSequence([int(seed), *[int(k) for k in keys]])


def apply_radiometry(radiance: np.ndarray, radiometry, *, seed: int, band_index: int, first_line: int = 0) -> np.ndarray:
    """Photon + read noise and quantisation of a radiance image → uint16 DN.

    ``radiance`` is reflectance × irradiance (≈ [0, 1]); the signal is
    ``radiance · full_well · signal_fraction`` electrons. Noise draws use one
    seeded generator per line, so the result does not depend on block sizes.
    """
    r = radiometry
    e = np.asarray(radiance, dtype=np.float64) * (r.full_well_e * r.signal_fraction)
    if r.enabled:
        noisy = np.empty_like(e)
        for i in range(e.shape[0]):
            rng = np.random.default_rng(_seed_seq(seed, 101, band_index, first_line + i))
            line = e[i]
            sigma = np.sqrt(np.maximum(line, 0.0) + r.read_noise_e ** 2)
            noisy[i] = line + sigma * rng.standard_normal(line.shape)
        e = noisy
    dn = np.rint(np.clip(e, 0.0, r.full_well_e) * r.gain_dn_per_e)
    return dn.astype(np.uint16)


def build_world(sc: Scenario):
    """Models of a scenario: attitude model, true/known DEMs, texture, irradiance grid."""
    model = sc.attitude_model()
    dem, known = sc.dems()
    texture = sc.texture()
    sun = sc.sun()
    irr_z = terrain.sun_irradiance(dem, elevation_deg=sun.elevation_deg, azimuth_deg=sun.azimuth_deg,
                                   ambient=sun.ambient, shadows=sun.cast_shadows)
    irr = terrain.Dem(x0_m=dem.x0_m, y0_m=dem.y0_m, dx_m=dem.dx_m, dy_m=dem.dy_m, z=irr_z * sun.irradiance_scale)
    return model, dem, known, texture, irr


def make_renderer(sc, model, dem, texture, irr):
    """The push-broom renderer of a scenario's world (:func:`build_world`)."""
    from .render.pushbroom import PushbroomRenderer  # Mitsuba / Dr.Jit: heavy, loaded only to render

    sun = sc.sun()
    # cloud tops are lit like flat ground in the open (no relief shading, no cast shadow)
    cloud_irr = (sun.ambient + (1.0 - sun.ambient) * math.sin(math.radians(sun.elevation_deg))) * sun.irradiance_scale
    return PushbroomRenderer(platform=sc.platform, instrument=sc.instrument, dem=dem, texture=texture,
                             attitude=model.evaluate, irradiance=irr, cloud_irradiance=cloud_irr)


def _versions() -> dict:
    out = {"python": sys.version.split()[0], "platform": _pyplatform.platform()}
    for mod in ("numpy", "scipy", "mitsuba", "drjit", "xarray", "netCDF4", "cv2"):
        try:
            m = __import__(mod)
            out[mod] = getattr(m, "__version__", "?")
        except Exception:  # pragma: no cover
            out[mod] = None
    out["simsat"] = __version__
    return out


def product_id(sc: Scenario) -> str:
    """Provenance id of the product of a scenario.

    A hash of what decides the product's bytes: the resolved scenario without
    its file location and without the tables read only after rendering
    (``[restoration]``, ``[report]``), the seed, and simsat's version.
    """
    d = sc.to_dict()
    d.pop("source", None)
    d["raw"] = {k: v for k, v in d["raw"].items() if k not in ("restoration", "report")}
    return content_id(d, int(sc.seed), __version__)


def simulate(scenario: Scenario | str | Path, out_dir: str | Path, *, progress: bool = True,
             force: bool = False) -> SimulationResult:
    """Render a scenario into ``out_dir`` (product.nc, truth.nc, run.json).

    ``out_dir`` may be new, empty, or a simsat run (whose own files are
    replaced; its restoration, corrected images and report, derived from the
    old product, are removed). A non-empty directory that is not a run is
    refused unless ``force`` (then simsat's files are written beside the
    others; nothing else is touched). The directory is locked while the
    render writes (:class:`simsat.rundir.RunLock`). Everything is first
    written into a temporary directory inside ``out_dir`` and moved into
    place at the end, ``run.json`` last: a crashed run leaves no product
    that looks whole.

    Raises
    ------
    simsat.rundir.RunDirError
        ``out_dir`` cannot be used (message names it and the way out).
    """
    sc = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
    out_dir = prepare_output_dir(out_dir, force=force)
    with RunLock(out_dir, "render"):
        return _simulate_locked(sc, out_dir, progress=progress)


def _simulate_locked(sc: Scenario, out_dir: Path, *, progress: bool) -> SimulationResult:
    import xarray as xr

    timings = {}
    t_all = _time.perf_counter()

    t = _time.perf_counter()
    model, dem, known_dem, texture, irr = build_world(sc)
    timings["world_s"] = _time.perf_counter() - t

    inst = sc.instrument
    t_lines = sc.line_times

    t = _time.perf_counter()
    renderer = make_renderer(sc, model, dem, texture, irr)
    timings["scene_build_s"] = _time.perf_counter() - t

    # knowledge and star tracker
    kn = model.knowledge_series()
    st = model.star_tracker_series()

    # truth: at line period / time_subsamples, covering every integration window
    nt = max(inst.time_subsamples, 2)
    dt_truth = inst.line_period_s / nt
    t_truth = np.arange(t_lines[0] - inst.line_period_s, t_lines[-1] + inst.line_period_s + 1e-12, dt_truth)
    tr, tp, ty = model.evaluate(t_truth)

    ds = product_dataset(sc, None, t_lines, kn, st, known_dem, knowledge_spec=model.knowledge,
                         star_tracker_spec=model.star_tracker)
    truth = xr.Dataset(
        {"roll": ("time", tr, {"units": "rad", "long_name": "true line-of-sight roll"}),
         "pitch": ("time", tp, {"units": "rad", "long_name": "true line-of-sight pitch"}),
         "yaw": ("time", ty, {"units": "rad", "long_name": "true line-of-sight yaw"}),
         "dem": (("dem_y", "dem_x"), np.asarray(dem.z, dtype=np.float64), {"units": "m", "long_name": "true DEM"})},
        coords={"time": ("time", t_truth, {"units": "s"}),
                "dem_x": ("dem_x", dem.x0_m + np.arange(dem.z.shape[1]) * dem.dx_m, {"units": "m"}),
                "dem_y": ("dem_y", dem.y0_m + np.arange(dem.z.shape[0]) * dem.dy_m, {"units": "m"})},
        attrs={"title": "simsat truth — NEVER read by restoration", "scenario": sc.name, "seed": sc.seed,
               "pixel_ifov_rad": inst.ifov_rad(sc.acquisition.reference_detector),
               "dem_dx_m": float(dem.dx_m), "dem_dy_m": float(dem.dy_m)})

    # write everything into a temp dir inside out_dir, then move simsat's files into place
    pid = product_id(sc)
    ds.attrs["product_id"] = pid
    truth.attrs["product_id"] = pid
    tmp = make_tmp_dir(out_dir / "render")
    try:
        t = _time.perf_counter()
        atomic_write_dataset(truth, tmp / "truth.nc")
        # the product: everything but the images, then the images block after block (memory bounded by
        # one block of lines, whatever the image length); tmp is moved into place only when complete
        ds.to_netcdf(tmp / "product.nc", engine="netcdf4", encoding=netcdf_encoding(ds))
        timings["write_s"] = _time.perf_counter() - t
        _render_images_into(sc, renderer, tmp / "product.nc", t_lines, timings, progress=progress)
        timings["total_s"] = _time.perf_counter() - t_all
        rs = renderer.stats
        render_stats = {"variant": rs.variant, "rays": rs.rays, "wall_s": rs.wall_s, "rays_per_s": rs.rays_per_s,
                        "intersect_s": rs.intersect_s, "raygen_s": rs.raygen_s, "texture_s": rs.texture_s,
                        "shade_s": rs.shade_s, "blocks": rs.blocks, "misses": rs.misses}
        run = {"scenario": sc.to_dict(), "seed": sc.seed, "name": sc.name, "versions": _versions(),
               "timings": timings, "render": render_stats,
               "product_id": pid, "files": {"product": "product.nc", "truth": "truth.nc"}}
        atomic_write_json(run, tmp / "run.json")
        replaced = install_files(tmp, out_dir, ["product.nc", "truth.nc", "run.json"])
        tmp.rmdir()
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    del renderer, model, dem, known_dem, texture, irr
    from .render import release_memory  # Mitsuba / Dr.Jit: loaded only to render
    release_memory()
    return SimulationResult(out_dir=out_dir, timings=timings, render_stats=render_stats, replaced=replaced)


def _finish(bar, timings: dict, t_render: float, t_radio: float, t_write: float) -> None:
    """Close the progress bar; record the render, radiometry and write times."""
    if bar is not None:
        bar.close()
    timings["render_s"] = t_render
    timings["radiometry_s"] = t_radio
    timings["write_s"] = timings.get("write_s", 0.0) + t_write


def _render_images_into(sc: Scenario, renderer, path: Path, t_lines, timings: dict, *, progress: bool) -> None:
    """Render the acquisition block by block, apply the radiometry, append each block to ``path``.

    The image variables (uint16 DN, compressed, chunked by block) are created
    in the product file written without them; noise draws are seeded per line,
    so the noise does not depend on the block size (the renderer's float32
    arithmetic may differ by 1 DN on rare pixels between block sizes).
    """
    import netCDF4

    if sc.acquisition.is_frames:
        return _render_frames_into(sc, renderer, path, t_lines, timings, progress=progress)
    inst = sc.instrument
    dets = inst.detectors
    block = sc.acquisition.block_lines
    lines = len(t_lines)
    same = len({d.pixels for d in dets}) == 1
    bar = None
    if progress:
        from tqdm import tqdm
        bar = tqdm(total=lines, unit="line", desc=f"render {sc.name}", file=sys.stderr, dynamic_ncols=True)
    t_render = t_radio = t_write = 0.0
    try:
        with netCDF4.Dataset(str(path), "a") as nc:
            variables = {}
            for d in dets:
                col_dim = "column" if same else f"column_{d.name}"
                if col_dim not in nc.dimensions:
                    nc.createDimension(col_dim, d.pixels)
                v = nc.createVariable(f"image_{d.name}", "u2", ("line", col_dim), zlib=True, complevel=4,
                                      shuffle=True, chunksizes=(min(block, lines), d.pixels), fill_value=False)
                v.setncatts({"units": "DN", "band": d.band, "detector": d.name,
                             "long_name": f"raw image of detector {d.name} ({d.band})"})
                variables[d.name] = v
            t = _time.perf_counter()
            for sl, radiance in renderer.render_blocks(t_lines, block_lines=block,
                                                       progress=(bar.update if bar is not None else None)):
                t1 = _time.perf_counter()
                t_render += t1 - t
                dn = {name: apply_radiometry(img, inst.radiometry, seed=sc.seed, band_index=i, first_line=sl.start)
                      for i, (name, img) in enumerate(radiance.items())}
                t2 = _time.perf_counter()
                t_radio += t2 - t1
                for name, img in dn.items():
                    variables[name][sl.start:sl.stop, :] = img
                t = _time.perf_counter()
                t_write += t - t2
    finally:
        _finish(bar, timings, t_render, t_radio, t_write)


def _render_frames_into(sc: Scenario, renderer, path: Path, t_frames, timings: dict, *, progress: bool) -> None:
    """The frames of the matrix detector (frame, row, column), rendered row by row over blocks of frames.

    Noise draws are seeded per (frame, row): the same as if each row of each
    frame were a line of its own.
    """
    import netCDF4

    from .frames import render_frames

    inst = sc.instrument
    det = inst.detectors[0]
    n = len(t_frames)
    block = max(1, min(n, sc.acquisition.block_lines))
    bar = None
    if progress:
        from tqdm import tqdm
        bar = tqdm(total=n * det.rows, unit="row", desc=f"render {sc.name} (frames)", file=sys.stderr,
                   dynamic_ncols=True)
    t_render = t_radio = t_write = 0.0
    try:
        with netCDF4.Dataset(str(path), "a") as nc:
            nc.createDimension("row", det.rows)
            nc.createDimension("column", det.pixels)
            v = nc.createVariable(f"image_{det.name}", "u2", ("line", "row", "column"), zlib=True, complevel=4,
                                  shuffle=True, chunksizes=(1, det.rows, det.pixels), fill_value=False)
            v.setncatts({"units": "DN", "band": det.band, "detector": det.name,
                         "long_name": f"raw frames of matrix detector {det.name} ({det.band}): frame, row, column"})
            for a in range(0, n, block):
                sl = slice(a, min(n, a + block))
                t = _time.perf_counter()
                rad = render_frames(renderer, det, t_frames[sl], progress=bar.update if bar is not None else None)
                t1 = _time.perf_counter()
                t_render += t1 - t
                dn = apply_radiometry(rad.reshape(-1, det.pixels), inst.radiometry, seed=sc.seed, band_index=0,
                                      first_line=sl.start * det.rows).reshape(rad.shape)
                t2 = _time.perf_counter()
                t_radio += t2 - t1
                v[sl.start:sl.stop] = dn
                t_write += _time.perf_counter() - t2
                renderer.stats.wall_s += t1 - t
    finally:
        _finish(bar, timings, t_render, t_radio, t_write)
