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
``parametric`` global parametric synthesis (CNES §2, SPOT5        :func:`.parametric.integrate_parametric`
               baseline): damped chirps + polynomial
=============  ===============================================  =====================================

``DEFAULT_METHOD`` is the most accurate for quasi-harmonic jitter (see
``reports/bench_integration.py``).
"""
from __future__ import annotations

import difflib
import math
from collections.abc import Mapping
from typing import Callable

import numpy as np

from . import gaps, spectrum, transfer
from .gaps import coverage, fill_from_differentials, interpolate_gaps, observed_mask
from .methods import (
    DEFAULT_METHOD,
    INTEGRATION_METHODS,
    PIPELINE_OPTIONS,
    IntegrationMethod,
    integration_method,
)
from .transfer import (
    blind_frequencies,
    chain_gain,
    fused_chain_gain,
    fused_gains,
    pair_transfer,
    wiener_gain,
)
from .wiener import integrate_inverse, integrate_wiener, integrate_wiener_fft

__all__ = ["integrate", "METHODS", "INTEGRATION_METHODS", "IntegrationMethod", "integration_method", "DEFAULT_METHOD", "method_function", "method_options", "check_options",
           "PIPELINE_OPTIONS", "coverage", "observed_mask",
           "fill_from_differentials", "interpolate_gaps", "pair_transfer", "wiener_gain",
           "chain_gain", "blind_frequencies", "fused_gains", "fused_chain_gain",
           "integrate_wiener", "integrate_wiener_fft", "integrate_inverse", "gaps", "spectrum",
           "transfer"]

class _MethodFunctions(Mapping):
    """Method name → function, read-only view of :data:`INTEGRATION_METHODS` (imports on first use)."""

    def __getitem__(self, name: str) -> Callable:
        return INTEGRATION_METHODS[name].function

    def __iter__(self):
        return iter(INTEGRATION_METHODS)

    def __len__(self) -> int:
        return len(INTEGRATION_METHODS)


#: method name -> function(diffs, taus, dt, **options) -> theta
METHODS: Mapping[str, Callable] = _MethodFunctions()


def method_function(name: str) -> Callable:
    """The function implementing integration method ``name``."""
    return integration_method(name).function


def method_options(name: str) -> dict:
    """Keyword options of method ``name`` a scenario may set, with their defaults."""
    return integration_method(name).options()


def _check_value(value, default, key: str) -> None:
    if isinstance(value, bool) or isinstance(default, bool):
        if default is not None and isinstance(default, bool) != isinstance(value, bool):
            raise ValueError(f"{key}: must be {'true or false' if isinstance(default, bool) else 'a number'}, "
                             f"got {value!r}")
        return
    if isinstance(value, (int, float)):
        if not math.isfinite(value):
            raise ValueError(f"{key}: must be finite, got {value!r}")
        if value < 0:
            raise ValueError(f"{key}: must be >= 0, got {value!r}")
        if isinstance(default, int) and not isinstance(default, bool) and not float(value).is_integer():
            raise ValueError(f"{key}: must be an integer, got {value!r}")
        return
    if isinstance(default, (int, float)) and default is not None:
        raise ValueError(f"{key}: must be a number, got {type(value).__name__} {value!r}")
    if isinstance(value, list):
        if not value:
            raise ValueError(f"{key}: must not be an empty array")
        for i, v in enumerate(value):
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ValueError(f"{key}[{i}]: must be a finite number, got {v!r}")
        return
    if isinstance(value, dict):
        for k, v in value.items():
            if isinstance(v, (int, float, list)):
                _check_value(v, None, f"{key}.{k}")
        return
    if isinstance(value, str):
        raise ValueError(f"{key}: must be a number, an array of numbers or a table, got string {value!r}")


def check_options(name: str | None, options: dict, *, where: str = "restoration.integration") -> dict:
    """Check a method's options as a scenario gives them; return them unchanged.

    Parameters
    ----------
    name : str or None
        Integration method (None: :data:`DEFAULT_METHOD`).
    options : dict
        Option name → value.
    where : str
        Dotted key path of the options table, for the messages.

    Raises
    ------
    ValueError
        Naming ``where.option``: an option the method does not take (with the
        ones it does), or a value of the wrong type, not finite or negative.
    """
    name = DEFAULT_METHOD if name is None else name
    allowed = method_options(name)
    for key, value in options.items():
        if key not in allowed:
            near = difflib.get_close_matches(key, list(allowed), n=1)
            hint = f" (did you mean {near[0]!r}?)" if near else ""
            raise ValueError(f"{where}.{key}: not an option of the {name!r} integration method{hint}; "
                             f"its options: {', '.join(sorted(allowed)) or '(none)'}")
        _check_value(value, allowed[key], f"{where}.{key}")
    return options


def _check_taus(diffs, taus, dt) -> None:
    if not (isinstance(dt, (int, float, np.floating)) and math.isfinite(dt) and dt > 0):
        raise ValueError(f"dt: must be a finite sampling step > 0 [s], got {dt!r}")
    try:
        taus = list(np.atleast_1d(np.asarray(taus, dtype=np.float64)))
    except (TypeError, ValueError):
        raise ValueError(f"taus: must be a sequence of lags [s], got {taus!r}") from None
    if len(diffs) and np.ndim(diffs[0]) == 0:
        diffs = [diffs]  # one series given as a single array
    if len(taus) != len(diffs):
        raise ValueError(f"taus: one lag per differential series expected, got {len(taus)} lags "
                         f"for {len(diffs)} series")
    n = len(diffs[0]) if len(diffs) else 0
    for j, tau in enumerate(taus):
        if not (math.isfinite(tau) and tau > 0):
            raise ValueError(f"taus[{j}]: must be a finite lag > 0 [s], got {tau!r}")
        if n and tau >= n * dt:
            raise ValueError(f"taus[{j}]: lag {tau:g} s is not shorter than the record ({n} samples × "
                             f"{dt:g} s = {n * dt:g} s); lags are in seconds")


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
    spec = integration_method(method)
    _check_taus(diffs, taus, dt)
    return spec.function(diffs, taus, dt, **options)
