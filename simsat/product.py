"""Product, truth and run files: writing (atomically) and reading.

A run directory holds:

* ``product.nc`` — what a ground segment receives: ``image_<band>`` (line,
  column) DN, ``time`` [s] per line, platform ephemeris, *knowledge* attitude,
  focal-plane geometry and band delays, the DEM the ground knows;
* ``truth.nc`` — never read by restoration: ``time`` [s] and ``roll``,
  ``pitch``, ``yaw`` [rad] of the true line of sight (sampled finer than the
  line period) and the true DEM;
* ``run.json`` — the resolved scenario, seed, versions and timings.

Files are written to a temporary name in the same directory and renamed, so a
crashed run never leaves a file that looks whole.
"""
from __future__ import annotations

import json
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import xarray as xr

from .attitude import KNOWLEDGE_FILTER_NAMES, KNOWLEDGE_FILTER_ORDER, AttitudeSeries
from .instrument import Detector, Instrument, Radiometry
from .platform import Platform
from .scan import scan_from_attrs
from .trajectory import trajectory_from_attrs
from .sensor_model import SensorModel
from .terrain import Dem
from .units import AXES

__all__ = ["atomic_write_dataset", "atomic_write_json", "atomic_write_bytes", "json_default", "netcdf_encoding",
           "product_dataset", "temporary_path", "Product", "read_product",
           "read_truth", "check_truth", "ProductError", "NETCDF_ENCODING", "clamped_attitude", "check_product", "check_image"]


class ProductError(ValueError):
    """A run directory or product file is missing or malformed (message names the file)."""


NETCDF_ENCODING = {"zlib": True, "complevel": 4, "shuffle": True}


def _umask() -> int:
    m = os.umask(0)
    os.umask(m)
    return m


def _tmp_path(path: Path) -> Path:
    fd, name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".part", dir=path.parent)
    os.close(fd)
    os.chmod(name, 0o666 & ~_umask())  # mkstemp's 0600 would survive the rename
    return Path(name)


def temporary_path(final: str | Path) -> Path:
    """A fresh temporary file name beside ``final`` (``.NAME.XXXX.part``), for writers that rename when done."""
    final = Path(final)
    final.parent.mkdir(parents=True, exist_ok=True)
    return _tmp_path(final)


def make_tmp_dir(final: Path) -> Path:
    """A temporary sibling directory of ``final`` with normal permissions."""
    d = Path(tempfile.mkdtemp(prefix=f".{final.name}.", suffix=".part", dir=final.parent))
    os.chmod(d, 0o777 & ~_umask())
    return d


def netcdf_encoding(ds) -> dict:
    """Compression of every numeric array variable of ``ds`` (:data:`NETCDF_ENCODING`)."""
    return {k: dict(NETCDF_ENCODING) for k, v in ds.data_vars.items() if v.dtype.kind in "fiu" and v.ndim >= 1}


def atomic_write_dataset(ds, path: str | Path, *, compress: bool = True) -> Path:
    """Write an xarray Dataset to NetCDF atomically (temp file + rename)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = _tmp_path(path)
    enc = netcdf_encoding(ds) if compress else {}
    try:
        ds.to_netcdf(tmp, engine="netcdf4", encoding=enc)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


def atomic_write_bytes(data: bytes, path: str | Path) -> Path:
    """Write ``data`` to ``path`` atomically (``.NAME.XXXX.part`` beside it, then renamed)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = _tmp_path(path)
    try:
        tmp.write_bytes(data)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


def atomic_write_json(obj, path: str | Path, *, sort_keys: bool = True) -> Path:
    """Write ``obj`` as indented JSON atomically (NumPy values and paths encoded by :func:`json_default`)."""
    text = json.dumps(obj, indent=2, sort_keys=sort_keys, default=json_default) + "\n"
    return atomic_write_bytes(text.encode(), path)


