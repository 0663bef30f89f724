"""Whether the matching stays locked: the restoration's matches against those the images themselves allow.

Issue 12 asks that matching stay locked under large jitter. A valid-match
fraction alone cannot say it: on phr_cmg's green / red pair about 18 % of the
points fail even when band B is resampled into band A's geometry with the
*true* attitude (the bands' textures differ, a 3-line window holds little
along-track texture), at 1 × the default amplitude as at 4 ×. What the
restoration can be asked is to find what the images allow.

With truth present, :func:`matching_lock` matches the same points of one pair
twice, as the restoration's last matching pass does (band B resampled into
A's geometry, :func:`restore.rematch.geometry_map` and
:func:`restore.rematch.resample_to_reference`, the restoration's window,
search, quality threshold and estimator): once under the restored attitude,
once under the true one. The ratio of the two valid fractions is the lock (1:
every point the images allow is found), and the residual shifts of the points
valid under both say how far the restored geometry is from the true one.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from restore.matching import MatchResult, match_points
from restore.rematch import geometry_map, resample_to_reference
from restore.stages import attitude_series
from simsat.product import clamped_attitude
from simsat.units import AXES

from .metrics import truth_at

__all__ = ["MatchingLock", "restored_attitude", "matches_under", "matching_lock"]


@dataclass(frozen=True)
class MatchingLock:
    """One pair's points matched under the restored and under the true attitude (:func:`matching_lock`).

    Attributes
    ----------
    pair : str
        ``"ahead/behind"``.
    points : int
        Points matched (the restoration's last matching pass's points of the pair).
    valid_stored : float
        Fraction valid in the restoration's own last pass (restoration.nc).
    valid_restored, valid_true : float
        Fraction valid with band B resampled under the restored / the true attitude.
    lost : float
        Fraction of the points valid under the true attitude and not under the restored one.
    shift_rms_restored_px, shift_rms_true_px : float
        RMS of the residual shift (line and column together) of the points valid under both [px]: under the true
        attitude it is the matching's own error, under the restored one that plus the geometry's.
    """

    pair: str
    points: int
    valid_stored: float
    valid_restored: float
    valid_true: float
    lost: float
    shift_rms_restored_px: float
    shift_rms_true_px: float

    @property
    def lock(self) -> float:
        """``valid_restored / valid_true`` (NaN when nothing is valid under the true attitude)."""
        return self.valid_restored / self.valid_true if self.valid_true > 0 else float("nan")

    def as_dict(self) -> dict:
        return {**asdict(self), "lock": self.lock}


def restored_attitude(res) -> dict:
    """Axis → the restored angle at the lines [rad], the AOCS knowledge where a line is not restored."""
    out = {}
    for a in AXES:
        r = np.asarray(res.restored[a], dtype=np.float64)
        out[a] = np.where(np.isfinite(r), r, np.asarray(res.knowledge[a], dtype=np.float64))
    return out


def matches_under(product, res, pair, attitude: dict) -> MatchResult:
    """The points of ``pair`` (a :class:`restore.result.PairData` of ``res``) matched with band B resampled into
    band A's geometry under ``attitude`` (axis → angles at ``res.time`` [rad]), with the restoration's settings."""
    st = res.settings
    sm = product.sensor_model(attitude=clamped_attitude(attitude_series(res.time, attitude)))
    image_a, image_b = product.image(pair.ahead), product.image(pair.behind)
    map_line, map_col = geometry_map(sm, pair.ahead, pair.behind, *image_a.shape)
    behind = resample_to_reference(image_b, map_line, map_col)
    la, ca = np.asarray(pair.line_a, dtype=np.float64), np.asarray(pair.col_a, dtype=np.float64)
    return match_points(image_a, behind, la, ca, la, ca, window=tuple(st.window), search=tuple(st.rematch_search),
                        method=st.match_method, min_quality=st.min_quality)


def _shift_rms(m: MatchResult, lines, cols, keep) -> float:
    if not keep.any():
        return float("nan")
    dl = np.asarray(m.line_b)[keep] - lines[keep]
    dc = np.asarray(m.col_b)[keep] - cols[keep]
    return float(np.sqrt(np.mean(dl ** 2 + dc ** 2)))


def matching_lock(product, res, truth, *, pair: str | None = None) -> MatchingLock:
    """One pair's points matched under the restored and under the true attitude (module docstring).

    Parameters
    ----------
    product : simsat.product.Product
        The run's product.
    res : restore.result.RestorationResult
        Its restoration (read back: the pairs' last matching pass, the restored angles, the settings).
    truth : xarray.Dataset
        The run's truth.nc.
    pair : str, optional
        ``"ahead/behind"``; by default the pair with the lowest valid fraction in the restoration's last pass.
    """
    pairs = [p for p in res.pairs if np.size(p.line_a)]
    if not pairs:
        raise ValueError("matching_lock: the restoration holds no matches")
    if pair is None:
        chosen = min(pairs, key=lambda p: float(np.mean(p.valid)))
    else:
        named = [p for p in pairs if p.name == pair]
        if not named:
            raise ValueError(f"matching_lock: no pair {pair!r} in the restoration (it has "
                             f"{', '.join(p.name for p in pairs)})")
        chosen = named[0]
    true_att = {a: truth_at(truth, a, res.time) for a in AXES}
    under_restored = matches_under(product, res, chosen, restored_attitude(res))
    under_true = matches_under(product, res, chosen, true_att)
    vr, vt = np.asarray(under_restored.valid, dtype=bool), np.asarray(under_true.valid, dtype=bool)
    la, ca = np.asarray(chosen.line_a, dtype=np.float64), np.asarray(chosen.col_a, dtype=np.float64)
    both = vr & vt
    return MatchingLock(pair=chosen.name, points=int(vr.size), valid_stored=float(np.mean(chosen.valid)),
                        valid_restored=float(vr.mean()), valid_true=float(vt.mean()), lost=float(np.mean(vt & ~vr)),
                        shift_rms_restored_px=_shift_rms(under_restored, la, ca, both),
                        shift_rms_true_px=_shift_rms(under_true, la, ca, both))
