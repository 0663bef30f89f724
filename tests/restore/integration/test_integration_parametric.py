"""Global parametric synthesis (CNES §2 SPOT5 baseline) against analytic damped chirps."""
import numpy as np
import pytest

from restore.integration import integrate
from restore.integration.parametric import (
    ParametricModel,
    damped_chirp_basis,
    initial_components,
    integrate_parametric,
)

DT = 4e-4
N = 6000
TAUS = [7.4e-3, 14.8e-3, 22.2e-3]
IFOV = 52e-6 / 12.905
TRUE = (0.30, 25.0, -5.0, 0.8)  # start s, Hz, Hz/s, damping s: SPOT5-like mirror rocking


def chirp(t, amp=3 * IFOV, comp=TRUE):
    s, f, k, T = comp
    x = np.maximum(t - s, 0.0)
    return np.where(t >= s, amp * np.exp(-x / T) * np.sin(2 * np.pi * (f * x + 0.5 * k * x ** 2)), 0.0)


def drift(t):
    u = (t - 1.2) / 1.2
    return 0.4 * IFOV * (u + 0.5 * u ** 2 - 0.3 * u ** 3)


def _diffs(th, noise_px=0.0, seed=0):
    t = np.arange(N) * DT
    rng = np.random.default_rng(seed)
    return [th(t + tau) - th(t) + noise_px * IFOV * rng.standard_normal(N) for tau in TAUS]


def _rms_px(e):
    e = e[np.isfinite(e)]
    return float(np.sqrt(np.mean((e - e.mean()) ** 2)) / IFOV)


def test_basis_is_the_damped_chirp_of_the_simulator():
    """a cos + b sin with (a, b) = (0, A) is simsat's DampedChirpJitter (zero before its start)."""
    from simsat.attitude import DampedChirpJitter

    t = np.arange(N) * DT
    jit = DampedChirpJitter(amplitude_rad=2e-6, frequency_hz=25.0, chirp_hz_per_s=-5.0, damping_time_s=0.8,
                            start_time_s=0.3)
    B = damped_chirp_basis(t, *TRUE)
    np.testing.assert_allclose(B @ np.array([0.0, 2e-6]), jit(t), rtol=0, atol=1e-18)
    assert np.all(B[t < 0.3] == 0)


def test_differential_design_is_the_difference_of_the_attitude_design():
    model = ParametricModel([TRUE], 3, t_c=1.2, h=1.2)
    t = np.linspace(0.0, 2.0, 50)
    for tau in TAUS:
        np.testing.assert_allclose(model.differential_design(t, tau),
                                   model.attitude_design(t + tau) - model.attitude_design(t), atol=1e-12)


def test_initial_components_read_the_chirp_from_a_sampled_attitude():
    t = np.arange(N) * DT
    (s, f, k, T), = initial_components(chirp(t) + drift(t), DT, 1, degree=3)
    assert s == pytest.approx(TRUE[0], abs=0.02)
    assert f == pytest.approx(TRUE[1], rel=0.05)
    assert k == pytest.approx(TRUE[2], abs=1.5)
    assert T == pytest.approx(TRUE[3], rel=0.25)


def test_recovers_a_damped_chirp_over_a_drift_from_noisy_differentials():
    """3 px rocking + a cubic drift, 0.05 px of noise per differential sample: the fit finds the parameters
    and the attitude to a small fraction of the noise (tens of parameters against 18 000 samples)."""
    t = np.arange(N) * DT
    th = lambda x: chirp(x) + drift(x)  # noqa: E731
    est, det = integrate_parametric(_diffs(th, 0.05), TAUS, DT, return_details=True)
    (s, f, k, T), = det["components"]
    assert f == pytest.approx(25.0, abs=0.05) and k == pytest.approx(-5.0, abs=0.1)
    # with a free phase the start trades against it (only the few samples at the onset tell them apart)
    assert T == pytest.approx(0.8, rel=0.01) and s == pytest.approx(0.3, abs=0.005)
    assert _rms_px(est - th(t)) < 0.03
    # the same through the public API
    assert np.allclose(integrate(_diffs(th, 0.05), TAUS, DT, method="parametric"), est, equal_nan=True)


def test_content_outside_the_model_is_left_as_error():
    """A CMG line the model has no term for stays in the error: that is what the baseline cannot do."""
    t = np.arange(N) * DT
    line = lambda x: 0.3 * IFOV * np.sin(2 * np.pi * 58.9 * x + 0.4)  # noqa: E731
    th = lambda x: chirp(x) + drift(x) + line(x)  # noqa: E731
    est = integrate_parametric(_diffs(th), TAUS, DT)
    err = _rms_px(est - th(t))
    assert err == pytest.approx(_rms_px(line(t)), rel=0.25)  # ~0.21 px: the line, unmodelled
    # with two components, the second one takes the (undamped, unchirped) line
    est2 = integrate_parametric(_diffs(th), TAUS, DT, components=2)
    assert _rms_px(est2 - th(t)) < 0.2 * err


def test_bad_options_are_named():
    d = _diffs(lambda x: chirp(x))
    with pytest.raises(ValueError, match="components"):
        integrate_parametric(d, TAUS, DT, components=7)
    with pytest.raises(ValueError, match="degree"):
        integrate_parametric(d, TAUS, DT, degree=9)


def test_polynomial_alone_when_no_component():
    t = np.arange(N) * DT
    est = integrate_parametric(_diffs(drift), TAUS, DT, components=0)
    assert _rms_px(est - drift(t)) < 1e-6
