"""The local matching error from two interleaved halves of the swath, against known error sources."""
import numpy as np
import pytest

from restore.local_noise import balance_scale, interleaved_halves, local_matching_error
from restore.result import PairData

N_LINES = 3000
COLS = np.arange(24) * 33.0 + 22.0          # 24 points per line, 33 columns apart (windows 31 wide)
S_LINE = 2.0e5                               # px per rad: the line position moves with pitch
S_COL = 2.5e5                                # the column position moves with roll


def _pair(common_line, common_col, point_sigma, rng):
    """A pair whose residuals are a per-line error every point shares plus an independent error per point."""
    lines = np.repeat(np.arange(N_LINES), COLS.size).astype(np.float64)
    cols = np.tile(COLS, N_LINES)
    k = lines.astype(int)
    rl = common_line[k] + point_sigma * rng.standard_normal(lines.size)
    rc = common_col[k] + point_sigma * rng.standard_normal(lines.size)
    sens = np.zeros((lines.size, 2, 3))
    sens[:, 0, 1] = S_LINE
    sens[:, 1, 0] = S_COL
    pair = PairData(name="A/B", ahead="A", behind="B", tau_s=0.0, line_a=lines, col_a=cols,
                    meas_line_b=lines + 5.0 + rl, meas_col_b=cols + rc, quality=np.ones(lines.size),
                    valid=np.ones(lines.size, bool), pred_line_b=lines + 5.0, pred_col_b=cols)
    return pair, sens


def test_interleaved_halves_alternate_blocks_and_refuse_a_null_width():
    assert interleaved_halves([0, 31, 32, 63, 64, 96], 32).tolist() == [True, True, False, False, True, False]
    with pytest.raises(ValueError, match="block_columns"):
        interleaved_halves([0.0], 0)


def test_local_error_has_the_point_noise_statistics_and_none_of_the_line_common_error():
    """Per line the full fit's local error is σ/√N (N points, equal weights); half the difference of the two
    halves' fits has that spread whatever the error every point shares, and is uncorrelated with it."""
    rng = np.random.default_rng(5)
    t = np.arange(N_LINES) * 4e-4
    common_line = 0.08 * np.sin(2 * np.pi * 1.7 * t) + 0.03 * rng.standard_normal(N_LINES)
    common_col = 0.05 * np.cos(2 * np.pi * 3.1 * t)
    sigma = 0.3
    pair, sens = _pair(common_line, common_col, sigma, rng)
    local = local_matching_error(pair, sens, n_lines=N_LINES, axes=("roll", "pitch"), block_columns=62,
                                 min_points=2, n_sigma=10.0)
    expected = sigma / np.sqrt(COLS.size)
    pitch_px = local[:, 1] * S_LINE
    roll_px = local[:, 0] * S_COL
    assert np.all(np.isfinite(pitch_px)) and np.all(np.isnan(local[:, 2]))   # yaw not fitted
    assert np.std(pitch_px) == pytest.approx(expected, rel=0.06)
    assert np.std(roll_px) == pytest.approx(expected, rel=0.06)
    assert abs(np.corrcoef(pitch_px, common_line)[0, 1]) < 0.06
    assert abs(np.corrcoef(roll_px, common_col)[0, 1]) < 0.06


def test_an_error_every_point_shares_leaves_no_local_error():
    rng = np.random.default_rng(6)
    common = 0.1 * rng.standard_normal(N_LINES)
    pair, sens = _pair(common, -common, 0.0, rng)
    local = local_matching_error(pair, sens, n_lines=N_LINES, axes=("roll", "pitch"), block_columns=62)
    assert np.nanmax(np.abs(local[:, :2])) * S_LINE < 1e-9
    full_fit = common / S_LINE                # what the full fit books as the pitch differential: all of it
    assert np.std(full_fit) > 1e-7


def test_lines_a_half_does_not_cover_are_gaps_and_the_sensitivities_must_match():
    rng = np.random.default_rng(7)
    pair, sens = _pair(np.zeros(N_LINES), np.zeros(N_LINES), 0.2, rng)
    pair.valid[(pair.line_a < 10) & (pair.col_a > 60)] = False      # the first lines: one block only (one half)
    v = pair.valid
    local = local_matching_error(pair, sens[v], n_lines=N_LINES, axes=("roll", "pitch"), block_columns=62)
    assert np.all(np.isfinite(local[10:, :2]))
    assert np.all(np.isnan(local[:10, :2]))
    with pytest.raises(ValueError, match="sensitivities"):
        local_matching_error(pair, sens, n_lines=N_LINES, axes=("roll", "pitch"), block_columns=62)


def test_points_all_in_one_block_give_no_estimate():
    rng = np.random.default_rng(8)
    pair, sens = _pair(np.zeros(N_LINES), np.zeros(N_LINES), 0.2, rng)
    pair.valid &= pair.col_a == COLS[0]
    local = local_matching_error(pair, sens[pair.valid], n_lines=N_LINES, axes=("roll", "pitch"), block_columns=62)
    assert np.all(np.isnan(local))


def test_unequal_halves_are_scaled_to_the_full_fits_local_error():
    """Three points of four in one half: the full fit's local error is still σ/√N, half the halves' difference
    has σ·√(1/n_A + 1/n_B)/2 (15 % more here); the halves' information-weighted scale gives σ/√N back."""
    rng = np.random.default_rng(9)
    sigma = 0.3
    pair, sens = _pair(np.zeros(N_LINES), np.zeros(N_LINES), sigma, rng)
    block = np.floor(pair.col_a / 62).astype(int) % 2            # 0: half A, 1: half B (blocks of 62 columns)
    # keep every point of half A and one in three of half B's: 18 and 6 points per line
    b_index = np.cumsum(block) * block
    pair.valid &= (block == 0) | (b_index % 3 == 0)
    v = pair.valid
    n_a = int(np.count_nonzero(v & (block == 0))) // N_LINES
    n_b = int(np.count_nonzero(v & (block == 1))) // N_LINES
    local = local_matching_error(pair, sens[v], n_lines=N_LINES, axes=("roll", "pitch"), block_columns=62,
                                 min_points=2, n_sigma=10.0)
    expected = sigma / np.sqrt(n_a + n_b)
    naive = sigma * np.sqrt(1 / n_a + 1 / n_b) / 2
    assert naive > 1.1 * expected
    assert np.std(local[:, 1] * S_LINE) == pytest.approx(expected, rel=0.06)
    assert np.std(local[:, 0] * S_COL) == pytest.approx(expected, rel=0.06)


def test_balance_scale_is_one_half_for_equal_halves_and_nan_where_a_half_is():
    assert balance_scale([2.0], [2.0])[0] == pytest.approx(0.5)
    assert balance_scale([1.0], [2.0])[0] == pytest.approx(2.0 / 5.0)
    assert np.isnan(balance_scale([np.nan], [1.0])[0])
