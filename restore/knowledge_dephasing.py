"""A causal AOCS knowledge with its filter's phase taken out: the lag gone, the knowledge a zero-phase one.

A ground segment knows its AOCS filter (product.nc records it). When that
filter runs forward only (``butterworth_causal``: a 4th-order Butterworth), the
knowledge ``k = F θ + n`` lags the attitude by the filter's group delay,
``2.61 / (2π f_c)`` at low frequencies (0.10 s at a 4 Hz cut-off: 30° at a
0.8 Hz high-pass). The restoration takes the knowledge for the attitude below
its high-pass, and predicts matches, bounds its prior and fuses bands with it:
every one of those assumes a zero-phase knowledge.

The phase is known, so it can be taken out without amplifying anything: the
all-pass ``e^{−i arg F(f)}`` applied to the samples leaves the noise's power
where it was and turns the knowledge into ``|F| θ + n′``, a zero-phase filter of
gain ``|F|`` (:func:`restore.knowledge_prior.knowledge_response` kind
``butterworth_dephased``). An all-pass is not causal: near the record's end it
needs the knowledge of the next group delay, which does not exist. The samples
are extended at both ends over a few filter time constants: for the first
:data:`PREDICTION_SPAN_S` by linear prediction (:func:`predicted_tail`, an
autoregression fitted on the record, backwards at the start), then by their
point reflection (``2 k(T) − k(2T − t)``, which continues the record's slope:
exact for a trend, but a 2.2 Hz line continued as a straight line was 1.7 of its
amplitude wrong over the last 0.1 s); a straight line through the extension's
two ends is taken out so that the periodic FFT sees no jump, and added back
advanced by the group delay at zero frequency (what the all-pass does to a line).

What stays is the latency (``delay_ms``: not recorded, so not known) and the
prediction's error over the record's last group delay.
"""
from __future__ import annotations

import numpy as np

__all__ = ["DEPHASED_KIND", "DEPHASABLE_KINDS", "EXTENSION_TIME_CONSTANTS", "PREDICTION_SPAN_S",
           "PREDICTION_MEMORY_PERIODS", "PREDICTION_SAMPLES_PER_ORDER", "PREDICTION_RANGE", "group_delay_at_zero",
           "prediction_memory_s", "predicted_tail", "stable_coefficients",
           "dephase_samples", "advance_samples"]

#: the kind product.nc's ``knowledge_filter`` reads once the knowledge is dephased
DEPHASED_KIND = "butterworth_dephased"
#: the recorded filters whose phase :func:`dephase_samples` takes out, and the kind each becomes
DEPHASABLE_KINDS = {"butterworth_causal": DEPHASED_KIND}
#: the extension at each end, in time constants ``1 / f_c`` of the filter (the all-pass's response has
#: decayed to under 1e-3 of its peak by 8 of them for a 4th-order Butterworth)
EXTENSION_TIME_CONSTANTS = 8.0
#: the record's end is extended by linear prediction over this long [s] (then blended into the reflection over as
#: long again): the all-pass needs the knowledge of the next group delay, and a reflection continues a 2.2 Hz line
#: as a straight line (on a causal 4 Hz knowledge the same operations redone on the record cut 0.15–0.8 s short
#: differed from the whole record's by 1.6 px over the cut's last 20 ms, by 0.4–0.6 px with the prediction)
PREDICTION_SPAN_S = 0.5
#: the prediction's autoregression remembers this many periods of the knowledge's cut-off, or as many of them as
#: the record holds (:func:`predicted_tail`). Over 30 draws each of five attitude kinds (lines at 2.2 / 5.5 / 9 Hz,
#: lines at 3–8 Hz, a damped chirp, CMG lines far above the knowledge, broadband jitter) under a causal 2, 4 and
#: 8 Hz knowledge 15 ms late (`simsat bench knowledge`, :mod:`reports.bench_knowledge`), one period unstabilised
#: (the first choice) left 0.013–0.060 px RMS below 1 Hz in the
#: advanced knowledge, four periods stabilised 0.013–0.040: the two kinds of lines under a 4 Hz knowledge
#: 0.049 → 0.019 and 0.060 → 0.018, under 8 Hz 0.041 → 0.015 and 0.033 → 0.014, the chirp under 4 Hz 0.020 → 0.016,
#: the rest within ± 0.003 (broadband under 8 Hz 0.019 → 0.023). Orders
#: chosen by Akaike's criterion (one-step errors) were worse under a 2 Hz knowledge (lines 0.024 → 0.040)
PREDICTION_MEMORY_PERIODS = 4.0
#: the prediction needs at least this many samples per order of its autoregression
PREDICTION_SAMPLES_PER_ORDER = 3
#: a prediction that leaves the record's range (less its line) by more than this factor is not used
PREDICTION_RANGE = 3.0


