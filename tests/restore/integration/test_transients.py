"""An abrupt onset the stationary prior cannot follow: found by the fit's misfit, restored without the prior."""
import numpy as np

from restore.integration import methods
from restore.axis_integration import (explained_windows, integrate_axis, running_misfit, transient_blend,
                                      transient_windows, windows_beyond_noise)

DT = 4e-4
TAUS = (0.0074, 0.0148, 0.0222)
IFOV = 4e-6
N = 4000


def _cmg(t):
    return 0.5e-6 * sum(np.sin(2 * np.pi * f * t + k) for k, f in enumerate((52.7, 58.9, 63.4, 74.1)))


def _chirp(t, start=0.15, amplitude=12e-6):
    """SPOT5's mirror (CNES §2): a 25 Hz oscillation switched on at ``start`` (3 px), falling 5 Hz/s, damped
    over 0.6 s."""
    s = np.clip(t - start, 0.0, None)
    return np.where(t >= start, amplitude * np.exp(-s / 0.6) * np.sin(2 * np.pi * (25.0 * s - 2.5 * s * s)), 0.0)


def _record(theta, pitch=None, noise_px=0.08, seed=0):
    """Differentials of ``theta`` seen at t + τ + λ, the lags λ set by the along-track ``pitch`` (1 px: 1 line)."""
    rng = np.random.default_rng(seed)
    t = np.arange(N) * DT
    diffs, lags = [], []
    for tau in TAUS:
        lag = np.zeros(N) if pitch is None else (pitch(t + tau) - pitch(t)) / IFOV * DT
        diffs.append(theta(t + tau + lag) - theta(t) + noise_px * IFOV * rng.standard_normal(N))
        lags.append(lag)
    return t, diffs, lags


def _rms_px(e):
    e = e[np.isfinite(e)]
    return float(np.sqrt(np.mean((e - e.mean()) ** 2))) / IFOV


def test_windows_are_the_lines_whose_running_misfit_stands_out_grown_by_the_margin():
    misfit = np.ones(1000)
    misfit[400:450] = 9.0
    assert transient_windows(misfit, factor=4.0, margin=100) == [[300, 550]]
    assert transient_windows(misfit, factor=10.0, margin=100) == []
    assert transient_windows(misfit, factor=0.0) == []
    # kept only where the estimate without prior fits: its misfit within the limit times the baseline
    local = np.ones(1000)
    assert explained_windows([[300, 550]], local, baseline=1.0, limit=2.0) == [[300, 550]]
    local[500] = 5.0
    assert explained_windows([[300, 550]], local, baseline=1.0, limit=2.0) == []


def test_the_estimate_without_prior_must_fit_the_window_as_it_fits_the_rest_of_the_record():
    """The least squares fit part of the noise: their misfit sits below the MAP's (0.57 × on an unseen 2 px
    scene). A window where they reach 3 × their own level is data neither explains, though it is within 2 × the
    MAP's level; one where they stay at their level is a transient."""
    local = np.full(1000, 0.5)
    local[400:450] = 1.6
    assert explained_windows([[300, 550]], local, limit=2.0) == []
    assert explained_windows([[300, 550]], local, baseline=1.0, limit=2.0) == [[300, 550]]   # the MAP's level
    local[400:450] = 0.6
    assert explained_windows([[300, 550]], local, limit=2.0) == [[300, 550]]


def test_the_running_median_ignores_a_few_failed_lines_but_not_a_misfit_of_most_lines():
    noise = np.ones((3, 1000))
    r = np.random.default_rng(1).standard_normal((3, 1000))
    spikes = r.copy()
    spikes[:, 500:506] = 30.0                       # six failed lines
    assert np.nanmax(running_misfit(spikes, noise, block=100)) < 2.0
    onset = r.copy()
    onset[:, 500:600] *= 4.0                         # a hundred lines misfit 16× in power
    assert np.nanmax(running_misfit(onset, noise, block=100)) > 8.0


def test_blend_ramps_between_the_estimates():
    out = transient_blend(np.zeros(400), np.ones(400), [[100, 300]], ramp=20)
    assert out[0] == 0.0 and out[200] == 1.0 and out[-1] == 0.0 and 0.0 < out[100] < 1.0


def test_an_abrupt_onset_is_restored_without_the_prior_that_cannot_follow_it():
    """A 3 px damped chirp switched on 0.15 s into the record over small CMG lines (SPOT5's mirror, 1 px of it
    along track setting the lags): the stationary MAP, on its periodic grid, rings ahead of the onset (0.19 px
    in the first 500 lines); with the transient window the least-squares estimate takes over there and the
    error falls several-fold. The window is kept in the options: a frozen rerun applies the same."""
    t, diffs, lags = _record(lambda x: _cmg(x) + _chirp(x), pitch=lambda x: _chirp(x) / 3)
    truth = _cmg(t) + _chirp(t)
    plain = integrate_axis(diffs, TAUS, DT, method="wiener", lags=lags, transient_factor=0.0)
    found = integrate_axis(diffs, TAUS, DT, method="wiener", lags=lags, transient_factor=4.0)
    windows = found.options["transient_lines"]
    assert len(windows) == 1 and windows[0][0] < 0.15 / DT < windows[0][1]
    e_plain, e_found = _rms_px(plain.theta - truth), _rms_px(found.theta - truth)
    assert e_found < 0.5 * e_plain, (e_plain, e_found)
    opts = methods.integration_method("wiener").frozen_options(found.options, found.spectrum)
    again = integrate_axis(diffs, TAUS, DT, method="wiener", lags=lags, options=opts)
    np.testing.assert_allclose(again.theta, found.theta, atol=1e-3 * IFOV)


