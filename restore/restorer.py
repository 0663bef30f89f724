"""The restoration as a composition of its stages (:mod:`restore.stages`).

>>> res = Restorer(settings).run(product)          # doctest: +SKIP

:meth:`Restorer.run` reads as the method: match every pair, then iterate
synthesis and integration (re-predicting with the refined attitude), remove
the unobservable mean, anchor on the star tracker, check the coverage, correct
the images. Never reads ``truth.nc``.
"""
from __future__ import annotations

import sys
import time as _time
from dataclasses import replace
from pathlib import Path

import numpy as np
from tqdm import tqdm

from simsat.product import Product, clamped_attitude

from . import stages
from .errors import RestorationError
from .method_choice import resolved_method_name
from .posterior import detrended_rms_over
from .matching import MATCHING_METHODS
from .result import PairData, RestorationResult
from .settings import RestorationSettings
from .synthesis import AXES

__all__ = ["Restorer"]


class _Progress:
    """A tqdm bar over the stages (silent when disabled)."""

    def __init__(self, enabled: bool, total: int):
        self.bar = tqdm(total=total, desc="restore", unit="stage", file=sys.stderr, dynamic_ncols=True) \
            if enabled else None

    def step(self, label: str):
        if self.bar is not None:
            self.bar.set_postfix_str(label)
            self.bar.update(1)

    def note(self, label: str):
        """Say what the current stage is doing, without advancing."""
        if self.bar is not None:
            self.bar.set_postfix_str(label)

    def close(self):
        if self.bar is not None:
            self.bar.close()

    def notes_only(self) -> "_Progress":
        """The same bar, whose steps only say what is being done (a stage run again: the count stays right)."""
        return _NotesOnly(self)


class _NotesOnly(_Progress):
    """A :class:`_Progress` sharing another's bar; a step only names what is being done."""

    def __init__(self, progress: _Progress):
        self.bar = progress.bar

    def step(self, label: str):
        self.note(label)


def _take_records(records: dict, estimate: dict, new: dict) -> None:
    """Put the axes of ``new`` (axis → IntegrationRecord) into ``records`` and their estimates
    (``previous + increment``, NaN where not estimated) into ``estimate``, in place."""
    for a, rec in new.items():
        records[a] = rec
        estimate[a] = np.where(np.isfinite(rec.increment), rec.previous + rec.increment, np.nan)


def _same_drops(a: list, b: list) -> bool:
    """Whether two per-pair ``{axis: line mask}`` drop lists drop the same lines."""
    def lines(dr):
        return {k: tuple(np.flatnonzero(m)) for k, m in dr.items() if np.any(m)}
    return len(a) == len(b) and all(lines(x) == lines(y) for x, y in zip(a, b))