def _phase(freq, cutoff_hz: float, order: int, kind: str) -> np.ndarray:
    from .knowledge_prior import knowledge_response

    return np.angle(knowledge_response(freq, cutoff_hz, order, kind))


def group_delay_at_zero(cutoff_hz: float, order: int, kind: str = "butterworth_causal") -> float:
    """The filter's group delay at zero frequency [s] (``−d arg F / dω``; 0 for a zero-phase filter).

    Examples
    --------
    >>> round(group_delay_at_zero(4.0, 4), 4)   # 2.6131 / (2π · 4 Hz)
    0.104
    """
    f0 = 1e-4 * float(cutoff_hz)
    return float(-_phase(np.array([f0]), cutoff_hz, order, kind)[0] / (2 * np.pi * f0))


def dephase_samples(values, dt: float, *, cutoff_hz: float, order: int,
                    kind: str = "butterworth_causal", predicted_ends: bool = True) -> np.ndarray:
    """The knowledge samples through the all-pass ``e^{−i arg F}`` of their recorded filter.

    Parameters
    ----------
    values : ndarray (n,)
        Knowledge samples of one axis on a regular grid [rad]; NaN marks a missing sample (bridged linearly
        for the filtering, NaN again in the result).
    dt : float
        Sampling interval [s].
    cutoff_hz, order, kind
        The knowledge's filter as product.nc records it (a kind of :data:`DEPHASABLE_KINDS`).
    predicted_ends : bool
        Extend the record by linear prediction before the reflection (the restoration's ends); False: the
        point reflection alone (what :mod:`reports.bench_knowledge` compares it with).

    Returns
    -------
    ndarray (n,)
        ``|F| θ`` plus the noise, all-passed [rad]: the lag gone but over the record's last group delay.

    Examples
    --------
    A slow sine lagged by a causal 4 Hz filter comes back in phase:

    >>> from scipy.signal import butter, sosfilt
    >>> dt = 1 / 64; t = np.arange(-4, 2, dt); x = np.sin(2 * np.pi * 0.5 * t)
    >>> k = sosfilt(butter(4, 4.0, fs=1 / dt, output="sos"), x)[t >= 0]
    >>> d = dephase_samples(k, dt, cutoff_hz=4.0, order=4)
    >>> bool(np.max(np.abs(k - x[t >= 0])) > 0.3), bool(np.max(np.abs(d - x[t >= 0])[:96]) < 0.01)
    (True, True)
    """
    if kind not in DEPHASABLE_KINDS:
        raise ValueError(f"kind: {kind!r} has no phase to take out (known: {sorted(DEPHASABLE_KINDS)})")
    if not (dt > 0 and cutoff_hz > 0):
        raise ValueError(f"dt and cutoff_hz must be > 0, got {dt}, {cutoff_hz}")
    return _all_passed(values, dt, lambda f: -_phase(f, cutoff_hz, order, kind),
                       group_delay_at_zero(cutoff_hz, order, kind), EXTENSION_TIME_CONSTANTS / cutoff_hz,
                       memory_s=prediction_memory_s(cutoff_hz) if predicted_ends else None)


def prediction_memory_s(cutoff_hz: float) -> float:
    """The linear prediction's memory for a knowledge filtered at ``cutoff_hz`` [s]:
    :data:`PREDICTION_MEMORY_PERIODS` periods of its cut-off."""
    return PREDICTION_MEMORY_PERIODS / float(cutoff_hz)