def json_default(o):
    """The JSON encoding of what simsat writes besides JSON types: NumPy scalars and arrays, paths."""
    if isinstance(o, (np.floating, np.integer, np.bool_)):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


def _open(path: Path):
    if not path.exists():
        raise ProductError(f"{path}: file not found")
    try:
        return xr.load_dataset(path, engine="netcdf4")
    except Exception as e:  # corrupted / not NetCDF
        raise ProductError(f"{path}: cannot read as NetCDF ({type(e).__name__}: {e})") from None


def _open_lazy_images(path: Path):
    """The product with every variable loaded but the band images, which stay in the file.

    ``Product.image`` reads a band when asked (and does not keep it), so a
    restoration holds only the bands it is working on, whatever the product's size.
    """
    if not path.exists():
        raise ProductError(f"{path}: file not found")
    try:
        ds = xr.open_dataset(path, engine="netcdf4", cache=False)
        small = [v for v in ds.variables if not str(v).startswith("image_")]
        for v in small:
            ds[v].load()
        return ds
    except Exception as e:  # corrupted / not NetCDF
        raise ProductError(f"{path}: cannot read as NetCDF ({type(e).__name__}: {e})") from None


@dataclass
class Product:
    """A product as read by the ground segment (never contains truth).

    Attributes
    ----------
    ds : xarray.Dataset
        The raw dataset.
    platform, instrument : the geometry needed by the sensor model.
    knowledge : simsat.attitude.AttitudeSeries
        AOCS knowledge of the line-of-sight attitude.
    dem : simsat.terrain.Dem
        The DEM the ground knows.
    """

    path: Path
    ds: object
    platform: object
    instrument: object
    knowledge: object
    dem: object
    star_tracker: object | None = None

    @property
    def time(self) -> np.ndarray:
        return np.asarray(self.ds["time"].values, dtype=np.float64)

    @property
    def knowledge_noise(self) -> tuple[float, float] | None:
        """The AOCS knowledge's white noise per sample [rad] and its rate [Hz] as the product records them
        (``knowledge_noise_urad``, ``knowledge_rate_hz``); None when it does not."""
        a = self.ds.attrs
        if "knowledge_noise_urad" not in a or "knowledge_rate_hz" not in a:
            return None
        return float(a["knowledge_noise_urad"]) * 1e-6, float(a["knowledge_rate_hz"])

    @property
    def star_tracker_noise_rad(self) -> float | None:
        """The star tracker's white noise per sample [rad] as the product records it (None: not recorded)."""
        v = self.ds.attrs.get("star_tracker_noise_urad") if self.star_tracker is not None else None
        return None if v is None else float(v) * 1e-6

    @property
    def is_frames(self) -> bool:
        """A matrix detector's frames (:mod:`simsat.frames`): each "line" is a frame of (row, column)."""
        return str(self.ds.attrs.get("acquisition", "pushbroom")) == "frames"

    @property
    def band_names(self) -> list[str]:
        return [d.name for d in self.instrument.detectors]

    @property
    def reference_detector(self) -> str:
        return str(self.ds.attrs.get("reference_detector", self.band_names[0]))

    @property
    def image_shapes(self) -> dict:
        """``{band: (lines, columns)}`` (from the file's metadata: no image is read)."""
        return {d.name: tuple(int(n) for n in self.ds[f"image_{d.name}"].shape)
                for d in self.instrument.detectors if f"image_{d.name}" in self.ds}

    @property
    def pixel_ifov_rad(self) -> float:
        return self.instrument.ifov_rad(self.reference_detector)

    def image(self, name: str, *, lines: slice | None = None) -> np.ndarray:
        """Band image as float32 (DN), read from the file now (not kept).

        Parameters
        ----------
        name : str
            Band name.
        lines : slice, optional
            Read only these lines (a block: memory bounded by the block, not the image).

        Raises
        ------
        ProductError
            The band is missing, or its content cannot be an image (non-finite
            values, every pixel zero), naming the file and the variable.
        """
        key = f"image_{name}"
        if key not in self.ds:
            raise ProductError(f"{self.path}: no variable {key!r} (bands: {', '.join(self.band_names)})")
        if lines is not None:  # a block: only finite values checked (a dark block may be all zero)
            img = np.asarray(self.ds[key][lines].values, dtype=np.float32)
            if not np.isfinite(img).all():
                check_image(img, f"{self.path}: {key}")
            return img
        img = np.asarray(self.ds[key].values, dtype=np.float32)  # read from the file now, not kept
        check_image(img, f"{self.path}: {key}")
        return img

    def sensor_model(self, attitude=None):
        """Sensor model with the product's geometry (default attitude: knowledge)."""
        return SensorModel(platform=self.platform, instrument=self.instrument, dem=self.dem,
                           attitude=attitude or clamped_attitude(self.knowledge), t0_s=float(self.ds.attrs["t0_s"]))

    @property
    def radiometry(self):
        """The detector's :class:`~simsat.instrument.Radiometry` (gain, read noise) when product.nc records it
        (``full_well_e``), else None (a product of an earlier version, an orthoimage)."""
        return self.instrument.radiometry if "full_well_e" in self.ds.attrs else None

    def delay_s(self, ahead: str, behind: str) -> float:
        """Delay τ [s] of the pair ``ahead/behind``: as stored in product.nc (``delay_s``), else computed from
        the product's geometry (:func:`simsat.sensor_model.flat_ground_delay_s`, the one place τ is computed)."""
        if "delay_s" in self.ds and "pair" in self.ds.coords:
            pairs = [str(p) for p in np.atleast_1d(self.ds["pair"].values)]
            if f"{ahead}/{behind}" in pairs:
                return float(np.atleast_1d(self.ds["delay_s"].values)[pairs.index(f"{ahead}/{behind}")])
        return self.sensor_model().nominal_delay_s(ahead, behind)


