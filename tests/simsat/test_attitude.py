"""Attitude models against their formulas, determinism, config errors, telemetry."""
import math

import numpy as np
import pytest

from simsat.units import RAD_PER_URAD as URAD
from simsat.attitude import (AttitudeModel, AttitudeSeries, CMGJitter, DampedChirpJitter,
                             HarmonicJitter, PolynomialDrift, PSDJitter, SmoothRandomProcess,
                             aocs_knowledge, star_tracker_samples)
from simsat.config import ScenarioError, Section


def _model(jitter, seed=3, t_end=2.0, **extra):
    return AttitudeModel.from_config(Section({"jitter": jitter, **extra}, "attitude"), seed=seed,
                                     t_start=0.0, t_end=t_end)


# --- disturbances against formulas ---------------------------------------------------
def test_harmonic_without_drift_is_a_sinusoid():
    h = HarmonicJitter(frequency_hz=7.0, amplitude_rad=2e-6, phase_rad=0.3, t0=1.0, t_end=3.0)
    t = np.linspace(0.5, 3.5, 1001)
    np.testing.assert_allclose(h.evaluate(t), 2e-6 * np.sin(0.3 + 2 * np.pi * 7.0 * (t - 1.0)),
                               atol=1e-18)


@pytest.mark.parametrize("shape,s", [("linear", lambda u: u), ("quadratic", lambda u: u**2),
                                     ("sine", lambda u: (1 - np.cos(np.pi * u)) / 2)])
def test_harmonic_drift_instantaneous_frequency(shape, s):
    h = HarmonicJitter(frequency_hz=50.0, amplitude_rad=1.0, drift=0.02, drift_shape=shape,
                       t0=0.0, t_end=2.0)
    t = np.linspace(0.1, 1.9, 50)
    eps = 1e-6
    f_num = (h.phase(t + eps) - h.phase(t - eps)) / (2 * eps) / (2 * np.pi)
    np.testing.assert_allclose(f_num, 50.0 * (1 + 0.02 * s(t / 2.0)), rtol=1e-7)
    np.testing.assert_allclose(h.frequency(2.0), 51.0)


def test_cmg_matches_line_formula_without_noise_or_drift():
    rng = np.random.default_rng(0)
    c = CMGJitter(exciter_frequencies_hz=[50.0, 70.0], harmonics=[1, 2], amplitude_rad=4e-6,
                  rng=rng, t0=0.0, t_end=1.0, harmonic_amplitude_ratios=[1.0, 0.3])
    t = np.linspace(0, 1, 777)
    ref = sum(c.amplitudes[e, h] * np.sin(2 * np.pi * mult * fe * t + c.phases[e, h])
              for e, fe in enumerate([50.0, 70.0]) for h, mult in enumerate([1, 2]))
    np.testing.assert_allclose(c.evaluate(t), ref, atol=1e-17)
    np.testing.assert_allclose(c.amplitudes, 4e-6 * np.array([[1, 0.3], [1, 0.3]]))


def test_cmg_drift_range_and_endpoints():
    c = CMGJitter(exciter_frequencies_hz=[50, 60, 70, 80], harmonics=[1, 2], amplitude_rad=1.0,
                  rng=np.random.default_rng(5), t0=0.0, t_end=4.0, drift_range=(0.002, 0.011))
    assert np.all((np.abs(c.drift) >= 0.002) & (np.abs(c.drift) <= 0.011))
    for e, fe in enumerate([50, 60, 70, 80]):
        assert c.exciter_frequency(0.0, e) == pytest.approx(fe)
        assert c.exciter_frequency(4.0, e) == pytest.approx(fe * (1 + c.drift[e]))


def test_smooth_random_process_std_and_integral():
    p = SmoothRandomProcess(np.random.default_rng(1), 0.01, 2.0, 0.0)
    t = np.linspace(0, 400, 400001)
    assert np.std(p(t)) == pytest.approx(0.01, rel=0.1)
    eps = 1e-4
    tt = np.array([0.3, 1.7, 5.0])
    np.testing.assert_allclose((p.integral(tt + eps) - p.integral(tt - eps)) / (2 * eps), p(tt),
                               rtol=1e-6)
    assert p.integral(0.0) == pytest.approx(0.0, abs=1e-15)


def test_damped_chirp_formula_and_start():
    d = DampedChirpJitter(amplitude_rad=3e-6, frequency_hz=10.0, chirp_hz_per_s=4.0,
                          damping_time_s=0.5, start_time_s=1.0, t0=2.0)
    t = np.linspace(0, 6, 601)
    x = t - 3.0
    ref = np.where(x >= 0, 3e-6 * np.exp(-x / 0.5) * np.sin(2 * np.pi * (10 * x + 2.0 * x**2)), 0)
    np.testing.assert_allclose(d.evaluate(t), ref, atol=1e-20)
    assert np.all(d.evaluate(t[t < 3.0]) == 0)


