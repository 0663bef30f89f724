"""The layout optimiser: the screen against the blind frequencies of a known line, the layout overrides."""
import numpy as np
import pytest

from reports.optimise import layout_overrides, optimise_layout, screen_layouts
from restore.observability import observability
from simsat.scenario import load_scenario

DT = 4e-4


def _line_psd(f0=100.0, amp=1e-6):
    f = np.fft.rfftfreq(10000, DT)  # 100 Hz falls on a bin
    s = np.zeros(f.size)
    s[np.argmin(np.abs(f - f0))] = amp ** 2 / 4 / (f[1] - f[0])
    return {"freq": f, "roll": s, "pitch": s, "dt": DT, "ifov": 1e-6, "highpass_hz": 2.0}


def test_the_screen_avoids_layouts_blind_to_the_jitter_line():
    """A 100 Hz line: a layout whose three delays are multiples of 10 ms sees none of it (floor ≈ the line's RMS);
    the best layout sees it, and its floor is the observability formula's."""
    psd = _line_psd()
    scr = screen_layouts(psd, noise_px=0.1, max_spread_s=0.03)
    g = list(scr["tau_lines"])
    blind = scr["floor_px"][g.index(25), g.index(25)]  # τ = 10 / 10 / 20 ms
    assert blind == pytest.approx(1.0 / np.sqrt(2), rel=0.02)
    i, j = np.unravel_index(np.nanargmin(scr["floor_px"]), scr["floor_px"].shape)
    assert scr["floor_px"][i, j] < 0.1 * blind
    taus = [g[i] * DT, g[j] * DT, (g[i] + g[j]) * DT]
    assert all(abs(t * 100 - round(t * 100)) > 0.05 for t in taus)  # no delay a multiple of 10 ms
    ref = observability(psd["freq"], psd["roll"], 0.1e-6, taus, DT, highpass_hz=2.0).floor_rms_rad / 1e-6
    assert scr["floor_px"][i, j] == pytest.approx(ref)
    assert np.all(np.isnan(scr["floor_px"][np.add.outer(scr["tau_lines"], scr["tau_lines"]) * DT > 0.03 + 1e-12]))


def test_layout_overrides_give_the_asked_delays():
    sc = load_scenario("phr_cmg")
    over = layout_overrides(sc, 0.0110, 0.0200)
    s2 = load_scenario("phr_cmg", overrides=over)
    assert s2.delay_s("B1", "B0") == pytest.approx(0.0110, rel=1e-9)
    assert s2.delay_s("B0", "B2") == pytest.approx(0.0200, rel=1e-9)


def test_optimise_on_tiny_finds_a_layout_at_least_as_good_as_the_reference(tmp_path):
    res = optimise_layout("tiny", tmp_path, noise_px=0.1, max_spread_s=0.03, seeds=(0, 1), top=2, confirm=False,
                          progress=False)
    assert res["best"]["worst_px"] <= res["reference"]["worst_px"]
    assert res["reference"]["tau_ms"] == pytest.approx([7.4, 14.8, 22.2], rel=1e-6)
    assert (tmp_path / "optimise.png").stat().st_size > 1000


def test_strip_line_screen_is_the_single_pair_floor_and_avoids_the_blind_separation():
    """Claims 22–23: one pair from two lines of a strip; a line at 125 Hz makes the separation whose
    blind frequency 1/τ falls on it (20 lines of 0.4 ms) the worst, and the screen equals the formula."""
    import numpy as np

    from reports.optimise import screen_strip_lines
    from restore.observability import observability

    dt, ifov = 4e-4, 4e-6
    f = np.linspace(0, 1 / (2 * dt), 2049)
    S = np.where(np.abs(f - 125.0) < 1.0, 1e-12, 1e-18)
    psd = {"freq": f, "roll": S, "pitch": 0.5 * S, "dt": dt, "ifov": ifov, "highpass_hz": 1.0}
    r = screen_strip_lines(psd, noise_px=0.05, strip_lines=24)
    k = r["separation_lines"]
    assert list(k) == list(range(1, 24))
    assert k[np.argmax(r["floor_px"])] == 20
    assert r["best_lines"] != 20 and r["floor_px"][k == r["best_lines"]][0] == r["floor_px"].min()
    exp = observability(f, S, 0.05 * ifov, [7 * dt], dt, highpass_hz=1.0).floor_rms_rad / ifov
    assert r["floor_px"][6] == pytest.approx(exp)
    with pytest.raises(ValueError, match="strip_lines"):
        screen_strip_lines(psd, noise_px=0.05, strip_lines=1)
