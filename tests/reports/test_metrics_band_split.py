"""The error split inside / outside a frequency band against tones of known amplitude."""
import numpy as np

from reports.metrics import error_split_by_band


def test_two_tones_split_by_the_band_they_fall_in():
    dt = 4e-4
    t = np.arange(4000) * dt                      # 1.6 s: 135 Hz and 60 Hz fall on whole periods
    a_in, a_out = 0.3, 0.1
    e = a_in * np.sin(2 * np.pi * 135.0 * t) + a_out * np.sin(2 * np.pi * 60.0 * t + 0.4) + 7.0
    freq = np.linspace(0.0, 1250.0, 3001)
    band = np.abs(freq - 135.0) < 1.0
    inside, outside = error_split_by_band(e, dt, freq, band)
    assert abs(inside - a_in / np.sqrt(2)) < 1e-6 and abs(outside - a_out / np.sqrt(2)) < 1e-6
    # Parseval: the parts add up to the mean square (mean removed)
    assert abs(inside ** 2 + outside ** 2 - np.var(e)) < 1e-9


def test_split_uses_the_longest_finite_run_and_refuses_short_ones():
    dt = 4e-4
    t = np.arange(4000) * dt
    e = 0.2 * np.sin(2 * np.pi * 60.0 * t)
    e[1000:1010] = np.nan                          # a gap: the 2990-sample run is used
    freq = np.linspace(0.0, 1250.0, 3001)
    inside, outside = error_split_by_band(e, dt, freq, np.zeros_like(freq, dtype=bool))
    assert inside == 0.0 and abs(outside - np.nanstd(e[1010:])) < 1e-3
    assert np.isnan(error_split_by_band(np.full(10, 1.0), dt, freq, freq > 0)[0])
