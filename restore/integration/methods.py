"""Registry of the integration methods: one small spec per method, with its capabilities.

Callers never branch on a method's name: they ask its spec what it can do.

* ``line_weights`` — takes ``weights=`` (one relative weight per pair and
  line: lines resting on more matched points weigh more);
* ``line_lags`` — takes ``lags=`` and models a lag that varies line by line
  (time synchronisation) itself; other methods assume constant lags and get
  differentials brought back to the nominal lag first
  (:func:`restore.axis_integration.integrate_axis`);
* ``prior_lags`` — takes ``lags=`` and models them exactly once its prior is
  given (``psd=``, ``noise_std=``): the prior is estimated on differentials
  brought back to the nominal lag, then the method runs again on the
  differentials as measured, lags modelled (a prior estimated from lagged
  differentials is wrong by the lags' modulation at large amplitude);
* ``blind_tones`` — with lags modelled, also estimates a tone on a frequency
  every pair is blind to, which only the lags show
  (:func:`restore.integration.wiener.blind_tones`; ``tones=`` when frozen);
* ``noise_colour`` — weighs the residual by the inverse of a coloured noise
  covariance (``noise_colour=`` (freq, colour per pair): the noise's power
  relative to white, as the predicted σ's check measures it);
* ``line_sigmas`` — takes ``sigmas=`` (per-line formal σ of the differentials);
* ``reports_spectrum`` — adapts its prior to the data and, with
  ``return_details=True``, reports the PSD prior and noise levels it used
  (``.spectrum`` with ``freq``, ``psd``, ``noise_std``); passed back as
  ``psd=(freq, psd), noise_std=σ`` they make it the fixed linear filter that
  was applied (:meth:`IntegrationMethod.frozen_options`);
* ``psd_ceiling`` — takes ``psd_ceiling=(freq, ceiling)``, an upper bound of
  the prior PSD it estimates (what the AOCS knowledge already knows:
  :mod:`restore.knowledge_prior`);
* ``gain_option`` — the option holding a fixed regularisation ``k`` of the
  stationary chain gain ``Σ|G_j|² / (Σ|G_j|² + k)``, when the method is that
  filter.

The functions are imported when first used (``local``, ``kalman``... pull
SciPy pieces that a plain ``wiener`` run never needs).
"""
from __future__ import annotations

import importlib
import inspect
from dataclasses import dataclass
from typing import Callable

__all__ = ["IntegrationMethod", "INTEGRATION_METHODS", "DEFAULT_METHOD", "PIPELINE_OPTIONS", "integration_method",
           "register_method"]

#: options the pipeline supplies itself from the data (not settable in a scenario)
PIPELINE_OPTIONS = frozenset({"weights", "lags", "sigmas", "psd_ceiling", "return_details", "return_weights"})

DEFAULT_METHOD = "wiener"


@dataclass(frozen=True)
class IntegrationMethod:
    """One integration method: where it lives and what it can do."""

    name: str
    module: str
    function_name: str
    principle: str
    implementation: Callable | None = None
    line_weights: bool = False
    line_lags: bool = False
    prior_lags: bool = False
    blind_tones: bool = False
    noise_colour: bool = False
    line_sigmas: bool = False
    reports_spectrum: bool = False
    psd_ceiling: bool = False
    gain_option: str | None = None

    @property
    def function(self) -> Callable:
        """The function ``f(diffs, taus, dt, **options) -> theta`` (imported on first use)."""
        if self.implementation is not None:
            return self.implementation
        return getattr(importlib.import_module(f"restore.integration.{self.module}"), self.function_name)

    def options(self) -> dict:
        """Keyword options a scenario may set, with their defaults (from the function's signature)."""
        sig = inspect.signature(self.function)
        return {p.name: p.default for p in sig.parameters.values()
                if p.kind is inspect.Parameter.KEYWORD_ONLY and p.name not in PIPELINE_OPTIONS}

    def data_options(self, *, weights=None, lags=None, sigmas=None, psd_ceiling=None) -> dict:
        """The per-line data options this method takes, from those available."""
        out = {}
        if self.psd_ceiling and psd_ceiling is not None:
            out["psd_ceiling"] = psd_ceiling
        if self.line_weights and weights is not None:
            out["weights"] = weights
        if (self.line_lags or self.prior_lags) and lags is not None:
            out["lags"] = lags
        if self.line_sigmas and sigmas is not None:
            out["sigmas"] = sigmas
        return out

    @staticmethod
    def frozen_options(options: dict, spectrum) -> dict:
        """``options`` with the prior a data-adaptive run used (``spectrum``: freq, psd, noise_std) fixed."""
        if spectrum is None:
            return dict(options)
        out = {**options, "psd": (spectrum.freq, spectrum.psd), "noise_std": spectrum.noise_std}
        if getattr(spectrum, "tones", None) is not None:
            out["tones"] = spectrum.tones
        if getattr(spectrum, "noise_colour", None) is not None:
            out["noise_colour"] = spectrum.noise_colour
        return out


