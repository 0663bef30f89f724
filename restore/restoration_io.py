"""Checks of ``restoration.nc`` as read back by its consumers (the report, studies).

A restoration that cannot belong to its product (another length, other line
times), that lost variables (truncated, edited), or that holds nothing
(every restored sample NaN) is refused with one line naming the file and the
variable, never drawn.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from simsat.product import ProductError

__all__ = ["open_restoration", "check_restoration", "REQUIRED_VARIABLES", "REQUIRED_ATTRS"]

AXES = ("roll", "pitch", "yaw")
REQUIRED_VARIABLES = tuple(f"{p}{a}" for a in AXES for p in ("", "knowledge_", "correction_", "diff_")) + (
    "time", "pair", "tau_s")
REQUIRED_ATTRS = ("pixel_ifov_rad", "settings", "method")


def open_restoration(path: str | Path):
    """Load ``restoration.nc`` (no check of its content: see :func:`check_restoration`).

    Raises
    ------
    ProductError
        The file is not readable NetCDF (truncated, corrupt).
    """
    import xarray as xr

    p = Path(path)
    try:
        return xr.load_dataset(p, engine="netcdf4")
    except Exception as e:
        raise ProductError(f"{p}: cannot read as NetCDF ({type(e).__name__}: {e}); "
                           f"run `simsat restore` again") from None


def check_restoration(ds, path: str | Path, *, product_time: np.ndarray) -> list[str]:
    """Refuse a restoration that does not belong to its product or holds nothing.

    Parameters
    ----------
    ds : xarray.Dataset
        The restoration as read.
    path : path
        Its file, for the messages.
    product_time : ndarray
        Line times of the product [s].

    Returns
    -------
    list of str
        The restored axes (from the recorded settings).

    Raises
    ------
    ProductError
        Naming the file and the variable or attribute at fault.
    """
    p = Path(path)
    for name in REQUIRED_VARIABLES:
        if name not in ds.variables:
            raise ProductError(f"{p}: no variable {name!r} (a truncated or foreign file); run `simsat restore` again")
    for name in REQUIRED_ATTRS:
        if name not in ds.attrs:
            raise ProductError(f"{p}: no global attribute {name!r}; run `simsat restore` again")
    try:
        settings = json.loads(str(ds.attrs["settings"]))
    except json.JSONDecodeError:
        raise ProductError(f"{p}: attribute 'settings' is not JSON; run `simsat restore` again") from None
    if not isinstance(settings, dict):
        raise ProductError(f"{p}: attribute 'settings' must be a JSON object")
    ifov = ds.attrs["pixel_ifov_rad"]
    try:
        ok = float(ifov) > 0 and np.isfinite(float(ifov))
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise ProductError(f"{p}: attribute 'pixel_ifov_rad' must be a finite angle > 0 [rad], got {ifov!r}")
    t = np.asarray(ds["time"].values, dtype=np.float64)
    pt = np.asarray(product_time, dtype=np.float64)
    if t.shape != pt.shape:
        raise ProductError(f"{p}: variable 'time' has {t.size} lines but the product has {pt.size}: "
                           f"this restoration belongs to another product; run `simsat restore` again")
    if not np.allclose(t, pt, rtol=0, atol=1e-9):
        raise ProductError(f"{p}: variable 'time' differs from the product's line times "
                           f"(by up to {np.nanmax(np.abs(t - pt)):.3g} s): another product; run `simsat restore` again")
    axes = [a for a in settings.get("axes", ["roll", "pitch"]) if a in AXES]
    if not axes:
        raise ProductError(f"{p}: attribute 'settings' names no restored axis")
    for a in axes:
        v = np.asarray(ds[a].values, dtype=np.float64)
        if v.shape != t.shape:
            raise ProductError(f"{p}: variable {a!r} has shape {v.shape}, expected ({t.size},) like 'time'")
        if not np.isfinite(v).any():
            raise ProductError(f"{p}: variable {a!r} is NaN on every line: nothing was restored on this axis "
                               f"(no usable match); see the restore command's messages")
        kn = np.asarray(ds[f"knowledge_{a}"].values, dtype=np.float64)
        if kn.shape != t.shape or not np.isfinite(kn).all():
            raise ProductError(f"{p}: variable 'knowledge_{a}' must be finite on every line")
    n_pairs = int(np.atleast_1d(ds["pair"].values).size)
    for a in AXES:
        shape = tuple(ds[f"diff_{a}"].shape)
        if shape != (n_pairs, t.size):
            raise ProductError(f"{p}: variable 'diff_{a}' has shape {shape}, expected ({n_pairs} pairs, {t.size} lines)")
    return axes
