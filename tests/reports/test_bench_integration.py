"""The differential-level CNES benchmark: the default method beats the CNES figures."""
import numpy as np
import pytest

from reports.bench_integration import (CNES_P997_PX, CNES_RMS_PX, bench_integration, cnes_case,
                                       error_stats, format_table)
from restore.integration import DEFAULT_METHOD


def test_case_noise_and_lags():
    c = cnes_case(seed=1, duration_s=0.5)
    assert c["taus"] == [7.4e-3, 14.8e-3, 22.2e-3] and c["dt"] == 0.4e-3
    assert c["noise_std"] == pytest.approx(0.17 / np.sqrt(20) * 4e-6)
    t = c["time"]
    m = c["model"]
    resid = c["diffs"][0] - (m.evaluate_axis("roll", t + 7.4e-3) - c["truth"])
    assert np.std(resid) == pytest.approx(c["noise_std"], rel=0.1)
    with pytest.raises(ValueError, match="^gap_fraction"):
        cnes_case(gap_fraction=0.95)


def test_error_stats():
    truth = np.zeros(1000)
    est = np.full(1000, 5.0)
    est[:10] = np.nan
    s = error_stats(est, truth, px=2.0)
    assert s["rms_px"] == 0 and s["coverage"] == pytest.approx(0.99)


def test_default_beats_cnes_on_the_cnes_case():
    r = bench_integration(seed=3, duration_s=2.0, methods=[DEFAULT_METHOD])
    s = r["methods"][DEFAULT_METHOD]
    assert s["rms_px"] < CNES_RMS_PX and s["p997_px"] < CNES_P997_PX
    assert s["coverage"] == 1.0
    assert r["uncorrected"]["rms_px"] > 0.5
    assert DEFAULT_METHOD in format_table(r)


def test_default_with_30_percent_gaps():
    r = bench_integration(seed=4, duration_s=2.0, methods=[DEFAULT_METHOD], gap_fraction=0.3)
    s = r["methods"][DEFAULT_METHOD]
    assert 0.6 < s["coverage"] < 0.8
    assert s["rms_px"] < CNES_RMS_PX and s["p997_px"] < CNES_P997_PX


@pytest.mark.slow
def test_all_methods_full_case():
    r = bench_integration(seed=0)
    for name in ("wiener", "harmonic", "kalman", "local"):
        assert r["methods"][name]["rms_px"] < CNES_RMS_PX