def _spec(name, module, function_name, principle, **caps) -> IntegrationMethod:
    return IntegrationMethod(name, module, function_name, principle, **caps)


#: method name → spec (the order is the documentation's)
INTEGRATION_METHODS: dict[str, IntegrationMethod] = {s.name: s for s in (
    _spec("wiener", "wiener", "integrate_wiener",
          "exact multi-pair Wiener / MAP on the finite record, data-estimated PSD prior, CG",
          line_weights=True, reports_spectrum=True, psd_ceiling=True, prior_lags=True, blind_tones=True,
          noise_colour=True),
    _spec("wiener_fft", "wiener", "integrate_wiener_fft", "one-shot multi-pair Wiener filter (FFT)"),
    _spec("inverse", "wiener", "integrate_inverse", "pseudo-inverse conj(G) / (|G|² + k)", gain_option="k"),
    _spec("local", "local", "integrate_local", "CNES local integration w = R⁻¹ r"),
    _spec("harmonic", "harmonic", "integrate_harmonic", "harmonic model with slowly varying amplitudes"),
    _spec("kalman", "kalman", "integrate_kalman", "Kalman filter + RTS smoother (oscillators + delay line)"),
    _spec("polynomial", "polynomial", "integrate_polynomial", "weighted least squares on a polynomial"),
    _spec("lsq", "lsq", "integrate_lsq",
          "time-domain regularised least squares, per-sample lags (time synchronisation), GCV-tuned prior",
          line_lags=True, line_sigmas=True),
    _spec("parametric", "parametric", "integrate_parametric",
          "global parametric synthesis (CNES §2, SPOT5 baseline): damped chirps + polynomial, non-linear least squares"),
)}


def integration_method(name: str | None) -> IntegrationMethod:
    """The spec of method ``name`` (None: :data:`DEFAULT_METHOD`).

    Raises
    ------
    ValueError
        Unknown name, with the known ones.
    """
    key = DEFAULT_METHOD if name is None else name
    if key not in INTEGRATION_METHODS:
        raise ValueError(f"method: must be one of {', '.join(sorted(INTEGRATION_METHODS))}; got {name!r}")
    return INTEGRATION_METHODS[key]


def register_method(name: str, function: Callable, principle: str, **capabilities) -> IntegrationMethod:
    """Add (or replace) an integration method: ``function(diffs, taus, dt, **options) -> theta``.

    ``capabilities`` are the flags of :class:`IntegrationMethod` (``line_weights``,
    ``line_lags``, ``line_sigmas``, ``reports_spectrum``, ``psd_ceiling``, ``gain_option``).
    Returns the spec; remove it with ``INTEGRATION_METHODS.pop(name)``.
    """
    spec = IntegrationMethod(name, getattr(function, "__module__", ""), getattr(function, "__name__", name), principle,
                             implementation=function, **capabilities)
    INTEGRATION_METHODS[name] = spec
    return spec
