"""The line's exposure, undone: the images see the attitude averaged over each line's integration time.

A push-broom line integrates the ground over its exposure, which simsat's
products take to be the line period ``T`` (centred on the line time, as the
renderer samples it; :mod:`simsat.render.pushbroom`). The image of a line is
therefore displaced by the attitude *averaged* over ``[t − T/2, t + T/2]``:
the box's gain ``sinc(f T)`` on the attitude, 0.994 at 150 Hz with phr_cmg's
0.4 ms. The differentials measure that average, the integration restores it,
and the restored angle falls short of the instantaneous attitude by
``(1 − sinc(f T)) θ``: a gain error proportional to the vibration's amplitude
(−0.3 to −0.6 % measured on the CMG lines, 40–160 Hz, of phr_cmg and of the
stress suite's large_amplitude, where 2.7 px make it 0.015 px).

:func:`exposure_deconvolution` multiplies the estimate by the inverse gain to
second order, ``1 / sinc(f T) ≈ 1 + (π f T)² / 6``, as a three-tap filter on
the estimate's grid of step ``Δt``: ``x − (T² / (24 Δt²)) Δ²x``, whose gain
``1 + (T² / (6 Δt²)) sin²(π f Δt)`` leaves, for ``Δt = T``, a gain error of
``(3/40) (π f T)⁴`` (1e-4 at 150 Hz, against the box's 6e-3) and stays ≤ 1.17 up to the line rate's Nyquist
frequency (the exact inverse reaches 1.57 there, amplifying noise the
attitude does not have).
"""
from __future__ import annotations

import numpy as np

__all__ = ["exposure_gain", "exposure_deconvolution"]


def exposure_gain(freq, exposure_s: float) -> np.ndarray:
    """Gain of a centred box exposure of ``exposure_s`` on an attitude at ``freq`` [Hz]: ``sinc(f T)``."""
    return np.sinc(np.asarray(freq, dtype=np.float64) * float(exposure_s))


def exposure_deconvolution(x, *, dt: float, exposure_s: float) -> np.ndarray:
    """``x − (T² / (24 Δt²)) Δ²x``: the estimate on a grid of step ``dt`` with its exposure's box undone to
    second order (module docstring). A sample whose neighbour is missing (NaN, a record end) is kept as is.

    Parameters
    ----------
    x : array_like (n,)
        Estimate [rad], NaN where not estimated.
    dt : float
        Grid step [s].
    exposure_s : float
        Exposure (integration time) of each sample [s]; 0 leaves ``x`` unchanged.
    """
    v = np.asarray(x, dtype=np.float64)
    if not dt > 0:
        raise ValueError(f"dt: must be > 0, got {dt}")
    if not exposure_s >= 0:
        raise ValueError(f"exposure_s: must be >= 0, got {exposure_s}")
    out = v.copy()
    if exposure_s == 0 or v.size < 3:
        return out
    lap = v[2:] - 2.0 * v[1:-1] + v[:-2]
    k = exposure_s ** 2 / (24.0 * dt ** 2)
    ok = np.isfinite(lap)
    out[1:-1] = np.where(ok, v[1:-1] - k * np.where(ok, lap, 0.0), v[1:-1])
    return out
