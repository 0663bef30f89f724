"""Attitude of the line of sight: jitter models, AOCS knowledge, star tracker.

Conventions
-----------
* Angles are in rad, times in s (float64).  Config keys carrying another unit
  say so (``amplitude_urad``, ``phase_deg``, ``drift_percent``).
* Axes are ``"roll"`` (about x, along-track; moves the image across-track),
  ``"pitch"`` (about y; moves the image along-track) and ``"yaw"`` (about z).
* Every disturbance draws all of its random parameters at construction, from a
  generator built on the scenario seed, so that it is a deterministic,
  continuous function of time that can be evaluated at any ``t`` (the renderer
  evaluates it at sub-line times): same seed, same bytes.
* Times ``t`` are absolute (the product's time axis).  Drift shapes, polynomial
  coefficients and chirp start times are referred to the acquisition start
  ``t_start``; relative drifts are spread over ``[t_start, t_end]``.

Scenario layout (``[attitude]`` table)::

    [[attitude.jitter]]
    kind = "cmg"                  # harmonic | cmg | damped_chirp | psd | polynomial
    axis = ["roll", "pitch"]      # one axis or several (independent draws)
    ...
    [attitude.knowledge]          # AOCS telemetry: cutoff_hz, rate_hz, noise_urad
    [attitude.star_tracker]       # enabled (false), rate_hz, noise_urad
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, Iterable, Sequence

import numpy as np
from scipy.interpolate import CubicSpline, make_interp_spline
from scipy.signal import butter, sosfilt, sosfiltfilt

from simsat.config import Section
from simsat.units import AXES, RAD_PER_URAD

__all__ = [
    "AXES",
    "Disturbance", "HarmonicJitter", "CMGJitter", "DampedChirpJitter", "PSDJitter",
    "PolynomialDrift", "SmoothRandomProcess",
    "AttitudeModel", "AttitudeSeries", "KnowledgeConfig", "StarTrackerConfig",
    "aocs_knowledge", "star_tracker_samples", "disturbance_from_config",
]

MAX_AMPLITUDE_URAD = 1e5    #: 0.1 rad (5.7°): beyond, the small-angle line-of-sight model is meaningless
MAX_FREQUENCY_HZ = 1e5      #: far above any line rate; bounds the truth sampling
MAX_SAMPLE_RATE_HZ = 1e4    #: AOCS knowledge / star tracker sampling
KNOWLEDGE_FILTER_KINDS = ("zero_phase", "causal")   #: ``[attitude.knowledge] filter``
MAX_PSD_COMPONENTS = 100_000  #: sinusoids of a ``psd`` jitter (memory and time grow with it)


def _check_list_max(sec, name: str, values, vmax: float) -> None:
    for i, v in enumerate(values):
        if v > vmax:
            raise sec.error(f"{name}[{i}]" if len(values) > 1 else name, f"must be <= {vmax:g}, got {v:g}")

# Stream tags appended to the scenario seed so that attitude draws never collide
# with other modules using ``SeedSequence([seed, index])``.
_STREAM_JITTER = 0x4A17
_STREAM_KNOWLEDGE = 0x4B10
_STREAM_KNOWLEDGE_ERRORS = 0x4B11
_STREAM_STAR = 0x5374
_DRIFT_SHAPES = ("linear", "quadratic", "sine")
_CHUNK = 4096  # time samples per block when summing many sinusoids


def _rng(*key: int) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence([int(k) for k in key]))


def _as_time(t) -> np.ndarray:
    return np.asarray(t, dtype=np.float64)


def _check_span(t_start: float, t_end: float) -> None:
    if not (math.isfinite(t_start) and math.isfinite(t_end)):
        raise ValueError(f"t_start, t_end: must be finite, got {t_start}, {t_end}")
    if not t_end > t_start:
        raise ValueError(f"t_end: must be > t_start ({t_start}), got {t_end}")


# ---------------------------------------------------------------------------
# Building blocks
# ---------------------------------------------------------------------------
def _drift_shape(u: np.ndarray, shape: str) -> tuple[np.ndarray, np.ndarray]:
    """Normalised drift shape s(u) (s(0)=0, s(1)=1) and its integral S(u)=∫0^u s."""
    if shape == "linear":
        return u, u**2 / 2
    if shape == "quadratic":
        return u**2, u**3 / 3
    if shape == "sine":  # smooth S-curve, zero slope at both ends
        return (1 - np.cos(np.pi * u)) / 2, u / 2 - np.sin(np.pi * u) / (2 * np.pi)
    raise ValueError(f"drift_shape: must be one of {', '.join(_DRIFT_SHAPES)}; got {shape!r}")


class SmoothRandomProcess:
    """Zero-mean smooth random process: a sum of a few low-frequency random sinusoids.

    ``x(t) = sum_k c sin(2 pi nu_k (t - t0) + psi_k)`` with ``c = std * sqrt(2 / n)``
    so that the time-averaged standard deviation is ``std``.  Being an analytic
    function it is continuous in ``t`` and has an analytic integral.

    Parameters
    ----------
    rng : numpy.random.Generator
        Source of the random frequencies and phases (drawn here, once).
    std : float
        Standard deviation (unit of the caller).
    bandwidth_hz : float
        Frequencies ``nu_k`` are drawn uniformly in ``[0.1, 1] * bandwidth_hz`` (Hz).
    t0 : float
        Time origin (s).
    n_terms : int, keyword-only
        Number of sinusoids (default 5).
    """

    def __init__(self, rng: np.random.Generator, std: float, bandwidth_hz: float, t0: float,
                 *, n_terms: int = 5):
        if std < 0:
            raise ValueError(f"std: must be >= 0, got {std}")
        if not bandwidth_hz > 0:
            raise ValueError(f"bandwidth_hz: must be > 0, got {bandwidth_hz}")
        self.nu = rng.uniform(0.1, 1.0, n_terms) * bandwidth_hz
        self.psi = rng.uniform(0.0, 2 * np.pi, n_terms)
        self.c = std * math.sqrt(2.0 / n_terms)
        self.t0 = float(t0)

    def __call__(self, t) -> np.ndarray:
        """Value at ``t`` (s)."""
        x = _as_time(t)[..., None] - self.t0
        return self.c * np.sin(2 * np.pi * self.nu * x + self.psi).sum(-1)

    def integral(self, t) -> np.ndarray:
        """Integral from ``t0`` to ``t`` (unit × s)."""
        x = _as_time(t)[..., None] - self.t0
        w = 2 * np.pi * self.nu
        return (self.c * (np.cos(self.psi) - np.cos(w * x + self.psi)) / w).sum(-1)


def _sum_of_sines(t: np.ndarray, freq: np.ndarray, amp: np.ndarray, phase: np.ndarray,
                  t0: float) -> np.ndarray:
    """``sum_k amp_k sin(2 pi freq_k (t - t0) + phase_k)`` by blocks of time."""
    flat = t.reshape(-1) - t0
    out = np.empty_like(flat)
    w = 2 * np.pi * freq
    for i in range(0, flat.size, _CHUNK):
        blk = flat[i:i + _CHUNK, None]
        out[i:i + _CHUNK] = np.sin(blk * w + phase) @ amp
    return out.reshape(t.shape)


# ---------------------------------------------------------------------------
# Disturbances
# ---------------------------------------------------------------------------
class Disturbance:
    """Base class: an attitude disturbance on one axis, a continuous function of time."""

    #: highest frequency present (Hz), used to choose sampling rates.
    max_frequency_hz: float = 0.0

    def evaluate(self, t) -> np.ndarray:  # pragma: no cover - interface
        """Disturbance angle (rad) at times ``t`` (s); same shape as ``t``."""
        raise NotImplementedError

    __call__ = evaluate


@dataclass(frozen=True)
class HarmonicJitter(Disturbance):
    """A sinusoid with an optional (non-linear) frequency drift.

    ``theta(t) = A sin(phi0 + 2 pi f0 [(t - t0) + delta T S(u)])`` with
    ``u = (t - t0) / T``, ``T = t_end - t0``, the instantaneous frequency
    ``f(t) = f0 (1 + delta s(u))`` and ``s`` the drift shape (``s(0) = 0``,
    ``s(1) = 1``): ``"linear"`` ``u``, ``"quadratic"`` ``u**2``, ``"sine"``
    ``(1 - cos(pi u)) / 2``.  ``delta`` is the total relative drift over
    ``[t0, t_end]``.

    Parameters
    ----------
    frequency_hz : float
        Frequency at ``t0`` (Hz, > 0).
    amplitude_rad : float
        Amplitude (rad, >= 0).
    phase_rad : float
        Phase at ``t0`` (rad).
    drift : float
        Total relative frequency drift (e.g. 0.01 for 1 %).
    drift_shape : str
        ``"linear"``, ``"quadratic"`` or ``"sine"``.
    t0, t_end : float
        Acquisition start and end (s).
    """

    frequency_hz: float
    amplitude_rad: float
    phase_rad: float = 0.0
    drift: float = 0.0
    drift_shape: str = "linear"
    t0: float = 0.0
    t_end: float = 1.0

    def __post_init__(self):
        if not self.frequency_hz > 0:
            raise ValueError(f"frequency_hz: must be > 0, got {self.frequency_hz}")
        if not self.amplitude_rad >= 0:
            raise ValueError(f"amplitude_rad: must be >= 0, got {self.amplitude_rad}")
        if self.drift_shape not in _DRIFT_SHAPES:
            raise ValueError(f"drift_shape: must be one of {', '.join(_DRIFT_SHAPES)}; "
                             f"got {self.drift_shape!r}")
        _check_span(self.t0, self.t_end)

    @property
    def max_frequency_hz(self) -> float:  # type: ignore[override]
        return self.frequency_hz * (1 + abs(self.drift))

    def phase(self, t) -> np.ndarray:
        """Total phase (rad) at ``t`` (s)."""
        t = _as_time(t)
        span = self.t_end - self.t0
        u = (t - self.t0) / span
        _, big_s = _drift_shape(u, self.drift_shape)
        return self.phase_rad + 2 * np.pi * self.frequency_hz * ((t - self.t0) + self.drift * span * big_s)

    def frequency(self, t) -> np.ndarray:
        """Instantaneous frequency (Hz) at ``t`` (s)."""
        u = (_as_time(t) - self.t0) / (self.t_end - self.t0)
        s, _ = _drift_shape(u, self.drift_shape)
        return self.frequency_hz * (1 + self.drift * s)

    def evaluate(self, t) -> np.ndarray:
        return self.amplitude_rad * np.sin(self.phase(t))

    __call__ = evaluate


class CMGJitter(Disturbance):
    """Control-moment-gyro jitter (the CNES / Pleiades case): harmonics of exciters.

    Each exciter ``e`` (base frequency ``F_e``) produces lines at ``h F_e`` for
    every multiplier ``h`` of ``harmonics``.  Line ``(e, h)``::

        theta_eh(t) = A r_e q_h (1 + a_eh(t)) sin(phi_eh + 2 pi h F_e [(t - t0)
                      + delta_e T S_e(u) + E_e(t)])

    * drift: exciter ``e`` drifts by ``delta_e`` (drawn uniformly in
      ``drift_range`` with a random sign) over ``T = t_end - t0`` along a random
      non-linear shape ``s_e(u) = (1 - b) u + b u**2 + c sin(pi u)``
      (``b`` in [-1, 1], ``c`` in [-0.5, 0.5]; ``s_e(0) = 0``, ``s_e(1) = 1``),
      ``S_e`` its integral;
    * frequency noise: ``E_e(t)`` is the integral of a smooth random process of
      relative standard deviation ``frequency_noise`` (shared by the exciter's
      harmonics, as a speed fluctuation would be);
    * amplitude noise: ``a_eh(t)`` smooth random process of standard deviation
      ``amplitude_noise`` (independent per line);
    * phases ``phi_eh`` uniform random.

    Parameters
    ----------
    exciter_frequencies_hz : sequence of float
        Base frequencies ``F_e`` (Hz, > 0).
    harmonics : sequence of float
        Multipliers ``h`` (> 0), e.g. ``[1, 2]``.
    amplitude_rad : float
        Amplitude ``A`` of the main line (rad).
    exciter_amplitude_ratios, harmonic_amplitude_ratios : sequence of float, optional
        ``r_e`` and ``q_h``.  Defaults: 1 for the first two exciters, 0.5 for the
        others; ``1 / h`` for the harmonics.
    drift_range : (float, float)
        Min and max of the relative drift magnitude (e.g. ``(0.002, 0.011)``).
    frequency_noise, amplitude_noise : float
        Relative standard deviations (e.g. 0.001 for 0.1 %).
    noise_bandwidth_hz : float
        Bandwidth of the slow random variations (Hz).
    t0, t_end : float
        Acquisition start and end (s).
    rng : numpy.random.Generator
        Source of all random draws (consumed here).
    """

    def __init__(self, *, exciter_frequencies_hz: Sequence[float], harmonics: Sequence[float],
                 amplitude_rad: float, rng: np.random.Generator, t0: float, t_end: float,
                 exciter_amplitude_ratios: Sequence[float] | None = None,
                 harmonic_amplitude_ratios: Sequence[float] | None = None,
                 drift_range: tuple[float, float] = (0.0, 0.0), frequency_noise: float = 0.0,
                 amplitude_noise: float = 0.0, noise_bandwidth_hz: float = 1.0):
        _check_span(t0, t_end)
        fe = np.asarray(exciter_frequencies_hz, dtype=float)
        hh = np.asarray(harmonics, dtype=float)
        if fe.size == 0 or np.any(~(fe > 0)):
            raise ValueError(f"exciter_frequencies_hz: must be > 0, got {fe.tolist()}")
        if hh.size == 0 or np.any(~(hh > 0)):
            raise ValueError(f"harmonics: must be > 0, got {hh.tolist()}")
        if not amplitude_rad >= 0:
            raise ValueError(f"amplitude_rad: must be >= 0, got {amplitude_rad}")
        re = (np.where(np.arange(fe.size) < 2, 1.0, 0.5) if exciter_amplitude_ratios is None
              else np.asarray(exciter_amplitude_ratios, dtype=float))
        qh = 1.0 / hh if harmonic_amplitude_ratios is None else np.asarray(harmonic_amplitude_ratios, float)
        if re.shape != fe.shape:
            raise ValueError(f"exciter_amplitude_ratios: must have {fe.size} values, got {re.size}")
        if qh.shape != hh.shape:
            raise ValueError(f"harmonic_amplitude_ratios: must have {hh.size} values, got {qh.size}")
        lo, hi = drift_range
        if not 0 <= lo <= hi:
            raise ValueError(f"drift_range: must be 0 <= min <= max, got {drift_range}")
        for name, v in (("frequency_noise", frequency_noise), ("amplitude_noise", amplitude_noise)):
            if not v >= 0:
                raise ValueError(f"{name}: must be >= 0, got {v}")
        self.t0, self.t_end = float(t0), float(t_end)
        self.exciter_frequencies_hz = fe
        self.harmonics = hh
        self.amplitudes = amplitude_rad * re[:, None] * qh[None, :]     # (E, H), rad
        ne, nh = fe.size, hh.size
        # --- all random draws, in a fixed order -------------------------------
        self.drift = rng.uniform(lo, hi, ne) * rng.choice([-1.0, 1.0], ne)
        self.shape_b = rng.uniform(-1.0, 1.0, ne)
        self.shape_c = rng.uniform(-0.5, 0.5, ne)
        self.phases = rng.uniform(0.0, 2 * np.pi, (ne, nh))
        self.freq_noise = [SmoothRandomProcess(rng, frequency_noise, noise_bandwidth_hz, t0)
                           for _ in range(ne)]
        self.amp_noise = [[SmoothRandomProcess(rng, amplitude_noise, noise_bandwidth_hz, t0)
                           for _ in range(nh)] for _ in range(ne)]
        self._fnoise = frequency_noise

    @property
    def line_frequencies_hz(self) -> np.ndarray:
        """Nominal line frequencies ``h F_e`` at ``t0`` (Hz), shape (E, H)."""
        return self.exciter_frequencies_hz[:, None] * self.harmonics[None, :]

    @property
    def max_frequency_hz(self) -> float:  # type: ignore[override]
        return float(self.line_frequencies_hz.max() * (1 + 1.5 * np.abs(self.drift).max()
                                                     + 4 * self._fnoise))

    def _shape(self, u: np.ndarray, e: int) -> tuple[np.ndarray, np.ndarray]:
        b, c = self.shape_b[e], self.shape_c[e]
        s = (1 - b) * u + b * u**2 + c * np.sin(np.pi * u)
        big_s = (1 - b) * u**2 / 2 + b * u**3 / 3 + c * (1 - np.cos(np.pi * u)) / np.pi
        return s, big_s

    def exciter_frequency(self, t, e: int) -> np.ndarray:
        """Instantaneous frequency (Hz) of exciter ``e`` at ``t`` (s)."""
        t = _as_time(t)
        u = (t - self.t0) / (self.t_end - self.t0)
        s, _ = self._shape(u, e)
        return self.exciter_frequencies_hz[e] * (1 + self.drift[e] * s + self.freq_noise[e](t))

    def evaluate(self, t) -> np.ndarray:
        t = _as_time(t)
        span = self.t_end - self.t0
        u = (t - self.t0) / span
        out = np.zeros(t.shape)
        for e, fe in enumerate(self.exciter_frequencies_hz):
            _, big_s = self._shape(u, e)
            base = 2 * np.pi * fe * ((t - self.t0) + self.drift[e] * span * big_s
                                     + self.freq_noise[e].integral(t))
            for h, mult in enumerate(self.harmonics):
                amp = self.amplitudes[e, h] * (1 + self.amp_noise[e][h](t))
                out += amp * np.sin(mult * base + self.phases[e, h])
        return out

    __call__ = evaluate


@dataclass(frozen=True)
class DampedChirpJitter(Disturbance):
    """Damped chirp (SPOT5 mirror rocking), zero before its start.

    ``theta(t) = A exp(-x / tau_d) sin(2 pi (f0 x + c x**2 / 2))`` for
    ``x = t - (t0 + start_time) >= 0``, else 0 (continuous at the start).

    Parameters
    ----------
    amplitude_rad, frequency_hz, chirp_hz_per_s, damping_time_s : float
        ``A`` (rad), ``f0`` (Hz, > 0), ``c`` (Hz/s), ``tau_d`` (s, > 0).
    start_time_s : float
        Start, in s since the acquisition start ``t0``.
    t0 : float
        Acquisition start (s).
    """

    amplitude_rad: float
    frequency_hz: float
    chirp_hz_per_s: float = 0.0
    damping_time_s: float = 1.0
    start_time_s: float = 0.0
    t0: float = 0.0

    def __post_init__(self):
        if not self.frequency_hz > 0:
            raise ValueError(f"frequency_hz: must be > 0, got {self.frequency_hz}")
        if not self.damping_time_s > 0:
            raise ValueError(f"damping_time_s: must be > 0, got {self.damping_time_s}")

    @property
    def max_frequency_hz(self) -> float:  # type: ignore[override]
        # the envelope is < 1e-6 after 14 damping times
        return self.frequency_hz + abs(self.chirp_hz_per_s) * 14 * self.damping_time_s

    def evaluate(self, t) -> np.ndarray:
        x = _as_time(t) - (self.t0 + self.start_time_s)
        xp = np.maximum(x, 0.0)
        val = (self.amplitude_rad * np.exp(-xp / self.damping_time_s)
               * np.sin(2 * np.pi * (self.frequency_hz * xp + 0.5 * self.chirp_hz_per_s * xp**2)))
        return np.where(x >= 0, val, 0.0)

    __call__ = evaluate


class PSDJitter(Disturbance):
    """Coloured random jitter synthesised from a PSD as a sum of random-phase sinusoids.

    One-sided PSD shape ``S(f) ∝ 1 / (1 + (f / f_c)**slope)`` on
    ``[f_min, f_max]`` (flat below the corner ``f_c``, power law ``f**-slope``
    beyond), zero outside.  ``n_components`` frequencies are drawn one per
    logarithmic cell of the band (so the process is not periodic); component
    ``k`` has amplitude ``sqrt(2 S(f_k) df_k)`` rescaled so that the RMS is
    exactly ``rms``, and a uniform random phase.

    Parameters
    ----------
    rms_rad : float
        RMS of the process (rad).
    corner_hz, slope, f_min_hz, f_max_hz : float
        PSD shape (Hz, dimensionless, Hz, Hz).
    rng : numpy.random.Generator
        Source of the random frequencies and phases (consumed here).
    t0 : float
        Time origin (s).
    n_components : int
        Number of sinusoids.
    """

    def __init__(self, *, rms_rad: float, corner_hz: float, slope: float, f_min_hz: float,
                 f_max_hz: float, rng: np.random.Generator, t0: float = 0.0, n_components: int = 400):
        if not rms_rad >= 0:
            raise ValueError(f"rms_rad: must be >= 0, got {rms_rad}")
        if not corner_hz > 0:
            raise ValueError(f"corner_hz: must be > 0, got {corner_hz}")
        if not f_min_hz > 0:
            raise ValueError(f"f_min_hz: must be > 0, got {f_min_hz}")
        if not f_max_hz > f_min_hz:
            raise ValueError(f"f_max_hz: must be > f_min_hz ({f_min_hz}), got {f_max_hz}")
        if not n_components >= 1:
            raise ValueError(f"n_components: must be >= 1, got {n_components}")
        edges = np.geomspace(f_min_hz, f_max_hz, n_components + 1)
        self.frequencies = rng.uniform(edges[:-1], edges[1:])
        self.phases = rng.uniform(0.0, 2 * np.pi, n_components)
        psd = 1.0 / (1.0 + (self.frequencies / corner_hz) ** slope)
        amp = np.sqrt(2 * psd * np.diff(edges))
        norm = math.sqrt(0.5 * float(np.sum(amp**2)))
        self.amplitudes = amp * (rms_rad / norm if norm > 0 else 0.0)
        self.rms_rad = float(rms_rad)
        self.t0 = float(t0)
        self.max_frequency_hz = float(f_max_hz)

    def evaluate(self, t) -> np.ndarray:
        return _sum_of_sines(_as_time(t), self.frequencies, self.amplitudes, self.phases, self.t0)

    __call__ = evaluate


@dataclass(frozen=True)
class PolynomialDrift(Disturbance):
    """Low-frequency drift ``theta(t) = sum_k c_k (t - t0)**k``.

    Parameters
    ----------
    coefficients_rad : sequence of float
        ``c_0, c_1, ...`` in rad, rad/s, rad/s², ... with ``t - t0`` in s
        since the acquisition start ``t0``.
    t0 : float
        Acquisition start (s).
    """

    coefficients_rad: tuple
    t0: float = 0.0
    max_frequency_hz: float = 0.0

    def evaluate(self, t) -> np.ndarray:
        x = _as_time(t) - self.t0
        return np.polynomial.polynomial.polyval(x, np.asarray(self.coefficients_rad, float)) + 0 * x

    __call__ = evaluate


# ---------------------------------------------------------------------------
# Config
# ---------------------------------------------------------------------------
def _phase_rad(sec: Section, rng: np.random.Generator) -> float:
    """``phase_deg`` when given; else a random phase drawn for this axis (independent axes, not one sine twice)."""
    deg = sec.number("phase_deg", None, ge=-1e6, le=1e6)
    return math.radians(deg) if deg is not None else float(rng.uniform(0.0, 2.0 * np.pi))


def _harmonic_from_config(sec: Section, *, rng: np.random.Generator, t_start: float, t_end: float) -> Disturbance:
    """``kind = "harmonic"``: one sine, optional slow frequency drift."""
    return HarmonicJitter(
        frequency_hz=sec.number("frequency_hz", gt=0, le=MAX_FREQUENCY_HZ),
        amplitude_rad=sec.number("amplitude_urad", ge=0, le=MAX_AMPLITUDE_URAD) * RAD_PER_URAD,
        phase_rad=_phase_rad(sec, rng),
        drift=sec.number("drift_percent", 0.0, gt=-100) / 100,
        drift_shape=sec.string("drift_shape", "linear", choices=_DRIFT_SHAPES),
        t0=t_start, t_end=t_end)


def _cmg_from_config(sec: Section, *, rng: np.random.Generator, t_start: float, t_end: float) -> Disturbance:
    """``kind = "cmg"``: CMG / reaction-wheel exciters and their harmonics, drifting."""
    fe = sec.numbers("exciter_frequencies_hz", min_length=1, gt=0)
    _check_list_max(sec, "exciter_frequencies_hz", fe, MAX_FREQUENCY_HZ)
    hh = sec.numbers("harmonics", [1.0], min_length=1, gt=0)
    _check_list_max(sec, "harmonics", hh, 1000.0)
    amp = sec.number("amplitude_urad", ge=0, le=MAX_AMPLITUDE_URAD) * RAD_PER_URAD
    rexc = sec.numbers("exciter_amplitude_ratios", None, length=len(fe), ge=0)
    rharm = sec.numbers("harmonic_amplitude_ratios", None, length=len(hh), ge=0)
    drift = sec.numbers("drift_percent", [0.0, 0.0], ge=0)
    _check_list_max(sec, "drift_percent", drift, 50.0)
    if len(drift) == 1:
        drift = drift * 2
    if len(drift) != 2 or drift[0] > drift[1]:
        raise sec.error("drift_percent", f"must be [min, max] with min <= max, got {drift}")
    return CMGJitter(
        exciter_frequencies_hz=fe, harmonics=hh, amplitude_rad=amp, rng=rng,
        t0=t_start, t_end=t_end, exciter_amplitude_ratios=rexc,
        harmonic_amplitude_ratios=rharm, drift_range=(drift[0] / 100, drift[1] / 100),
        frequency_noise=sec.number("frequency_noise_percent", 0.0, ge=0, le=50) / 100,
        amplitude_noise=sec.number("amplitude_noise_percent", 0.0, ge=0, le=100) / 100,
        noise_bandwidth_hz=sec.number("noise_bandwidth_hz", 1.0, gt=0, le=MAX_FREQUENCY_HZ))


def _damped_chirp_from_config(sec: Section, *, rng: np.random.Generator, t_start: float, t_end: float) -> Disturbance:
    """``kind = "damped_chirp"``: damped chirp (SPOT5 mirror rocking)."""
    return DampedChirpJitter(
        amplitude_rad=sec.number("amplitude_urad", ge=0, le=MAX_AMPLITUDE_URAD) * RAD_PER_URAD,
        frequency_hz=sec.number("frequency_hz", gt=0, le=MAX_FREQUENCY_HZ),
        chirp_hz_per_s=sec.number("chirp_hz_per_s", 0.0, ge=-1e5, le=1e5),
        damping_time_s=sec.number("damping_time_s", gt=0, le=1e6),
        start_time_s=sec.number("start_time_s", 0.0, ge=-1e6, le=1e6), t0=t_start)


def _psd_from_config(sec: Section, *, rng: np.random.Generator, t_start: float, t_end: float) -> Disturbance:
    """``kind = "psd"``: random jitter of a given PSD (sum of sines)."""
    f_min = sec.number("f_min_hz", 0.1, gt=0, le=MAX_FREQUENCY_HZ)
    f_max = sec.number("f_max_hz", 1000.0, gt=0, le=MAX_FREQUENCY_HZ)
    if not f_max > f_min:
        raise sec.error("f_max_hz", f"must be > f_min_hz ({f_min:g}), got {f_max:g}")
    return PSDJitter(
        rms_rad=sec.number("rms_urad", ge=0, le=MAX_AMPLITUDE_URAD) * RAD_PER_URAD,
        corner_hz=sec.number("corner_hz", gt=0, le=MAX_FREQUENCY_HZ), slope=sec.number("slope", 2.0, ge=0, le=10),
        f_min_hz=f_min, f_max_hz=f_max, rng=rng, t0=t_start,
        n_components=sec.integer("n_components", 400, ge=1, le=MAX_PSD_COMPONENTS))


def _polynomial_from_config(sec: Section, *, rng: np.random.Generator, t_start: float, t_end: float) -> Disturbance:
    """``kind = "polynomial"``: slow polynomial drift."""
    coefs = sec.numbers("coefficients_urad", min_length=1)
    _check_list_max(sec, "coefficients_urad", [abs(c) for c in coefs], MAX_AMPLITUDE_URAD)
    if len(coefs) > 8:
        raise sec.error("coefficients_urad", f"at most 8 coefficients (degree 7), got {len(coefs)}")
    return PolynomialDrift(tuple(c * RAD_PER_URAD for c in coefs), t0=t_start)


@dataclass(frozen=True)
class DisturbanceKind:
    """One ``[[attitude.jitter]]`` kind: its name, what it models and its builder from the table."""

    name: str
    description: str
    from_config: Callable


#: kind name → spec (``disturbance_from_config`` dispatches through it)
DISTURBANCE_KINDS: dict[str, DisturbanceKind] = {k: DisturbanceKind(k, d, f) for k, d, f in (
    ("harmonic", "one sine, optional slow frequency drift", _harmonic_from_config),
    ("cmg", "CMG / reaction-wheel exciters and their harmonics, drifting", _cmg_from_config),
    ("damped_chirp", "damped chirp (SPOT5 mirror rocking)", _damped_chirp_from_config),
    ("psd", "random jitter of a given PSD (sum of sines)", _psd_from_config),
    ("polynomial", "slow polynomial drift", _polynomial_from_config),
)}


def disturbance_from_config(sec: Section, *, rng: np.random.Generator, t_start: float,
                            t_end: float, kind: str) -> Disturbance:
    """Build one disturbance of ``kind`` (:data:`DISTURBANCE_KINDS`) from its ``[[attitude.jitter]]`` table.

    Reads the kind-specific keys (not ``kind`` nor ``axis``); the caller calls
    ``sec.finish()``.  ``rng`` supplies every random draw.
    """
    return DISTURBANCE_KINDS[kind].from_config(sec, rng=rng, t_start=t_start, t_end=t_end)


_KINDS = tuple(DISTURBANCE_KINDS)


@dataclass(frozen=True)
class KnowledgeConfig:
    """``[attitude.knowledge]``: AOCS telemetry (cut-off Hz, rate Hz, noise µrad) and how it errs.

    A real AOCS estimate is not the truth low-passed: it carries a constant
    bias (``bias_urad``, 1 σ per axis, drawn from the seed), a slow drift
    (``drift_urad_per_s``, 1 σ per axis), a latency (``delay_ms``: the
    telemetry at t describes t − delay) and a causal filter (``filter =
    "causal"``: a Butterworth run forward only, with its phase lag) — the
    defaults keep the ideal knowledge of the built-in scenarios.
    """

    cutoff_hz: float = 10.0
    rate_hz: float = 50.0
    noise_urad: float = 0.5
    bias_urad: float = 0.0
    drift_urad_per_s: float = 0.0
    delay_ms: float = 0.0
    filter: str = "zero_phase"

    @classmethod
    def from_section(cls, sec: Section) -> "KnowledgeConfig":
        cut = sec.number("cutoff_hz", cls.cutoff_hz, gt=0, le=MAX_FREQUENCY_HZ)
        rate = sec.number("rate_hz", cls.rate_hz, gt=0, le=MAX_SAMPLE_RATE_HZ)
        noise = sec.number("noise_urad", cls.noise_urad, ge=0, le=MAX_AMPLITUDE_URAD)
        bias = sec.number("bias_urad", cls.bias_urad, ge=0, le=MAX_AMPLITUDE_URAD)
        drift = sec.number("drift_urad_per_s", cls.drift_urad_per_s, ge=0, le=MAX_AMPLITUDE_URAD)
        delay = sec.number("delay_ms", cls.delay_ms, ge=0, le=1000.0)
        filt = sec.string("filter", cls.filter, choices=KNOWLEDGE_FILTER_KINDS)
        sec.finish()
        return cls(cut, rate, noise, bias, drift, delay, filt)


@dataclass(frozen=True)
class StarTrackerConfig:
    """``[attitude.star_tracker]``: sparse absolute samples (off by default)."""

    enabled: bool = False
    rate_hz: float = 1.0
    noise_urad: float = 2.0

    @classmethod
    def from_section(cls, sec: Section) -> "StarTrackerConfig":
        en = sec.boolean("enabled", cls.enabled)
        rate = sec.number("rate_hz", cls.rate_hz, gt=0, le=MAX_SAMPLE_RATE_HZ)
        noise = sec.number("noise_urad", cls.noise_urad, ge=0, le=MAX_AMPLITUDE_URAD)
        sec.finish()
        return cls(en, rate, noise)


# ---------------------------------------------------------------------------
# Attitude model
# ---------------------------------------------------------------------------
@dataclass
class AttitudeModel:
    """True LOS attitude: nominal constants plus disturbances per axis.

    Parameters
    ----------
    nominal : (float, float, float)
        Constant roll, pitch, yaw (rad).
    disturbances : list of (str, Disturbance)
        ``(axis, disturbance)`` pairs, axis in ``AXES``.
    knowledge, star_tracker : KnowledgeConfig, StarTrackerConfig
        The scenario's telemetry settings (defaults when built by hand).
    t_start, t_end : float
        Acquisition span (s).
    seed : int
        Scenario seed (used by :meth:`knowledge_series` and :meth:`star_tracker_series`).
    """

    nominal: tuple = (0.0, 0.0, 0.0)
    disturbances: list = field(default_factory=list)
    knowledge: KnowledgeConfig = field(default_factory=KnowledgeConfig)
    star_tracker: StarTrackerConfig = field(default_factory=StarTrackerConfig)
    t_start: float = 0.0
    t_end: float = 1.0
    seed: int = 0

    def __post_init__(self):
        if len(self.nominal) != 3:
            raise ValueError(f"nominal: must have 3 values (roll, pitch, yaw), got {self.nominal}")
        for axis, _ in self.disturbances:
            if axis not in AXES:
                raise ValueError(f"axis: must be one of {', '.join(AXES)}; got {axis!r}")

    @property
    def max_frequency_hz(self) -> float:
        """Highest frequency among the disturbances (Hz; 0 if none)."""
        return max([d.max_frequency_hz for _, d in self.disturbances], default=0.0)

    def evaluate_axis(self, axis: str, t) -> np.ndarray:
        """Attitude angle (rad) about ``axis`` at times ``t`` (s)."""
        if axis not in AXES:
            raise ValueError(f"axis: must be one of {', '.join(AXES)}; got {axis!r}")
        t = _as_time(t)
        out = np.full(t.shape, float(self.nominal[AXES.index(axis)]))
        for ax, dist in self.disturbances:
            if ax == axis:
                out = out + dist.evaluate(t)
        return out

    def evaluate(self, t) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(roll, pitch, yaw) in rad at times ``t`` (s), each of the shape of ``t``."""
        return tuple(self.evaluate_axis(ax, t) for ax in AXES)  # type: ignore[return-value]

    __call__ = evaluate

    @classmethod
    def from_config(cls, section: Section, *, seed: int, nominal=(0.0, 0.0, 0.0),
                    t_start: float, t_end: float, extra_allowed: Iterable[str] = ()) -> "AttitudeModel":
        """Build the model from the scenario's ``[attitude]`` table.

        Reads ``[[attitude.jitter]]`` (one disturbance per table; with several
        axes, each axis gets an independent random draw of the same
        distribution), ``[attitude.knowledge]`` and ``[attitude.star_tracker]``,
        then rejects unknown keys (``extra_allowed`` names keys that the caller
        reads itself).  Disturbance ``i`` on its ``k``-th axis draws from
        ``SeedSequence([seed, 0x4A17, i, k])``.
        """
        _check_span(t_start, t_end)
        dists = []
        for i, js in enumerate(section.sections("jitter")):
            kind = js.string("kind", choices=_KINDS)
            axes = js.strings("axis", choices=AXES)
            if not axes:
                raise js.error("axis", "must name at least one axis")
            if len(set(axes)) != len(axes):
                raise js.error("axis", f"repeated axis in {axes}")
            for k, axis in enumerate(axes):
                # a fresh view of the same table per axis: independent draws, and
                # finish() checks every key of the table
                sub = Section(js.data, js.path)
                sub.string("kind")
                sub.strings("axis")
                dist = disturbance_from_config(sub, rng=_rng(seed, _STREAM_JITTER, i, k),
                                               t_start=t_start, t_end=t_end, kind=kind)
                sub.finish()
                dists.append((axis, dist))
        knowledge = KnowledgeConfig.from_section(section.section("knowledge"))
        star = StarTrackerConfig.from_section(section.section("star_tracker"))
        section.finish(extra_allowed)
        return cls(nominal=tuple(float(v) for v in nominal), disturbances=dists,
                   knowledge=knowledge, star_tracker=star, t_start=float(t_start),
                   t_end=float(t_end), seed=int(seed))

    def knowledge_series(self) -> "AttitudeSeries":
        """AOCS knowledge over the acquisition, with this model's knowledge settings."""
        k = self.knowledge
        return aocs_knowledge(self, t_start=self.t_start, t_end=self.t_end, cutoff_hz=k.cutoff_hz,
                              rate_hz=k.rate_hz, noise_urad=k.noise_urad, seed=self.seed, bias_urad=k.bias_urad,
                              drift_urad_per_s=k.drift_urad_per_s, delay_ms=k.delay_ms,
                              causal=k.filter == "causal")

    def star_tracker_series(self) -> "AttitudeSeries | None":
        """Star-tracker samples, or None when ``[attitude.star_tracker]`` is disabled."""
        s = self.star_tracker
        if not s.enabled:
            return None
        return star_tracker_samples(self, t_start=self.t_start, t_end=self.t_end,
                                    rate_hz=s.rate_hz, noise_urad=s.noise_urad, seed=self.seed)


