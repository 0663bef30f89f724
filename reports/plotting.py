"""Shared plotting and file-writing helpers for the reports package.

Everything here is presentation only: no physics.  Figures are drawn with the
non-interactive Agg backend and written atomically (temporary file in the same
folder, then :func:`os.replace`), so a reader never sees a half-written PNG or
CSV.
"""

from __future__ import annotations

import csv
import io
import os
from pathlib import Path
from typing import Iterable, Mapping, Sequence

import matplotlib

matplotlib.use("Agg")  # before pyplot: files only, never a window

import numpy as np  # noqa: E402
from matplotlib.axes import Axes  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

from simsat.product import atomic_write_bytes  # noqa: E402

__all__ = [
    "STYLE",
    "SERIES_COLORS",
    "new_axes",
    "new_axes_grid",
    "mark_blind_frequencies",
    "rug_blind_frequencies",
    "plot_mc_points",
    "legend_below",
    "legend_right",
    "save_figure",
    "write_table_csv",
    "read_table_csv",
]

#: rcParams used by every report figure.
STYLE: dict = {
    "figure.dpi": 100,
    "savefig.dpi": 150,
    "font.size": 10,
    "axes.titlesize": 11,
    "axes.labelsize": 10,
    "legend.fontsize": 8.5,
    "legend.framealpha": 0.92,
    "axes.grid": True,
    "grid.alpha": 0.3,
    "grid.linewidth": 0.6,
    "lines.linewidth": 1.4,
}

#: Colour cycle (colour-blind safe, Okabe–Ito).
SERIES_COLORS: tuple[str, ...] = (
    "#0072B2",  # blue
    "#D55E00",  # vermilion
    "#009E73",  # green
    "#CC79A7",  # purple
    "#E69F00",  # orange
    "#56B4E9",  # sky
    "#000000",
)


def new_axes(figsize: tuple[float, float] = (8.0, 4.6)) -> tuple[Figure, Axes]:
    """Return a fresh ``(figure, axes)`` pair in the report style.

    The figure is *not* registered with pyplot's figure manager, so nothing
    leaks between calls and no ``plt.close`` is needed.
    """
    with matplotlib.rc_context(STYLE):
        fig = Figure(figsize=figsize, layout="constrained")
        ax = fig.add_subplot(1, 1, 1)
    _style_axes(ax)
    return fig, ax


def new_axes_grid(nrows: int, *, figsize: tuple[float, float], sharex: bool = True,
                  height_ratios: Sequence[float] | None = None) -> tuple[Figure, list[Axes]]:
    """Return a figure with ``nrows`` stacked axes in the report style."""
    with matplotlib.rc_context(STYLE):
        fig = Figure(figsize=figsize, layout="constrained")
        axes = fig.subplots(nrows, 1, sharex=sharex,
                            gridspec_kw={"height_ratios": height_ratios} if height_ratios else None)
    axes = list(np.atleast_1d(axes))
    for ax in axes:
        _style_axes(ax)
    return fig, axes


def _style_axes(ax: Axes) -> None:
    ax.grid(True, alpha=STYLE["grid.alpha"], linewidth=STYLE["grid.linewidth"])
    ax.tick_params(labelsize=9)


def mark_blind_frequencies(ax: Axes, tau_s: float, *, f_max_hz: float, f_min_hz: float = 0.0,
                           color: str = "0.45", label_top: bool = True,
                           legend_label: str | None = "blind frequencies n/τ") -> list[float]:
    """Draw dotted vertical lines at the blind frequencies ``n/τ`` (n ≥ 1).

    Parameters
    ----------
    ax : matplotlib Axes
    tau_s : float
        Pair delay τ in s.
    f_max_hz, f_min_hz : float
        Frequency range (Hz) in which to mark.
    label_top : bool
        Write ``1/τ``, ``2/τ`` … just inside the top of the axes.
    legend_label : str or None
        Legend text attached to the first line.

    Returns
    -------
    list of float
        The frequencies marked, Hz.
    """
    f0 = 1.0 / tau_s
    n_lo = max(1, int(np.ceil(f_min_hz / f0)))
    n_hi = int(np.floor(f_max_hz / f0))
    marked = []
    for n in range(n_lo, n_hi + 1):
        f = n * f0
        ax.axvline(f, color=color, linestyle=":", linewidth=1.0, zorder=1,
                   label=legend_label if (legend_label and not marked) else None)
        if label_top:
            ax.text(f, 0.985, f" {n}/τ", transform=ax.get_xaxis_transform(), rotation=90,
                    va="top", ha="right", fontsize=7.5, color=color)
        marked.append(f)
    return marked


