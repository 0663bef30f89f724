"""A causal AOCS knowledge with its filter's phase taken out (restore.knowledge_dephasing), on analytic cases."""
import numpy as np
import pytest
from scipy.signal import butter, sosfilt

from restore.knowledge_dephasing import DEPHASED_KIND, dephase_samples, group_delay_at_zero
from restore.knowledge_prior import knowledge_response

RATE = 64.0
FC = 4.0


def _causal_knowledge(signal, *, fc=FC, rate=RATE, span=2.0, lead=4.0, fs=2048.0):
    """``signal(t)`` through a 4th-order causal Butterworth run at ``fs`` from ``-lead`` s (its transient
    gone), sampled at ``rate`` over ``[0, span)``: (t, knowledge, truth)."""
    tg = np.arange(-lead, span, 1 / fs)
    y = sosfilt(butter(4, fc, fs=fs, output="sos"), signal(tg))
    t = np.arange(0, span, 1 / rate)
    return t, np.interp(t, tg, y), signal(t)


def test_group_delay_is_the_butterworth_formula():
    """A 4th-order Butterworth's group delay at zero frequency is 2.6131 / (2π f_c); a zero-phase one has none."""
    for fc in (2.0, 4.0, 10.0):
        assert group_delay_at_zero(fc, 4) == pytest.approx(2.6131259 / (2 * np.pi * fc), rel=1e-4)
    assert group_delay_at_zero(4.0, 4, "butterworth_zero_phase") == pytest.approx(0.0, abs=1e-12)


def test_dephased_response_is_the_causal_modulus_with_no_phase():
    f = np.array([0.0, 1.0, 4.0, 9.0])
    d = knowledge_response(f, FC, 4, DEPHASED_KIND)
    assert np.allclose(d.imag, 0.0)
    assert np.allclose(d.real, np.abs(knowledge_response(f, FC, 4, "butterworth_causal")))
    assert d.real[2] == pytest.approx(1 / np.sqrt(2))


@pytest.mark.parametrize("f0", [0.3, 0.6, 1.0, 2.0])
def test_a_lagged_sine_comes_back_in_phase_but_over_the_last_group_delays(f0):
    """The lag (30° at 0.8 Hz under a 4 Hz cut-off) is gone to |1 − |F|| plus a small edge term, away from
    the record's end; the recorded knowledge erred by 2 sin(φ/2) of the amplitude."""
    t, k, x = _causal_knowledge(lambda s: np.sin(2 * np.pi * f0 * s + 0.4))
    d = dephase_samples(k, 1 / RATE, cutoff_hz=FC, order=4)
    h = knowledge_response(f0, FC, 4, "butterworth_causal")
    inner = t < t[-1] - 3 * group_delay_at_zero(FC, 4)
    lag_error = np.max(np.abs(k - x)[inner])
    assert lag_error == pytest.approx(abs(h - 1), rel=0.05)
    assert np.max(np.abs(d - x)[inner]) < 0.01 + abs(1 - abs(h)) + 0.1 * lag_error


def test_a_trend_and_a_bias_pass_whole_and_in_time():
    """A line is advanced by the group delay (what the all-pass does at zero frequency), to the record's end."""
    t, k, x = _causal_knowledge(lambda s: 3.0 + 0.8 * s)
    assert np.max(np.abs(k - x)) == pytest.approx(0.8 * group_delay_at_zero(FC, 4), rel=0.02)
    d = dephase_samples(k, 1 / RATE, cutoff_hz=FC, order=4)
    assert np.max(np.abs(d - x)) < 1e-3


def test_white_noise_keeps_its_power():
    """An all-pass: the knowledge's noise is neither amplified nor removed (its level is what σ holds)."""
    n = np.random.default_rng(3).standard_normal(4096)
    d = dephase_samples(n, 1 / RATE, cutoff_hz=FC, order=4)
    inner = slice(64, -64)
    assert np.std(d[inner]) == pytest.approx(np.std(n[inner]), rel=0.03)
    assert abs(np.corrcoef(d[inner], n[inner])[0, 1]) < 0.9   # it is rotated, not passed


