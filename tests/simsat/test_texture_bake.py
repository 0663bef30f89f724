"""The baked texture: a later render of the same ground takes its tiles from the store, same bytes."""
import numpy as np
import pytest

from simsat.render.texture_bake import TileStore, bake_key, enable_bake, texture_fingerprint
from simsat.terrain.texture import ProceduralTexture


def test_store_drops_least_recently_used_beyond_its_bound():
    store = TileStore(max_bytes=3 * 800)
    arrs = {k: np.full(100, k, dtype=np.float64) for k in range(4)}  # 800 bytes each
    for k in range(3):
        store.put(("s", k), arrs[k])
    assert store.get(("s", 0)) is arrs[0]  # 0 becomes the most recent
    store.put(("s", 3), arrs[3])  # over the bound: the least recent (1) goes
    assert store.get(("s", 1)) is None
    assert store.get(("s", 0)) is arrs[0] and store.get(("s", 3)) is arrs[3]
    assert store.nbytes == 3 * 800 and len(store) == 3
    assert not arrs[0].flags.writeable  # what is shared cannot be changed by a caller
    store.put(("s", 9), np.zeros(1000))  # larger than the whole store: not kept
    assert store.get(("s", 9)) is None and store.nbytes == 3 * 800


def test_disabled_store_keeps_nothing():
    store = TileStore(max_bytes=0)
    store.put(("s", 0), np.zeros(4))
    assert store.get(("s", 0)) is None and len(store) == 0


def test_texture_fingerprint_follows_the_parameters_not_the_threads():
    a = ProceduralTexture(seed=3, workers=1)
    b = ProceduralTexture(seed=3, workers=2)
    c = ProceduralTexture(seed=4, workers=1)
    d = ProceduralTexture(seed=3, workers=1, water_fraction=0.2)
    assert texture_fingerprint(a) == texture_fingerprint(b)
    assert len({texture_fingerprint(x) for x in (a, c, d)}) == 3
    assert texture_fingerprint(object()) is None  # a texture that cannot say what it is: never baked
    assert bake_key(None, None, 1.0, np.ones(1), (1.0, 0.0, 10, 64)) is None


def test_bake_key_changes_with_irradiance_kernel_and_grid():
    from simsat.terrain import Dem

    fp = texture_fingerprint(ProceduralTexture(seed=3))
    irr = Dem(x0_m=0.0, y0_m=0.0, dx_m=10.0, dy_m=10.0, z=np.ones((4, 4)))
    irr2 = Dem(x0_m=0.0, y0_m=0.0, dx_m=10.0, dy_m=10.0, z=np.full((4, 4), 0.9))
    k = np.array([0.25, 0.5, 0.25])
    grid = (1.4, -500.0, 700, 183)
    base = bake_key(fp, irr, 1.0, k, grid)
    assert base == bake_key(fp, irr, 1.0, k.copy(), grid)
    others = [bake_key(fp, irr2, 1.0, k, grid), bake_key(fp, None, 1.0, k, grid), bake_key(fp, irr, 0.9, k, grid),
              bake_key(fp, irr, 1.0, np.array([1.0]), grid), bake_key(fp, irr, 1.0, k, (1.4, -501.4, 700, 183))]
    assert len({base, *others}) == 6


def test_environment_bound_is_checked(monkeypatch):
    from simsat.render import texture_bake

    monkeypatch.setenv("SIMSAT_TEXTURE_BAKE_MB", "lots")
    with pytest.raises(ValueError, match="SIMSAT_TEXTURE_BAKE_MB"):
        texture_bake._capacity_from_env()
    monkeypatch.setenv("SIMSAT_TEXTURE_BAKE_MB", "2")
    assert texture_bake._capacity_from_env() == 2 * 2 ** 20


def test_second_render_of_the_same_ground_is_baked_and_identical(monkeypatch):
    from simsat.scenario import load_scenario
    from simsat.simulate import build_world, make_renderer

    monkeypatch.delenv("SIMSAT_TEXTURE_BAKE_MB", raising=False)
    sc = load_scenario("tiny", overrides={"acquisition": {"lines": 96}})
    model, dem, known, texture, irr = build_world(sc)
    store = TileStore(max_bytes=256 * 2 ** 20)
    r1 = make_renderer(sc, model, dem, texture, irr)
    r1.tile_store = store
    first = r1.render(sc.line_times, block_lines=32)
    assert r1.stats.baked_tiles == 0 and r1.stats.texture_synthesis_s > 0 and len(store) > 0
    # a new world from the same scenario: a new texture object with the same parameters
    model2, dem2, known2, texture2, irr2 = build_world(sc)
    r2 = make_renderer(sc, model2, dem2, texture2, irr2)
    r2.tile_store = store
    again = r2.render(sc.line_times, block_lines=32)
    assert r2.stats.baked_tiles > 0 and r2.stats.texture_synthesis_s == 0.0
    for name in first:
        np.testing.assert_array_equal(first[name], again[name])
    # other ground (another scenario seed draws another texture): nothing taken from the bake, other images
    sc3 = load_scenario("tiny", overrides={"acquisition": {"lines": 96}, "scenario": {"seed": 99}})
    w3 = build_world(sc3)
    r3 = make_renderer(sc3, *w3[:2], w3[3], w3[4])
    r3.tile_store = store
    other = r3.render(sc3.line_times, block_lines=32)
    assert r3.stats.baked_tiles == 0
    assert not np.array_equal(first["B0"], other["B0"])


def test_enable_bake_respects_the_environment(monkeypatch):
    from simsat.render import texture_bake

    saved = texture_bake.TILE_STORE.max_bytes
    try:
        monkeypatch.setenv("SIMSAT_TEXTURE_BAKE_MB", "0")
        assert enable_bake(64).max_bytes == 0
        monkeypatch.delenv("SIMSAT_TEXTURE_BAKE_MB")
        assert enable_bake(64).max_bytes == 64 * 2 ** 20
    finally:
        texture_bake.TILE_STORE.max_bytes = saved