def advance_samples(values, dt: float, advance_s: float, *, extension_s: float | None = None,
                    memory_s: float | None = None) -> np.ndarray:
    """The samples advanced in time by ``advance_s`` [s] (``x(t + advance_s)``; a negative value delays them):
    the all-pass ``e^{i 2π f advance_s}`` with the same ends as :func:`dephase_samples` (point reflection over
    ``extension_s``, by default 2 s or 4 × the advance, whichever is longer; with ``memory_s``, linear prediction
    of that memory over its first :data:`PREDICTION_SPAN_S`). Used to take a latency the images measured out of
    the knowledge (:mod:`restore.knowledge_timing`; :func:`restore.stages.advanced_knowledge` gives one cut-off
    period as the memory).

    Examples
    --------
    >>> t = np.arange(0, 2, 1 / 64); x = np.sin(2 * np.pi * 1.5 * t)
    >>> y = advance_samples(x, 1 / 64, 0.02)
    >>> bool(np.max(np.abs(y - np.sin(2 * np.pi * 1.5 * (t + 0.02)))[:100]) < 1e-3)
    True
    """
    if not dt > 0:
        raise ValueError(f"dt must be > 0, got {dt}")
    ext = max(2.0, 4.0 * abs(advance_s)) if extension_s is None else float(extension_s)
    return _all_passed(values, dt, lambda f: 2 * np.pi * f * advance_s, advance_s, ext, memory_s=memory_s)


def predicted_tail(x, m: int, order: int, valid=None) -> np.ndarray | None:
    """``m`` samples past the end of ``x`` by linear prediction: a least-squares autoregression of ``order`` on
    ``x`` less its straight line (fitted on the stretches of ``order + 1`` samples that are all ``valid``: a gap
    bridged by a straight line is no sample of the process), stabilised (:func:`stable_coefficients`), run forward,
    the line continued. The order is lowered as far as the record needs to hold it
    (:data:`PREDICTION_SAMPLES_PER_ORDER` samples per order, as many complete rows less one per order). None when
    no order is held or the prediction leaves the record's range by more than :data:`PREDICTION_RANGE` ×.

    Examples
    --------
    A line at 2.2 Hz on a bias and a drift, sampled at 64 Hz, is predicted a quarter of a second on:

    >>> t = np.arange(0, 1.6, 1 / 64); x = np.sin(2 * np.pi * 2.2 * t + 0.3) + 3 + 2 * t
    >>> after = t[-1] + np.arange(1, 17) / 64
    >>> tail = predicted_tail(x, 16, 16)
    >>> bool(np.max(np.abs(tail - (np.sin(2 * np.pi * 2.2 * after + 0.3) + 3 + 2 * after))) < 1e-9)
    True
    """
    x = np.asarray(x, dtype=np.float64)
    n = x.size
    p = _order_held(n, int(order), valid)
    if p < 1 or m < 1:
        return None
    u = np.arange(n, dtype=np.float64)
    line = np.polyfit(u, x, 1)
    r = x - np.polyval(line, u)
    lagged = np.lib.stride_tricks.sliding_window_view(r[:-1], p)          # rows r[k..k+p-1] -> r[k+p]
    rows = _complete_rows(n, p, valid)
    coef = stable_coefficients(np.linalg.lstsq(lagged[rows], r[p:][rows], rcond=None)[0])
    buf = np.concatenate([r[-p:], np.zeros(m)])
    for k in range(m):
        buf[p + k] = float(np.dot(coef, buf[k:k + p]))
    out = buf[p:]
    if not np.all(np.isfinite(out)) or np.max(np.abs(out)) > PREDICTION_RANGE * max(np.max(np.abs(r)), 1e-300):
        return None
    return out + np.polyval(line, np.arange(n, n + m, dtype=np.float64))


def _complete_rows(n: int, p: int, valid) -> np.ndarray:
    """Which of the ``n − p`` regression rows (``p`` samples and the next) are all valid samples."""
    if valid is None:
        return np.ones(n - p, dtype=bool)
    return np.lib.stride_tricks.sliding_window_view(np.asarray(valid, dtype=bool), p + 1).all(axis=1)