def test_psd_jitter_rms_and_shape():
    p = PSDJitter(rms_rad=2e-6, corner_hz=10.0, slope=2.0, f_min_hz=1.0, f_max_hz=200.0,
                  rng=np.random.default_rng(2), n_components=300)
    assert math.sqrt(0.5 * np.sum(p.amplitudes**2)) == pytest.approx(2e-6, rel=1e-12)
    assert np.all((p.frequencies >= 1.0) & (p.frequencies <= 200.0))
    # amplitude² / cell width follows 1 / (1 + (f / fc)²)
    edges = np.geomspace(1.0, 200.0, 301)
    dens = p.amplitudes**2 / np.diff(edges)
    shape = 1 / (1 + (p.frequencies / 10.0) ** 2)
    np.testing.assert_allclose(dens / dens[0], shape / shape[0], rtol=1e-10)
    t = np.arange(0, 20, 1e-3)
    assert np.std(p.evaluate(t)) == pytest.approx(2e-6, rel=0.15)


def test_polynomial_drift_time_origin():
    d = PolynomialDrift((1e-6, 2e-6, -3e-6), t0=10.0)
    t = np.array([10.0, 11.0, 12.5])
    np.testing.assert_allclose(d.evaluate(t), 1e-6 + 2e-6 * (t - 10) - 3e-6 * (t - 10) ** 2,
                               atol=1e-18)


# --- model, config, determinism -----------------------------------------------------
CMG = {"kind": "cmg", "axis": ["roll", "pitch"], "exciter_frequencies_hz": [52.0, 56.0, 71.0, 77.0],
       "harmonics": [1, 2], "amplitude_urad": 4.0, "drift_percent": [0.2, 1.1],
       "frequency_noise_percent": 0.1, "amplitude_noise_percent": 5.0}


def test_model_from_config_axes_and_nominal():
    m = AttitudeModel.from_config(
        Section({"jitter": [CMG, {"kind": "harmonic", "axis": "yaw", "frequency_hz": 3,
                                  "amplitude_urad": 2, "phase_deg": 0.0}]}, "attitude"),
        seed=1, nominal=(0.1, -0.2, 0.3), t_start=0.0, t_end=2.0)
    t = np.linspace(0, 2, 101)
    r, p, y = m.evaluate(t)
    np.testing.assert_allclose(y, 0.3 + 2 * URAD * np.sin(2 * np.pi * 3 * t), atol=1e-15)
    assert len(m.disturbances) == 3
    assert not np.allclose(r - 0.1, p + 0.2)          # independent draws per axis
    assert m.knowledge.cutoff_hz == 10.0 and not m.star_tracker.enabled


def test_harmonic_on_several_axes_gets_an_independent_phase_per_axis_unless_given():
    """One table on roll and pitch: two sines of the same frequency and amplitude, phases drawn per axis."""
    t = np.linspace(0, 1, 2001)
    tab = {"kind": "harmonic", "axis": ["roll", "pitch"], "frequency_hz": 7.0, "amplitude_urad": 3.0}
    m = AttitudeModel.from_config(Section({"jitter": [tab]}, "attitude"), seed=4, nominal=(0, 0, 0),
                                  t_start=0.0, t_end=1.0)
    r, p, _ = m.evaluate(t)
    phases = []
    for x in (r, p):
        c, s_ = (np.mean(x * f(2 * np.pi * 7.0 * t)) * 2 / (3.0 * URAD) for f in (np.sin, np.cos))
        assert np.hypot(c, s_) == pytest.approx(1.0, rel=1e-3)   # same amplitude
        phases.append(np.arctan2(s_, c))
    assert abs(np.angle(np.exp(1j * (phases[0] - phases[1])))) > 0.05   # not the same sine twice
    given = AttitudeModel.from_config(Section({"jitter": [{**tab, "phase_deg": 30.0}]}, "attitude"), seed=4,
                                      nominal=(0, 0, 0), t_start=0.0, t_end=1.0)
    r, p, _ = given.evaluate(t)
    np.testing.assert_allclose(r, p, atol=1e-18)                 # a given phase is the same on every axis
    np.testing.assert_allclose(r, 3.0 * URAD * np.sin(2 * np.pi * 7.0 * t + np.radians(30.0)), atol=1e-15)


