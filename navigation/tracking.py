"""Frame-to-frame tracking of 2-D segments through a short sequence (the patent's "pistas").

For frames k → k+1 the tracker maps each live track's last segment through
the homography predicted from the INS relative pose and the ground plane
(coarse registration), associates it with the nearest segment of k+1 of the
same orientation that overlaps it, refits the homography to those pairs by
least squares,
and associates again with a tighter gate. The refit is a trimmed least squares
(:func:`~navigation.homography.trimmed_homography_lines`, RANSAC only when
most pairs are wrong). A track not found in k+1 continues
with a *virtual* segment (its last one mapped by the homography) for up to
``max_gap`` frames, so that a short occlusion or a missed detection does not
cut it (claim 4).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .homography import map_segments, segment_lines, trimmed_homography_lines
from .segments import segment_angles, segment_lengths

__all__ = ["Track", "TrackingResult", "associate_segments", "track_sequence"]


@dataclass
class Track:
    """One line seen through the sequence: per frame its segment and whether it was virtual."""

    frames: list = field(default_factory=list)
    segs: list = field(default_factory=list)
    virtual: list = field(default_factory=list)

    @property
    def real_count(self) -> int:
        return int(len(self.virtual) - sum(self.virtual))

    def real(self):
        """(frames, segments (n, 4)) of the real observations."""
        idx = [i for i, v in enumerate(self.virtual) if not v]
        return [self.frames[i] for i in idx], np.array([self.segs[i] for i in idx]).reshape(-1, 4)


@dataclass
class TrackingResult:
    tracks: list
    homographies: list          # fitted H k → k+1 (None where the fit failed: the prediction was used)
    pairs_per_step: list
    virtual_count: int


def associate_segments(pred: np.ndarray, cand: np.ndarray, *, gate_px: float, angle_deg: float,
                       min_overlap: float = 0.3) -> list[tuple[int, int]]:
    """Greedy one-to-one pairs ``(i, j)`` of predicted segments and candidates.

    Cost: the larger distance of ``pred[i]``'s endpoints to ``cand[j]``'s line;
    pairs need the cost below ``gate_px``, orientations within ``angle_deg``
    and an overlap along the line of at least ``min_overlap`` of the shorter.
    """
    if len(pred) == 0 or len(cand) == 0:
        return []
    lc = segment_lines(cand)                                     # (m, 3)
    ends = [np.column_stack([pred[:, 0:2], np.ones(len(pred))]), np.column_stack([pred[:, 2:4], np.ones(len(pred))])]
    dist = np.maximum(np.abs(ends[0] @ lc.T), np.abs(ends[1] @ lc.T))      # (n, m)
    da = np.abs(segment_angles(pred)[:, None] - segment_angles(cand)[None, :])
    da = np.minimum(da, np.pi - da)
    u = np.column_stack([lc[:, 1], -lc[:, 0]])                  # candidate directions
    s_c = np.stack([np.einsum("mk,mk->m", cand[:, 0:2], u), np.einsum("mk,mk->m", cand[:, 2:4], u)])
    s_p = np.stack([pred[:, 0:2] @ u.T, pred[:, 2:4] @ u.T])      # (2, n, m)
    lo = np.maximum(s_p.min(0), s_c.min(0)[None, :])
    hi = np.minimum(s_p.max(0), s_c.max(0)[None, :])
    shorter = np.minimum(segment_lengths(pred)[:, None], segment_lengths(cand)[None, :])
    ok = (dist < gate_px) & (da < np.radians(angle_deg)) & ((hi - lo) >= min_overlap * shorter)
    cost = np.where(ok, dist, np.inf)
    pairs = []
    order = np.argsort(cost, axis=None)
    used_i, used_j = set(), set()
    for flat in order:
        c = cost.flat[flat]
        if not np.isfinite(c):
            break
        i, j = divmod(int(flat), cost.shape[1])
        if i in used_i or j in used_j:
            continue
        used_i.add(i)
        used_j.add(j)
        pairs.append((i, j))
    return pairs


def track_sequence(segments: list, predicted: list, *, width: int, height: int, gate_px: float = 10.0,
                   fine_gate_px: float = 2.5, angle_deg: float = 5.0, max_gap: int = 2,
                   rng: np.random.Generator | None = None) -> TrackingResult:
    """Tracks through frames ``segments[0..n-1]`` given predicted homographies ``predicted[k]`` (k → k+1)."""
    rng = rng if rng is not None else np.random.default_rng(0)
    tracks = [Track([0], [s], [False]) for s in segments[0]]
    live = list(range(len(tracks)))
    gaps = {i: 0 for i in live}
    fitted, npairs, nvirt = [], [], 0
    for k in range(len(segments) - 1):
        cur = np.array([tracks[i].segs[-1] for i in live]).reshape(-1, 4)
        nxt = np.asarray(segments[k + 1]).reshape(-1, 4)
        H = predicted[k]
        pairs = associate_segments(map_segments(H, cur), nxt, gate_px=gate_px, angle_deg=angle_deg)
        Hf = None
        if len(pairs) >= 6:
            i_idx, j_idx = np.array(pairs).T
            Hf, _ = trimmed_homography_lines(cur[i_idx], nxt[j_idx], threshold_px=1.5, rng=rng)
        if Hf is not None:
            H = Hf
            pairs = associate_segments(map_segments(H, cur), nxt, gate_px=fine_gate_px, angle_deg=angle_deg)
        fitted.append(Hf)
        npairs.append(len(pairs))
        matched_t = {live[i]: j for i, j in pairs}
        mapped = map_segments(H, cur)
        new_live = []
        for pos, ti in enumerate(live):
            t = tracks[ti]
            if ti in matched_t:
                t.frames.append(k + 1)
                t.segs.append(nxt[matched_t[ti]])
                t.virtual.append(False)
                gaps[ti] = 0
                new_live.append(ti)
            elif gaps[ti] < max_gap and _inside(mapped[pos], width, height):
                t.frames.append(k + 1)
                t.segs.append(mapped[pos])
                t.virtual.append(True)
                gaps[ti] += 1
                nvirt += 1
                new_live.append(ti)
        used = set(matched_t.values())
        for j in range(len(nxt)):
            if j not in used:
                tracks.append(Track([k + 1], [nxt[j]], [False]))
                gaps[len(tracks) - 1] = 0
                new_live.append(len(tracks) - 1)
        live = new_live
    for t in tracks:   # a track does not end on virtual segments
        while t.virtual and t.virtual[-1]:
            t.frames.pop()
            t.segs.pop()
            t.virtual.pop()
    return TrackingResult(tracks, fitted, npairs, nvirt)


def _inside(seg: np.ndarray, width: int, height: int) -> bool:
    return bool(np.all((seg[[0, 2]] >= 0) & (seg[[0, 2]] < width) & (seg[[1, 3]] >= 0) & (seg[[1, 3]] < height)))
