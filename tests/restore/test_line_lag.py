"""Per-line lags (restore.stages.line_lag) against a known along-track motion."""
import numpy as np

from restore.result import PairData
from restore.stages import line_lag

TE = 4e-4                        # line period [s]
TAU_LINES = 18.5                 # the pair's delay τ′ [lines]


def _pair(motion, prediction_motion, *, n_lines=300, per_line=8, noise=0.0, seed=0):
    """Band B matched at ``l + τ′ + motion(l)`` (plus noise); the prediction the residuals were taken about moves
    by ``prediction_motion(l)`` (the knowledge's own differential: its noise)."""
    rng = np.random.default_rng(seed)
    la = np.repeat(np.arange(n_lines, dtype=float), per_line)
    ca = np.tile(np.linspace(40, 600, per_line), n_lines)
    meas = la + TAU_LINES + motion(la) + noise * rng.standard_normal(la.size)
    pred = la + TAU_LINES + prediction_motion(la)
    ok = np.ones(la.size, bool)
    return PairData(name="A/B", ahead="A", behind="B", tau_s=TAU_LINES * TE, line_a=la, col_a=ca, meas_line_b=meas,
                    meas_col_b=ca.copy(), quality=np.ones(la.size), valid=ok, pred_line_b=pred, pred_col_b=ca.copy(),
                    inlier=ok.copy())


def test_the_lag_is_the_matched_offset_less_the_delay_whatever_the_prediction():
    motion = lambda l: 2.0 * np.sin(2 * np.pi * l / 41.0)                       # noqa: E731
    knowledge_noise = lambda l: 0.1 * np.cos(2 * np.pi * l / 7.3)               # noqa: E731
    lines = np.arange(300.0)
    for pred in (lambda l: 0.0 * l, knowledge_noise, motion):
        lag = line_lag(_pair(motion, pred), 300, max_gap=8, line_period_s=TE)
        np.testing.assert_allclose(lag, motion(lines), atol=1e-9)


def test_noise_averages_over_the_line_and_a_long_gap_is_zero():
    motion = lambda l: 0.7 + 0.0 * l                                             # noqa: E731
    pair = _pair(motion, lambda l: 0.0 * l, noise=0.2, per_line=16)
    gone = (pair.line_a >= 100) & (pair.line_a < 250)
    pair.inlier[gone] = False
    lag = line_lag(pair, 300, max_gap=8, line_period_s=TE)
    lines = np.arange(300)
    kept = (lines < 100) | (lines >= 250)
    assert abs(np.mean(lag[kept]) - 0.7) < 0.01
    assert 0.02 < np.std(lag[kept]) < 0.08                      # 0.2 / √16 = 0.05 per line
    assert np.all(lag[(lines >= 100 + 64) & (lines < 250 - 64)] == 0.0)
