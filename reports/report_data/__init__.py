"""Data preparation for the run report (``simsat report RUN_DIR``).

Every function here reads a run (product, restoration, truth) and returns plain
dicts of NumPy arrays and numbers — no drawing (that is
:mod:`reports.report_plots`) and no file writing (that is
:mod:`reports.run_report`). Tests check these numbers against independent
computations.

Conventions
-----------
* Angles are rad inside; the tables the report writes are in µrad and in pixels
  of the reference band (``pixel_ifov_rad``).
* ``δ(t) = true(t) − knowledge(t)`` is the part of the attitude the images have to
  restore; the restoration's *correction* is ``restored − knowledge``.
* Errors follow docs/design.md: estimate − truth over the lines where an estimate
  exists, mean removed, RMS and 99.7th percentile of |error|
  (:func:`reports.metrics.error_stats`).
* A pair's differential at line ``l`` is ``δ(t_l + τ) − δ(t_l)`` (restoration's
  ``diff_<axis>``); the integrator has the signature of
  :func:`restore.integration.integrate`:
  ``integrate(diffs, taus, te, method=..., **options) -> θ̂`` (NaN where not
  estimated).

The functions live in one module per job: :mod:`.loading`, :mod:`.headline`,
:mod:`.series`, :mod:`.transfer`, :mod:`.budget`, :mod:`.uncertainty`, :mod:`.matches`,
:mod:`.scene`.
"""
from __future__ import annotations

from simsat.units import AXES

from .budget import (
    BUDGET_COMPONENTS,
    axis_integration,
    error_budget,
    local_errors,
    integration_record,
    line_lags,
    measured_differentials,
    true_differentials,
)
from .headline import attitude_table, headline, restored_axes, scenario_summary
from .loading import RunData, get_integrator, load_run, pair_file_tag
from .matches import (
    match_density,
    matching_lock_of_run,
    matching_lock_sentence,
    misregistration_rows,
    misregistration_with_true_attitude,
)
from .scene import scene_geometry
from .series import longest_finite_run, minmax_decimate, zoom_window
from .uncertainty import sigma_calibration, uncertainty
from .transfer import (
    analytic_chain_gain,
    analytic_joint_gain,
    frozen_chain_gain,
    integration_probe,
    measured_transfer,
    probe_window_gain,
    regularisation_k,
    spectra,
    transfer_curves,
    welch_settings,
)

__all__ = ["AXES", "RunData", "load_run", "get_integrator", "pair_file_tag", "scenario_summary", "restored_axes", "attitude_table", "headline", "minmax_decimate", "longest_finite_run", "zoom_window", "welch_settings", "spectra", "frozen_chain_gain", "probe_window_gain", "integration_probe", "measured_transfer", "analytic_chain_gain", "analytic_joint_gain", "regularisation_k", "transfer_curves", "integration_record", "line_lags", "true_differentials", "measured_differentials", "axis_integration", "error_budget", "local_errors", "BUDGET_COMPONENTS", "match_density", "matching_lock_of_run", "matching_lock_sentence", "misregistration_rows", "misregistration_with_true_attitude", "scene_geometry", "uncertainty", "sigma_calibration"]
