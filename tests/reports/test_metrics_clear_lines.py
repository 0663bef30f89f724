"""Which lines are clear (land, no cloud, no water) and how many of them a restoration covers."""
import numpy as np

from reports.metrics import clear_line_coverage, clear_line_fraction
from simsat.terrain.texture import LandCover


class _Sensor:
    def direct_location(self, detector, lines, columns):
        lines, columns = np.broadcast_arrays(np.asarray(lines, float), np.asarray(columns, float))
        return np.stack([lines * 2.0, columns * 2.0, np.zeros_like(lines)], axis=-1)   # x along, y across [m]


class _Product:
    reference_detector = "B0"
    image_shapes = {"B0": (100, 64)}

    def sensor_model(self):
        return _Sensor()


class _Texture:
    """Cloud over lines 20–39 (x in [40, 80) m), water on the right quarter of lines 60–99."""

    def land_cover(self, x, y):
        out = np.full(np.shape(x), LandCover.CROPLAND, dtype=np.uint8)
        out[(x >= 40) & (x < 80)] = LandCover.CLOUD
        out[(x >= 120) & (y >= 96)] = LandCover.WATER
        return out


def test_clear_fraction_per_line_and_the_coverage_of_clear_lines():
    frac = clear_line_fraction(_Product(), _Texture(), column_step=1)
    assert np.all(frac[:20] == 1.0) and np.all(frac[20:40] == 0.0) and np.all(frac[40:60] == 1.0)
    np.testing.assert_allclose(frac[60:], 48 / 64)          # columns 48–63 see water
    restored = np.zeros(100)
    restored[20:45] = np.nan                                 # the cloud and 5 clear lines after it
    # 80 clear lines (≥ half their columns on land), 5 of them not restored
    assert clear_line_coverage(restored, frac) == 75 / 80
    assert np.isnan(clear_line_coverage(restored, np.zeros(100)))


def test_a_texture_without_land_cover_gives_nan():
    class Ortho:
        def land_cover(self, x, y):
            return np.full(np.shape(x), LandCover.UNKNOWN, dtype=np.uint8)

    assert np.all(np.isnan(clear_line_fraction(_Product(), Ortho())))