def rug_blind_frequencies(ax: Axes, tau_s: float, *, f_max_hz: float, f_min_hz: float = 0.0,
                          color: str = "k", y_axes: float = 1.0, size: float = 5.0,
                          label: str | None = None) -> np.ndarray:
    """Mark blind frequencies ``n/τ`` with small triangles at the top edge of ``ax``.

    Used where several delays share one axes and full-height lines would clutter.
    Returns the frequencies marked (Hz).
    """
    f0 = 1.0 / tau_s
    n_lo = max(1, int(np.ceil(f_min_hz / f0)))
    n_hi = int(np.floor(f_max_hz / f0))
    f = np.arange(n_lo, n_hi + 1) * f0
    if f.size:
        ax.plot(f, np.full(f.size, y_axes), linestyle="none", marker="v", markersize=size,
                color=color, transform=ax.get_xaxis_transform(), clip_on=False, label=label,
                zorder=5)
    return f


def legend_below(ax: Axes, *, ncols: int = 2, **kwargs):
    """Figure legend under the axes (outside the data area, so it hides nothing).

    Uses the figure's constrained layout (``loc="outside lower center"``), which
    reserves the room the legend needs.
    """
    handles, labels = ax.get_legend_handles_labels()
    return ax.figure.legend(handles, labels, loc="outside lower center", ncols=ncols,
                            frameon=False, **kwargs)


def legend_right(ax: Axes, **kwargs):
    """Legend to the right of the axes."""
    return ax.legend(loc="center left", bbox_to_anchor=(1.01, 0.5), frameon=False, **kwargs)


def plot_mc_points(ax: Axes, x, y, yerr, *, color: str, label: str | None,
                   marker: str = "o", n_sigma: float = 2.0):
    """Monte Carlo points with ``n_sigma`` × standard-error bars."""
    return ax.errorbar(np.asarray(x), np.asarray(y), yerr=n_sigma * np.asarray(yerr),
                       fmt=marker, markersize=4.5, markerfacecolor="white",
                       markeredgecolor=color, ecolor=color, elinewidth=1.2, capsize=2.5,
                       color=color, label=label, zorder=6)


def save_figure(fig: Figure, path: str | os.PathLike) -> Path:
    """Save ``fig`` as PNG at ``path`` atomically."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    return atomic_write_bytes(buf.getvalue(), path)


def _fmt(v) -> str:
    if isinstance(v, (float, np.floating)):
        if np.isnan(v):
            return ""
        return repr(float(v))
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    return str(v)


def write_table_csv(path: str | os.PathLike, table: Mapping[str, Iterable]) -> Path:
    """Write a column table (dict name → equal-length sequence) as CSV, atomically.

    Floats are written with full precision (``repr``); NaN is written as an empty
    field.
    """
    names = list(table)
    cols = [list(table[n]) for n in names]
    lengths = {len(c) for c in cols}
    if len(lengths) > 1:
        raise ValueError(f"table columns have different lengths: "
                         f"{dict(zip(names, map(len, cols)))}")
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(names)
    for row in zip(*cols):
        w.writerow([_fmt(v) for v in row])
    return atomic_write_bytes(buf.getvalue().encode("utf-8"), path)


def read_table_csv(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Read a CSV written by :func:`write_table_csv`.

    Columns that parse as numbers become float arrays (empty → NaN); others stay
    string arrays.
    """
    with open(path, newline="", encoding="utf-8") as fh:
        rows = list(csv.reader(fh))
    names, body = rows[0], rows[1:]
    out: dict[str, np.ndarray] = {}
    for i, name in enumerate(names):
        raw = [r[i] for r in body]
        try:
            out[name] = np.array([float(v) if v != "" else np.nan for v in raw], dtype=float)
        except ValueError:
            out[name] = np.array(raw, dtype=object)
    return out