def test_stationary_lines_find_no_transient():
    t, diffs, lags = _record(_cmg)
    res = integrate_axis(diffs, TAUS, DT, method="wiener", lags=lags, transient_factor=4.0)
    assert "transient_lines" not in res.options


def test_a_frozen_rerun_with_windows_is_one_linear_map():
    """Reruns (Monte Carlo, budget) integrate other differentials with the same filter: with the windows and the
    least-squares weights frozen, integrating d + n is integrating d plus integrating n."""
    t, diffs, lags = _record(lambda x: _cmg(x) + _chirp(x), pitch=lambda x: _chirp(x) / 3)
    sigmas = [np.full(N, 0.08 * IFOV) for _ in TAUS]      # the synthesis's formal σ, as the pipeline gives them
    found = integrate_axis(diffs, TAUS, DT, method="wiener", lags=lags, sigmas=sigmas, transient_factor=4.0)
    assert "transient_lines" in found.options and "transient_lsq" in found.options
    opts = methods.integration_method("wiener").frozen_options(found.options, found.spectrum)
    noise = [0.05 * IFOV * np.random.default_rng(7 + j).standard_normal(N) for j in range(len(TAUS))]

    def run(d):
        return integrate_axis(d, TAUS, DT, method="wiener", lags=lags, sigmas=sigmas, options=opts).theta

    both = run([a + b for a, b in zip(diffs, noise)])
    np.testing.assert_allclose(both, run(diffs) + run(noise), atol=1e-4 * IFOV)


def test_filled_lines_the_main_fit_ignores_do_not_spoil_the_local_estimate():
    """Lines of weight 0 (cubic fills across a fold, pixels off) are left out of the least-squares estimate
    too: with four 8-line fills 3 px off in every pair it is what it is without them."""
    from restore.axis_integration import _lsq_estimate

    t, clean, lags = _record(lambda x: _cmg(x) + _chirp(x), pitch=lambda x: _chirp(x) / 3)
    truth = _cmg(t) + _chirp(t)
    spoilt = [d.copy() for d in clean]
    weights = [np.ones(N) for _ in TAUS]
    for j, d in enumerate(spoilt):
        for start in (500, 900, 1300, 1700):
            d[start:start + 8] += 3 * IFOV
            weights[j][start:start + 8] = 0.0
    ref, _ = _lsq_estimate(clean, TAUS, DT, lags, None, weights, 0.0)
    got, _ = _lsq_estimate(spoilt, TAUS, DT, lags, None, weights, 0.0)
    assert _rms_px(got - truth) < 1.2 * _rms_px(ref - truth) < 0.05
    ignored, _ = _lsq_estimate(spoilt, TAUS, DT, lags, None, None, 0.0)       # the fills taken at face value
    assert _rms_px(ignored - truth) > 3 * _rms_px(got - truth)


def test_the_estimate_without_prior_is_judged_where_the_prior_failed_not_over_the_whole_margin():
    """A window [0, 800) grown from failing lines 0-300: the least squares fit lines 0-400 (≤ 1.2 × their median)
    but not a stretch at 700-760 inside the margin (3 ×). Judged over the whole window it is refused; judged
    where the prior failed (and a block beyond) it is kept. Where they do not fit the failing lines themselves
    (a record end, clouds) it is refused either way."""
    from restore.axis_integration import TRANSIENT_JUDGED_MARGIN_LINES, explained_windows, failing_lines

    n = 3000
    map_misfit = np.ones(n)
    map_misfit[:300] = 20.0
    judged = failing_lines(map_misfit, factor=4.0, margin=TRANSIENT_JUDGED_MARGIN_LINES)
    assert judged[:300 + TRANSIENT_JUDGED_MARGIN_LINES].all() and not judged[300 + TRANSIENT_JUDGED_MARGIN_LINES + 1:].any()
    lsq = np.ones(n)
    lsq[:400] = 1.2
    lsq[700:760] = 3.0
    window = [[0, 800]]
    assert explained_windows(window, lsq, limit=2.0) == []
    assert explained_windows(window, lsq, limit=2.0, judged=judged) == window
    lsq[100:200] = 3.0
    assert explained_windows(window, lsq, limit=2.0, judged=judged) == []


def test_a_window_is_kept_only_where_the_estimate_without_prior_differs_by_more_than_its_own_noise():
    """windows_beyond_noise: a difference of 3 × the least squares' noise RMS (a transient's signal) keeps its
    window; a difference that is that noise (a false window: nothing but the least squares' own error) does not;
    the window's mean (the offset no pair sees) does not count."""
    rng = np.random.default_rng(3)
    n = 2000
    noise = rng.standard_normal((4, n)) * 1e-7
    theta = np.zeros(n)
    local = theta + 5e-6                                      # an offset alone: nothing
    local[200:700] += noise[0, 200:700] * 1.0                 # noise-sized: a false window
    t = np.arange(n) * DT
    local[1000:1500] += 3e-7 * np.sqrt(2) * np.sin(2 * np.pi * 20 * t[1000:1500])   # 3 × the noise RMS
    got = windows_beyond_noise([[200, 700], [1000, 1500], [1600, 1900]], theta, local, noise)
    assert got == [[1000, 1500]]
    assert windows_beyond_noise([[1000, 1500]], theta, local, noise, factor=4.0) == []
