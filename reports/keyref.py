"""The scenario-key reference (``docs/scenario-keys.md``), generated from the validators.

Every key is listed as the validators read it -- type, default, accepted range
or choices -- by recording the reads of :class:`simsat.config.Section` while a
scenario holding every table (and a jitter of every kind) is validated, so the
reference cannot drift from the code. Meanings come from :data:`MEANING`; a
test fails when a key has none.

Run ``python -m reports.keyref > docs/scenario-keys.md`` after changing a key.
"""
from __future__ import annotations

import copy
import re

import restore  # noqa: F401  (registers [restoration])
from restore.integration import METHODS, method_options
from simsat import config
from simsat.scenario import _read_toml, builtin_scenarios, load_scenario

__all__ = ["recorded_keys", "scenario_key_reference", "MEANING"]

#: one-line meaning per key ("[]" stands for an index of an array of tables)
MEANING = {
    "scenario.name": "name of the scenario (default run directory `runs/<name>`)",
    "scenario.seed": "seed of every random draw (same scenario and seed: same bytes)",
    "scenario.description": "free text shown by `simsat scenarios` and in the report",
    "scenario.requirement.max_rms_px": "requirement: worst restored axis RMS error [px of the reference band]",
    "scenario.requirement.max_p997_px": "requirement: worst restored axis 99.7th percentile of the error magnitude [px]",
    "platform.altitude_m": "platform altitude above the scene's datum [m]",
    "platform.ground_speed_m_s": "speed of the sub-satellite point along track [m/s]",
    "platform.off_nadir_roll_deg": "viewing tilt across track [deg]",
    "platform.off_nadir_pitch_deg": "viewing tilt along track [deg]",
    "restoration.tdi_mean_attitude": "locate a TDI band with the attitude averaged over its stages (true) or at its line date, the last stage (false: CNES §3.3.4's error)",
    "instrument.detectors[].rows": "rows of a 2-D matrix detector taking frames (1: a line); needs acquisition.frame_period_ms",
    "acquisition.frame_period_ms": "a matrix detector takes a frame every this [ms] (0: push-broom lines); acquisition.lines then counts frames",
    "instrument.detectors[].tdi_stages": "time-delay-integration stages; the line is dated at the last stage (1: a single line)",
    "platform.trajectory": "straight track over a flat Earth, or a circular Keplerian orbit over a round one",
    "platform.inclination_deg": "orbit inclination (0: equatorial; with the geostationary altitude: still over the ground) [deg]",
    "platform.earth_radius_m": "radius of the spherical Earth under an orbit [m]",
    "platform.scan.kind": "how the lines of sight are swept besides the platform's motion: none, spin, mirror",
    "platform.scan.rate_rpm": "spin rate about the across-track axis [rev/min]",
    "platform.scan.mirror_rate_deg_s": "scan mirror angular rate (the line of sight turns at twice it) [deg/s]",
    "platform.scan.scan_frequency_hz": "mirror scan frequency: one sweep lasts 1 / (2 f) and must hold the acquisition [Hz]",
    "instrument.focal_length_m": "focal length [m]",
    "instrument.line_period_ms": "line period Te: one image line per Te [ms]",
    "instrument.pixel_pitch_um": "default detector pixel pitch [µm]",
    "instrument.pixels": "default detector length [pixels]",
    "instrument.focal_plane_width_mm": "focal plane size across track: detectors must fit [mm]",
    "instrument.focal_plane_height_mm": "focal plane size along track: detectors must fit [mm]",
    "instrument.mtf_nyquist": "MTF at Nyquist (sets the optical PSF)",
    "instrument.time_subsamples": "time samples per line period (smear of fast jitter)",
    "instrument.spatial_subsamples": "rays per pixel side (pixel footprint integration)",
    "instrument.noise.full_well_e": "full-well capacity [electrons]",
    "instrument.noise.signal_fraction": "signal of a reflectance-1 scene as a fraction of the full well",
    "instrument.noise.read_noise_e": "read noise, 1 σ [electrons]",
    "instrument.noise.bits": "quantisation depth [bits]",
    "instrument.noise.enabled": "add photon and read noise",
    "instrument.detectors[].name": "detector (band) name, e.g. B0",
    "instrument.detectors[].band": "spectral band of the texture it sees",
    "instrument.detectors[].along_track_mm": "along-track position on the focal plane: sets the delays τ [mm]",
    "instrument.detectors[].across_track_mm": "across-track offset of the detector's centre [mm]",
    "instrument.detectors[].pixels": "this detector's length (default instrument.pixels)",
    "instrument.detectors[].pixel_pitch_um": "this detector's pitch (default instrument.pixel_pitch_um) [µm]",
    "acquisition.lines": "image lines per band",
    "acquisition.block_lines": "lines rendered per block (memory and progress granularity)",
    "acquisition.reference_detector": "band whose pixel is the unit of the error figures",
    "acquisition.start_time_s": "time of the first line [s]",
    "acquisition.scene_margin_m": "terrain margin around the footprint (jitter and relief) [m]",
    "attitude.jitter[].kind": "disturbance model",
    "attitude.jitter[].axis": "axis or axes it moves (independent draws per axis)",
    "attitude.jitter[].frequency_hz": "frequency [Hz]",
    "attitude.jitter[].amplitude_urad": "amplitude [µrad] (cmg: of the main lines)",
    "attitude.jitter[].phase_deg": "phase at the acquisition start [deg]; omitted: a random phase drawn for each axis",
    "attitude.jitter[].drift_percent": "frequency drift over the acquisition [%] (cmg: a [min, max] range)",
    "attitude.jitter[].drift_shape": "time shape of the drift",
    "attitude.jitter[].exciter_frequencies_hz": "fundamental frequency of each exciter (wheel, CMG) [Hz]",
    "attitude.jitter[].harmonics": "harmonic orders of each exciter",
    "attitude.jitter[].exciter_amplitude_ratios": "relative amplitude of each exciter",
    "attitude.jitter[].harmonic_amplitude_ratios": "relative amplitude of each harmonic order",
    "attitude.jitter[].frequency_noise_percent": "random frequency wander, 1 σ [%]",
    "attitude.jitter[].amplitude_noise_percent": "random amplitude wander, 1 σ [%]",
    "attitude.jitter[].noise_bandwidth_hz": "bandwidth of the frequency and amplitude wander [Hz]",
    "attitude.jitter[].chirp_hz_per_s": "frequency rate of the chirp [Hz/s]",
    "attitude.jitter[].damping_time_s": "exponential damping time [s]",
    "attitude.jitter[].start_time_s": "start of the chirp after the acquisition start [s]",
    "attitude.jitter[].f_min_hz": "lowest frequency of the spectrum [Hz]",
    "attitude.jitter[].f_max_hz": "highest frequency of the spectrum [Hz]",
    "attitude.jitter[].rms_urad": "RMS of the coloured jitter [µrad]",
    "attitude.jitter[].corner_hz": "corner frequency of the spectrum [Hz]",
    "attitude.jitter[].slope": "spectral slope above the corner (PSD ∝ f^-slope)",
    "attitude.jitter[].n_components": "sinusoids summed to realise the spectrum",
    "attitude.jitter[].coefficients_urad": "polynomial coefficients in time from the start [µrad, µrad/s, ...]",
    "attitude.knowledge.cutoff_hz": "AOCS knowledge bandwidth: it knows the attitude below this [Hz]",
    "attitude.knowledge.rate_hz": "AOCS knowledge sampling rate [Hz]",
    "attitude.knowledge.noise_urad": "AOCS knowledge noise, 1 σ [µrad]",
    "attitude.knowledge.bias_urad": "constant bias of the AOCS knowledge, 1 σ per axis (drawn from the seed) [µrad]",
    "attitude.knowledge.drift_urad_per_s": "linear drift of the AOCS knowledge, 1 σ per axis [µrad/s]",
    "attitude.knowledge.delay_ms": "latency: the knowledge at t describes the attitude at t − delay [ms]",
    "attitude.knowledge.filter": "the AOCS low-pass: zero phase (forward and backward) or causal (forward only, "
                                 "with its phase lag); recorded in product.nc",
    "attitude.star_tracker.enabled": "provide sparse absolute star-tracker samples",
    "attitude.star_tracker.rate_hz": "star-tracker sampling rate [Hz]",
    "attitude.star_tracker.noise_urad": "star-tracker noise, 1 σ [µrad]",
    "scene.dem.kind": "terrain source",
    "scene.dem.resolution_m": "DEM grid spacing [m] (fractal: generated at it; files: resampled to it)",
    "scene.dem.relief_m": "peak-to-peak height of the fractal terrain [m]",
    "scene.dem.roughness": "Hurst-like exponent of the fractal terrain (small: rugged)",
    "scene.dem.path": "GeoTIFF DEM file, relative to the scenario's folder",
    "scene.dem.nodata": "no-data value of the GeoTIFF (default: the file's)",
    "scene.dem_knowledge.noise_m": "height error of the DEM the ground segment knows, 1 σ [m]",
    "scene.dem_knowledge.bias_m": "height bias of the known DEM [m]",
    "scene.dem_knowledge.correlation_m": "correlation length of the known DEM's error [m]",
    "scene.sun.elevation_deg": "sun elevation [deg]",
    "scene.sun.irradiance_scale": "scene brightness: the sun's irradiance relative to the built-in scenes (0.2: five times less signal)",
    "scene.sun.azimuth_deg": "sun azimuth from +x (along track) toward +y [deg]",
    "scene.sun.ambient": "diffuse sky light as a fraction of the irradiance",
    "scene.sun.cast_shadows": "terrain casts shadows",
    "scene.texture.kind": "ground reflectance source",
    "scene.texture.texel_m": "texture sample size on the ground [m]",
    "scene.texture.bands": "bands to synthesise (default: the instrument's)",
    "scene.texture.water_fraction": "fraction of the area covered by water (no texture)",
    "scene.texture.cloud_fraction": "fraction of the area covered by clouds",
    "scene.texture.urban_fraction": "fraction of built-up area",
    "scene.texture.forest_fraction": "fraction of forest",
    "scene.texture.field_size_m": "typical field size [m]",
    "scene.texture.cloud_height_m": "height of the cloud tops [m]",
    "restoration.pairs": "band pairs `[\"AHEAD/BEHIND\", ...]`, or \"auto\" (every pair of visible bands)",
    "restoration.selection": "candidate points: grid, double_gradient or spread",
    "restoration.points_per_line": "candidates per line and pair",
    "restoration.texture_max_std_px": "a-priori criterion: skip windows whose expected matching σ exceeds this [px]",
    "restoration.noise_model": "the images' noise in that criterion: signal_dependent (read + photon noise: the "
                               "detector's calibration from product.nc, else fitted on the band) or constant (one σ "
                               "per band)",
    "restoration.window_lines": "matching window height [lines] (PHR: 3)",
    "restoration.window_columns": "matching window width [columns], odd; \"auto\": the narrowest of 31, 47, 63 whose median a-priori matching σ is ≤ 0.1 px on the reference band (31 on the built-in scenes)",
    "restoration.search_lines": "integer search half-range around the prediction, lines [px]",
    "restoration.search_columns": "integer search half-range around the prediction, columns [px]",
    "restoration.pilot_search_lines": "wide search of the pilot pass, lines [px] (0: off)",
    "restoration.pilot_search_columns": "wide search of the pilot pass, columns [px] (0: off)",
    "restoration.match_method": "sub-pixel matcher: ncc (Gauss-Newton NCC) or phase",
    "restoration.min_quality": "correlation below which a match is rejected",
    "restoration.axes": "axes fitted by the instant synthesis",
    "restoration.n_sigma": "outlier rejection threshold [σ]",
    "restoration.match_covariance": "weigh each match in the instant synthesis by the inverse of its 2 × 2 covariance (the matcher's line and column σ and their correlation: on an edge or an oriented texture a slide along the edge moves both coordinates together), not by two independent variances",
    "restoration.line_weighting": "weigh each line of a pair by how the fit residual grows with what makes its matches worse — the along-track stretch of band B's window against A's (|dλ/dl|: where the lag changes fast) and the closeness to a gap (cloud, water, no texture) — learnt from the data (monotone in each), and integrate again",
    "restoration.transient_factor": "where the fit of the estimated (stationary) prior misses the data by more than this many times its record median over 100 lines — an abrupt onset it cannot follow — and the estimate without prior (least squares) fits them, that estimate is blended in over the window (0: off)",
    "restoration.despike_sigma": "a line whose synthesised differential departs from what the integrated attitude predicts by more than this many robust σ, its neighbours not, is a failed synthesis: dropped and filled (0: off)",
    "restoration.min_points_per_line": "fewest points that make a line's differential",
    "restoration.highpass_hz": "high-pass of the estimate [Hz]: \"auto\" = 0.2 × the AOCS knowledge cut-off recorded in product.nc (10 Hz → 2 Hz), lowered to where the images' error crosses the knowledge's recorded noise when that is below a quarter of it (a noisy knowledge; a margin for the images' optimistic low-frequency error model; needs the predicted σ's measured noise colour)",
    "restoration.max_gap_fill_lines": "longest run of lines filled from neighbours; longer gaps are NaN",
    "restoration.compensate_window": "undo the matching window's moving average on the differentials",
    "restoration.method": "integration method (default wiener), or \"auto\": per axis the one of wiener and lsq that best predicts each pair left out from the others (leave-one-pair-out cross-validation on the differentials); options in [restoration.integration] (none with auto)",
    "restoration.integration": "options of the integration method (table below)",
    "restoration.iterations": "passes with re-prediction from the refined attitude",
    "restoration.pair_order": "fused (all pairs at once) or best_first (patent claims 9-11)",
    "restoration.anchor_star_tracker": "absolute constant from star-tracker samples when present",
    "restoration.correct_images": "write corrected.nc and measure misregistration before/after",
    "restoration.correction_column_step": "resampling grid exact every N columns, linear in between",
    "restoration.corrected_compression": "corrected.nc image compression: zlib (any netCDF reader), lz4 (Blosc, ~12x faster to write, needs the HDF5 Blosc plugin that netCDF4-python wheels carry), none",
    "restoration.min_coverage": "least fraction of lines restored for the run to succeed",
    "restoration.knowledge_prior": "bound the estimated prior PSD by what the AOCS knowledge already knows "
                                   "(its recorded filter, rate and noise): nothing restored deep inside its band",
    "restoration.knowledge_conditioning": "after the predicted σ, integrate each axis again with the prior of "
    "the knowledge's error given the knowledge itself (k = G θ + ε and e = θ − k share ε): the conditional mean "
    "h k is taken off the differentials and added back, the prior is S_θ N / (|G|² S_θ + N) (S_θ: the restored "
    "angle's power less its predicted error's; N: the knowledge's recorded noise; G: its filter and spline "
    "interpolation, counted only where at least ½), so where the attitude is quiet and the knowledge noisy the "
    "images' noise no longer passes; then predict σ again. On by default; a product that does not record its "
    "knowledge's filter and noise, or a method with no spectral prior, is not conditioned",
    "restoration.knowledge_band_noise": "where an axis's prior is conditioned on the knowledge, measure each "
        "pair's matching noise between the high-pass and 0.9 × the knowledge's cut-off from its differentials "
        "against the record's own draws (a band's error common to a line's points moves the pairs like an "
        "attitude, so no residual shows it) and integrate again weighing each pair by that colour where it "
        "exceeds the record's own (restore.knowledge_band_noise; σ predicted again)",
    "restoration.excess_shrink": "where an axis's prior is conditioned on the knowledge, test its estimate's "
    "power per bin between the high-pass and 0.9 × the knowledge's cut-off (strong lines above fitted out) "
    "against what a Wiener output of that prior can hold, the prior allowed 10 % of the attitude for the "
    "knowledge's model error (family-wise 5 % false alarm over the band); where it fails, shrink each bin above "
    "its expectation by the Wiener gain with the excess counted as noise and book that estimate's error on σ "
    "(restore.conditioned_excess; restoration.nc conditioned_excess on sigma_<axis>). Off: the test is only "
    "reported",
    "restoration.rematch": "coarse to fine: passes matching again in band B resampled into band A's geometry with "
                           "the estimate so far; \"auto\": one pass when the estimate moves by more than 0.3 px "
                           "per line (RMS: large amplitude), else none, and a second when that pass still "
                           "moved the estimate by more than 0.01 px RMS",
    "restoration.rematch_search_lines": "search half-range of the rematch, lines [px]",
    "restoration.rematch_search_columns": "search half-range of the rematch, columns [px]",
    "restoration.noise_colour_weighting": "after the predicted σ, integrate each axis again (its prior frozen) "
    "weighing the pairs' residuals by the noise colour the σ's check of the fit residual measured, only by the "
    "part of the excess the AOCS knowledge proves is noise (what exceeds the most signal its ceiling leaves "
    "room for), then predict σ again. On by default; an axis whose product does not record its knowledge's "
    "filter, or with restoration.knowledge_prior = false, is not weighed",
    "restoration.knowledge_noise_floor": "keep the estimated prior PSD at least at the AOCS knowledge's own white "
    "noise (σ_k² / f_k through the spline interpolation, below f_k / 2, as product.nc records them): the "
    "knowledge's error holds that noise whatever the attitude does; with restoration.knowledge_prior. Off by default (see highpass_per_axis)",
    "restoration.knowledge_dephasing": "a knowledge product.nc records as causally filtered (knowledge_filter = "
                                       "butterworth_causal) has its filter's phase taken out before anything uses it: "
                                       "an all-pass e^(−i arg F) on its samples, extended by their point reflection; "
                                       "the restoration then reads it as a zero-phase filter of gain |F|. The lag "
                                       "(0.10 s at a 4 Hz cut-off) is gone but over the record's last group delay; "
                                       "the latency is not (it is not recorded)",
    "restoration.knowledge_timing": "measure the AOCS knowledge's latency from the images (each pair's "
                                    "differentials of what the knowledge misses, regressed on those of its "
                                    "derivative, from the high-pass to where its filter passes 90 %; σ from the "
                                    "residuals' spectrum) and, where the knowledge's derivative there is the attitude's (4 × "
                                    "its noise's or more), advance the knowledge by it shrunk by its σ (δ (1 − σ²/δ²), "
                                    "nothing within one σ of zero) and integrate again. A latency the knowledge does not record is an error the "
                                    "prior's ceiling, the low band and the conditioning all take for known",
    "restoration.knowledge_smoothing": "below the high-pass, where the restored angle is the AOCS knowledge's, "
    "take its white noise out: a quadratic kept whole, then each DCT coefficient of the knowledge samples' rest "
    "shrunk by the empirical Wiener gain max(0, 1 − σ_k² / P̄) (P̄: the power of five neighbouring coefficients; "
    "σ_k as product.nc records it); the predicted σ counts the error it leaves. On by default (phr_cmg "
    "0.0238 / 0.0273 → 0.0178 / 0.0220 px); a product that does not record its knowledge's noise is not smoothed",
    "restoration.deconvolve_exposure": "undo the line's exposure (the line period, centred on the line time) on "
    "the restored angle: the images see the attitude averaged over it, a gain sinc(f T) on the vibration (0.994 at "
    "150 Hz for 0.4 ms); the estimate is multiplied by its inverse to second order (a three-tap filter). On by default",
    "restoration.highpass_per_axis": "with highpass_hz = \"auto\": an axis whose images beat the knowledge's noise "
    "below the default high-pass (its crossover, as for the quarter rule) takes its crossover as its own "
    "high-pass unless its differentials showed more power there than the knowledge's ceiling lets the attitude "
    "have (the prior estimate clipped: a band's error every point of a line shares); the others keep the "
    "default. The axis is integrated again; restoration.nc records each axis's high-pass. Off by default: roll gained on every scenario where it was lowered (phr_cmg 0.0238 → 0.0212 px), but pitch lost on two stress scenarios whose band error the evidence did not show (damped_chirp 0.0320 → 0.0357)",
    "restoration.posterior_samples": "Monte Carlo draws through the integration for the predicted 1-σ per line "
                                     "(restoration.nc sigma_<axis>); 0: none",
    "restoration.sigma_local_error": "predict σ also with the measured local matching error as the noise (the "
    "differentials fitted again from two interleaved halves of the swath, their difference scaled by the halves' information (½ for equal halves), integrated "
    "through the frozen filter) and keep, line by line, the larger of that and the residual-calibrated "
    "prediction: each misses what the other holds (an error moving like an attitude, an error every point of "
    "a line shares)",
    "restoration.sigma_knowledge_check": "add to σ, in quadrature, the images' share (P_I / (P_I + P_K)) of what "
    "each axis's restored angle and its smoothed AOCS knowledge disagree by beyond both predicted errors (between "
    "1.25 × the high-pass and 0.7 × the knowledge's cut-off, as measured: the report calls it a disagreement beyond two "
    "sampling spreads, σ takes its share of any excess; the check itself is always recorded, restoration.nc sigma_<axis> knowledge_check, when the product records the knowledge's "
    "noise and filter, and the band holds at least three periodogram bins); the data cannot tell which prediction is short, so each takes its share",
    "restoration.knowledge_fusion": "where a stretch of the restored angle holds, between the high-pass and 0.7 × "
    "the knowledge's cut-off and once its strong lines above that band are fitted out, more than five times the "
    "power the AOCS knowledge's error has there (its noise, or the prior where larger: a drift near a record end "
    "or a gap edge, band offsets that move like an attitude), take the knowledge's band there with the "
    "minimum-variance weight 1 − v_k / P, brought in from five to ten times, and add that weight's error to σ "
    "(restore.knowledge_fusion; restoration.nc knowledge_fusion_weight_<axis>); needs the knowledge's noise and "
    "filter in product.nc",
    "restoration.max_sigma_px": "lines whose predicted σ exceeds this [px] are flagged and not restored; \"auto\": "
                                "3 × the axis's median σ",
}

