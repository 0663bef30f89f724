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


def test_unobservable_split_takes_out_the_yaw_the_trend_and_at_most_the_predicted_band_power():
    """An error made of known parts: c × yaw, a slope, a tone in the blind band and a tone outside it."""
    from reports.metrics import unobservable_split

    dt = 4e-4
    t = np.arange(4000) * dt
    yaw = 0.8 * np.sin(2 * np.pi * 63.4 * t + 1.0)
    slope = 0.05 * (t - t.mean()) / t.std()                          # RMS 0.05
    blind = 0.02 * np.sqrt(2) * np.sin(2 * np.pi * 135.0 * t)         # RMS 0.02
    rest = 0.03 * np.sqrt(2) * np.sin(2 * np.pi * 60.0 * t + 0.4)     # RMS 0.03
    c = 0.364
    e = c * yaw + slope + blind + rest + 3.0
    freq = np.linspace(0.0, 1250.0, 3001)
    band = np.abs(freq - 135.0) < 1.0
    got = unobservable_split(e, dt, freq, band, predicted_band_rms=1.0, yaw_seen=c * yaw)
    assert abs(got["yaw_rms"] - c * 0.8 / np.sqrt(2)) < 1e-3
    assert abs(got["trend_rms"] - 0.05) < 2e-3                        # a sine is nearly orthogonal to a line
    assert abs(got["detrended_rms"] - np.hypot(0.02, 0.03)) < 2e-3
    assert abs(got["band_rms"] - 0.02) < 1e-3 and abs(got["outside_rms"] - 0.03) < 1e-3
    # error the restoration put in the band beyond what the product predicts there stays in "outside"
    capped = unobservable_split(e, dt, freq, band, predicted_band_rms=0.005, yaw_seen=c * yaw)
    assert capped["band_rms"] == 0.005
    assert abs(capped["outside_rms"] - np.sqrt(0.03 ** 2 + 0.02 ** 2 - 0.005 ** 2)) < 2e-3
    # on nadir (no yaw) nothing is subtracted for it
    assert unobservable_split(e - c * yaw, dt, freq, band, predicted_band_rms=1.0)["yaw_rms"] == 0.0


def test_record_trend_is_the_least_squares_line_over_finite_samples():
    from restore.observability import record_trend

    x = np.arange(500, dtype=float)
    y = 2.0 + 0.01 * x + 0.1 * np.sin(2 * np.pi * x / 50.0)          # a fast wiggle barely tilts it
    np.testing.assert_allclose(record_trend(y), 2.0 + 0.01 * x, atol=0.02)
    line = 2.0 + 0.01 * x
    line[100:130] = np.nan                                            # gaps are left out, not filled
    tr = record_trend(line)
    assert np.all(np.isnan(tr[100:130]))
    np.testing.assert_allclose(tr[np.isfinite(line)], line[np.isfinite(line)], atol=1e-9)
    assert np.isnan(record_trend(np.full(5, np.nan))).all()
