"""Correcting a TDI band: the raw image is located with the attitude averaged over its stages.

Knowledge at zero, a restored pitch ramp of r px per line: the raw line that an
output line maps to moves, between the date attitude and the stage mean, by the
ramp over (N − 1) / 2 line periods, r (N − 1) / 2 / (1 − r) lines (a line l shows
the ground at x / v + θ(l)).
"""
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from restore.correction import resampling_nodes
from restore.stages import attitude_series
from simsat.sensor_model import SensorModel, constant_attitude

from support.geometry import centred_platform, flat_dem, small_instrument

N_LINES, STAGES, RATE = 200, 9, 0.05


def _product():
    inst = small_instrument()
    inst = replace(inst, detectors=(inst.detector("B1"), replace(inst.detector("B0"), tdi_stages=STAGES)))
    plat = centred_platform(inst, N_LINES)
    dem = flat_dem()
    time = np.arange(N_LINES) * inst.line_period_s

    def sensor_model(attitude=None):
        return SensorModel(platform=plat, instrument=inst, dem=dem, attitude=attitude or constant_attitude())
    return SimpleNamespace(instrument=inst, time=time, sensor_model=sensor_model)


@pytest.mark.parametrize("exact", [False, True])
def test_tdi_band_is_resampled_with_the_stage_mean_attitude(exact):
    p = _product()
    te, ifov = p.instrument.line_period_s, p.instrument.ifov_rad()
    t = np.arange(-20, N_LINES + 20) * te
    restored = attitude_series(t, {"roll": 0 * t, "pitch": RATE * ifov * (t - 0.04) / te, "yaw": 0 * t})
    sl = slice(40, 160)
    mean_l, mean_c, _ = resampling_nodes(p, "B0", restored, column_step=16, lines=sl, exact=exact)
    date_l, date_c, _ = resampling_nodes(p, "B0", restored, column_step=16, lines=sl, exact=exact, tdi_mean=False)
    hand = RATE * (STAGES - 1) / 2 / (1 - RATE)
    np.testing.assert_allclose(np.abs(mean_l - date_l), hand, rtol=2e-3)
    np.testing.assert_allclose(mean_c, date_c, atol=1e-6)
    # a single-line band is unaffected by the setting
    a, _, _ = resampling_nodes(p, "B1", restored, column_step=16, lines=sl, exact=exact)
    b, _, _ = resampling_nodes(p, "B1", restored, column_step=16, lines=sl, exact=exact, tdi_mean=False)
    np.testing.assert_array_equal(a, b)