_JITTER = {
    "harmonic": {"frequency_hz": 10.0, "amplitude_urad": 1.0},
    "cmg": {"exciter_frequencies_hz": [50.0], "amplitude_urad": 1.0},
    "damped_chirp": {"frequency_hz": 10.0, "amplitude_urad": 1.0, "damping_time_s": 1.0},
    "psd": {"rms_urad": 1.0, "corner_hz": 10.0},
    "polynomial": {"coefficients_urad": [1.0]},
}


def _norm(key: str) -> str:
    return re.sub(r"\[\d+\]", "[]", key)


def _record(raw: dict) -> list:
    """Keys read by the scenario's validation pass (every registered table, [restoration] included)."""
    rec = config.record_keys(True)
    try:
        load_scenario(raw)
    finally:
        config.record_keys(False)
    return rec


#: platforms whose keys the base scenario does not read (an orbit with a spin; a geostationary scan mirror)
_PLATFORMS = (
    {"trajectory": "orbit", "altitude_m": 694000.0, "inclination_deg": 98.0, "earth_radius_m": 6371008.8,
     "scan": {"kind": "spin", "rate_rpm": 0.5}},
    {"trajectory": "orbit", "altitude_m": 35793e3, "inclination_deg": 0.0,
     "scan": {"kind": "mirror", "mirror_rate_deg_s": 0.005, "scan_frequency_hz": 0.05}},
)


