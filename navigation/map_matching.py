"""Matching reconstructed 3-D lines with the 2-D reference map, seen from above.

The 3-D segments, placed in the world by the INS pose, are projected into the
reference's perspective (an orthographic top view: drop z) and associated
with reference segments of the same orientation. The INS error shifts the
whole reconstruction, so the association is decided by a vote over that
shift: every candidate pair (line i, reference j) is a band in the shift
plane (``n_j · δ ≈ o_ij``); the shift that the most *lines* agree with wins,
provided no distinct shift is nearly as popular (an ambiguous vote means no
fix rather than a wrong one). Pairs consistent with the winning shift are the
matches; the Kalman update then uses their normal distances, not the shift.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

__all__ = ["MapMatch", "match_to_reference", "normal_distances"]


@dataclass
class MapMatch:
    pairs: list            # (line index, reference index)
    shift: np.ndarray      # voted horizontal shift (m) that moves the lines onto the map
    votes: int
    runner_up: int
    directions: int        # distinct directions (20° bins) among the matched lines
    status: str            # "ok" or why there is no fix


def _unit_normal(seg: np.ndarray) -> np.ndarray:
    d = seg[:, 2:4] - seg[:, 0:2]
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return np.column_stack([-d[:, 1], d[:, 0]])


def normal_distances(points_xy: np.ndarray, ref_seg: np.ndarray) -> np.ndarray:
    """Signed distances (n,) of points (n, 2) to the lines of reference segments (n, 4)."""
    n = _unit_normal(ref_seg)
    return np.einsum("ij,ij->i", points_xy - ref_seg[:, 0:2], n)


def match_to_reference(lines_xy: np.ndarray, ref, *, gate_m: float, angle_deg: float = 6.0, tol_m: float = 6.0,
                       min_lines: int = 5, min_directions: int = 2, cell_m: float = 2.0,
                       prior_sigma_m: float | None = None) -> MapMatch:
    """Associate horizontal segments ``lines_xy`` (n, 4) with the reference map ``ref`` (a LineMap).

    ``prior_sigma_m``: 1-σ of the shift the INS error can cause; a rival island of the vote farther
    than 3 σ from no shift does not make the vote ambiguous (None: every island counts).
    """
    n = len(lines_xy)
    if n == 0 or len(ref) == 0:
        return MapMatch([], np.zeros(2), 0, 0, 0, "no reconstructed lines" if n == 0 else "empty reference map")
    rs = ref.segments
    rmid = 0.5 * (rs[:, :2] + rs[:, 2:])
    rhalf = 0.5 * np.hypot(*(rs[:, 2:] - rs[:, :2]).T)
    tree = cKDTree(rmid)
    mid = 0.5 * (lines_xy[:, :2] + lines_xy[:, 2:])
    half = 0.5 * np.hypot(*(lines_xy[:, 2:] - lines_xy[:, :2]).T)
    ang_l = np.mod(np.arctan2(lines_xy[:, 3] - lines_xy[:, 1], lines_xy[:, 2] - lines_xy[:, 0]), np.pi)
    ang_r = np.mod(np.arctan2(rs[:, 3] - rs[:, 1], rs[:, 2] - rs[:, 0]), np.pi)
    nr = _unit_normal(rs)
    cand = []   # (i, j, normal, offset)
    for i in range(n):
        js = np.array(tree.query_ball_point(mid[i], gate_m + half[i] + rhalf.max()), dtype=int)
        if len(js) == 0:
            continue
        da = np.abs(ang_l[i] - ang_r[js])
        da = np.minimum(da, np.pi - da)
        js = js[da < np.radians(angle_deg)]
        # along the reference line the segments must be able to overlap once shifted by ≤ gate
        d_along = np.abs(np.einsum("ij,ij->i", mid[i] - rmid[js], np.column_stack([nr[js, 1], -nr[js, 0]])))
        js = js[d_along <= rhalf[js] + half[i] + gate_m]
        off = np.einsum("ij,ij->i", rs[js, :2] - mid[i], nr[js])
        js, off = js[np.abs(off) <= gate_m], off[np.abs(off) <= gate_m]
        cand += [(i, j, nr[j], o) for j, o in zip(js, off)]
    if not cand:
        return MapMatch([], np.zeros(2), 0, 0, 0, "no reference segment within the gate")
    g = np.arange(-gate_m, gate_m + cell_m, cell_m)
    GX, GY = np.meshgrid(g, g)
    score = np.zeros(GX.shape, np.int32)
    by_line: dict = {}
    for c in cand:
        by_line.setdefault(c[0], []).append(c)
    for i, cs in by_line.items():
        hit = np.zeros(GX.shape, bool)
        for _, _, nn, o in cs:
            hit |= np.abs(nn[0] * GX + nn[1] * GY - o) < tol_m
        score += hit
    best = np.unravel_index(np.argmax(score), score.shape)
    shift = np.array([GX[best], GY[best]])
    votes = int(score[best])
    # a distinct shift is a separate island of high score (roads' two edges widen the peak, not split it)
    from scipy.ndimage import label

    islands, count = label(score >= max(1, int(np.ceil(0.6 * votes))))
    own = islands[best]
    runner = 0
    for k in range(1, count + 1):
        if k == own:
            continue
        m = islands == k
        peak = int(score[m].max())
        where = np.argmax(np.where(m, score, -1))
        # a rival shift the INS's own uncertainty makes implausible (beyond 3 σ) is no rival
        if prior_sigma_m is not None and np.hypot(GX.flat[where], GY.flat[where]) > 3 * prior_sigma_m + tol_m:
            continue
        runner = max(runner, peak)
    # the vote's top is flat over ~tol: refine the shift by least squares on the pairs it selects, twice
    for _ in range(2):
        pairs, rows = [], []
        for i, cs in by_line.items():
            res = [abs(nn @ shift - o) for _, _, nn, o in cs]
            k = int(np.argmin(res))
            if res[k] < tol_m:
                pairs.append((i, cs[k][1]))
                rows.append((cs[k][2], cs[k][3]))
        if len(rows) >= 2:
            A = np.array([r[0] for r in rows])
            if np.linalg.matrix_rank(A) == 2:
                shift = np.linalg.lstsq(A, np.array([r[1] for r in rows]), rcond=None)[0]
    dirs = len({int(np.degrees(ang_l[i]) // 20) for i, _ in pairs})
    status = "ok"
    if len(pairs) < min_lines:
        status = f"{len(pairs)} matched lines (< {min_lines})"
    elif dirs < min_directions:
        status = f"matched lines in {dirs} direction(s) only"
    elif runner >= max(0.75 * votes, votes - 2):
        status = f"ambiguous: a shift {runner} lines agree with is as good as {votes}"
    return MapMatch(pairs, shift, votes, runner, dirs, status)
