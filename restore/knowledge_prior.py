"""What the AOCS knowledge already knows: a ceiling on the prior PSD of the part the images must restore.

The images restore ``e = θ − k``, the error of the AOCS knowledge ``k``. A
ground segment knows its AOCS: the knowledge is the attitude through a
low-pass of known gain ``G(f)`` (product.nc: ``knowledge_cutoff_hz``,
``knowledge_filter_order``; a zero-phase Butterworth has
``G = 1 / (1 + (f/f_c)^(2N))``), plus white noise of ``σ_k`` per sample at
``f_k``. So ``e`` has the PSD

    S_e(f) = S_θ(f) · (1 − G(f))² + σ_k² / f_k

and where ``G`` is not small the knowledge's own PSD gives ``S_θ ≈ S_k / G²``:

    S_e(f) ≤ S_k(f) · ((1 − G(f)) / G(f))² + σ_k² / f_k.

Well inside the AOCS bandwidth this ceiling is tiny: the restoration should
put (almost) nothing there. Estimated from the differentials alone, the prior
at those frequencies is poorly determined (``|e^{2πifτ} − 1|`` is small), and
an over-estimate lets slow systematic errors of the differentials (a
thousandth of a pixel) turn into record-long drifts of the estimate. Above a
few cut-offs the ceiling is infinite: the images alone decide.
"""
from __future__ import annotations

import numpy as np

__all__ = ["knowledge_gain", "knowledge_response", "knowledge_psd_ceiling", "spline_response", "knowledge_noise_floor"]

#: where the knowledge's gain is below this, the ceiling is infinite (the knowledge says nothing)
MIN_GAIN = 1e-6


def knowledge_gain(freq, cutoff_hz: float, order: int) -> np.ndarray:
    """Gain of a zero-phase Butterworth low-pass of ``order`` (run forward and backward) at ``freq`` [Hz]."""
    f = np.abs(np.asarray(freq, dtype=np.float64))
    if not cutoff_hz > 0:
        raise ValueError(f"cutoff_hz: must be > 0, got {cutoff_hz}")
    if int(order) < 1:
        raise ValueError(f"order: must be >= 1, got {order}")
    return 1.0 / (1.0 + (f / cutoff_hz) ** (2 * int(order)))


def knowledge_response(freq, cutoff_hz: float, order: int, kind: str = "butterworth_zero_phase") -> np.ndarray:
    """Complex response of the knowledge's filter at ``freq`` [Hz].

    ``butterworth_zero_phase``: :func:`knowledge_gain` (real); ``butterworth_causal``: the Butterworth run
    forward only (its analogue prototype: modulus ``1 / √(1 + (f/f_c)^(2N))`` and a phase lag);
    ``butterworth_dephased``: the causal one with its phase taken out (:mod:`restore.knowledge_dephasing`), the
    causal modulus with no phase (real).
    """
    f = np.abs(np.asarray(freq, dtype=np.float64))
    if kind == "butterworth_dephased":
        return np.abs(knowledge_response(f, cutoff_hz, order, "butterworth_causal")).astype(complex)
    if kind == "butterworth_causal":
        from scipy.signal import butter, freqs

        if not cutoff_hz > 0:
            raise ValueError(f"cutoff_hz: must be > 0, got {cutoff_hz}")
        b, a = butter(int(order), 2 * np.pi * cutoff_hz, analog=True)
        return freqs(b, a, 2 * np.pi * f)[1]
    if kind != "butterworth_zero_phase":
        raise ValueError(f"kind: unknown knowledge filter {kind!r}")
    return knowledge_gain(f, cutoff_hz, order).astype(complex)


def knowledge_psd_ceiling(knowledge, dt: float, *, cutoff_hz: float, order: int, rate_hz: float,
                          noise_rad: float, kind: str = "butterworth_zero_phase") -> tuple[np.ndarray, np.ndarray]:
    """Ceiling on the two-sided PSD of the knowledge's error, from the knowledge series itself.

    Parameters
    ----------
    knowledge : ndarray (N,)
        AOCS knowledge of one axis at the line times [rad].
    dt : float
        Line period [s].
    cutoff_hz, order : float, int
        The knowledge's low-pass (Butterworth).
    rate_hz, noise_rad : float
        Telemetry rate [Hz] and white noise per sample [rad].
    kind : str
        The filter as ``product.nc`` records it (:func:`knowledge_response`).

    Returns
    -------
    (freq, ceiling)
        One-sided grid [Hz] and the ceiling [rad²/Hz] (``inf`` where the
        knowledge is blind).
    """
    k = np.asarray(knowledge, dtype=np.float64)
    n = k.size
    f = np.fft.rfftfreq(n, dt)
    if n < 8 or not np.all(np.isfinite(k)):
        return f, np.full(f.size, np.inf)
    t = np.arange(n, dtype=np.float64) / n
    x = k - np.polyval(np.polyfit(t, k, 2), t)  # a slow drift would leak into every bin of the periodogram
    w = np.hanning(n)
    s_k = np.abs(np.fft.rfft(x * w)) ** 2 * dt / np.sum(w ** 2)
    # smoothed over a few bins: the ceiling must not dip between the lines of a line spectrum
    s_k = np.convolve(np.pad(s_k, 2, mode="edge"), np.ones(5) / 5, mode="valid")
    g = knowledge_response(f, cutoff_hz, order, kind)
    with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
        ceiling = s_k * np.abs((1.0 - g) / g) ** 2 + noise_rad ** 2 / max(rate_hz, 1e-300)
    return f, np.where(np.abs(g) > MIN_GAIN, ceiling, np.inf)


def spline_response(freq, rate_hz: float) -> np.ndarray:
    """Frequency response of cubic-spline interpolation of samples taken at ``rate_hz`` (the cardinal cubic
    spline: ``sinc⁴(f/f_s) / (2/3 + cos(2π f/f_s)/3)``; 1 at 0 Hz), at ``freq`` [Hz]."""
    if not rate_hz > 0:
        raise ValueError(f"rate_hz: must be > 0, got {rate_hz}")
    x = np.abs(np.asarray(freq, dtype=np.float64)) / float(rate_hz)
    return np.sinc(x) ** 4 / (2.0 / 3.0 + np.cos(2 * np.pi * x) / 3.0)


def knowledge_noise_floor(freq, *, rate_hz: float, noise_rad: float) -> np.ndarray:
    """Floor on the two-sided PSD of the knowledge's error [rad²/Hz], from its own white noise alone.

    The knowledge is the attitude low-passed plus white noise of ``noise_rad``
    per sample at ``rate_hz``, spline-interpolated to the lines: whatever the
    attitude does, its error ``e = θ − k`` holds that noise, independent of
    the attitude, so its PSD is at least ``σ_k² / f_k · |H(f)|²`` below
    ``f_k / 2`` (``H``: :func:`spline_response`; the aliases only add to it).
    Zero above ``f_k / 2``.
    """
    if not noise_rad >= 0:
        raise ValueError(f"noise_rad: must be >= 0, got {noise_rad}")
    f = np.abs(np.asarray(freq, dtype=np.float64))
    floor = noise_rad ** 2 / rate_hz * spline_response(f, rate_hz) ** 2
    return np.where(f <= 0.5 * rate_hz, floor, 0.0)
