"""Terrain of the simulated scene: DEMs, ground reflectance textures, sun illumination.

Local frame: x along-track (m), y across-track (m), z up (m), scene centred near (0, 0).
Real DEMs and orthoimages are mapped with x = east, y = north.

Modules: :mod:`.dem` (Dem, synthetic and real DEMs), :mod:`.texture` (procedural and
orthoimage reflectance), :mod:`.illumination` (sun shading and cast shadows),
:mod:`.from_config` (scenario sections ``[scene.dem]``, ``[scene.dem_knowledge]``,
``[scene.texture]``, ``[scene.sun]``).
"""
from .dem import Dem, degrees_to_metres, fractal_dem, load_geotiff_dem, matplotlib_sample_dem, resample
from .illumination import Sun, cast_shadows, sample_grid, sun_direction, sun_irradiance, texel_centres
from .texture import BAND_NAMES, PAN_WEIGHTS, LandCover, OrthoTexture, ProceduralTexture
from .from_config import dem_from_config, knowledge_dem_from_config, sun_from_config, texture_from_config

__all__ = [
    "Dem", "fractal_dem", "load_geotiff_dem", "matplotlib_sample_dem", "resample", "degrees_to_metres",
    "Sun", "sun_direction", "sun_irradiance", "cast_shadows", "sample_grid", "texel_centres",
    "BAND_NAMES", "PAN_WEIGHTS", "LandCover", "ProceduralTexture", "OrthoTexture",
    "dem_from_config", "knowledge_dem_from_config", "texture_from_config", "sun_from_config",
]