def _radiometry_from_attrs(a) -> Radiometry:
    """The detector radiometry product.nc records (older products: the bits only, the rest default)."""
    if "full_well_e" not in a:
        return Radiometry(bits=int(a.get("bits", 12)))
    return Radiometry(bits=int(a.get("bits", 12)), full_well_e=float(a["full_well_e"]),
                      read_noise_e=float(a["read_noise_e"]), enabled=bool(int(a.get("radiometric_noise", 1))))


def product_dataset(sc, images: dict | None, t_lines, kn, st, known_dem, knowledge_spec=None,
                    star_tracker_spec=None):
    """The ``product.nc`` dataset of scenario ``sc`` (the reader is :func:`read_product`).

    ``knowledge_spec`` (cut-off, rate, noise of the AOCS knowledge, as a ground
    segment knows its AOCS) is recorded in the attributes ``knowledge_cutoff_hz``,
    ``knowledge_rate_hz``, ``knowledge_noise_urad``: restoration derives from it
    which frequencies the images must supply. ``star_tracker_spec`` (its noise
    and rate) likewise in ``star_tracker_noise_urad``, ``star_tracker_rate_hz``
    when the product carries star-tracker samples: the anchoring's uncertainty.
    The sun's elevation and azimuth (``sun_elevation_deg``, ``sun_azimuth_deg``,
    from the local +x towards +y) as a ground segment knows them.

    ``images``: band → (line, column) DN, or None (streamed in afterwards by
    the renderer); ``kn``/``st``: knowledge and star-tracker attitude series;
    ``known_dem``: the DEM the ground segment knows.
    """
    inst = sc.instrument
    plat = sc.platform
    dets = inst.detectors
    npix = {d.pixels for d in dets}
    data = {}
    coords = {"line": ("line", np.arange(len(t_lines), dtype=np.int32)),
              "time": ("line", np.asarray(t_lines, dtype=np.float64), {"units": "s", "long_name": "line time"}),
              "detector": ("detector", np.array([d.name for d in dets]))}
    for d in dets if images is not None else ():
        col_dim = "column" if len(npix) == 1 else f"column_{d.name}"
        data[f"image_{d.name}"] = ((("line", col_dim)), images[d.name],
                                   {"units": "DN", "band": d.band, "detector": d.name,
                                    "long_name": f"raw image of detector {d.name} ({d.band})"})
    pos = plat.position(np.asarray(t_lines))
    data["ephemeris"] = (("line", "xyz"), pos, {"units": "m", "long_name": "platform position, local frame"})
    data["detector_band"] = ("detector", np.array([d.band for d in dets]))
    data["detector_along_m"] = ("detector", np.array([d.along_m for d in dets]), {"units": "m"})
    data["detector_across_m"] = ("detector", np.array([d.across_m for d in dets]), {"units": "m"})
    data["detector_pixels"] = ("detector", np.array([d.pixels for d in dets], dtype=np.int32))
    data["detector_pitch_m"] = ("detector", np.array([d.pitch_m for d in dets]), {"units": "m"})
    data["detector_rows"] = ("detector", np.array([d.rows for d in dets], dtype=np.int32),
                             {"long_name": "rows of a matrix detector (1: a line); its frames are the lines"})
    data["detector_tdi_stages"] = ("detector", np.array([d.tdi_stages for d in dets], dtype=np.int32),
                                   {"long_name": "TDI stages (1: a single line); a TDI line is dated at its last stage"})
    data["knowledge_roll"] = ("knowledge_time", kn.roll, {"units": "rad", "long_name": "AOCS knowledge roll"})
    data["knowledge_pitch"] = ("knowledge_time", kn.pitch, {"units": "rad"})
    data["knowledge_yaw"] = ("knowledge_time", kn.yaw, {"units": "rad"})
    coords["knowledge_time"] = ("knowledge_time", kn.time, {"units": "s"})
    if st is not None:
        data["star_tracker_roll"] = ("star_tracker_time", st.roll, {"units": "rad"})
        data["star_tracker_pitch"] = ("star_tracker_time", st.pitch, {"units": "rad"})
        data["star_tracker_yaw"] = ("star_tracker_time", st.yaw, {"units": "rad"})
        coords["star_tracker_time"] = ("star_tracker_time", st.time, {"units": "s"})
    # band delays for every ordered pair (ahead, behind)
    pairs, taus = [], []
    for a in dets:
        for b in dets:
            if a.name != b.name and a.along_m > b.along_m:
                pairs.append(f"{a.name}/{b.name}")
                taus.append(sc.delay_s(a.name, b.name))
    data["delay_s"] = ("pair", np.array(taus), {"units": "s", "long_name": "nominal delay: behind sees what ahead saw"})
    coords["pair"] = ("pair", np.array(pairs))
    data["dem"] = (("dem_y", "dem_x"), np.asarray(known_dem.z, dtype=np.float64),
                   {"units": "m", "long_name": "DEM known by the ground segment"})
    coords["dem_x"] = ("dem_x", known_dem.x0_m + np.arange(known_dem.z.shape[1]) * known_dem.dx_m, {"units": "m"})
    coords["dem_y"] = ("dem_y", known_dem.y0_m + np.arange(known_dem.z.shape[0]) * known_dem.dy_m, {"units": "m"})
    attrs = {
        "title": f"simsat product {sc.name}", "scenario": sc.name, "conventions": "simsat-1",
        "t0_s": float(sc.t0_s), "line_period_s": inst.line_period_s, "focal_length_m": inst.focal_length_m,
        **plat.attrs(),
        **({"acquisition": "frames", "frame_period_s": float(sc.acquisition.frame_period_s)}
           if sc.acquisition.is_frames else {"acquisition": "pushbroom"}),
        "reference_detector": sc.acquisition.reference_detector,
        "pixel_ifov_rad": inst.ifov_rad(sc.acquisition.reference_detector),
        "mtf_nyquist": inst.mtf_nyquist, "bits": inst.radiometry.bits,
        # the detector's radiometric calibration, as a ground segment knows it (restore's noise model)
        "full_well_e": float(inst.radiometry.full_well_e), "read_noise_e": float(inst.radiometry.read_noise_e),
        "radiometric_noise": int(bool(inst.radiometry.enabled)),
        "dem_dx_m": float(known_dem.dx_m), "dem_dy_m": float(known_dem.dy_m),
        **({} if knowledge_spec is None else {"knowledge_cutoff_hz": float(knowledge_spec.cutoff_hz),
                                              "knowledge_rate_hz": float(knowledge_spec.rate_hz),
                                              "knowledge_noise_urad": float(knowledge_spec.noise_urad),
                                              "knowledge_filter": KNOWLEDGE_FILTER_NAMES[knowledge_spec.filter],
                                              "knowledge_filter_order": KNOWLEDGE_FILTER_ORDER}),
        **({} if st is None or star_tracker_spec is None else
           {"star_tracker_noise_urad": float(star_tracker_spec.noise_urad),
            "star_tracker_rate_hz": float(star_tracker_spec.rate_hz)}),
        "attitude_convention": "body->local R = Rz(yaw) Ry(pitch) Rx(roll); roll moves image across-track",
        # the sun over the scene, as a ground segment knows it from the date and place: the scene's band offset
        # lies along its azimuth (restore.observability.sun_offset_shares)
        **_sun_attrs(sc),
    }
    return xr.Dataset(data, coords=coords, attrs=attrs)


