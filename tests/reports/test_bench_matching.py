"""Matching benchmark: analytic data and a small run against skimage and OpenCV."""
import numpy as np
import pytest

from reports.bench_matching import METHODS, bench_matching, format_table
from reports.synthetic import synthetic_pairs


def test_synthetic_pairs():
    d = synthetic_pairs(seed=0, n=4, max_shift=1.0, noise=0.0)
    assert np.array_equal(d["image_a"], synthetic_pairs(seed=0, n=4, max_shift=1.0, noise=0.0)["image_a"])
    assert np.all(np.abs(d["shift_lines"]) <= 1.0) and np.all(np.abs(d["shift_cols"]) <= 1.0)
    assert d["image_a"].shape == (4 * d["patch_shape"][0], d["patch_shape"][1])
    # zero shift: identical bands, up to the level
    z = synthetic_pairs(seed=0, n=3, max_shift=0.0, noise=0.0)
    assert np.allclose(z["image_a"] - 10.0, z["image_b"] - 7.0, atol=1e-5)  # levels differ by design
    c = synthetic_pairs(seed=0, n=3, max_shift=0.0, noise=0.0, case="cross")
    assert not np.allclose(c["image_a"], c["image_b"])
    with pytest.raises(ValueError, match="case"):
        synthetic_pairs(case="other")
    with pytest.raises(ValueError, match="max_shift"):
        synthetic_pairs(max_shift=3.0, search=(2, 2))


def test_bench_small_run():
    r = bench_matching(seed=1, n=300, repeat=1, skimage_n=40)
    assert set(r["results"]) == {"same", "cross"}
    for case, res in r["results"].items():
        assert set(res) == set(METHODS)
        for m, v in res.items():
            assert v["us_per_match"] > 0 and 0 <= v["valid"] <= 1
            for ax in ("line", "col"):
                assert set(v[ax]) == {"bias", "std", "rmse", "locking"}
        # ours: as accurate as the reference implementations, on both axes
        for ax in ("line", "col"):
            ours = res["ours-ncc"][ax]["rmse"]
            assert ours <= res["skimage"][ax]["rmse"] and ours <= res["opencv"][ax]["rmse"]
    same = r["results"]["same"]["ours-ncc"]
    assert abs(same["line"]["bias"]) < 0.01 and abs(same["col"]["bias"]) < 0.01
    text = format_table(r)
    assert all(m in text for m in METHODS) and "µs/match" in text
    with pytest.raises(ValueError, match="methods"):
        bench_matching(n=10, methods=("ours-ncc", "magic"))
