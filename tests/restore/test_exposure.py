"""The line's exposure undone (restore.exposure): against the box average of known sines."""
import numpy as np
import pytest

from restore.exposure import exposure_deconvolution, exposure_gain

T = 0.4e-3


def test_box_gain_is_the_sinc():
    assert exposure_gain(0.0, T) == 1.0
    assert abs(exposure_gain(1 / T, T)) < 1e-12
    # the box average of a sine, computed by quadrature, has that gain
    f = 150.0
    tau = np.linspace(-T / 2, T / 2, 20001)
    avg = np.trapezoid(np.cos(2 * np.pi * f * tau), tau) / T
    assert avg == pytest.approx(float(exposure_gain(f, T)), rel=1e-9)


@pytest.mark.parametrize("f", [50.0, 150.0, 300.0])
def test_a_box_averaged_sine_gets_its_amplitude_back(f):
    t = np.arange(4000) * T
    seen = exposure_gain(f, T) * np.sin(2 * np.pi * f * t + 0.3)      # what a line's image is displaced by
    back = exposure_deconvolution(seen, dt=T, exposure_s=T)
    true = np.sin(2 * np.pi * f * t + 0.3)
    # second-order inverse: sinc(x/π)·(1 + sin²(x)/6) = 1 − (3/40) x⁴ + O(x⁶), x = π f T: 1e-4 at 150 Hz
    bound = 0.08 * (np.pi * f * T) ** 4 + 1e-12
    assert np.max(np.abs(back - true)[1:-1]) < bound
    assert np.max(np.abs(seen - true)) > 10 * bound                   # and it was needed


def test_gaps_and_ends_are_kept_and_zero_exposure_changes_nothing():
    x = np.sin(np.arange(50) * 0.7)
    x[20:23] = np.nan
    y = exposure_deconvolution(x, dt=T, exposure_s=T)
    assert np.isnan(y[20:23]).all()
    assert y[0] == x[0] and y[-1] == x[-1] and y[19] == x[19] and y[23] == x[23]
    assert np.array_equal(exposure_deconvolution(x, dt=T, exposure_s=0.0), x, equal_nan=True)
    with pytest.raises(ValueError, match="dt"):
        exposure_deconvolution(x, dt=0.0, exposure_s=T)
    with pytest.raises(ValueError, match="exposure_s"):
        exposure_deconvolution(x, dt=T, exposure_s=-1.0)


def test_high_frequency_noise_is_amplified_at_most_by_one_sixth():
    rng = np.random.default_rng(0)
    x = rng.standard_normal(200000)
    y = exposure_deconvolution(x, dt=T, exposure_s=T)
    assert np.std(y) / np.std(x) < 1.1
