"""A study's outputs: the tidy table (Parquet + CSV), an xarray dataset over the sweep, the plots.

The table has one row per (design, seed): every swept value (``design.<axis>``),
the seed, RMS / 99.7 % / coverage / unobservable / floor per axis, timings,
and the point's error if it failed. The dataset puts each figure on the grid
``(<axis 1>, <axis 2>, ..., seed)``. The plots show the error against each
swept value, median over seeds with the 16–84 % band (the Monte Carlo spread),
one curve per value of the other axes; and, when the τ set varies, the
simulated gain σ_est/σ_meas against the shortest delay over the analytic
fig. 14 curve (``gain_vs_tau.png``).
"""
from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from simsat.product import atomic_write_bytes, atomic_write_dataset

__all__ = ["rows_table", "sweep_dataset", "write_outputs", "simulated_gain", "FIGURES"]

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
        gain = _plot_gain(spec, ok, out_dir / "gain_vs_tau.png")
        if gain:
            paths["gain_plot"] = gain
    return paths


def simulated_gain(df) -> dict:
    """Per axis: (τ₁ [s], gain) of every row — τ₁ the shortest delay of the row's pairs, the gain its
    restored RMS over its per-line matching noise (σ_est / σ_meas, fig. 14's ordinate)."""
    out = {}
    if "taus_ms" not in df:
        return out
    tau1 = np.array([min(float(x) for x in str(t).split(",")) * 1e-3 for t in df["taus_ms"]])
    for axis in ("roll", "pitch", "yaw"):
        r, n = f"{axis}_rms_px", f"{axis}_noise_px"
        if r in df and n in df:
            g = np.asarray(df[r], float) / np.asarray(df[n], float)
            ok = np.isfinite(g) & (g > 0)
            out[axis] = (tau1[ok], g[ok])
    return out


def _plot_gain(spec, df, path: Path) -> Path | None:
    """Simulated gain σ_est/σ_meas against τ₁ (median and 16–84 % per τ set) over the analytic fig. 14
    curve of the least-squares polynomial estimator for the base scenario's acquisition."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    from simsat.scenario import load_scenario

    from ..figures.formulas import polynomial_gain

    pts = simulated_gain(df)
    if not pts or len({round(t, 9) for t, _ in zip(*next(iter(pts.values())))}) < 2:
        return None
    sc = load_scenario(spec.base, check_models=False)
    te, n_lines = sc.instrument.line_period_s, sc.acquisition.lines
    fig = Figure(figsize=(7.0, 4.4), layout="constrained")
    ax = fig.subplots()
    allt = np.concatenate([t for t, _ in pts.values()])
    taus = np.geomspace(allt.min() / 3, allt.max() * 3, 60)
    g = polynomial_gain(taus, degree=5, line_period_s=te, lines_per_measurement=1, n_lines=n_lines)
    ax.plot(taus, g["mean"], color="0.3", lw=1.3,
            label=f"fig. 14 analytic: least-squares polynomial (degree 5), mean over the {n_lines} lines")
    ax.plot(taus, g["max"], color="0.3", lw=1.0, ls="--", label="fig. 14 analytic: maximum over the record")
    for axis, marker in (("roll", "o"), ("pitch", "s"), ("yaw", "^")):
        if axis not in pts:
            continue
        t, v = pts[axis]
        ut = np.unique(t)
        med = np.array([np.median(v[t == u]) for u in ut])
        lo = np.array([np.percentile(v[t == u], 16) for u in ut])
        hi = np.array([np.percentile(v[t == u], 84) for u in ut])
        ax.errorbar(ut, med, yerr=[med - lo, hi - med], marker=marker, ls="-", capsize=3,
                    label=f"{axis}: simulated ({spec.level} level, median and 16–84 % of every design and seed)")
    ax.set_xscale("log")
    ax.set_yscale("log")
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    ax.xaxis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
    ax.xaxis.set_major_formatter(FuncFormatter(lambda x, _: f"{x * 1e3:g}"))
    ax.xaxis.set_minor_formatter(NullFormatter())
    ax.set_xlabel(r"shortest delay of the τ set, $\tau_1$ (ms)")
    ax.set_ylabel(r"gain $\sigma_{est} / \sigma_{meas}$")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, frameon=False)
    ax.set_title(f"study {spec.name}: restored error over matching noise against τ", fontsize=10)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    atomic_write_bytes(buf.getvalue(), path)
    return path
