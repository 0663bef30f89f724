"""Patent parameters (see :mod:`reports.figures`)."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ['PATENT_TAU_S', 'PATENT_K', 'PATENT_PAIRS', 'FIG09_K_VALUES', 'FIG11_TAU_VALUES_S', 'FIG14_LINE_PERIOD_S', 'FIG14_LINES_PER_MEASUREMENT', 'FIG14_N_LINES', 'FIG14_DEGREE', 'F_MAX_WIENER_HZ', 'F_RANGE_FIG13_HZ', 'FIGURE_NAMES', 'FigureData']

#: Delay of figs. 7–8 (s): 7.44 ms, i.e. 1/τ = 134.4 Hz.
PATENT_TAU_S: float = 7.44e-3
#: Noise-attenuation coefficient of figs. 7–8.
PATENT_K: float = 0.1
#: Band pairs and delays (s) of fig. 13.
PATENT_PAIRS: dict[str, float] = {
    "PAN/B2": 172.2e-3,
    "B1/B2": 22.2e-3,
    "B1/B0": 7.4e-3,
    "B2/B0": 14.8e-3,
}
#: Values of k for fig. 9/10 and of τ (s) for figs. 11/12.
FIG09_K_VALUES: tuple[float, ...] = (0.01, 0.1, 1.0)
FIG11_TAU_VALUES_S: tuple[float, ...] = (3.72e-3, 7.44e-3, 14.88e-3)
#: Fig. 14 acquisition: line period (s), lines per independent measurement,
#: number of lines (12 000 × 0.5 ms = 6 s, hence 1 200 measurements), degree.
FIG14_LINE_PERIOD_S: float = 0.5e-3
FIG14_LINES_PER_MEASUREMENT: int = 10
FIG14_N_LINES: int = 12_000
FIG14_DEGREE: int = 5

#: Frequency span (Hz) of figs. 7–12 and of fig. 13.
F_MAX_WIENER_HZ: float = 600.0
F_RANGE_FIG13_HZ: tuple[float, float] = (0.05, 500.0)

FIGURE_NAMES: dict[int, str] = {
    7: "fig07_wiener_gain",
    8: "fig08_wiener_phase",
    9: "fig09_k_estimator_gain",
    10: "fig10_k_chain_gain",
    11: "fig11_tau_estimator_gain",
    12: "fig12_tau_chain_gain",
    13: "fig13_pairs_fusion",
    14: "fig14_polynomial_gain",
}


@dataclass
class FigureData:
    """Data of one figure.

    Attributes
    ----------
    number : int
        Patent figure number.
    name : str
        File stem, e.g. ``"fig07_wiener_gain"``.
    table : dict of str → ndarray
        Tidy table, one row per point, written verbatim as the CSV.  Columns:
        ``source`` (``analytic`` / ``monte_carlo``), ``quantity``, ``series``,
        ``unit`` and numeric columns (``freq_hz``, ``tau_s``, ``k``, ``value``,
        ``stderr``, ``n_trials`` …; NaN where not applicable).
    meta : dict
        Parameters and notes (not in the CSV).
    """

    number: int
    name: str
    table: dict[str, np.ndarray]
    meta: dict = field(default_factory=dict)

    def select(self, *, source: str | None = None, quantity: str | None = None,
               series: str | None = None) -> dict[str, np.ndarray]:
        """Rows matching the given labels, as a dict of columns."""
        m = np.ones(len(self.table["source"]), dtype=bool)
        for col, want in (("source", source), ("quantity", quantity), ("series", series)):
            if want is not None:
                m &= self.table[col] == want
        return {c: v[m] for c, v in self.table.items()}

    def series_names(self, *, source: str, quantity: str) -> list[str]:
        """Distinct series of ``quantity`` from ``source``, in table order."""
        sel = self.select(source=source, quantity=quantity)["series"]
        return list(dict.fromkeys(sel.tolist()))
