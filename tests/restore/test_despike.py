"""Gross errors of one line's synthesis (a failed match of a whole line) are dropped before the integration."""
from dataclasses import replace

import numpy as np
import pytest

from restore import stages
from restore.restorer import Restorer
from restore.settings import RestorationSettings
from restore.synthesis import spikes
from simsat.product import read_product
from simsat.simulate import simulate


def _residual(n=4000, seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(n)
    return 0.05 * np.sin(2 * np.pi * t / 300.0) + rng.normal(0.0, 1.0, n)


def test_isolated_gross_errors_are_flagged_and_nothing_else():
    r = _residual()
    clean = spikes(r, n_sigma=10.0)
    assert not clean.any()                      # Gaussian noise never reaches 10 σ
    planted = r.copy()
    planted[[500, 1700, 3200]] += [25.0, -30.0, 18.0]
    planted[2000:2003] += 40.0                  # a run of three: not isolated, not a failed line
    planted[2500] = np.nan
    got = spikes(planted, n_sigma=10.0)
    assert np.flatnonzero(got).tolist() == [500, 1700, 3200]


def test_runs_of_large_residuals_are_the_models_misfit_and_nothing_is_flagged():
    r = _residual()
    r[::90] += 30.0                             # isolated failed lines...
    assert spikes(r, n_sigma=10.0).sum() == r[::90].size
    r[1::180] += 30.0                           # ...but 23 pairs of neighbours: 1.1 % of the lines in runs
    assert not spikes(r, n_sigma=10.0).any()
    assert spikes(r, n_sigma=10.0, max_fraction=0.02).sum() == r[::90].size - r[1::180].size
    assert not spikes(r, n_sigma=0.0).any()     # 0 disables


def test_a_dropped_line_is_filled_as_a_short_gap():
    class Syn:
        diff = np.zeros((200, 3))
        sigma = np.ones((200, 3))
        n_points = np.full(200, 20)

    t = np.arange(200)
    Syn.diff[:, 1] = np.sin(2 * np.pi * t / 50.0)
    Syn.diff[100, 1] = 7.0
    pair = type("P", (), {"synthesis": Syn, "tau_s": 0.01, "inlier": None, "valid": np.zeros(0, bool),
                          "line_a": np.zeros(0), "meas_line_b": np.zeros(0), "pred_line_b": np.zeros(0)})()
    s = replace(RestorationSettings(), compensate_window=False)
    kept = stages.pair_differentials(pair, s, 200, 4e-4)
    drop = np.zeros(200, bool)
    drop[100] = True
    dropped = stages.pair_differentials(pair, s, 200, 4e-4, drop={"pitch": drop})
    assert kept.diffs["pitch"][100] == 7.0
    assert dropped.diffs["pitch"][100] == pytest.approx(np.sin(2 * np.pi * 100 / 50.0), abs=1e-3)
    np.testing.assert_array_equal(dropped.diffs["roll"], kept.diffs["roll"])
    # the filled line is an interpolation: no weight in the integration, the others keep theirs
    assert kept.weight[100] == 20 and dropped.weight[100] == 0
    assert np.all(np.delete(dropped.weight, 100) == 20)
    # with the window compensation its taps reach the neighbours: they lose their weight too
    comp = stages.pair_differentials(pair, replace(s, compensate_window=True, window=(3, 31)), 200, 4e-4,
                                     drop={"pitch": drop})
    assert np.flatnonzero(comp.weight == 0).tolist() == [99, 100, 101]


@pytest.fixture(scope="module")
def tiny_product(tmp_path_factory):
    d = tmp_path_factory.mktemp("despike") / "tiny"
    simulate("tiny", d, progress=False)
    return read_product(d)


def test_a_planted_failed_line_is_dropped_and_barely_moves_the_restoration(tiny_product, monkeypatch):
    """A 6 px error on one line of one pair's synthesis: without the despiking it moves the restored attitude
    around that line; with it the restoration stays within a fifth of that of the clean one."""
    settings = replace(RestorationSettings(), posterior_samples=0, correct_images=False, rematch=0)
    px = tiny_product.pixel_ifov_rad
    clean = Restorer(settings).run(tiny_product)
    real = stages.synthesise_pair

    def planted(pair, *args, **kwargs):
        out = real(pair, *args, **kwargs)
        if pair.name == clean.pairs[0].name:
            out.synthesis.diff[190, :2] += 6.0 * px
        return out

    monkeypatch.setattr(stages, "synthesise_pair", planted)
    hit = Restorer(replace(settings, despike_sigma=0.0)).run(tiny_product)
    cured = Restorer(settings).run(tiny_product)
    assert cured.timings.get("despiked_lines", 0) >= 2          # the line, on roll and on pitch
    assert "despiked_lines" not in hit.timings
    for a in ("roll", "pitch"):
        moved = np.nanmax(np.abs(hit.restored[a] - clean.restored[a]))
        left = np.nanmax(np.abs(cured.restored[a] - clean.restored[a]))
        assert moved > 0.05 * px, a
        assert left < 0.2 * moved, a
