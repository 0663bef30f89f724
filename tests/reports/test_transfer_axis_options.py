"""The report's transfer probe runs the method itself: the options the axis's integration records for itself
(a transient's windows, the notches raised) are not the method's and must not reach it."""
import numpy as np

from reports import report_data as D
from restore.axis_integration import AXIS_OPTIONS
from restore.integration import integrate

TE = 4e-4
TAUS = [7.4e-3, 14.8e-3, 22.2e-3]


def test_probe_of_a_frozen_wiener_with_axis_options_runs():
    f = np.fft.rfftfreq(1200, TE)
    psd = np.where((f > 20) & (f < 300), 1e-15, 0.0)
    base = {"psd": (f, psd), "noise_std": np.full(3, 2e-8)}
    axis_only = {"transient_lines": [[100, 300]], "transient_lsq": {"alpha": 1.0, "beta": 0.0},
                 "notch_levels": [[129.2, 141.2, 7.5e-15]]}
    assert set(axis_only) == set(AXIS_OPTIONS)
    clean = D.integration_probe(TAUS, TE, 800, integrate=integrate, method="wiener", options=base,
                                pair_names=["B1/B0", "B0/B2", "B1/B2"], n_realisations=1)
    pr = D.integration_probe(TAUS, TE, 800, integrate=integrate, method="wiener", options={**base, **axis_only},
                             pair_names=["B1/B0", "B0/B2", "B1/B2"], n_realisations=1)
    assert pr["errors"] == {} and clean["errors"] == {}
    np.testing.assert_allclose(pr["gain_fused"], clean["gain_fused"])