def test_missing_samples_stay_missing_and_do_not_spread():
    t, k, x = _causal_knowledge(lambda s: np.sin(2 * np.pi * 0.5 * s))
    holed = k.copy()
    holed[40:44] = np.nan
    d = dephase_samples(holed, 1 / RATE, cutoff_hz=FC, order=4)
    assert np.all(np.isnan(d[40:44])) and np.all(np.isfinite(np.delete(d, np.arange(40, 44))))
    full = dephase_samples(k, 1 / RATE, cutoff_hz=FC, order=4)
    assert np.nanmax(np.abs(d - full)) < 0.02


def test_a_filter_with_no_phase_is_refused():
    with pytest.raises(ValueError, match="no phase to take out"):
        dephase_samples(np.zeros(16), 1 / RATE, cutoff_hz=FC, order=4, kind="butterworth_zero_phase")
    with pytest.raises(ValueError, match="must be > 0"):
        dephase_samples(np.zeros(16), 0.0, cutoff_hz=FC, order=4)


@pytest.fixture(scope="module")
def causal_tiny(tmp_path_factory):
    """tiny with a causal 10 Hz knowledge over a 3 Hz line of 2 px (lagged by 0.04 s: 0.75 px of error)."""
    from simsat.scenario import load_scenario
    from simsat.simulate import simulate

    d = tmp_path_factory.mktemp("dephasing") / "tiny_causal"
    sc = load_scenario("tiny", overrides={
        "attitude": {"knowledge": {"filter": "causal"},
                     "jitter": [{"kind": "harmonic", "axis": ["roll", "pitch"], "frequency_hz": 3.0,
                                 "amplitude_urad": 8.0},
                                {"kind": "polynomial", "axis": ["roll", "pitch", "yaw"],
                                 "coefficients_urad": [0.0, 3.0, -1.5]}]}})
    simulate(sc, d, progress=False)
    return d


def test_the_stage_takes_the_lag_out_of_a_rendered_products_knowledge(causal_tiny):
    """On a rendered product: the dephased knowledge at the lines errs less than the recorded one (its 0.04 s
    lag gone), the product it returns reads as dephased, and a zero-phase product is left alone."""
    from dataclasses import replace as dc_replace

    from restore import stages
    from restore.settings import RestorationSettings
    from simsat.product import read_product, read_truth

    product = read_product(causal_tiny)
    truth = read_truth(causal_tiny, product_time=product.time)
    s = RestorationSettings()
    out, dephasing = stages.dephased_knowledge(product, s)
    assert out.ds.attrs["knowledge_filter"] == DEPHASED_KIND
    assert product.ds.attrs["knowledge_filter"] == "butterworth_causal"   # the product read is not changed
    recorded = dict(zip(("roll", "pitch", "yaw"), product.knowledge.at(product.time)))
    ifov = product.pixel_ifov_rad
    for a in ("roll", "pitch"):
        true = np.asarray(truth[a].interp(time=product.time).values, dtype=np.float64)
        before = recorded[a] - true
        after = recorded[a] + dephasing[a] - true
        rms_before = np.std(before) / ifov
        rms_after = np.std(after) / ifov
        assert rms_before > 0.3, rms_before
        assert rms_after < 0.3 * rms_before, (a, rms_before, rms_after)
    off, none = stages.dephased_knowledge(product, dc_replace(s, knowledge_dephasing=False))
    assert off is product and none == {}


