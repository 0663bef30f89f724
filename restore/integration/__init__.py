"""Temporal integration of attitude differentials (patent step c) — image-free API.

>>> from restore.integration import integrate
>>> theta = integrate(diffs, taus, dt, method="wiener")        # doctest: +SKIP

``diffs`` is a list of 1-D arrays of the same length ``N``, one per pair of
bands, sampled every ``dt`` seconds, with ``diffs[j][n] ≈ theta(n dt + taus[j])
- theta(n dt) + noise`` (rad) and NaN at gaps; ``taus`` need not be multiples of
``dt``.  The result is ``theta`` at ``n dt`` (rad) with its mean removed (the
constant is unobservable) and NaN where it cannot be estimated (see
:mod:`.gaps`).

Methods (``integrate(..., method=name, **options)``; options are the keyword
arguments of the function named):

=============  ===============================================  =====================================
name           principle                                         function
=============  ===============================================  =====================================
``wiener``     exact multi-pair Wiener / MAP on the finite        :func:`.wiener.integrate_wiener`
               record, data-estimated PSD prior, CG (default)
``wiener_fft`` one-shot multi-pair Wiener filter (FFT)           :func:`.wiener.integrate_wiener_fft`
``inverse``    pseudo-inverse ``conj(G) / (|G|² + k)``           :func:`.wiener.integrate_inverse`
``local``      CNES local integration ``w = R^-1 r``             :func:`.local.integrate_local`
``harmonic``   harmonic model with slowly varying amplitudes     :func:`.harmonic.integrate_harmonic`
``kalman``     Kalman filter + RTS smoother (oscillators +       :func:`.kalman.integrate_kalman`
               delay line)
``polynomial`` weighted least squares on a polynomial            :func:`.polynomial.integrate_polynomial`
``lsq``        time-domain regularised least squares, per-sample  :func:`.lsq.integrate_lsq`
               lags (time synchronisation), GCV-tuned prior
=============  ===============================================  =====================================

``DEFAULT_METHOD`` is the most accurate for quasi-harmonic jitter (see
``reports/bench_integration.py``).
"""
from __future__ import annotations

from typing import Callable

import numpy as np

from . import gaps, spectrum, transfer
from .gaps import coverage, fill_from_differentials, interpolate_gaps, observed_mask
from .transfer import (blind_frequencies, chain_gain, fused_chain_gain, fused_gains,
                       pair_transfer, wiener_gain)
from .wiener import integrate_inverse, integrate_wiener, integrate_wiener_fft

__all__ = ["integrate", "METHODS", "DEFAULT_METHOD", "coverage", "observed_mask",
           "fill_from_differentials", "interpolate_gaps", "pair_transfer", "wiener_gain",
           "chain_gain", "blind_frequencies", "fused_gains", "fused_chain_gain",
           "integrate_wiener", "integrate_wiener_fft", "integrate_inverse", "gaps", "spectrum",
           "transfer"]

DEFAULT_METHOD = "wiener"


def _lazy(module: str, name: str) -> Callable:
    def call(*args, **kwargs):
        import importlib
        return getattr(importlib.import_module(f"{__name__}.{module}"), name)(*args, **kwargs)
    call.__name__ = name
    call.__doc__ = f"See :func:`restore.integration.{module}.{name}`."
    return call


#: method name -> function(diffs, taus, dt, **options) -> theta
METHODS: dict[str, Callable] = {
    "wiener": integrate_wiener,
    "wiener_fft": integrate_wiener_fft,
    "inverse": integrate_inverse,
    "local": _lazy("local", "integrate_local"),
    "harmonic": _lazy("harmonic", "integrate_harmonic"),
    "kalman": _lazy("kalman", "integrate_kalman"),
    "polynomial": _lazy("polynomial", "integrate_polynomial"),
    "lsq": _lazy("lsq", "integrate_lsq"),
}


def integrate(diffs, taus, dt, method: str | None = None, **options) -> np.ndarray:
    """Integrate attitude differentials back to the attitude.

    Parameters
    ----------
    diffs : sequence of 1-D arrays
        ``diffs[j][n] ≈ theta(n dt + taus[j]) - theta(n dt) + noise`` (rad),
        all of length N, NaN at gaps.
    taus : sequence of float
        Lag of each pair (s, > 0, any value — not necessarily a multiple of ``dt``).
    dt : float
        Sampling step (s).
    method : str, optional
        One of :data:`METHODS`; default :data:`DEFAULT_METHOD`.
    **options
        Keyword options of the chosen method.

    Returns
    -------
    ndarray, shape (N,)
        theta at ``n dt`` (rad), mean removed, NaN where no estimate exists.
    """
    name = DEFAULT_METHOD if method is None else method
    if name not in METHODS:
        raise ValueError(f"method: must be one of {', '.join(sorted(METHODS))}; got {method!r}")
    return METHODS[name](diffs, taus, dt, **options)
