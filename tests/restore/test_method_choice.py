"""Choosing the integration method by leave-one-pair-out cross-validation, on analytic cases."""
import numpy as np
import pytest

from restore.method_choice import (
    AUTO_METHOD,
    choose_method,
    cross_validation_score,
    predicted_differential,
    resolve_method,
)

DT = 4e-4
N = 4000
TAUS = [7.4e-3, 14.8e-3, 22.2e-3]
IFOV = 52e-6 / 12.905
T = np.arange(N) * DT


def cmg(t):
    """Stationary micro-vibration lines (the PHR CMG exciters and their second harmonics)."""
    rng = np.random.default_rng(1)
    ph = rng.uniform(0, 2 * np.pi, 8)
    return sum(2.2e-6 / h * np.sin(2 * np.pi * f * h * t + ph[2 * i + h - 1])
               for i, f in enumerate((52.7, 58.9, 63.4, 74.1)) for h in (1, 2))


def onset(t, start=0.15):
    """A mirror that starts rocking inside the record (damped chirp, 3 px, zero before its start)."""
    x = np.maximum(t - start, 0.0)
    return np.where(t >= start, 12.1e-6 * np.exp(-x / 0.6) * np.sin(2 * np.pi * (25 * x - 2.5 * x ** 2)), 0.0)


def _diffs(th, noise_px=0.05, seed=2):
    rng = np.random.default_rng(seed)
    return [th(T + tau) - th(T) + noise_px * IFOV * rng.standard_normal(N) for tau in TAUS]


def test_predicted_differential_is_the_shifted_difference():
    th = 1e-6 * np.sin(2 * np.pi * 7.0 * T)
    d = predicted_differential(th, 0.0222, DT)
    exact = 1e-6 * (np.sin(2 * np.pi * 7.0 * (T + 0.0222)) - np.sin(2 * np.pi * 7.0 * T))
    ok = np.isfinite(d)
    assert np.all(~ok[T + 0.0222 > T[-1]]) and ok[T + 0.0222 <= T[-1]].all()  # no extrapolation
    np.testing.assert_allclose(d[ok], exact[ok], atol=1e-12)
    lag = np.full(N, 1e-3)  # a per-line extra lag moves the later time
    np.testing.assert_allclose(predicted_differential(th, 0.0212, DT, lag)[ok], exact[ok], atol=1e-12)


def test_score_measures_how_well_the_other_pairs_predict_the_left_out_one():
    d = _diffs(cmg, noise_px=0.05)
    score = cross_validation_score("wiener", d, TAUS, DT)
    # the held-out samples carry 0.05 px of noise: the score cannot fall below it, and a good fit adds little
    assert 0.05 * IFOV < score < 0.07 * IFOV
    wrong = cross_validation_score("wiener", d, [TAUS[0], TAUS[1], 0.9 * TAUS[2]], DT)  # a wrong delay
    assert wrong > 1.5 * score
    assert np.isnan(cross_validation_score("wiener", d[:1], TAUS[:1], DT))  # nothing to hold out


@pytest.mark.parametrize("signal, expected", [(cmg, "wiener"), (onset, "lsq"), (lambda t: onset(t) + cmg(t), "lsq")])
def test_choice_follows_which_method_is_actually_closer_to_the_truth(signal, expected):
    """Stationary lines: the Wiener filter; a transient inside the record: the least squares. The choice reads
    the differentials only; the truth confirms it was the better one."""
    from restore.integration import integrate

    d = _diffs(signal)
    chosen, scores = choose_method(d, TAUS, DT)
    assert set(scores) == {"wiener", "lsq"} and chosen == expected

    def err(m):
        e = integrate(d, TAUS, DT, method=m) - signal(T)
        e = e[np.isfinite(e)]
        return np.sqrt(np.mean((e - e.mean()) ** 2))

    other = "lsq" if expected == "wiener" else "wiener"
    assert err(expected) < err(other)


def test_resolve_method_passes_named_methods_through():
    d = _diffs(cmg)
    assert resolve_method("kalman", d, TAUS, DT) == ("kalman", None)
    assert resolve_method(None, d, TAUS, DT) == (None, None)
    name, sel = resolve_method(AUTO_METHOD, d, TAUS, DT)
    assert name == "wiener" and sel["chosen"] == "wiener" and set(sel["scores_rad"]) == {"wiener", "lsq"}
    assert resolve_method(AUTO_METHOD, d[:1], TAUS[:1], DT)[0] == "wiener"  # one pair: the default


def test_auto_settings():
    from restore.settings import restoration_settings
    from simsat.config import ScenarioError

    assert restoration_settings({"method": "auto"}).method == "auto"
    with pytest.raises(ScenarioError, match="restoration.integration"):
        restoration_settings({"method": "auto", "integration": {"k": 1.0}})
    with pytest.raises(ScenarioError, match="'auto'"):
        restoration_settings({"method": "wienner"})


def test_paired_improvement_on_known_residuals():
    from restore.method_choice import paired_improvement

    rng = np.random.default_rng(4)
    r = rng.standard_normal(6400)
    w = np.ones_like(r)
    gain, t = paired_improvement(r, 0.5 * r, w)  # a candidate with half the residual: 75 % less squared error
    assert gain == pytest.approx(0.75) and t > 20
    assert paired_improvement(r, r, w) == (0.0, 0.0)
    gain, t = paired_improvement(r, rng.standard_normal(6400), w)  # as good, independently: no significance
    assert abs(gain) < 0.1 and abs(t) < 3
    assert paired_improvement(r[:50], r[:50], w[:50]) == (0.0, 0.0)  # too few samples to test


def test_a_run_restored_with_auto_records_and_reports_the_method_each_axis_ran(tmp_path):
    """End to end on tiny: restoration.nc records per axis the chosen method and its scores; the report's
    transfer probe re-runs that method (not "auto", which is no integration method)."""
    import shutil

    from reports import report_data as D
    from restore.pipeline import restore_run
    from restore.restoration_io import read_restoration
    from simsat.simulate import simulate

    d = tmp_path / "tiny"
    simulate("tiny", d, progress=False)
    res = restore_run(d, progress=False, overrides={"method": "auto", "correct_images": False,
                                                    "posterior_samples": 0})
    assert res.method == "auto"
    back = read_restoration(d / "restoration.nc")
    for a in ("roll", "pitch"):
        rec = back.integration[a]
        assert rec.method in ("wiener", "lsq") and rec.selection["chosen"] == rec.method
        assert set(rec.selection["scores_rad"]) == {"wiener", "lsq"}
    run = D.load_run(d)
    integrate, _ = D.get_integrator()
    taus = [p.tau_s for p in back.pairs]
    tc = D.transfer_curves(run, taus, [p.name for p in back.pairs], ["roll", "pitch"], method="auto", options={},
                           integrate=integrate, f_max=200.0)
    assert not [n for n in tc["notes"] if "failed" in n], tc["notes"]
    assert set(tc["probes"]) == {"roll", "pitch"}
    shutil.rmtree(d)