def _sun_attrs(sc) -> dict:
    """``sun_elevation_deg`` and ``sun_azimuth_deg`` (from the local +x, along the track, towards +y)."""
    sun = sc.sun()
    return {"sun_elevation_deg": float(sun.elevation_deg), "sun_azimuth_deg": float(sun.azimuth_deg)}


def check_image(img: np.ndarray, where: str) -> None:
    """Refuse an image no instrument could have delivered (``where`` names file and variable)."""
    if img.size == 0:
        raise ProductError(f"{where}: empty image")
    finite = np.isfinite(img)
    if not finite.all():
        bad = np.flatnonzero(~finite.all(axis=1)) if img.ndim == 2 else np.array([0])
        raise ProductError(f"{where}: {int((~finite).sum())} non-finite pixels (first on line {int(bad[0])}); "
                           f"a raw image holds finite DN")
    if not np.any(img):
        raise ProductError(f"{where}: every pixel is 0 (a dead band or a corrupt file)")


_REQUIRED_ATTRS = ("t0_s", "line_period_s", "focal_length_m", "altitude_m", "ground_speed_m_s",
                   "platform_x_at_t0_m", "platform_y_m", "dem_dx_m", "dem_dy_m")
_REQUIRED_VARS = ("time", "detector", "detector_band", "detector_along_m", "detector_across_m",
                  "detector_pixels", "detector_pitch_m", "knowledge_time", "knowledge_roll", "knowledge_pitch",
                  "knowledge_yaw", "dem", "dem_x", "dem_y")


