"""Focal plane, detectors, optics and radiometry of a push-broom instrument.

Geometry of the focal plane (body frame, metres at the focal plane):

* ``along_m`` — position of a detector line along-track (+x, direction of
  flight). A detector ahead (larger ``along_m``) looks further forward and sees
  a ground point *earlier*.
* ``across_m`` — across-track position (+y) of the centre of the line.
* Column ``u`` of a detector (pixel centres at integer ``u``) sits at
  ``y = across_m + (u - (pixels - 1) / 2) * pitch_m``.

The body-frame line of sight of a point ``(x, y)`` of the focal plane is the
unit vector along ``(x / f, y / f, -1)`` (looking down, -z).

Band delay between two detectors A and B (A ahead of B) for a platform at
altitude ``H`` flying at ground speed ``V``: ``tau = H (xA - xB) / (f V)``.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .config import Section

__all__ = ["Detector", "Radiometry", "Instrument", "instrument_from_config"]

SPECTRAL_BANDS = ("blue", "green", "red", "nir", "pan")


@dataclass(frozen=True)
class Detector:
    """One detector line (a band) of the focal plane.

    Parameters
    ----------
    name : str
        Band name used in the product (``image_<name>``).
    band : str
        Spectral band of the scene texture it sees (``blue``, ``green``, ``red``,
        ``nir``, ``pan``).
    along_m, across_m : float
        Position of the line centre in the focal plane [m].
    pixels : int
        Number of pixels (image columns).
    pitch_m : float
        Pixel pitch [m].
    tdi_stages : int
        Time-delay-integration stages (1: a single line). A TDI detector
        integrates each pixel over ``tdi_stages`` rows, the charge moving
        backwards one row (one pitch) per line period with the image: row
        ``along_m + k pitch`` sees the ground point at ``t − k Te``, and the
        pixel is dated at the *last* stage (row ``along_m``, time ``t``), not at
        the middle of its integration (CNES §3.3.4, the PHR PAN band).
    rows : int
        Rows of a 2-D matrix detector taking frames (1: a line;
        :mod:`simsat.frames`); ``along_m`` is then the matrix centre.
    """

    name: str
    band: str
    along_m: float
    across_m: float
    pixels: int
    pitch_m: float
    tdi_stages: int = 1
    rows: int = 1

    def focal_plane_y(self, columns) -> np.ndarray:
        """Across-track focal-plane coordinate [m] of (fractional) columns."""
        return self.across_m + (np.asarray(columns, dtype=np.float64) - (self.pixels - 1) / 2.0) * self.pitch_m

    def column_of_y(self, y_m) -> np.ndarray:
        """Inverse of :meth:`focal_plane_y`: fractional column of a focal-plane y [m]."""
        return (np.asarray(y_m, dtype=np.float64) - self.across_m) / self.pitch_m + (self.pixels - 1) / 2.0


@dataclass(frozen=True)
class Radiometry:
    """Detector radiometry: photon and read noise, quantisation.

    A reflectance-times-irradiance value ``L`` in [0, 1] becomes
    ``L * full_well_e * signal_fraction`` electrons; photon noise (Poisson,
    Gaussian approximation) and read noise are added; the result is converted
    to digital numbers with ``bits`` bits over the full well.
    """

    full_well_e: float = 60000.0
    signal_fraction: float = 0.6
    read_noise_e: float = 40.0
    bits: int = 12
    enabled: bool = True

    @property
    def gain_dn_per_e(self) -> float:
        return (2 ** self.bits - 1) / self.full_well_e


@dataclass(frozen=True)
class Instrument:
    """A push-broom instrument.

    Parameters
    ----------
    focal_length_m : float
        Focal length [m].
    line_period_s : float
        Line period Te [s]; every detector line integrates during one Te.
    detectors : tuple of Detector
    mtf_nyquist : float
        Optics MTF at the Nyquist frequency (Gaussian PSF), in (0, 1].
    time_subsamples : int
        Samples in time inside the line integration window (motion smear).
    spatial_subsamples : int
        Rays per pixel side inside the footprint; 1 means the pixel aperture is
        applied by prefiltering the ground texture (equivalent, faster).
    """

    focal_length_m: float
    line_period_s: float
    detectors: tuple
    focal_plane_width_m: float = 0.1
    focal_plane_height_m: float = 0.02
    mtf_nyquist: float = 0.3
    time_subsamples: int = 4
    spatial_subsamples: int = 1
    radiometry: Radiometry = field(default_factory=Radiometry)

    def detector(self, name: str) -> Detector:
        for d in self.detectors:
            if d.name == name:
                return d
        raise KeyError(f"no detector named {name!r}; have {', '.join(d.name for d in self.detectors)}")

    @property
    def names(self) -> list[str]:
        return [d.name for d in self.detectors]

    def ifov_rad(self, name: str | None = None) -> float:
        """Instantaneous field of view of one pixel [rad] (pitch / focal length)."""
        d = self.detectors[0] if name is None else self.detector(name)
        return d.pitch_m / self.focal_length_m

    def psf_sigma_px(self) -> float:
        """Gaussian PSF standard deviation [px] giving ``mtf_nyquist`` at 0.5 cycle/px.

        MTF(f) = exp(-2 π² σ² f²)  ⇒  σ = sqrt(-2 ln MTF_N) / π.
        """
        if self.mtf_nyquist >= 1.0:
            return 0.0
        return float(np.sqrt(-2.0 * np.log(self.mtf_nyquist)) / np.pi)


def instrument_from_config(sec: Section) -> Instrument:
    """Build an :class:`Instrument` from the ``[instrument]`` table."""
    f = sec.number("focal_length_m", ge=1e-3, le=1000.0)
    te = sec.number("line_period_ms", ge=1e-3, le=1e4) * 1e-3
    default_pitch_um = sec.number("pixel_pitch_um", None, ge=0.1, le=1e4)
    default_pixels = sec.integer("pixels", None, gt=0, le=100_000)
    width = sec.number("focal_plane_width_mm", 100.0, gt=0, le=1e4) * 1e-3
    height = sec.number("focal_plane_height_mm", 20.0, gt=0, le=1e4) * 1e-3
    mtf = sec.number("mtf_nyquist", 0.3, gt=0, le=1)
    nt = sec.integer("time_subsamples", 4, ge=1, le=64)
    ns = sec.integer("spatial_subsamples", 1, ge=1, le=8)
    rsec = sec.section("noise")
    rad = Radiometry(
        full_well_e=rsec.number("full_well_e", 60000.0, ge=1, le=1e9),
        signal_fraction=rsec.number("signal_fraction", 0.6, gt=0, le=1),
        read_noise_e=rsec.number("read_noise_e", 40.0, ge=0, le=1e6),
        bits=rsec.integer("bits", 12, ge=1, le=16),
        enabled=rsec.boolean("enabled", True),
    )
    rsec.finish()
    dets = []
    secs = sec.sections("detectors")
    if not secs:
        raise sec.error("detectors", "at least one [[instrument.detectors]] is required")
    for ds in secs:
        name = ds.string("name")
        if not name.isidentifier():
            raise ds.error("name", f"must be a simple identifier (letters, digits, _), got {name!r}")
        band = ds.string("band", choices=SPECTRAL_BANDS)
        along = ds.number("along_track_mm") * 1e-3
        across = ds.number("across_track_mm", 0.0) * 1e-3
        pixels = ds.integer("pixels", default_pixels, gt=0, le=100_000)
        if pixels is None:
            raise ds.error("pixels", "missing (required, or set instrument.pixels)")
        pitch = ds.number("pixel_pitch_um", default_pitch_um, ge=0.1, le=1e4)
        if pitch is None:
            raise ds.error("pixel_pitch_um", "missing (required, or set instrument.pixel_pitch_um)")
        pitch *= 1e-6
        tdi = ds.integer("tdi_stages", 1, ge=1, le=256)
        rows = ds.integer("rows", 1, ge=1, le=4096)
        if rows > 1 and tdi > 1:
            raise ds.error("rows", "a matrix detector (rows > 1) has no TDI stages; set one of rows, tdi_stages")
        if abs(along) > height / 2:
            raise ds.error("along_track_mm", f"detector off the focal plane: |{along*1e3:g}| mm > "
                           f"focal_plane_height_mm/2 = {height*1e3/2:g} mm")
        if rows > 1 and abs(along) + (rows - 1) / 2 * pitch > height / 2:
            raise ds.error("rows", f"the {rows}-row matrix spans {(abs(along) + (rows - 1) / 2 * pitch) * 1e3:g} mm "
                           f"from the axis, off the focal plane (focal_plane_height_mm/2 = {height*1e3/2:g} mm)")
        if abs(along + (tdi - 1) * pitch) > height / 2:
            raise ds.error("tdi_stages", f"the {tdi} TDI rows reach {(along + (tdi - 1) * pitch) * 1e3:g} mm along "
                           f"track, off the focal plane (focal_plane_height_mm/2 = {height*1e3/2:g} mm)")
        half_len = pixels * pitch / 2
        if abs(across) + half_len > width / 2 + 1e-12:
            raise ds.error("pixels", f"detector off the focal plane: it spans {abs(across)*1e3 + half_len*1e3:g} mm "
                           f"from the axis, focal_plane_width_mm/2 = {width*1e3/2:g} mm")
        ds.finish()
        if any(d.name == name for d in dets):
            raise ds.error("name", f"duplicate detector name {name!r}")
        dets.append(Detector(name=name, band=band, along_m=along, across_m=across, pixels=pixels, pitch_m=pitch,
                             tdi_stages=tdi, rows=rows))
    sec.finish()
    return Instrument(focal_length_m=f, line_period_s=te, detectors=tuple(dets), focal_plane_width_m=width,
                      focal_plane_height_m=height, mtf_nyquist=mtf, time_subsamples=nt, spatial_subsamples=ns,
                      radiometry=rad)
