"""A study's outputs: the tidy table (Parquet + CSV), an xarray dataset over the sweep, the plots.

The table has one row per (design, seed): every swept value (``design.<axis>``),
the seed, RMS / 99.7 % / coverage / unobservable / floor per axis, timings,
and the point's error if it failed. The dataset puts each figure on the grid
``(<axis 1>, <axis 2>, ..., seed)``. The plots show the error against each
swept value, median over seeds with the 16–84 % band (the Monte Carlo spread),
one curve per value of the other axes.
"""
from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from simsat.product import atomic_write_bytes, atomic_write_dataset

__all__ = ["rows_table", "sweep_dataset", "write_outputs", "FIGURES"]

#: the per-axis figures of a row
FIGURES = ("rms_px", "p997_px", "coverage", "unobservable_px", "floor_px", "knowledge_rms_px")


def rows_table(spec, rows: list[dict]):
    """The tidy table (pandas DataFrame), rows in the study's point order."""
    import pandas as pd

    df = pd.DataFrame(rows)
    if "traceback" in df:
        df = df.drop(columns=["traceback"])
    first = ["key", "seed"] + [f"design.{a.name}" for a in spec.axes]
    return df[[c for c in first if c in df] + [c for c in df.columns if c not in first]]


def sweep_dataset(spec, df):
    """Every numeric figure on the grid (sweep axes..., seed) as an :class:`xarray.Dataset`."""
    import xarray as xr
    from pandas.api.types import is_numeric_dtype

    dims = [a.name for a in spec.axes] + ["seed"]
    coords = {a.name: [_label(_as_tuple(a.label(i))) for i in range(len(a.values))] for a in spec.axes}
    coords["seed"] = list(spec.seeds)
    shape = tuple(len(coords[d]) for d in dims)
    data = {}
    numeric = [c for c in df.columns if c not in ("key", "seed", "error") and not c.startswith("design.")
               and is_numeric_dtype(df[c].dtype)]
    index = []
    for _, r in df.iterrows():
        idx = tuple(coords[a.name].index(_label(_as_tuple(r[f"design.{a.name}"]))) for a in spec.axes)
        index.append(idx + (coords["seed"].index(int(r["seed"])),))
    for c in numeric:
        arr = np.full(shape, np.nan)
        for idx, v in zip(index, df[c].to_numpy(dtype=float)):
            arr[idx] = v
        data[c] = (dims, arr)
    ds = xr.Dataset(data, coords=coords, attrs={"study": spec.name, "base": spec.base, "level": spec.level})
    return ds


def _as_tuple(v):
    if isinstance(v, (list, tuple)):
        return tuple(v)
    if isinstance(v, str) and "," in v:
        return tuple(v.split(","))
    return (v,)


def _label(v) -> str | float:
    """Coordinate label of an axis value (a tuple of the keys' values): a number when it is one number."""
    vals = v if isinstance(v, tuple) else (v,)
    if len(vals) == 1:
        x = vals[0]
        try:
            return float(x)
        except (TypeError, ValueError):
            return str(x)
    return ",".join(str(x) for x in vals)


def _plot(spec, ds, path: Path) -> Path | None:
    """Error against each swept value (median over seeds, 16–84 % band), roll and pitch."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    if not spec.axes:
        return None
    n = len(spec.axes)
    fig = Figure(figsize=(6.0 * n, 4.2), layout="constrained")
    axs = np.atleast_1d(fig.subplots(1, n))
    for ax, swept in zip(axs, spec.axes):
        others = [a.name for a in spec.axes if a.name != swept.name]
        x = np.asarray(ds[swept.name].values)
        numeric = np.issubdtype(x.dtype, np.number)
        xp = x if numeric else np.arange(x.size)
        for axis, style in (("roll", "-"), ("pitch", "--")):
            var = f"{axis}_rms_px"
            if var not in ds:
                continue
            da = ds[var]
            groups = [{}] if not others else [dict(zip(others, combo)) for combo in
                                              np.array(np.meshgrid(*[ds[o].values for o in others],
                                                                   indexing="ij")).reshape(len(others), -1).T]
            for g in groups:
                sel = da.sel({k: v for k, v in g.items()}) if g else da
                vals = np.asarray(sel.transpose(swept.name, "seed").values)
                med = np.nanmedian(vals, axis=1)
                lo, hi = np.nanpercentile(vals, 16, axis=1), np.nanpercentile(vals, 84, axis=1)
                label = f"{axis}" + (" " + ", ".join(f"{k}={v}" for k, v in g.items()) if g else "")
                line, = ax.plot(xp, med, style, marker="o", label=label)
                ax.fill_between(xp, lo, hi, color=line.get_color(), alpha=0.15, lw=0)
        if not numeric:
            ax.set_xticks(xp, [str(v) for v in x], rotation=20)
        ax.set_xlabel(swept.name)
        ax.set_ylabel("restored error, RMS [px]")
        ax.set_yscale("log")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7, frameon=False)
    fig.suptitle(f"study {spec.name} ({spec.level} level, {len(spec.seeds)} seeds per design; median and "
                 f"16–84 % over seeds)", fontsize=10)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    atomic_write_bytes(buf.getvalue(), path)
    return path


def write_outputs(spec, rows: list[dict], out_dir: Path) -> dict:
    """Write ``table.parquet``, ``table.csv``, ``sweep.nc`` and ``errors.png``; returns their paths."""
    out_dir = Path(out_dir)
    df = rows_table(spec, rows)
    paths = {}
    buf = io.BytesIO()
    df.to_parquet(buf, index=False)
    atomic_write_bytes(buf.getvalue(), out_dir / "table.parquet")
    paths["parquet"] = out_dir / "table.parquet"
    atomic_write_bytes(df.to_csv(index=False).encode("utf-8"), out_dir / "table.csv")
    paths["csv"] = out_dir / "table.csv"
    ok = df[df["error"] == ""] if "error" in df else df
    if len(ok):
        ds = sweep_dataset(spec, ok)
        atomic_write_dataset(ds, out_dir / "sweep.nc")
        paths["netcdf"] = out_dir / "sweep.nc"
        png = _plot(spec, ds, out_dir / "errors.png")
        if png:
            paths["plot"] = png
    return paths