def recorded_keys() -> dict:
    """``{table: [(key, type, default, required, constraints)]}``, jitter keys per kind."""
    base = _read_toml(builtin_scenarios()["phr_cmg"])
    base["attitude"]["star_tracker"] = {"enabled": True}
    out: dict = {}
    seen: set = set()

    def add(table, entry):
        if (table, entry[0]) in seen:
            return
        seen.add((table, entry[0]))
        out.setdefault(table, []).append(entry)

    raw = copy.deepcopy(base)
    raw["attitude"]["jitter"] = [{"kind": "harmonic", "axis": "roll", **_JITTER["harmonic"]}]
    for key, kind, default, req, cons in _record(raw):
        k = _norm(key)
        if k.startswith("attitude.jitter[]"):
            continue
        table = k.rsplit(".", 1)[0]
        add(table, (k, kind, default, req, cons))
    for plat in _PLATFORMS:  # the keys of the other trajectories and scans
        raw = copy.deepcopy(base)
        raw["platform"] = copy.deepcopy(plat)
        raw["acquisition"]["lines"] = 64
        raw["scene"]["dem"]["resolution_m"] = 50.0
        raw["scene"]["texture"]["texel_m"] = 20.0
        for key, kind, default, req, cons in _record(raw):
            k = _norm(key)
            if k.startswith("platform."):
                add(k.rsplit(".", 1)[0], (k, kind, default, req, cons))
    for jk, keys in _JITTER.items():
        raw = copy.deepcopy(base)
        raw["attitude"]["jitter"] = [{"kind": jk, "axis": "roll", **keys}]
        for key, kind, default, req, cons in _record(raw):
            k = _norm(key)
            if k.startswith("attitude.jitter[]"):
                add(f"attitude.jitter[] (kind = \"{jk}\")", (k, kind, default, req, cons))
    return out


