"""The local part of the matching error, measured by splitting the swath into two interleaved halves.

A line's differential is fitted from the matched points across the swath
(:func:`restore.synthesis.instant_synthesis`). Its error has two parts of
different nature:

* a **local** part: each point's own error (image noise, the texture in its
  window seen through each band's spectrum), independent from one point's
  window to the next, which averages down as more points are matched;
* a **line-common** part: the same for every point of the line (a band's
  along-track bias that follows the scene's large features, its shading seen
  through its own spectrum, the time sampling): more points do not reduce it,
  and a part of it that moves like an attitude is not seen by any fit residual.

Fitting the differentials again from two halves of the points, taken in
interleaved blocks of columns wider than a matching window (so that no
window is in both halves and both halves span the swath), gives two
estimates with independent local errors and the same line-common error:
their difference, scaled, has the local error's statistics and none of the
line-common one. The full fit weighs the halves by their information, so its
local error has the variance ``v_A v_B / (v_A + v_B)`` (``v``: each half's
formal variance) and ``d_A − d_B`` has ``v_A + v_B``: the scale is
``√(v_A v_B) / (v_A + v_B) = s_A s_B / (s_A² + s_B²)``, ½ for equal halves.
Unequal halves are the rule on a real line (a half with a few weak points in
dark or flat blocks): a fixed ½ then over-states the local error, most on the
lines where one half barely holds its fit (on the rendered stress scenes the
½ gave 5–20 % more than the differentials' whole error, local and
line-common together, at 300–1250 Hz). It needs no truth. The report integrates it like a
noise draw (:func:`reports.report_data.budget.error_budget`), so that a
budget shows how much of the measurement error is local and, with truth,
how much is common to the line.
"""
from __future__ import annotations

import numpy as np

from simsat.units import AXES

from .synthesis import instant_synthesis, match_weights, window_compensation

__all__ = ["interleaved_halves", "balance_scale", "local_matching_error"]


def interleaved_halves(columns, block_columns: int) -> np.ndarray:
    """Which half each point belongs to: True in even blocks of ``block_columns`` columns, False in odd ones.

    Examples
    --------
    >>> interleaved_halves([0, 10, 40, 70, 130], 32).tolist()
    [True, True, False, True, True]
    """
    if block_columns < 1:
        raise ValueError(f"block_columns: must be >= 1, got {block_columns}")
    c = np.asarray(columns, dtype=np.float64)
    return (np.floor(c / block_columns).astype(np.int64) % 2) == 0


def _halves_balanced(columns: np.ndarray, block_columns: int) -> np.ndarray | None:
    """:func:`interleaved_halves`, with the block width lowered (to a quarter) until both halves hold points;
    None when they never do (all points in one block)."""
    for b in (block_columns, block_columns // 2, block_columns // 4):
        half = interleaved_halves(columns, max(int(b), 1))
        if half.any() and (~half).any():
            return half
    return None


def balance_scale(sigma_a, sigma_b) -> np.ndarray:
    """The scale that gives ``d_A − d_B`` the variance of the two halves' information-weighted combination:
    ``s_A s_B / (s_A² + s_B²)`` (½ for equal formal σ, smaller the more unequal; NaN where either is).

    Examples
    --------
    >>> balance_scale([1.0, 1.0], [1.0, 3.0]).round(3).tolist()
    [0.5, 0.3]
    """
    a = np.asarray(sigma_a, dtype=np.float64)
    b = np.asarray(sigma_b, dtype=np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        return a * b / (a * a + b * b)


def local_matching_error(pair, sensitivities, *, n_lines: int, axes=AXES, block_columns: int, min_points: int = 2,
                         n_sigma: float = 3.0, window_lines: int = 0, covariance: bool = True) -> np.ndarray:
    """The difference of the differentials fitted from two interleaved halves of a pair's points, scaled to the
    full fit's local error (:func:`balance_scale`: ½ for equal halves).

    Parameters
    ----------
    pair : restore.result.PairData
        The pair's matches with their predictions (``pred_line_b``/``pred_col_b``) and, when the matcher
        gave them, the per-coordinate σ (weights as the pipeline's synthesis).
    sensitivities : array (n_valid, 2, 3)
        ∂(line, column)/∂(roll, pitch, yaw) of the pair's valid matches [px/rad].
    n_lines : int
        Lines of the record.
    axes : sequence of str
        The axes the pipeline fitted.
    block_columns : int
        Width of the interleaved blocks [columns]; at least a matching window's width.
    min_points : int
        Fewest points per line in each half.
    n_sigma : float
        Outlier rejection of the synthesis.
    window_lines : int
        The matching window's height when the pipeline compensated its averaging (0: not compensated).
    covariance : bool
        Weigh the points by their 2 × 2 covariance, as the pipeline's synthesis does with
        ``restoration.match_covariance`` (:func:`restore.synthesis.match_weights`).

    Returns
    -------
    ndarray (n_lines, 3)
        Per line and axis of :data:`simsat.units.AXES` [rad]: an estimate of the
        local part of the differential's error; NaN where a half has too few
        points or the axis is not fitted (everywhere when every point lies in
        one block).
    """
    v = np.asarray(pair.valid, dtype=bool)
    sens = np.asarray(sensitivities, dtype=np.float64)
    if sens.shape[0] != int(v.sum()):
        raise ValueError(f"sensitivities: {sens.shape[0]} rows for {int(v.sum())} valid matches of pair {pair.name}")
    la, ca = np.asarray(pair.line_a)[v], np.asarray(pair.col_a)[v]
    rl = (np.asarray(pair.meas_line_b) - np.asarray(pair.pred_line_b))[v]
    rc = (np.asarray(pair.meas_col_b) - np.asarray(pair.pred_col_b))[v]
    w, rho = match_weights(pair, v, covariance=covariance)
    half = _halves_balanced(ca, block_columns)
    if half is None:
        return np.full((n_lines, len(AXES)), np.nan)
    fits = [instant_synthesis(np.rint(la[m]).astype(np.int64), rl[m], rc[m], sens[m], n_lines=n_lines,
                              weights=w[m], correlation=None if rho is None else rho[m], axes=axes,
                              min_points=min_points, n_sigma=n_sigma) for m in (half, ~half)]
    out = (fits[0].diff - fits[1].diff) * balance_scale(fits[0].sigma, fits[1].sigma)
    if window_lines > 1:
        out = np.stack([window_compensation(out[:, k], window_lines=window_lines) for k in range(out.shape[1])],
                       axis=1)
    return out