def _order_held(n: int, order: int, valid) -> int:
    """The largest order up to ``order`` that ``n`` samples hold at :data:`PREDICTION_SAMPLES_PER_ORDER` per order,
    with complete rows enough for it (a gap removes ``p + 1`` rows); 0 if none."""
    for p in range(min(int(order), n // PREDICTION_SAMPLES_PER_ORDER), 0, -1):
        if np.count_nonzero(_complete_rows(n, p, valid)) >= (PREDICTION_SAMPLES_PER_ORDER - 1) * p:
            return p
    return 0


def stable_coefficients(coef) -> np.ndarray:
    """An autoregression's coefficients (``coef[k]`` multiplies ``x[t − p + k]`` in ``x[t]``) with the roots of its
    characteristic polynomial that lie outside the unit circle reflected into it (``z → 1 / z̄``): the same
    spectral shape, but a prediction that decays instead of growing. A least-squares fit of a long order on a short
    record often has such a root (over 40 draws of lines under a causal 4 Hz knowledge, an order of 36 left
    0.15 px of error in a few; stabilised, at most 0.04).

    Examples
    --------
    >>> stable_coefficients([-1.0, 2.5])      # x[t] = 2.5 x[t−1] − x[t−2]: roots 2 and 1/2, 2 reflected to 1/2
    array([-0.25,  1.  ])
    """
    c = np.asarray(coef, dtype=np.float64)
    roots = np.roots(np.concatenate([[1.0], -c[::-1]]))
    out = np.abs(roots) > 1.0 + 1e-6       # not a root on the circle (a line's double root at 1 splits by ~1e-8)
    if not out.any():
        return c
    roots[out] = 1.0 / np.conj(roots[out])
    return -np.real(np.poly(roots))[1:][::-1]


def _all_passed(values, dt: float, rotation, line_advance_s: float, extension_s: float,
                memory_s: float | None = None) -> np.ndarray:
    """``values`` through ``e^{i rotation(f)}`` on their extension (module docstring): point-reflected at both
    ends; with ``memory_s``, predicted instead (:func:`predicted_tail`, order ``memory_s / dt``; backwards at the
    start) over :data:`PREDICTION_SPAN_S` and blended into the reflection over as long again. The line through the
    extension's ends is taken out first and put back advanced by ``line_advance_s``."""
    v = np.asarray(values, dtype=np.float64)
    n = v.size
    ok = np.isfinite(v)
    if n < 3 or np.count_nonzero(ok) < 2:
        return v.copy()
    i = np.arange(n)
    x = np.where(ok, v, np.interp(i, i[ok], v[ok]))
    m = int(min(n - 1, np.ceil(extension_s / dt)))
    head = 2 * x[0] - x[m:0:-1]
    tail = 2 * x[-1] - x[-2:-m - 2:-1]
    if memory_s is not None and memory_s > 0:
        order = int(round(memory_s / dt))
        w = np.clip(2.0 - np.arange(1, m + 1) * dt / PREDICTION_SPAN_S, 0.0, 1.0)
        pred = predicted_tail(x, m, order, valid=ok)
        if pred is not None:
            tail = w * pred + (1.0 - w) * tail
        pred = predicted_tail(x[::-1], m, order, valid=ok[::-1])       # the start, predicted backwards
        if pred is not None:
            head = (w * pred + (1.0 - w) * head[::-1])[::-1]
    xe = np.concatenate([head, x, tail])
    ne = xe.size
    te = (np.arange(ne) - m) * dt
    slope = (xe[-1] - xe[0]) / (te[-1] - te[0])
    line = xe[0] + slope * (te - te[0])
    f = np.fft.rfftfreq(ne, dt)
    rotated = np.fft.irfft(np.fft.rfft(xe - line) * np.exp(1j * rotation(f)), ne)
    out = (rotated + line + slope * line_advance_s)[m:m + n]
    return np.where(ok, out, np.nan)