# ---------------------------------------------------------------------------
# Sampled attitude
# ---------------------------------------------------------------------------
@dataclass
class AttitudeSeries:
    """A sampled attitude (knowledge, star tracker, restored).

    Parameters
    ----------
    time : ndarray
        Strictly increasing sample times (s).
    roll, pitch, yaw : ndarray
        Angles (rad), same length as ``time``; NaN marks a missing sample.
    """

    time: np.ndarray
    roll: np.ndarray
    pitch: np.ndarray
    yaw: np.ndarray

    def __post_init__(self):
        self.time = np.asarray(self.time, dtype=np.float64)
        if self.time.ndim != 1 or self.time.size < 1:
            raise ValueError(f"time: must be a non-empty 1-D array, got shape {self.time.shape}")
        if not np.all(np.isfinite(self.time)):
            raise ValueError("time: must be finite")
        if self.time.size > 1 and not np.all(np.diff(self.time) > 0):
            raise ValueError("time: must be strictly increasing")
        for name in AXES:
            arr = np.asarray(getattr(self, name), dtype=np.float64)
            if arr.shape != self.time.shape:
                raise ValueError(f"{name}: must have the shape of time {self.time.shape}, got {arr.shape}")
            setattr(self, name, arr)
        self._interp: dict = {}

    def __len__(self) -> int:
        return self.time.size

    def axis(self, name: str) -> np.ndarray:
        """Samples (rad) of one axis."""
        if name not in AXES:
            raise ValueError(f"axis: must be one of {', '.join(AXES)}; got {name!r}")
        return getattr(self, name)

    def _interpolator(self, name: str):
        if name not in self._interp:
            y = self.axis(name)
            ok = np.isfinite(y)
            x = self.time[ok]
            if x.size == 0:
                f = None
            elif x.size == 1:
                f = (lambda v, c=y[ok][0]: np.full(np.shape(v), c))
            elif x.size < 4:
                f = make_interp_spline(x, y[ok], k=min(3, x.size - 1) if x.size != 3 else 2)
            else:
                f = CubicSpline(x, y[ok])
            self._interp[name] = (f, ok)
        return self._interp[name]

    def at(self, t, *, outside: str = "raise") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(roll, pitch, yaw) in rad at times ``t`` (s), by cubic interpolation.

        Parameters
        ----------
        t : array_like
            Times (s).
        outside : {"raise", "nan"}, keyword-only
            Times outside ``[time[0], time[-1]]`` raise ``ValueError`` or give NaN.
            Times whose bracketing samples include a NaN give NaN.
        """
        if outside not in ("raise", "nan"):
            raise ValueError(f"outside: must be 'raise' or 'nan', got {outside!r}")
        t = _as_time(t)
        tol = 1e-9 * max(1.0, abs(self.time[-1]))
        out_of = (t < self.time[0] - tol) | (t > self.time[-1] + tol) | ~np.isfinite(t)
        if outside == "raise" and np.any(out_of):
            bad = t[out_of].ravel()[0]
            raise ValueError(f"t: {bad!r} is outside the series [{self.time[0]!r}, {self.time[-1]!r}] s")
        tc = np.clip(np.where(np.isfinite(t), t, self.time[0]), self.time[0], self.time[-1])
        if self.time.size > 1:
            i1 = np.clip(np.searchsorted(self.time, tc, side="right"), 1, self.time.size - 1)
            i0 = i1 - 1
        else:
            i0 = i1 = np.zeros(t.shape, dtype=int)
        res = []
        for name in AXES:
            f, ok = self._interpolator(name)
            if f is None:
                res.append(np.full(t.shape, np.nan))
                continue
            v = np.asarray(f(tc), dtype=np.float64)
            bad = out_of | ~ok[i0] | ~ok[i1]
            res.append(np.where(bad, np.nan, v))
        return tuple(res)  # type: ignore[return-value]

    def evaluate(self, t) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Same as :meth:`at` with ``outside="raise"`` (model-compatible)."""
        return self.at(t)