def test_same_seed_same_bytes_and_scalar_time():
    t = np.linspace(0, 2, 5001)
    a = np.stack(_model([CMG], seed=7).evaluate(t))
    b = np.stack(_model([CMG], seed=7).evaluate(t))
    c = np.stack(_model([CMG], seed=8).evaluate(t))
    assert a.tobytes() == b.tobytes()
    assert not np.array_equal(a, c)
    m = _model([CMG], seed=7)
    assert float(m.evaluate_axis("roll", 0.123)) == pytest.approx(
        m.evaluate_axis("roll", np.array([0.1, 0.123]))[1], abs=0)
    assert m.evaluate_axis("roll", np.zeros((2, 3))).shape == (2, 3)


@pytest.mark.parametrize("jitter,key", [
    ([{"kind": "harmonic", "axis": "roll", "frequency_hz": -3, "amplitude_urad": 1}],
     "attitude.jitter[0].frequency_hz: must be > 0, got -3"),
    ([CMG, {"kind": "harmonic", "axis": "roll", "frequency_hz": 3}],
     "attitude.jitter[1].amplitude_urad: missing"),
    ([{"kind": "harmonic", "axis": "roll", "frequency_hz": 3, "amplitude_urad": 1, "foo": 1}],
     "attitude.jitter[0].foo: unknown key"),
    ([{"kind": "wobble", "axis": "roll"}], "attitude.jitter[0].kind: must be one of"),
    ([{"kind": "harmonic", "axis": "spin", "frequency_hz": 3, "amplitude_urad": 1}],
     "attitude.jitter[0].axis: must be one of"),
    ([dict(CMG, drift_percent=[1.1, 0.2])], "attitude.jitter[0].drift_percent"),
    ([{"kind": "psd", "axis": "roll", "rms_urad": 1, "corner_hz": 5, "f_min_hz": 10,
       "f_max_hz": 5}], "attitude.jitter[0].f_max_hz"),
    ([{"kind": "harmonic", "axis": "roll", "frequency_hz": 3, "amplitude_urad": 1,
       "drift_shape": "cubic"}], "attitude.jitter[0].drift_shape"),
])
def test_config_errors_name_the_key(jitter, key):
    with pytest.raises(ScenarioError) as err:
        _model(jitter)
    assert str(err.value).startswith(key)
    assert "\n" not in str(err.value)


def test_config_errors_in_subtables():
    with pytest.raises(ScenarioError, match=r"^attitude\.knowledge\.cutoff_hz: must be > 0"):
        _model([], knowledge={"cutoff_hz": 0})
    with pytest.raises(ScenarioError, match=r"^attitude\.star_tracker\.rate: unknown key"):
        _model([], star_tracker={"rate": 1})
    with pytest.raises(ScenarioError, match=r"^attitude\.nominal: unknown key"):
        _model([], nominal=1)


# --- sampled series and telemetry ------------------------------------------------------
def test_attitude_series_cubic_exact_and_outside():
    t = np.linspace(0, 1, 11)
    s = AttitudeSeries(t, t**3, 2 * t**2, -t)
    q = np.array([0.05, 0.5, 0.93])
    r, p, y = s.at(q)
    np.testing.assert_allclose(r, q**3, atol=1e-12)
    np.testing.assert_allclose(p, 2 * q**2, atol=1e-12)
    with pytest.raises(ValueError, match="^t: "):
        s.at([1.5])
    r, _, _ = s.at([-0.1, 0.5], outside="nan")
    assert np.isnan(r[0]) and np.isfinite(r[1])
    with pytest.raises(ValueError, match="^time: must be strictly increasing"):
        AttitudeSeries(t[::-1], t, t, t)


def test_attitude_series_nan_samples():
    t = np.linspace(0, 1, 21)
    roll = np.sin(t)
    roll[10] = np.nan
    s = AttitudeSeries(t, roll, t, t)
    r, p, _ = s.at([0.47, 0.52, 0.2])
    assert np.isnan(r[0]) and np.isnan(r[1]) and np.isfinite(r[2])
    assert np.all(np.isfinite(p))