class Restorer:
    """Restore the line-of-sight attitude of a product from its bands.

    Parameters
    ----------
    settings : RestorationSettings, optional
        The ``[restoration]`` settings (defaults otherwise).
    progress : bool
        Show a progress bar over the stages on stderr.
    """

    def __init__(self, settings: RestorationSettings | None = None, *, progress: bool = False):
        self.settings = settings or RestorationSettings()
        self.progress = progress
        self._given = self.settings

    def run(self, product: Product, *, run_dir: Path | None = None, corrected_path: Path | None = None,
            corrected_attrs: dict | None = None) -> RestorationResult:
        """Restore ``product``.

        Long: the pipeline's stages in order, one call each, so that a reader sees the whole chain in one place.
        With ``corrected_path``, the corrected images are written there block
        by block (memory bounded by one band) and ``result.corrected`` is that
        file opened lazily; otherwise they are kept in memory.
        """
        s = self.settings = self._settings_for(product)
        self._axis_highpass = {}
        self.latency = None
        recorded, (product, dephasing) = product, stages.dephased_knowledge(product, s)
        recorded_knowledge = dict(zip(AXES, recorded.knowledge.at(recorded.time)))
        t_all = _time.perf_counter()
        timings: dict = {}
        pairs_ab = stages.resolve_pairs(product, s)
        bar = _Progress(self.progress, len(pairs_ab) + self._n_iterations(len(pairs_ab)) + 2)
        try:
            t = _time.perf_counter()
            pairs = self.match(product, pairs_ab, bar)
            timings["matching_s"] = _time.perf_counter() - t
            knowledge = dict(zip(AXES, product.knowledge.at(product.time)))
            pairs, records, estimate = self.synthesise_and_integrate(product, pairs, knowledge, timings, bar)
            pairs, records, estimate = self.rematch(product, pairs, knowledge, records, estimate, timings, bar)
            product, knowledge, dephasing, (pairs, records, estimate) = self.time_knowledge(
                product, knowledge, dephasing, pairs, records, estimate, timings, bar)
            bar.note("predicted σ (Monte Carlo through the integration)")
            t = _time.perf_counter()
            sigma = stages.predicted_sigma(records, product, s)
            timings["posterior_s"] = _time.perf_counter() - t
            pairs, records, estimate, sigma = self.lower_highpass(product, pairs, knowledge, records, estimate,
                                                                   sigma, timings, bar)
            records, estimate, sigma = self.weigh_noise_colour(product, knowledge, records, estimate, sigma, timings,
                                                                bar)
            records, estimate, sigma = self.condition_on_knowledge(product, knowledge, records, estimate, sigma,
                                                                    timings, bar)
            records, estimate, sigma = self.weigh_knowledge_band(product, records, estimate, sigma, timings, bar)
            records, estimate, excesses = self.shrink_excess(product, records, estimate, bar)
            s = self.settings
            sigma = self.raise_by_local_error(sigma, records, pairs, product, timings, bar)
            smoothings = stages.knowledge_smoothings(product, s, s.axes)
            smoothing = stages.knowledge_smoothing_correction(product, smoothings, records)
            sigma, checks = stages.raise_by_knowledge_check(
                sigma, records, product, s, {a: knowledge[a] + estimate[a] + smoothing.get(a, 0.0) for a in AXES},
                smoothings)
            sigma = stages.raise_by_knowledge_filter(sigma, records, product, self.latency)
            sigma = stages.raise_by_excess_shrink(sigma, excesses)
            estimate, sigma, fusions = stages.fuse_knowledge_band(estimate, sigma, records, product, s)
            flag_limits: dict = {}
            estimate, flagged = stages.flag_uncertain(estimate, sigma, s.max_sigma_px, product.pixel_ifov_rad,
                                                      flag_limits)
            estimate = stages.undo_exposure(estimate, product, s)
            correction, restored = stages.restored_from(recorded_knowledge, estimate, (smoothing, dephasing), s.axes)
            anchored = False
            if s.anchor_star_tracker:
                anchor_sigma = stages.anchoring_sigma(restored, product.time, product.star_tracker, s.axes,
                                                      noise_rad=product.star_tracker_noise_rad)
                restored, anchored = stages.anchor_on_star_tracker(restored, product.time, product.star_tracker,
                                                                   s.axes)
                sigma = stages.add_anchoring_sigma(sigma, anchor_sigma)
            coverage = stages.check_coverage(restored, s, product.path, flagged)
            bar.step("integrated")
            t = _time.perf_counter()
            corrected, misreg = None, {}
            if s.correct_images:
                corrected, misreg = stages.correct_images(recorded, product.time, restored, knowledge, pairs, s,
                                                          path=corrected_path, attrs=corrected_attrs)
            timings["correction_s"] = _time.perf_counter() - t
            bar.step("corrected")
        finally:
            bar.close()
        n_matches = sum(p.valid.size for p in pairs)
        timings["total_s"] = _time.perf_counter() - t_all
        timings["lines_per_s"] = product.time.size / timings["total_s"]
        timings["matches_per_s"] = n_matches / max(timings["matching_s"], 1e-9)
        timings["matches"] = n_matches
        return RestorationResult(run_dir=run_dir, time=product.time, restored=restored, knowledge=recorded_knowledge,
                                 correction=correction, coverage=coverage, pairs=pairs, timings=timings,
                                 misregistration=misreg, settings=s, pixel_ifov_rad=product.pixel_ifov_rad,
                                 method=resolved_method_name(s.method), integration=records,
                                 anchored=anchored, corrected=corrected,
                                 sigma={a: ps.sigma for a, ps in sigma.items()}, flagged=flagged,
                                 flag_limits=flag_limits,
                                 noise_scale={a: ps.noise_scale for a, ps in sigma.items()},
                                 band_shares={a: ps.band_shares for a, ps in sigma.items()},
                                 detrended_rms={a: detrended_rms_over(ps, restored[a]) for a, ps in sigma.items()},
                                 yaw_pitch_coupling=stages.yaw_pitch_coupling(pairs),
                                 yaw_roll_coupling=stages.yaw_coupling(pairs, "roll"),
                                 knowledge_smoothing=smoothing, knowledge_dephasing=dephasing, knowledge_checks=checks,
                                 knowledge_latency=self.latency.to_dict() if self.latency is not None else {},
                                 knowledge_fusion=fusions, conditioned_excess=excesses)

    def _settings_for(self, product: Product) -> RestorationSettings:
        """The settings the product decides: the "auto" high-pass (from the AOCS knowledge's cut-off) and
        the "auto" matching window width (from the reference band's noise and texture)."""
        g = self._given
        s = replace(g, highpass_hz=stages.highpass_from_product(g.highpass_hz, product))
        if g.window_columns == "auto":
            img = product.image(product.reference_detector, lines=slice(0, 1000))
            s = replace(s, window=(g.window[0], stages.window_columns_for(img, window_lines=g.window[0],
                                                                          noise_model=g.noise_model,
                                                                          radiometry=product.radiometry)))
        return s

    def _n_iterations(self, n_pairs: int) -> int:
        # best_first (patent claims 9-11): the best-correlated pair alone first, then the next ones
        # folded in one per iteration, re-predicting with the refined attitude, then all of them
        # until the increment is immaterial (at most `iterations` passes after the last pair)
        s = self.settings
        return s.iterations if s.pair_order == "fused" else n_pairs - 1 + s.iterations

    def match(self, product: Product, pairs_ab: list, bar) -> list[PairData]:
        """Select and match every pair (knowledge prediction, pilot-centred search)."""
        s = self.settings
        if MATCHING_METHODS[s.match_method].compiled and stages.ncc_kernel_cold():
            bar.note("loading the matching kernel (compiled on first use, ~10-15 s, cached after)")
        sm = product.sensor_model()
        pairs = []
        for a, b in pairs_ab:
            pairs.append(stages.match_pair(product, a, b, s, sm))
            bar.step(f"matched {a}/{b}")
        n_matches = sum(p.valid.size for p in pairs)
        n_valid = sum(int(np.count_nonzero(p.valid)) for p in pairs)
        if n_valid < s.min_points_per_line * 10:
            raise RestorationError(
                f"{product.path}: no usable texture — only {n_valid} valid matches out of {n_matches} candidates over "
                f"{len(pairs)} pairs (water, clouds, flat areas or noise everywhere? candidates pass the a-priori "
                f"criterion restoration.texture_max_std_px = {s.texture_max_std_px}, matches "
                f"restoration.min_quality = {s.min_quality}); nothing to restore")
        return pairs

    def synthesise_and_integrate(self, product: Product, pairs: list, knowledge: dict, timings: dict, bar, *,
                                 only: tuple | None = None) -> tuple:
        """Iterate synthesis and integration; returns (pairs as last synthesised, records, estimate).

        ``only``: integrate these axes alone (the synthesis still fits every restored axis).

        Each iteration re-predicts the matches with the knowledge plus the
        estimate so far, synthesises the differentials of the pairs in use and
        integrates the remaining differentials of every restored axis.
        """
        s = self.settings
        t_line, te, n_lines = product.time, product.instrument.line_period_s, product.time.size
        estimate = {a: np.zeros(n_lines) for a in AXES}
        order = self._pair_ranking(pairs)
        sens: dict = {}
        records: dict = {}
        ceilings = stages.knowledge_ceilings(product, knowledge, s)
        t_syn = t_int = 0.0
        for it in range(self._n_iterations(len(pairs))):
            ts = _time.perf_counter()
            used_idx = sorted(order[:it + 1]) if s.pair_order == "best_first" else list(range(len(pairs)))
            sm = product.sensor_model() if it == 0 else product.sensor_model(attitude=clamped_attitude(
                stages.attitude_series(t_line, {a: knowledge[a] + np.nan_to_num(estimate[a]) for a in AXES})))
            for j in used_idx:
                pairs[j] = stages.synthesise_pair(pairs[j], sm, s, n_lines, sens=sens.get(j))
                sens.setdefault(j, pairs[j].sens)
            used = [pairs[j] for j in used_idx]
            differentials = [stages.pair_differentials(p, s, n_lines, te) for p in used]
            t_syn += _time.perf_counter() - ts
            ti = _time.perf_counter()
            recs, inc = self._integrate_axes(product, used, differentials, estimate, ceilings, only=only)
            # a line whose synthesis is a gross error stands out of what the integrated attitude predicts:
            # drop it (filled as a short gap) and integrate again
            drops = [stages.differential_spikes(p, d, inc, s, te) for p, d in zip(used, differentials)]
            if any(drops):
                differentials = [stages.pair_differentials(p, s, n_lines, te, drop=dr) for p, dr in zip(used, drops)]
                recs, inc = self._integrate_axes(product, used, differentials, estimate, ceilings, only=only)
                # that integration held the gross errors it looked for (their power in the prior, the filter
                # following them): every line judged again against the one without them, so that a marginal
                # line's fate does not hang on a gross error elsewhere (a planted 6 px line had kept a line
                # 68 lines away that the clean record drops)
                again = [stages.differential_spikes(p, d, inc, s, te) for p, d in zip(used, differentials)]
                if not _same_drops(again, drops):
                    drops = again
                    differentials = [stages.pair_differentials(p, s, n_lines, te, drop=dr)
                                     for p, dr in zip(used, drops)]
                    recs, inc = self._integrate_axes(product, used, differentials, estimate, ceilings, only=only)
                timings["despiked_lines"] = timings.get("despiked_lines", 0) + sum(
                    int(m.sum()) for dr in drops for m in dr.values())
            # a line whose bands' windows are stretched against each other, or that lies next to a gap, matches
            # worse: weigh it by how its pair's fit residual grows with that, and integrate again
            factors = stages.line_weight_factors(differentials, recs, s, te)
            if any(factors):
                for d, fac in zip(differentials, factors):
                    d.axis_factor = fac
                # reweighting does not make a tone appear: where the search found none, it is not run again
                toneless = {a for a, r in recs.items() if r.spectrum is not None and r.spectrum.tones is None}
                recs, inc = self._integrate_axes(product, used, differentials, estimate, ceilings, toneless,
                                                 only=only)
            records.update(recs)
            change = 0.0
            for a in inc:
                new_est = np.where(np.isfinite(inc[a]), np.nan_to_num(estimate[a]) + inc[a], np.nan)
                if np.isfinite(new_est).any():
                    change = max(change, float(np.sqrt(np.nanmean(inc[a] ** 2)) /
                                               max(np.sqrt(np.nanmean(new_est ** 2)), 1e-300)))
                estimate[a] = new_est
            t_int += _time.perf_counter() - ti
            bar.step(f"iteration {it + 1}" + (f" ({len(used)} pair{'s' * (len(used) > 1)})"
                                              if s.pair_order == "best_first" else ""))
            if s.pair_order == "best_first" and len(used) == len(pairs) and it > 0 and change < 0.02:
                break  # converged: the last pass changed the estimate by < 2 % RMS
        timings["synthesis_s"] = t_syn
        timings["integration_s"] = t_int
        for a in AXES:
            if a not in s.axes:
                estimate[a] = np.zeros(n_lines)
        return pairs, records, estimate

    def _integrate_axes(self, product: Product, used: list, differentials: list, estimate: dict,
                        ceilings: dict, toneless: set = frozenset(), *, only: tuple | None = None) -> tuple:
        """Integrate every restored axis's differentials once (``only``: these axes): ({axis: record}, {axis:
        increment}); the axes in ``toneless`` without the search for a blind tone."""
        s = self.settings
        hp = getattr(self, "_axis_highpass", {})
        recs = {a: stages.integrate_differentials(a, used, differentials, estimate[a],
                                                  replace(s, highpass_hz=hp[a]) if a in hp else s,
                                                  product.instrument.line_period_s, where=product.path,
                                                  psd_ceiling=ceilings.get(a), no_blind_tone=a in toneless)
                for a in (s.axes if only is None else only)}
        return recs, {a: r.increment for a, r in recs.items()}

    def raise_by_local_error(self, sigma: dict, records: dict, pairs: list, product: Product, timings: dict,
                             bar) -> dict:
        """σ raised by the local matching error (:func:`stages.raise_by_local_error`), timed."""
        t = _time.perf_counter()
        if self.settings.sigma_local_error and sigma:
            bar.note("predicted σ with the local matching error (two interleaved halves of the swath)")
        sigma = stages.raise_by_local_error(sigma, records, pairs, product, self.settings)
        timings["local_error_sigma_s"] = _time.perf_counter() - t
        return sigma

    def time_knowledge(self, product: Product, knowledge: dict, dephasing: dict, pairs: list, records: dict,
                       estimate: dict, timings: dict, bar) -> tuple:
        """With ``knowledge_timing``: the AOCS knowledge's latency as the images measure it
        (:func:`stages.knowledge_latency`); where it is taken, the knowledge advanced by it shrunk by its σ
        (:func:`stages.advanced_knowledge`, added to ``dephasing``: part of the correction) and every axis
        integrated again. Returns ``(product, knowledge, dephasing, (pairs, records, estimate))``, new or as
        given; the estimate is kept in ``self.latency``."""
        t = _time.perf_counter()
        self.latency = est = stages.knowledge_latency(records, knowledge, product, self.settings)
        if est is None or not est.taken:
            return product, knowledge, dephasing, (pairs, records, estimate)
        bar.note(f"AOCS knowledge {est.delay_s * 1e3:.1f} ± {est.sigma_s * 1e3:.1f} ms late against the images: "
                 f"advanced by {est.applied_s * 1e3:.1f} ms (shrunk by its σ), integrating again")
        product, moved = stages.advanced_knowledge(product, est.applied_s)
        knowledge = dict(zip(AXES, product.knowledge.at(product.time)))
        dephasing = {a: dephasing.get(a, 0.0) + moved[a] for a in AXES}
        out = self.synthesise_and_integrate(product, pairs, knowledge, {}, bar.notes_only())
        timings["knowledge_timing_s"] = _time.perf_counter() - t
        return product, knowledge, dephasing, out

    def weigh_noise_colour(self, product: Product, knowledge: dict, records: dict, estimate: dict, sigma: dict,
                           timings: dict, bar) -> tuple:
        """With ``noise_colour_weighting``: integrate each axis again weighing the pairs' residuals by the noise
        colour its predicted σ's check measured, where the AOCS knowledge proves the excess is noise
        (:func:`stages.colour_weighted` with the knowledge's ceiling), then predict σ of those axes again.

        An axis without a ceiling (knowledge prior off, or a product that does
        not record its knowledge's filter) is left as it is. Returns (records,
        estimate, sigma), new where an axis was weighted, as given otherwise.
        """
        s = self.settings
        if not s.noise_colour_weighting or not sigma:
            return records, estimate, sigma
        t = _time.perf_counter()
        ceilings = stages.knowledge_ceilings(product, knowledge, s)
        records, estimate = dict(records), dict(estimate)
        if ceilings:
            bar.note("integrating again, weighed by the noise colour the knowledge proves")
        weighted = {}
        for a, rec in records.items():
            ps = sigma.get(a)
            if ps is None or ceilings.get(a) is None:
                continue
            rec = stages.colour_weighted(rec, ps.colour_estimate, ceilings[a])
            if rec is not None:
                weighted[a] = rec
        if weighted:
            _take_records(records, estimate, weighted)
            # checked again through the new filter: the weighted fit follows the data less where the colour
            # is, and its residual shows more of the noise there (reusing the first check's noise model
            # predicted σ lower: low_frequencies' pitch × 1.67 → 1.73, geo_noisy_knowledge's × 1.52 → 1.59)
            sigma = {**sigma, **stages.predicted_sigma(weighted, product, s)}
        timings["colour_weighting_s"] = _time.perf_counter() - t
        return records, estimate, sigma

    def condition_on_knowledge(self, product: Product, knowledge: dict, records: dict, estimate: dict,
                               sigma: dict, timings: dict, bar) -> tuple:
        """With ``knowledge_conditioning``: integrate each axis again with the prior given the AOCS knowledge
        (:func:`stages.knowledge_conditioned`), then predict σ of those axes again through the new filter.

        Returns (records, estimate, sigma), new where an axis was conditioned, as given otherwise.
        """
        s = self.settings
        if not s.knowledge_conditioning or not sigma:
            return records, estimate, sigma
        t = _time.perf_counter()
        done = {}
        for a, rec in records.items():
            new = stages.knowledge_conditioned(rec, sigma.get(a), product, knowledge[a], estimate[a], s)
            if new is not None:
                done[a] = new
        if done:
            bar.note("integrating again, with the prior given the AOCS knowledge")
            records, estimate = dict(records), dict(estimate)
            _take_records(records, estimate, done)
            sigma = {**sigma, **stages.predicted_sigma(done, product, s)}
        timings["knowledge_conditioning_s"] = _time.perf_counter() - t
        return records, estimate, sigma

    def weigh_knowledge_band(self, product: Product, records: dict, estimate: dict, sigma: dict, timings: dict,
                             bar) -> tuple:
        """With ``knowledge_band_noise``: integrate each knowledge-conditioned axis again, each pair weighed by the
        noise its differentials show in the knowledge's band (:func:`stages.knowledge_band_weighted`), then
        predict σ of those axes again through the new filter. Returns (records, estimate, sigma), new where an axis was weighted."""
        if not self.settings.knowledge_band_noise or not sigma:
            return records, estimate, sigma
        t = _time.perf_counter()
        weighted, found = {}, {}
        for a, rec in records.items():
            out = stages.knowledge_band_weighted(rec, product, self.settings)
            if out is not None:
                weighted[a], found[a] = out
        if weighted:
            bar.note("the pairs' differentials in the AOCS knowledge's band hold up to "
                     + ", ".join(f"{v:.1f} × ({a})" for a, v in found.items())
                     + " their white matching noise: integrating again, weighed by it")
            records, estimate = dict(records), dict(estimate)
            _take_records(records, estimate, weighted)
            sigma = {**sigma, **stages.predicted_sigma(weighted, product, self.settings)}
        timings["knowledge_band_noise_s"] = _time.perf_counter() - t
        return records, estimate, sigma

    def shrink_excess(self, product: Product, records: dict, estimate: dict, bar) -> tuple:
        """With ``excess_shrink``: where an axis's estimate holds more, in the band its prior is conditioned on the
        AOCS knowledge, than a Wiener output can, shrink it there (:func:`stages.shrunk_excesses`). Returns
        (records, estimate, ``{axis: ConditionedExcess}``): the excess found on every conditioned axis, its
        ``shrink_error_rad`` set where shrunk and ``shared_above_rad`` where another axis's offset reaches it
        (:func:`stages.offset_shared_excesses`): what σ must hold; without the shrink, the excess as a diagnostic
        (:func:`stages.conditioned_excesses`)."""
        if not self.settings.excess_shrink:
            return records, estimate, stages.conditioned_excesses(records, product)
        shrinks = stages.shrunk_excesses(records, product, self.settings)
        done = {a: replace(records[a], increment=sh.increment) for a, sh in shrinks.items() if sh.shrunk}
        if done:
            bar.note("shrinking the estimate where it exceeds what its knowledge-conditioned prior allows: "
                     + ", ".join(sorted(done)))
            records, estimate = dict(records), dict(estimate)
            _take_records(records, estimate, done)
        # the offset one axis shows first reaches the others by the sun's split, above the knowledge's band
        return records, estimate, stages.offset_shared_excesses({a: sh.excess for a, sh in shrinks.items()}, product)

    def lower_highpass(self, product: Product, pairs: list, knowledge: dict, records: dict, estimate: dict,
                       sigma: dict, timings: dict, bar) -> tuple:
        """With ``highpass_hz = "auto"``: when the AOCS knowledge is noisy enough that the images beat it well
        below the default high-pass (:func:`stages.knowledge_crossover_hz` under
        :data:`stages.CROSSOVER_FRACTION` of it), integrate again with the high-pass at that crossover.
        Otherwise, with ``highpass_per_axis``, each axis the knowledge does not prove wrong below the default
        takes its own crossover (:meth:`_axes_to_lower`) and is integrated again alone.

        Returns (pairs, records, estimate, sigma), new or as given.
        """
        s = self.settings
        if self._given.highpass_hz != "auto" or not sigma:
            return pairs, records, estimate, sigma
        fx = stages.knowledge_crossover_hz(records, sigma, product, s.highpass_hz)
        if fx is None:
            return pairs, records, estimate, sigma
        t = _time.perf_counter()
        if fx < stages.CROSSOVER_FRACTION * s.highpass_hz:
            bar.note(f"AOCS knowledge noisy: high-pass {s.highpass_hz:.2f} → {fx:.2f} Hz, integrating again")
            self.settings = s = replace(s, highpass_hz=fx)
            timings["highpass_lowered_hz"] = fx
        else:
            lowered = self._axes_to_lower(records, sigma, product) if s.highpass_per_axis else {}
            if not lowered:
                return pairs, records, estimate, sigma
            bar.note("high-pass lowered to the knowledge crossover on " +
                     ", ".join(f"{a} ({f:.2f} Hz)" for a, f in lowered.items()) + ", integrating again")
            self._axis_highpass = lowered
            timings["highpass_lowered_hz"] = dict(lowered)
            # only the lowered axes are integrated again (and their σ predicted again); the others stand
            recs, est = self.synthesise_and_integrate(product, list(pairs), knowledge, {}, bar.notes_only(),
                                                      only=tuple(a for a in s.axes if a in lowered))[1:]
            sigma = {**sigma, **stages.predicted_sigma(recs, product, s)}
            records = {**records, **recs}
            estimate = {**estimate, **{a: est[a] for a in recs}}
            timings["highpass_lowering_s"] = _time.perf_counter() - t
            return pairs, records, estimate, sigma
        pairs, records, estimate = self.synthesise_and_integrate(product, pairs, knowledge, {}, bar)
        sigma = stages.predicted_sigma(records, product, s)
        timings["highpass_lowering_s"] = _time.perf_counter() - t
        return pairs, records, estimate, sigma

    def _axes_to_lower(self, records: dict, sigma: dict, product: Product) -> dict:
        """Per axis, the knowledge crossover (:func:`stages.knowledge_crossover_hz`) where it lies below the
        high-pass and the differentials show nothing there that the knowledge proves not attitude
        (:func:`stages.knowledge_proves_excess`); {axis: crossover [Hz]}.

        Below the default high-pass the images' error is modelled from what the
        residual shows, which misses a band's error common to a line's points;
        but where that error is large enough to matter it lifts the prior the
        differentials give above the ceiling the knowledge sets, and the axis
        keeps the default (phr_cmg: pitch's prior at the ceiling at 0.6–3 Hz,
        roll's far below it).
        """
        hp = float(self.settings.highpass_hz)
        out = {}
        for a, rec in records.items():
            if a not in sigma:
                continue
            fa = stages.knowledge_crossover_hz({a: rec}, {a: sigma[a]}, product, hp)
            if fa is not None and fa < hp and not stages.knowledge_proves_excess(rec, fa, hp):
                out[a] = fa
        return out

    def rematch(self, product: Product, pairs: list, knowledge: dict, records: dict, estimate: dict, timings: dict,
                bar) -> tuple:
        """Coarse to fine (:mod:`restore.rematch`): match again in B resampled with the estimate so far, then
        synthesise and integrate again (:func:`stages.rematch_passes` passes).

        Returns (pairs, records, estimate) of the last pass.
        """
        s = self.settings
        first = stages.rematch_passes(s.rematch, estimate, s.axes, product.pixel_ifov_rad)
        t = _time.perf_counter()
        passes = 0
        for k in range(first if s.rematch != "auto" or not first else stages.MAX_AUTO_REMATCH):
            bar.note(f"rematch {k + 1}: matching again in B resampled with the estimate "
                     f"(worst pair {stages.valid_fraction(pairs) * 100:.0f} % valid)")
            attitude = {a: knowledge[a] + np.nan_to_num(estimate[a]) for a in AXES}
            pairs = stages.rematch_pairs(product, pairs, attitude, s)
            before = estimate
            pairs, records, estimate = self.synthesise_and_integrate(product, pairs, knowledge, {}, bar)
            passes += 1
            if s.rematch == "auto" and not stages.rematch_moved(before, estimate, s.axes, product.pixel_ifov_rad):
                break  # converged: B resampled with the estimate would not be any closer to A
        if passes:
            timings["rematch_s"] = _time.perf_counter() - t
            timings["rematch_passes"] = passes
        return pairs, records, estimate

    @staticmethod
    def _pair_ranking(pairs: list) -> list[int]:
        """Pairs ranked by correlation: valid matches × their mean quality, best first."""
        score = [float(np.count_nonzero(p.valid)) * float(np.nanmean(p.quality[p.valid])) if p.valid.any() else 0.0
                 for p in pairs]
        return sorted(range(len(pairs)), key=lambda j: -score[j])
