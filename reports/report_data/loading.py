"""Run report data: loading (see :mod:`reports.report_data`)."""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from restore.integration import integrate
from restore.restoration_io import (
    check_restoration,
    open_restoration,
    result_from_dataset,
)
from simsat.product import ProductError, read_product, read_truth

__all__ = ['RunData', 'load_run', 'get_integrator', 'pair_file_tag']


@dataclass
class RunData:
    """Everything the report reads from a run directory.

    Attributes
    ----------
    run_dir : Path
    product : simsat.product.Product
        Geometry, knowledge and DEM (images are *not* loaded: see
        :attr:`simsat.product.Product.image_shapes`).
    image_shapes : dict
        ``{band: (lines, columns)}``.
    restoration : xarray.Dataset or None
        ``restoration.nc`` (None when the run was not restored).
    result : restore.result.RestorationResult or None
        The same file read back by :func:`restore.restoration_io.result_from_dataset`:
        what the pipeline did (pairs, τ′, per-axis integration records), never re-derived here.
    truth : xarray.Dataset or None
        ``truth.nc`` (None for a real product).
    run_info : dict
        ``run.json`` ({} when absent).
    notes : list of str
        What could not be read, to be said in the page.
    """

    run_dir: Path
    product: object
    image_shapes: dict
    restoration: object = None
    truth: object = None
    run_info: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)
    has_corrected: bool = False
    result: object = None
    _cache: dict = field(default_factory=dict, repr=False)

    @property
    def ifov(self) -> float:
        """Pixel IFOV of the reference band [rad]."""
        if self.restoration is not None and "pixel_ifov_rad" in self.restoration.attrs:
            return float(self.restoration.attrs["pixel_ifov_rad"])
        return float(self.product.pixel_ifov_rad)

    @property
    def line_period_s(self) -> float:
        return float(self.product.instrument.line_period_s)

    @property
    def time(self) -> np.ndarray:
        """Line times [s] (restoration's when present, else the product's)."""
        if self.restoration is not None:
            return np.asarray(self.restoration["time"].values, dtype=np.float64)
        return self.product.time

    @property
    def settings(self) -> dict:
        """Restoration settings (JSON attr ``settings``), {} when unknown."""
        if "settings" not in self._cache:
            s = {}
            if self.restoration is not None:
                try:
                    s = json.loads(str(self.restoration.attrs.get("settings", "{}")))
                except json.JSONDecodeError:
                    s = {}
            self._cache["settings"] = s
        return self._cache["settings"]

    @property
    def pairs(self) -> list:
        """Pair names of the restoration (``"A/B"``), [] without restoration."""
        if self.restoration is None:
            return []
        return [str(p) for p in np.atleast_1d(self.restoration["pair"].values)]

    @property
    def taus(self) -> list:
        """Delays τ [s] used by the restoration, per pair."""
        if self.restoration is None:
            return []
        return [float(t) for t in np.atleast_1d(self.restoration["tau_s"].values)]


def load_run(run_dir) -> RunData:
    """Read a run directory: product (without images), restoration, truth, run.json.

    Raises
    ------
    simsat.product.ProductError
        When ``product.nc`` is missing or malformed (the only required file).
    """
    run_dir = Path(run_dir)
    notes: list = []
    product = read_product(run_dir)  # images stay in the file (opened lazily)
    shapes = product.image_shapes
    rest = result = None
    if (run_dir / "restoration.nc").exists():
        rest = open_restoration(run_dir / "restoration.nc")
        check_restoration(rest, run_dir / "restoration.nc", product_time=product.time)
        result = result_from_dataset(rest, run_dir / "restoration.nc")
    else:
        notes.append("No restoration.nc in the run: run `simsat restore RUN_DIR` for the restored attitude; "
                     "only the product (and truth) are shown.")
    truth = None
    if (run_dir / "truth.nc").exists():
        truth = read_truth(run_dir, product_time=product.time)
    else:
        notes.append("No truth.nc (a real product): errors, spectra of truth and error, the measured transfer "
                     "and the error budget rows that need truth are left out.")
    info = {}
    if (run_dir / "run.json").exists():
        try:
            info = json.loads((run_dir / "run.json").read_text())
        except (json.JSONDecodeError, OSError, UnicodeDecodeError) as e:
            raise ProductError(f"{run_dir / 'run.json'}: not a readable JSON file ({e})") from None
        if not isinstance(info, dict):
            raise ProductError(f"{run_dir / 'run.json'}: must hold a JSON object (simsat's run record), "
                               f"got {type(info).__name__}")
    return RunData(run_dir=run_dir, product=product, image_shapes=shapes, restoration=rest, truth=truth,
                   run_info=info, notes=notes, has_corrected=(run_dir / "corrected.nc").exists(), result=result)


def get_integrator(integrator: Callable | None = None) -> tuple:
    """The integration function the transfer probe re-runs: ``(integrator or restore's integrate, "")``.

    ``(None, why)`` means the report must not re-run the integration (the
    tests and a cost guard use that form).
    """
    return (integrator if integrator is not None else integrate), ""


def pair_file_tag(pair: str) -> str:
    """File-name-safe tag of a pair name (``"B1/B0"`` → ``"B1-B0"``)."""
    return "".join(c if c.isalnum() or c in "-_" else "-" for c in pair.replace("/", "-"))
