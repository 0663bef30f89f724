"""Whether matching stays locked: the same points matched under the restored and under the true attitude."""
import dataclasses

import numpy as np
import pytest

from reports.matching_lock import matching_lock, restored_attitude
from reports.metrics import truth_at
from restore.pipeline import restore_run
from restore.restoration_io import read_restoration
from simsat.product import read_product, read_truth
from simsat.simulate import simulate


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    d = tmp_path_factory.mktemp("lock") / "tiny"
    simulate("tiny", d, progress=False)
    restore_run(d, progress=False)
    return read_product(d), read_restoration(d / "restoration.nc"), read_truth(d)


def test_the_restoration_finds_what_the_true_geometry_allows(tiny):
    product, res, truth = tiny
    lk = matching_lock(product, res, truth)
    worst = min(res.pairs, key=lambda p: float(np.mean(p.valid)))
    assert lk.pair == worst.name and lk.points == worst.line_a.size
    assert 0.6 < lk.valid_true <= 1.0 and 0.97 < lk.lock < 1.02
    assert lk.lost < 0.03
    # under the true attitude the residual shift is the matching's own error: the restored geometry adds little
    assert lk.shift_rms_restored_px < 1.05 * lk.shift_rms_true_px + 0.01
    d = lk.as_dict()
    assert d["lock"] == pytest.approx(lk.valid_restored / lk.valid_true)


def test_a_wrong_geometry_loses_the_lock(tiny):
    """A 3 px sine at 1 / (2 τ) on roll and pitch moves band B by 6 px against band A: beyond the ±2 px search."""
    product, res, truth = tiny
    worst = min(res.pairs, key=lambda p: float(np.mean(p.valid)))
    ifov = res.pixel_ifov_rad
    f = 1.0 / (2.0 * worst.tau_s)
    wrong = {a: truth_at(truth, a, res.time) for a in ("roll", "pitch", "yaw")}
    for a in ("roll", "pitch"):
        wrong[a] = wrong[a] + 3.0 * ifov * np.sin(2 * np.pi * f * res.time)
    lk = matching_lock(product, dataclasses.replace(res, restored=wrong), truth, pair=worst.name)
    assert lk.lock < 0.5 and lk.lost > 0.3
    exact = matching_lock(product, dataclasses.replace(res, restored={a: truth_at(truth, a, res.time)
                                                                      for a in ("roll", "pitch", "yaw")}), truth,
                          pair=worst.name)
    assert exact.valid_restored == exact.valid_true and exact.lost == 0.0 and exact.lock == 1.0


def test_unrestored_lines_take_the_knowledge_and_bad_pairs_are_named(tiny):
    product, res, truth = tiny
    gap = {a: np.where(np.arange(res.time.size) < 50, np.nan, res.restored[a]) for a in res.restored}
    att = restored_attitude(dataclasses.replace(res, restored=gap))
    for a in ("roll", "pitch", "yaw"):
        ok = np.isfinite(gap[a])
        assert np.array_equal(att[a][~ok], res.knowledge[a][~ok]) and np.array_equal(att[a][ok], gap[a][ok])
        assert (~ok[:50]).all() and np.isfinite(att[a]).all()
    with pytest.raises(ValueError, match="no pair 'B9/B1'.*B1/B0"):
        matching_lock(product, res, truth, pair="B9/B1")


def test_the_report_sentence_says_whether_the_restoration_finds_what_the_images_allow():
    from reports.matching_lock import MatchingLock
    from reports.report_data import matching_lock_sentence

    good = MatchingLock(pair="B1/B2", points=86966, valid_stored=0.79, valid_restored=0.793, valid_true=0.802,
                        lost=0.015, shift_rms_restored_px=0.62, shift_rms_true_px=0.61)
    text = matching_lock_sentence(good)
    assert "B1/B2" in text and "79.3 %" in text and "80.2 %" in text and "lock 98.9 %" in text
    assert "finds what the images allow" in text and "0.61 px RMS" in text
    bad = dataclasses.replace(good, valid_restored=0.5, lost=0.3)
    assert "loses matches the true geometry keeps" in matching_lock_sentence(bad)
    assert matching_lock_sentence(dataclasses.replace(good, valid_true=0.0)) is None
    assert matching_lock_sentence(None) is None