def _fmt_default(default, required) -> str:
    if required:
        return "**required**"
    if default is None:
        return "—"
    if isinstance(default, bool):
        return "true" if default else "false"
    if isinstance(default, str):
        return f'"{default}"'
    return f"{default!r}" if not isinstance(default, (list, tuple)) else str(list(default))


def _fmt_range(cons: dict) -> str:
    parts = []
    if "choices" in cons:
        parts.append(" \\| ".join(f'"{c}"' for c in cons["choices"]))
    lo = (">", cons["gt"]) if "gt" in cons else ((">=", cons["ge"]) if "ge" in cons else None)
    hi = ("<", cons["lt"]) if "lt" in cons else (("<=", cons["le"]) if "le" in cons else None)
    if lo:
        parts.append(f"{lo[0]} {lo[1]:g}")
    if hi:
        parts.append(f"{hi[0]} {hi[1]:g}")
    if "length" in cons:
        parts.append(f"{cons['length']} values")
    if "min_length" in cons:
        parts.append(f">= {cons['min_length']} values")
    return ", ".join(parts) or "—"


def scenario_key_reference() -> str:
    """The Markdown reference of every scenario key."""
    lines = ["# Scenario keys", "",
             "Every key a scenario may hold, as the validators read it (generated by "
             "`python -m reports.keyref`; a test checks that this file is up to date). Units are in the "
             "key names (`_m`, `_ms`, `_urad`, `_deg`, `_hz`, `_px`, `_percent`). `simsat validate FILE` "
             "checks a scenario against these rules; an unknown key is an error. On the command line, "
             "`--set TABLE.KEY=VALUE` overrides a key (`--set attitude.jitter[0].amplitude_urad=3`).", "",
             "Besides the ranges below, `simsat validate` refuses designs whose resources would exhaust "
             "the machine (strip length, swath, rays, product size, DEM samples, texture sampling, jitter "
             "components), naming the key that drives them.", ""]
    tables = recorded_keys()
    for table, entries in tables.items():
        lines += [f"## `[{table}]`", "", "| key | type | default | accepted | meaning |", "|---|---|---|---|---|"]
        for k, kind, default, req, cons in entries:
            name = k.rsplit(".", 1)[-1]
            meaning = MEANING.get(k, "")
            lines.append(f"| `{name}` | {kind} | {_fmt_default(default, req)} | {_fmt_range(cons)} | {meaning} |")
        lines.append("")
    lines += ["## Deriving a scenario from another: `[scenario] base`", "",
              "`base = \"phr_cmg\"` (a built-in name, or a path relative to the file) starts from that "
              "scenario: its tables are overlaid key by key by this file's; a table naming another `kind` "
              "(e.g. `[scene.dem] kind = \"matplotlib_sample\"`) and every array "
              "(`[[attitude.jitter]]`) replace the base's; the base's `[scenario.requirement]` is not "
              "inherited. The stress suite `scenarios/stress/*.toml` is written this way.", ""]
    lines += ["## `[scene.dem]` and `[scene.texture]` from files", "",
              "`[scene.dem] kind = \"geotiff\"` reads `path` (a GeoTIFF, relative to the scenario's folder) "
              "and `nodata`; it is re-centred on the scene and resampled to `resolution_m` when given. "
              "`[scene.texture] kind = \"orthoimage\"` reads `path`, `channels` (band → channel index table, "
              "required), `x0_m`, `y0_m` (lower-left corner, default centred) and `scale` (DN → reflectance); "
              "`texel_m` is then its pixel size.", ""]
    lines += ["## `[restoration.integration]`", "",
              "Options of the method named by `restoration.method` (checked against it at `simsat validate`; "
              "each is the keyword of the method's function in `restore.integration`).", "",
              "| method | options (default) |", "|---|---|"]
    for m in sorted(METHODS):
        opts = method_options(m)
        lines.append(f"| `{m}` | " + ", ".join(f"`{k}` ({_fmt_default(v, False)})" for k, v in opts.items()) + " |")
    lines += ["", "## `[report]`", "", "No key yet: the report reads nothing from this table, so any key in it "
              "is refused.", ""]
    return "\n".join(lines)