def _increasing(x: np.ndarray) -> bool:
    return x.size < 2 or bool(np.all(np.diff(x) > 0))


def check_product(ds, path) -> None:
    """Cheap structural checks of a product dataset (no image is decompressed).

    Raises
    ------
    ProductError
        Naming the file and the variable or attribute at fault and what is expected.
    """
    for name in _REQUIRED_VARS:
        if name not in ds.variables:
            raise ProductError(f"{path}: malformed product, no variable {name!r}")
    for name in _REQUIRED_ATTRS:
        if name not in ds.attrs:
            raise ProductError(f"{path}: malformed product, no global attribute {name!r}")
        try:
            v = float(ds.attrs[name])
        except (TypeError, ValueError):
            raise ProductError(f"{path}: attribute {name!r} must be a number, got {ds.attrs[name]!r}") from None
        if not np.isfinite(v):
            raise ProductError(f"{path}: attribute {name!r} must be finite, got {v}")
    for name in ("line_period_s", "focal_length_m", "altitude_m", "ground_speed_m_s", "dem_dx_m", "dem_dy_m"):
        if not float(ds.attrs[name]) > 0:
            raise ProductError(f"{path}: attribute {name!r} must be > 0, got {ds.attrs[name]}")
    t = np.asarray(ds["time"].values, dtype=np.float64)
    if t.ndim != 1 or t.size < 2:
        raise ProductError(f"{path}: variable 'time' must hold one time per line (at least 2), got shape {t.shape}")
    if not np.isfinite(t).all():
        raise ProductError(f"{path}: variable 'time' has {int((~np.isfinite(t)).sum())} non-finite line times "
                           f"(first at line {int(np.flatnonzero(~np.isfinite(t))[0])})")
    if not _increasing(t):
        raise ProductError(f"{path}: variable 'time' must increase strictly from line to line "
                           f"(first fault at line {int(np.flatnonzero(np.diff(t) <= 0)[0]) + 1})")
    for name in ("knowledge_time", "knowledge_roll", "knowledge_pitch", "knowledge_yaw", "dem",
                 "detector_along_m", "detector_across_m", "detector_pitch_m"):
        v = np.asarray(ds[name].values, dtype=np.float64)
        if v.size == 0 or not np.isfinite(v).all():
            raise ProductError(f"{path}: variable {name!r} must hold finite values "
                               f"({int((~np.isfinite(v)).sum())} of {v.size} are not)")
    if not _increasing(np.asarray(ds["knowledge_time"].values, dtype=np.float64)):
        raise ProductError(f"{path}: variable 'knowledge_time' must increase strictly")
    names = [str(x) for x in np.atleast_1d(ds["detector"].values)]
    pixels = np.atleast_1d(ds["detector_pixels"].values)
    rows = np.atleast_1d(ds["detector_rows"].values) if "detector_rows" in ds else np.ones(len(names), int)
    frames = str(ds.attrs.get("acquisition", "pushbroom")) == "frames"
    for i, name in enumerate(names):
        key = f"image_{name}"
        if key not in ds.variables:
            raise ProductError(f"{path}: no variable {key!r} for detector {name!r}")
        shape = tuple(int(n) for n in ds[key].shape)
        want = (t.size, int(rows[i]), int(pixels[i])) if frames else (t.size, int(pixels[i]))
        if shape != want:
            what = "frames, rows, columns" if frames else "lines, columns"
            raise ProductError(f"{path}: variable {key!r} has shape {shape}; expected {want} ({what}) from 'time', "
                               f"{'detector_rows, ' if frames else ''}'detector_pixels'")


