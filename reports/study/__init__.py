"""Trade studies: sweeps and Monte Carlo over scenario keys, run as Dask tasks (``simsat study STUDY.toml``).

:mod:`.spec` parses a study, :mod:`.evaluate` computes one point (differential
or rendered level), :mod:`.runner` runs them on a Dask cluster (resumable),
:mod:`.outputs` writes the tidy table, the xarray dataset and the plots.
"""