#: one-line meaning per navigation-scenario key
NAV_MEANING = {
    "kind": "`\"navigation\"`: says the file is a navigation scenario",
    "navigation.name": "name of the scenario (default run directory `runs/<name>`)",
    "navigation.seed": "seed of the world, the flight, the frames and the reference map",
    "navigation.seeds": "Monte Carlo seeds (IMU and initial errors) of a run",
    "route.length_km": "route length [km]",
    "route.speed_mps": "ground speed [m/s]",
    "route.agl_min_m": "lowest height above the terrain of the flight plan [m]",
    "route.agl_max_m": "highest height above the terrain of the flight plan [m]",
    "route.turns": "number of smooth coordinated turns (25–90° each)",
    "route.max_bank_deg": "largest bank angle in the turns [deg]",
    "terrain.relief_m": "peak-to-peak relief of the fractal DEM [m]",
    "terrain.resolution_m": "DEM grid spacing [m]",
    "terrain.roughness": "Hurst-like exponent of the relief (small: rugged)",
    "world.field_size_min_m": "smallest field parcel side [m]",
    "world.field_size_max_m": "largest field parcel side [m]",
    "degraded[].from_km": "start of a degraded stretch along the route [km]",
    "degraded[].to_km": "end of the degraded stretch [km]",
    "degraded[].kind": "featureless sand (`desert`) or fog (`fog`) over the stretch",
    "degraded[].visibility_m": "fog: meteorological visibility [m]",
    "world.edge_contrast": "albedo step from which a parcel border is a map line",
    "world.road_spacing_m": "route length per road crossing the corridor [m]",
    "world.road_width_m": "road width [m]; the map holds both edges",
    "world.lakes_per_100km": "lakes per 100 km of route (the map holds their shorelines)",
    "world.villages_per_100km": "villages per 100 km of route (the map holds building outlines)",
    "world.background_weight": "weight of the procedural background texture (clutter not in the map)",
    "camera.width": "image width [px]",
    "camera.height": "image height [px]",
    "camera.hfov_deg": "horizontal field of view [deg]",
    "camera.depression_deg": "optical axis below the vehicle's x axis [deg]",
    "camera.frame_rate_hz": "camera frame rate [Hz] (must divide imu.rate_hz)",
    "camera.band": "`visible` (reflected sunlight) or `ir` (emission-like: inverted, weaker contrast)",
    "camera.visibility_m": "meteorological visibility of the haze [m]",
    "camera.max_range_m": "range beyond which the ground fades into the sky [m]",
    "camera.supersample": "rays per pixel side",
    "camera.snr": "signal-to-noise ratio at the mean radiance",
    "camera.texel_m": "ground albedo texel [m]",
    "camera.sun_elevation_deg": "sun elevation [deg]",
    "camera.sun_azimuth_deg": "sun azimuth from +x toward +y [deg]",
    "imu.gyro_bias_deg_h": "gyro turn-on bias, 1 σ per axis [°/h]",
    "imu.accel_bias_mg": "accelerometer turn-on bias, 1 σ per axis [mg]",
    "imu.gyro_arw_deg_sqrt_h": "gyro angle random walk [°/√h]",
    "imu.accel_vrw_m_s_sqrt_h": "accelerometer velocity random walk [m/s/√h]",
    "imu.gyro_scale_ppm": "gyro scale factor error, 1 σ [ppm]",
    "imu.accel_scale_ppm": "accelerometer scale factor error, 1 σ [ppm]",
    "imu.rate_hz": "IMU output rate [Hz]",
    "aiding.interval_s": "time between two aiding sequences [s]",
    "aiding.frames": "frames per aiding sequence (only those are rendered)",
    "aiding.frame_step": "camera frames between two frames of a sequence (sets the baseline)",
    "aiding.first_s": "time of the first aiding sequence [s] (default: one interval)",
    "aiding.min_views": "real (not virtual) observations a track needs to be reconstructed",
    "aiding.line_sigma_px": "image-line error propagated into the measurement noise, 1 σ [px]",
    "aiding.min_lines": "matched lines a fix needs",
    "aiding.common_sigma_m": "model error common to a sequence's reconstruction (raster edges, mesh vs DEM, shared "
                             "detector biases), 1 σ per axis [m]",
    "aiding.max_range_m": "farthest reconstructed line used [m]",
    "reference_map.segment_sigma_m": "digitisation error of each reference segment, 1 σ per axis [m]",
    "reference_map.bias_m": "common registration error of the reference map (x, y) [m]",
    "reference_map.keep_fraction": "share of the true lines the reference map holds",
    "initial.position_sigma_m": "initial position error, 1 σ per axis [m]",
    "initial.velocity_sigma_mps": "initial velocity error, 1 σ per axis [m/s]",
    "initial.attitude_sigma_mrad": "initial roll and pitch error, 1 σ [mrad]",
    "initial.heading_sigma_mrad": "initial heading error, 1 σ [mrad]",
    "requirement.final_horizontal_m": "requirement: 95th percentile over seeds of the final horizontal error [m]",
    "requirement.improvement": "requirement: median ratio unaided / aided final horizontal error",
    "requirement.nees_inside": "requirement: share of (seed, update) whose position NEES lies inside the χ²₃ 95 % interval",
}