# ---------------------------------------------------------------------------
# Telemetry
# ---------------------------------------------------------------------------
def _sample_times(t_start: float, t_end: float, rate_hz: float) -> np.ndarray:
    n = int(math.floor((t_end - t_start) * rate_hz * (1 + 1e-12))) + 1
    return t_start + np.arange(n) / rate_hz


#: the AOCS knowledge's filter: a Butterworth of this order run forward and backward (zero phase), so that its
#: gain is ``1 / (1 + (f / f_c)^(2 order))`` (recorded in product.nc: a ground segment knows its AOCS filter);
#: or, ``filter = "causal"``, run forward only (gain ``1 / √(1 + (f / f_c)^(2 order))`` and a phase lag)
KNOWLEDGE_FILTER = "butterworth_zero_phase"
KNOWLEDGE_FILTER_NAMES = {"zero_phase": "butterworth_zero_phase", "causal": "butterworth_causal"}
KNOWLEDGE_FILTER_ORDER = 4


def aocs_knowledge(model: AttitudeModel, *, t_start: float, t_end: float, cutoff_hz: float = 10.0,
                   rate_hz: float = 50.0, noise_urad: float = 0.5, seed: int, bias_urad: float = 0.0,
                   drift_urad_per_s: float = 0.0, delay_ms: float = 0.0, causal: bool = False) -> AttitudeSeries:
    """Attitude knowledge from AOCS telemetry.

    The true attitude low-passed at ``cutoff_hz`` with a zero-phase filter
    (4th-order Butterworth run forward and backward: gain 1/2 at the cut-off,
    no delay), plus white Gaussian noise of ``noise_urad`` per sample and axis,
    sampled every ``1 / rate_hz`` from ``t_start`` to ``t_end``.  The truth is
    evaluated on a dense grid (fast enough not to alias the model's highest
    frequency) with margins of a few filter time constants, so there is no
    edge transient.

    How a real AOCS errs (all off by default): ``causal`` runs the Butterworth
    forward only (phase lag); ``delay_ms`` makes the sample at t describe
    t − delay; per axis a constant bias ~ N(0, ``bias_urad``) and a drift
    ~ N(0, ``drift_urad_per_s``) × (t − t_start) are added, drawn from
    ``SeedSequence([seed, 0x4B11])`` (a stream of their own: the noise stays
    the same bytes).

    Parameters
    ----------
    model : AttitudeModel
        The true attitude.
    t_start, t_end : float
        Time span (s).
    cutoff_hz, rate_hz : float, keyword-only
        Filter cut-off (Hz) and telemetry rate (Hz).
    noise_urad : float, keyword-only
        Noise standard deviation (µrad).
    seed : int, keyword-only
        Scenario seed (noise drawn from ``SeedSequence([seed, 0x4B10])``).

    Returns
    -------
    AttitudeSeries
    """
    _check_span(t_start, t_end)
    if not cutoff_hz > 0:
        raise ValueError(f"cutoff_hz: must be > 0, got {cutoff_hz}")
    if not rate_hz > 0:
        raise ValueError(f"rate_hz: must be > 0, got {rate_hz}")
    if not noise_urad >= 0:
        raise ValueError(f"noise_urad: must be >= 0, got {noise_urad}")
    for name, v in (("bias_urad", bias_urad), ("drift_urad_per_s", drift_urad_per_s), ("delay_ms", delay_ms)):
        if not (math.isfinite(v) and v >= 0):
            raise ValueError(f"{name}: must be >= 0, got {v}")
    fs = max(20.0 * cutoff_hz, 2.5 * model.max_frequency_hz, 4.0 * rate_hz)
    delay = delay_ms * 1e-3
    margin = 5.0 / cutoff_hz
    # a causal filter starts from rest: give its transient a longer lead-in
    tg = np.arange(t_start - delay - (4 if causal else 1) * margin, t_end + margin + 1.0 / fs, 1.0 / fs)
    sos = butter(KNOWLEDGE_FILTER_ORDER, cutoff_hz, fs=fs, output="sos")
    times = _sample_times(t_start, t_end, rate_hz)
    rng = _rng(seed, _STREAM_KNOWLEDGE)
    noise = rng.standard_normal((3, times.size)) * noise_urad * RAD_PER_URAD
    err = _rng(seed, _STREAM_KNOWLEDGE_ERRORS).standard_normal((3, 2)) * \
        np.array([bias_urad, drift_urad_per_s]) * RAD_PER_URAD
    vals = []
    for k, axis in enumerate(AXES):
        y = model.evaluate_axis(axis, tg)
        yf = sosfilt(sos, y) if causal else sosfiltfilt(sos, y)
        vals.append(CubicSpline(tg, yf)(times - delay) + noise[k] + err[k, 0] + err[k, 1] * (times - t_start))
    return AttitudeSeries(times, *vals)


def star_tracker_samples(model: AttitudeModel, *, t_start: float, t_end: float, rate_hz: float,
                         noise_urad: float, seed: int) -> AttitudeSeries:
    """Sparse absolute attitude samples from a star tracker.

    The true attitude at ``t_start + k / rate_hz`` plus white Gaussian noise of
    ``noise_urad`` (µrad) per sample and axis, drawn from
    ``SeedSequence([seed, 0x5374])``.

    Returns
    -------
    AttitudeSeries
    """
    _check_span(t_start, t_end)
    if not rate_hz > 0:
        raise ValueError(f"rate_hz: must be > 0, got {rate_hz}")
    if not noise_urad >= 0:
        raise ValueError(f"noise_urad: must be >= 0, got {noise_urad}")
    times = _sample_times(t_start, t_end, rate_hz)
    rng = _rng(seed, _STREAM_STAR)
    noise = rng.standard_normal((3, times.size)) * noise_urad * RAD_PER_URAD
    vals = [model.evaluate_axis(ax, times) + noise[k] for k, ax in enumerate(AXES)]
    return AttitudeSeries(times, *vals)