def clamped_attitude(series):
    """Attitude callable of a sampled series, held constant beyond its ends (no extrapolation)."""
    t0, t1 = float(series.time[0]), float(series.time[-1])

    def fn(t):
        return series.at(np.clip(np.asarray(t, dtype=np.float64), t0, t1))
    return fn


def read_product(run_dir: str | Path) -> Product:
    """Read ``product.nc`` of a run directory (or a product file path)."""
    p = Path(run_dir)
    if p.is_dir():
        p = p / "product.nc"
    if not p.exists():
        raise ProductError(f"{p}: product file not found (run `simsat render SCENARIO --out DIR` first)")
    ds = _open_lazy_images(p)
    check_product(ds, p)
    try:
        a = ds.attrs
        dets = []
        for i, name in enumerate([str(s) for s in ds["detector"].values]):
            dets.append(Detector(name=name, band=str(ds["detector_band"].values[i]),
                                 along_m=float(ds["detector_along_m"].values[i]),
                                 across_m=float(ds["detector_across_m"].values[i]),
                                 pixels=int(ds["detector_pixels"].values[i]),
                                 pitch_m=float(ds["detector_pitch_m"].values[i]),
                                 tdi_stages=int(ds["detector_tdi_stages"].values[i]) if "detector_tdi_stages" in ds
                                 else 1,
                                 rows=int(ds["detector_rows"].values[i]) if "detector_rows" in ds else 1))
        inst = Instrument(focal_length_m=float(a["focal_length_m"]), line_period_s=float(a["line_period_s"]),
                          detectors=tuple(dets), mtf_nyquist=float(a.get("mtf_nyquist", 1.0)),
                          radiometry=_radiometry_from_attrs(a))
        plat = Platform(trajectory=trajectory_from_attrs(a), scan=scan_from_attrs(a),
                        off_nadir_roll_rad=float(a.get("off_nadir_roll_rad", 0.0)),
                        off_nadir_pitch_rad=float(a.get("off_nadir_pitch_rad", 0.0)))
        kn = AttitudeSeries(time=np.asarray(ds["knowledge_time"].values, dtype=np.float64),
                            roll=np.asarray(ds["knowledge_roll"].values, dtype=np.float64),
                            pitch=np.asarray(ds["knowledge_pitch"].values, dtype=np.float64),
                            yaw=np.asarray(ds["knowledge_yaw"].values, dtype=np.float64))
        dem = Dem(x0_m=float(ds["dem_x"].values[0]), y0_m=float(ds["dem_y"].values[0]),
                  dx_m=float(ds.attrs["dem_dx_m"]), dy_m=float(ds.attrs["dem_dy_m"]),
                  z=np.asarray(ds["dem"].values, dtype=np.float64))
        st = None
        if "star_tracker_time" in ds:
            st = AttitudeSeries(time=np.asarray(ds["star_tracker_time"].values, dtype=np.float64),
                                roll=np.asarray(ds["star_tracker_roll"].values, dtype=np.float64),
                                pitch=np.asarray(ds["star_tracker_pitch"].values, dtype=np.float64),
                                yaw=np.asarray(ds["star_tracker_yaw"].values, dtype=np.float64))
    except KeyError as e:
        raise ProductError(f"{p}: malformed product, missing {e}") from None
    return Product(path=p, ds=ds, platform=plat, instrument=inst, knowledge=kn, dem=dem, star_tracker=st)