def test_aocs_knowledge_lowpass_zero_phase_and_noise():
    m = _model([{"kind": "harmonic", "axis": "roll", "frequency_hz": 0.5, "amplitude_urad": 10, "phase_deg": 0.0},
                {"kind": "harmonic", "axis": "pitch", "frequency_hz": 100, "amplitude_urad": 10},
                {"kind": "harmonic", "axis": "roll", "frequency_hz": 80, "amplitude_urad": 4}],
               t_end=4.0)
    k = aocs_knowledge(m, t_start=0.0, t_end=4.0, cutoff_hz=10.0, rate_hz=50.0, noise_urad=0.0,
                       seed=1)
    np.testing.assert_allclose(np.diff(k.time), 0.02)
    ref = 10 * URAD * np.sin(2 * np.pi * 0.5 * k.time)      # passes, no delay
    np.testing.assert_allclose(k.roll, ref, atol=0.01 * 10 * URAD)
    assert np.max(np.abs(k.pitch)) < 0.01 * 10 * URAD         # 100 Hz: stopped
    kn = aocs_knowledge(m, t_start=0.0, t_end=4.0, cutoff_hz=10.0, rate_hz=50.0, noise_urad=2.0,
                        seed=1)
    assert np.std(kn.yaw) == pytest.approx(2 * URAD, rel=0.15)
    kn2 = m.knowledge_series()
    assert kn2.roll.tobytes() == m.knowledge_series().roll.tobytes()


def test_star_tracker_samples():
    m = _model([CMG], star_tracker={"enabled": True, "rate_hz": 4, "noise_urad": 0.0})
    s = m.star_tracker_series()
    np.testing.assert_allclose(np.diff(s.time), 0.25)
    np.testing.assert_allclose(s.roll, m.evaluate_axis("roll", s.time))
    assert _model([CMG]).star_tracker_series() is None
    n = star_tracker_samples(m, t_start=0.0, t_end=2.0, rate_hz=10.0, noise_urad=3.0, seed=4)
    assert np.std(n.yaw - m.evaluate_axis("yaw", n.time)) == pytest.approx(3 * URAD, rel=0.4)


def test_aocs_knowledge_errs_like_a_real_one():
    """Bias, drift, delay and a causal filter, each against its analytic effect; off by default."""
    from scipy.signal import butter, freqs

    f0 = 2.0
    m = _model([{"kind": "harmonic", "axis": "roll", "frequency_hz": f0, "amplitude_urad": 10, "phase_deg": 0.0}],
               t_end=4.0)
    kw = dict(t_start=0.0, t_end=4.0, cutoff_hz=10.0, rate_hz=200.0, noise_urad=0.0, seed=3)
    ideal = aocs_knowledge(m, **kw)
    assert ideal.roll.tobytes() == aocs_knowledge(m, **kw, bias_urad=0, drift_urad_per_s=0, delay_ms=0).roll.tobytes()
    t = ideal.time

    def fit(y):   # amplitude, phase, offset and slope of y against a sine at f0
        A = np.column_stack([np.sin(2 * np.pi * f0 * t), np.cos(2 * np.pi * f0 * t), np.ones_like(t), t])
        c = np.linalg.lstsq(A, y, rcond=None)[0]
        return np.hypot(c[0], c[1]), np.arctan2(c[1], c[0]), c[2], c[3]

    # bias and drift: a constant and a slope per axis, drawn from the seed, the same on a flat axis (yaw)
    from simsat.attitude import _STREAM_KNOWLEDGE_ERRORS, _rng

    b = aocs_knowledge(m, **kw, bias_urad=20.0, drift_urad_per_s=3.0)
    draws = _rng(3, _STREAM_KNOWLEDGE_ERRORS).standard_normal((3, 2)) * [20.0, 3.0]
    _, _, off, slope = fit(b.yaw / URAD)
    assert (off, slope) == pytest.approx(tuple(draws[2]), abs=1e-9)
    np.testing.assert_allclose(b.yaw / URAD, off + slope * t, atol=1e-9)
    np.testing.assert_allclose((b.roll - ideal.roll) / URAD, draws[0, 0] + draws[0, 1] * t, atol=1e-9)
    # delay: the phase lags by 2π f0 delay
    _, ph_d, _, _ = fit(aocs_knowledge(m, **kw, delay_ms=25.0).roll)
    _, ph_0, _, _ = fit(ideal.roll)
    assert ph_0 == pytest.approx(0.0, abs=2e-3)
    assert ph_d - ph_0 == pytest.approx(-2 * np.pi * f0 * 0.025, abs=2e-3)
    # causal Butterworth: the analogue prototype's modulus and phase at f0; zero phase has none
    amp_c, ph_c, _, _ = fit(aocs_knowledge(m, **kw, causal=True).roll)
    bb, aa = butter(4, 2 * np.pi * 10.0, analog=True)
    h = freqs(bb, aa, [2 * np.pi * f0])[1][0]
    assert amp_c / (10 * URAD) == pytest.approx(abs(h), rel=2e-3)
    assert ph_c == pytest.approx(np.angle(h), abs=3e-3)
    with pytest.raises(ValueError, match="delay_ms"):
        aocs_knowledge(m, **kw, delay_ms=-1.0)
