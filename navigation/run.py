"""A navigation run: world → flight → rendered sequences → Monte Carlo of aided / unaided INS → NetCDF.

:class:`NavigationRun` builds the seed-independent part once (terrain, line
map, reference map, true flight, rendered frames and their segments: the
frames depend on the true trajectory only), then runs every Monte Carlo
seed (IMU errors, initial errors) as a Dask task. Reduced-frame mode: only
the ``aiding.frames`` frames of each aiding sequence are rendered (one
sequence every ``aiding.interval_s``), which is all the method uses.
"""
from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field

import numpy as np

from .aided import Sequence, SeedRun, run_seed
from .flight import fly, plan_route, true_increments
from .frames import FrameRenderer
from .scenario import NavigationScenario
from .segments import SegmentExtractor
from .world import World

__all__ = ["NavigationRun", "NavigationResult"]


@dataclass
class NavigationResult:
    scenario: NavigationScenario
    flight: object
    runs: list                      # SeedRun per seed
    seeds: list
    sample_frames: list             # [(update index, image, extracted segments, projected reference segments)]
    timings: dict = field(default_factory=dict)
    reference: object = None        # the reference LineMap
    dem: object = None


class NavigationRun:
    """Everything of one navigation scenario that does not depend on the Monte Carlo seed."""

    def __init__(self, sc: NavigationScenario, *, progress: bool = True):
        from simsat.terrain.dem import fractal_dem

        self.sc = sc
        self.progress = progress
        t0 = time.perf_counter()
        rng = np.random.default_rng([sc.seed, 0x7A1])
        imu_rate = sc.imu.rate_hz
        self.route = plan_route(length_m=sc.length_m, speed_mps=sc.speed_mps, rate_hz=imu_rate, turns=sc.turns,
                                max_bank_deg=sc.max_bank_deg, rng=rng)
        margin = sc.world.corridor_m + 3000.0
        lo, hi = self.route.xy.min(0) - margin, self.route.xy.max(0) + margin
        self.dem = fractal_dem(x_range_m=(lo[0], hi[0]), y_range_m=(lo[1], hi[1]), resolution_m=sc.dem_resolution_m,
                               relief_m=sc.relief_m, roughness=sc.roughness, seed=sc.seed)
        self.flight = fly(self.route, lambda x, y: self.dem.height(x, y, outside="clamp"), agl_min_m=sc.agl_m[0],
                          agl_max_m=sc.agl_m[1], rng=rng)
        self.world = World.generate(sc.world, self.route.xy, self.route.distance_m, seed=sc.seed)
        self.reference = self.world.reference_map(np.random.default_rng([sc.seed, 0x3EF]),
                                                  segment_sigma_m=sc.map_sigma_m, bias_m=sc.map_bias_m,
                                                  keep_fraction=sc.map_keep_fraction)
        self.increments = true_increments(self.flight)
        self.timings = {"world_s": time.perf_counter() - t0}
        self.sequences: list[Sequence] = []
        self.samples: list = []

    # -- frames ---------------------------------------------------------------------------
    def sequence_indices(self) -> list[np.ndarray]:
        """IMU sample indices of the frames of every aiding sequence."""
        sc, f = self.sc, self.flight
        step = int(round(sc.imu.rate_hz / sc.frame_rate_hz)) * sc.frame_step
        out = []
        t = sc.first_s
        while True:
            k = f.index_at(t)
            idx = k + step * np.arange(sc.frames)
            if idx[-1] >= len(f.t) - 1:
                break
            out.append(idx)
            t += sc.interval_s
        return out

    def render_sequences(self, *, samples: int = 3) -> list[Sequence]:
        """Render every aiding sequence (reduced-frame mode) and extract each frame's segments."""
        from tqdm import tqdm

        sc, f = self.sc, self.flight
        renderer = FrameRenderer(self.world, self.dem, sc.camera, sc.sensor)
        extractor = SegmentExtractor()
        seqs = []
        all_idx = self.sequence_indices()
        if not all_idx:
            from simsat.config import ScenarioError

            span = (sc.frames - 1) * sc.frame_step / sc.frame_rate_hz
            raise ScenarioError(f"aiding.first_s: no aiding sequence fits in the flight ({f.t[-1]:.1f} s for "
                                f"route.length_km = {sc.length_m / 1000:g}; the first sequence starts at "
                                f"{sc.first_s:g} s and lasts {span:.2f} s); lengthen the route or start earlier")
        keep = set(np.linspace(0, len(all_idx) - 1, min(samples, len(all_idx))).round().astype(int).tolist())
        t_render = t_extract = 0.0
        nframes = 0
        for u, idx in enumerate(tqdm(all_idx, desc=f"render {sc.name}", unit="sequence", file=sys.stderr,
                                     disable=not self.progress)):
            poses = [sc.camera.pose(f.p[i], f.R[i]) for i in idx]
            fog = sc.fog_at(float(f.distance_m[idx[-1]]))
            t0 = time.perf_counter()
            renderer.prepare(poses)
            imgs = [renderer.render(p, visibility_m=fog, rng=np.random.default_rng([sc.seed, int(i)]))
                    for p, i in zip(poses, idx)]
            t1 = time.perf_counter()
            segs = [extractor(im) for im in imgs]
            t_extract += time.perf_counter() - t1
            t_render += t1 - t0
            nframes += len(imgs)
            seqs.append(Sequence(idx, segs, fog=fog is not None))
            if u in keep:
                self.samples.append((u, imgs[0], segs[0], self.project_reference(poses[0])))
        self.sequences = seqs
        self.timings.update(render_s=t_render, extract_s=t_extract, frames=nframes, rays=renderer.rays)
        return seqs

    def project_reference(self, pose) -> np.ndarray:
        """Reference segments (lifted onto the DEM) projected into a frame seen from ``pose`` (n, 4) px."""
        cam = self.sc.camera
        ref = self.reference.near(pose.c[:2], self.sc.sensor.max_range_m)
        seg = ref.segments
        if len(seg) == 0:
            return np.zeros((0, 4))
        ends = []
        for e in (seg[:, :2], seg[:, 2:]):
            ends.append(np.column_stack([e, self.dem.height(e[:, 0], e[:, 1], outside="clamp")]))
        (ua, za), (ub, zb) = cam.project(ends[0], pose), cam.project(ends[1], pose)
        ok = (za > 50) & (zb > 50) & (np.linalg.norm(ends[0] - pose.c, axis=1) < self.sc.aiding.max_range_m)
        ok &= ((ua[:, 0] > 0) | (ub[:, 0] > 0)) & ((ua[:, 0] < cam.width) | (ub[:, 0] < cam.width))
        ok &= ((ua[:, 1] > 0) | (ub[:, 1] > 0)) & ((ua[:, 1] < cam.height) | (ub[:, 1] < cam.height))
        return np.column_stack([ua, ub])[ok]

    # -- Monte Carlo ------------------------------------------------------------------------
    def run_one(self, seed: int) -> SeedRun:
        dth, dv = self.increments
        sc = self.sc
        return run_seed(self.flight, dth, dv, self.sequences, sc.camera, self.reference, self.dem, sc.imu,
                        seed=seed, init=sc.initial, settings=sc.aiding)

    def run(self, *, seeds: list[int] | None = None, scheduler: str | None = None, workers: int | None = None):
        """Render (once) then run every seed as a Dask task; returns a :class:`NavigationResult`."""
        from tqdm import tqdm

        if not self.sequences:
            self.render_sequences()
        seeds = list(seeds if seeds is not None else range(self.sc.seed * 1000, self.sc.seed * 1000 + self.sc.seeds))
        t0 = time.perf_counter()
        runs: dict = {}
        if workers == 1 and scheduler is None:
            for s in tqdm(seeds, desc="Monte Carlo", unit="seed", file=sys.stderr, disable=not self.progress):
                runs[s] = self.run_one(s)
        else:
            from distributed import as_completed

            from simsat.cluster import dask_client

            with dask_client(scheduler, workers) as client:
                me = client.scatter(self, broadcast=True)
                futs = {client.submit(_run_seed_task, me, s, pure=False): s for s in seeds}
                bar = tqdm(total=len(seeds), desc="Monte Carlo", unit="seed", file=sys.stderr,
                           disable=not self.progress)
                for fut in as_completed(futs):
                    runs[futs[fut]] = fut.result()
                    bar.update()
                bar.close()
        self.timings["monte_carlo_s"] = time.perf_counter() - t0
        return NavigationResult(self.sc, self.flight, [runs[s] for s in seeds], seeds, self.samples,
                                dict(self.timings), reference=self.reference, dem=self.dem)


def _run_seed_task(run: NavigationRun, seed: int) -> SeedRun:
    return run.run_one(seed)