def test_the_summary_says_the_knowledge_was_dephased_and_nothing_otherwise():
    import xarray as xr

    from reports.summary import knowledge_dephasing_line

    attrs = {"knowledge_cutoff_hz": 4.0, "knowledge_filter_order": 4, "knowledge_filter": "butterworth_causal"}
    done = xr.Dataset({"knowledge_dephasing_roll": ("time", np.zeros(4))})
    line = knowledge_dephasing_line(attrs, done)
    assert line is not None and "lags the attitude by 0.104 s" in line and "4 Hz" in line
    assert knowledge_dephasing_line(attrs, xr.Dataset()) is None   # restored with knowledge_dephasing = false
    assert knowledge_dephasing_line({**attrs, "knowledge_filter": "butterworth_zero_phase"}, done) is None
    assert knowledge_dephasing_line({}, done) is None and knowledge_dephasing_line(attrs, None) is None


def test_the_records_end_is_predicted_not_reflected():
    """Over the record's last 0.1 s the all-pass needs the knowledge of the next group delay: a 2.2 Hz line
    (on a bias and a drift) continued by linear prediction comes back within 2 % of its amplitude there, and
    over the first 0.1 s (predicted backwards) too; the point reflection alone (a straight line past the end)
    leaves 10 times that."""
    from restore.knowledge_dephasing import _all_passed, _phase

    def signal(s):
        return np.sin(2 * np.pi * 2.2 * s + 0.4) + 0.3 + 0.2 * s
    t, k, x = _causal_knowledge(signal, span=1.6)
    gain = np.abs(knowledge_response(np.array([2.2]), FC, 4, "butterworth_causal"))[0]
    want = gain * np.sin(2 * np.pi * 2.2 * t + 0.4) + 0.3 + 0.2 * t
    end = t > t[-1] - 0.1
    d = dephase_samples(k, 1 / RATE, cutoff_hz=FC, order=4)
    assert np.max(np.abs(d - want)[t < 0.1]) < 0.02
    reflected = _all_passed(k, 1 / RATE, lambda f: -_phase(f, FC, 4, "butterworth_causal"),
                            group_delay_at_zero(FC, 4), 8.0 / FC)
    assert np.max(np.abs(d - want)[end]) < 0.02
    assert np.max(np.abs(reflected - want)[end]) > 0.2


def test_stable_coefficients_keep_the_spectrum_and_put_every_root_inside():
    """Reflecting a root z into 1/z̄ scales |A(e^{iω})| by |z| at every ω: the autoregression's spectral shape is
    kept, its prediction no longer grows."""
    from restore.knowledge_dephasing import stable_coefficients

    rng = np.random.default_rng(3)
    w = np.linspace(0, np.pi, 257)
    for _ in range(20):
        c = rng.normal(0.0, 0.6, 12)
        s = stable_coefficients(c)
        roots = np.roots(np.concatenate([[1.0], -s[::-1]]))
        assert np.all(np.abs(roots) <= 1.0 + 1e-6)

        def gain(coef):
            a = np.concatenate([[1.0], -np.asarray(coef)[::-1]])
            return np.abs(np.polyval(a, np.exp(1j * w)))
        ratio = gain(c) / gain(s)
        assert np.ptp(ratio) < 1e-6 * ratio.mean()
    inside = np.array([-0.25, 1.0])
    np.testing.assert_array_equal(stable_coefficients(inside), inside)


def test_a_gap_lowers_the_order_instead_of_dropping_the_prediction():
    """Two lines under a causal 4 Hz filter, a gap of 4 samples: the prediction still comes (a lower order, the
    rows the gap leaves) and ends within 0.02 of the whole record's; a record too short for any order gets none."""
    from restore.knowledge_dephasing import predicted_tail

    t, k, x = _causal_knowledge(lambda s: np.sin(2 * np.pi * 1.3 * s) + 0.5 * np.sin(2 * np.pi * 2.9 * s + 1.0))
    ok = np.ones(k.size, dtype=bool)
    ok[40:44] = False
    holed = np.where(ok, k, np.interp(np.arange(k.size), np.flatnonzero(ok), k[ok]))
    whole = predicted_tail(k, 16, 42)
    gapped = predicted_tail(holed, 16, 42, valid=ok)
    assert gapped is not None and np.max(np.abs(gapped - whole)) < 0.02
    assert predicted_tail(k[:2], 4, 8) is None