def check_truth(truth, path, product_time: np.ndarray) -> None:
    """Refuse a ``truth.nc`` whose axes are missing or not finite, or that does not cover the product's lines."""
    for name in ("time",) + AXES:
        if name not in truth.variables:
            raise ProductError(f"{path}: no variable {name!r} (truth needs time, roll, pitch, yaw)")
        v = np.asarray(truth[name].values, dtype=np.float64)
        if v.ndim != 1 or v.size < 2 or not np.isfinite(v).all():
            raise ProductError(f"{path}: variable {name!r} must be a finite series over 'time'")
    t = np.asarray(truth["time"].values, dtype=np.float64)
    if np.any(np.diff(t) <= 0):
        raise ProductError(f"{path}: variable 'time' must increase strictly")
    if t[0] > product_time[0] + 1e-9 or t[-1] < product_time[-1] - 1e-9:
        raise ProductError(f"{path}: truth covers [{t[0]:.6g}, {t[-1]:.6g}] s, not the product's lines "
                           f"[{product_time[0]:.6g}, {product_time[-1]:.6g}] s: another run's truth")


def read_truth(run_dir: str | Path, *, product_time: np.ndarray | None = None):
    """Read ``truth.nc`` (for reports and benchmarks only — never for restoration).

    With ``product_time`` the truth is checked against the product's lines (:func:`check_truth`).
    """
    p = Path(run_dir)
    if p.is_dir():
        p = p / "truth.nc"
    truth = _open(p)
    if product_time is not None:
        check_truth(truth, p, np.asarray(product_time, dtype=np.float64))
    return truth