def navigation_key_reference() -> str:
    """The Markdown reference of every navigation-scenario key (``simsat navigate``)."""
    from navigation.scenario import _read, load_navigation_scenario

    data, _ = _read("nav_degraded")
    rec = config.record_keys(True)
    try:
        load_navigation_scenario(data)
    finally:
        config.record_keys(False)
    tables: dict = {}
    for key, kind, default, req, cons in rec:
        k = _norm(key)
        table = k.rsplit(".", 1)[0] if "." in k else "(top level)"
        if all(e[0] != k for e in tables.get(table, [])):
            tables.setdefault(table, []).append((k, kind, default, req, cons))
    lines = ["# Navigation scenario keys", "",
             "Every key of a `kind = \"navigation\"` scenario (`simsat navigate`), as the validators read it "
             "(generated by `python -m reports.keyref --navigation`; a test checks that this file is up to "
             "date). An unknown key is an error naming the key; `--set TABLE.KEY=VALUE` overrides one.", ""]
    for table, entries in tables.items():
        lines += [f"## `[{table}]`", "", "| key | type | default | accepted | meaning |", "|---|---|---|---|---|"]
        for k, kind, default, req, cons in entries:
            lines.append(f"| `{k.rsplit('.', 1)[-1]}` | {kind} | {_fmt_default(default, req)} | {_fmt_range(cons)} | "
                         f"{NAV_MEANING.get(k, '')} |")
        lines.append("")
    return "\n".join(lines)


if __name__ == "__main__":  # pragma: no cover
    import sys

    print(navigation_key_reference() if "--navigation" in sys.argv[1:] else scenario_key_reference(), end="")
