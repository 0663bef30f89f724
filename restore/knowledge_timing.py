"""The AOCS knowledge's latency, measured by the images: a time-tag offset between the knowledge and the lines.

A real AOCS knowledge may describe the attitude a little before its time tag
says (``k(t) = θ(t − δ)`` through its filter: on-board time-tagging, a
telemetry pipeline's delay). Nothing in product.nc says so, and the
restoration takes the knowledge for the attitude wherever the knowledge is
good: below its high-pass, in the prior's ceiling, in the conditioning and the
fusion. A latency of 15 ms under a 2.2 Hz line of 1 px is 0.2 px of knowledge
error in a band the ceiling calls known to 1 %: the prior then shrinks the
images' estimate there toward the knowledge.

The images see the same attitude at their own times, and where both see it
(above the high-pass, below the frequency where the knowledge's filter passes
less than :data:`MIN_GAIN`) the attitude the knowledge misses is, to first
order, ``θ − k ≈ δ k'``. Each pair's differentials of ``θ − k`` — the
remaining differentials the integration was given plus those of the estimate
it started from, ``y = D + Δ_τ(previous)``, less what the integration's own estimate of it explains outside the band
(the differentials of a 9 Hz line, bridged over a gap, would put power in it) — are regressed on the same
differentials of the knowledge's derivative in that band,
``x = Δ_τ(BP(k'))``, ``y`` band-limited the same way (the pairs' differentials of what the knowledge misses
above its band are far larger and would leak in over a short record): weighted least squares, the
weights ``1/σ²`` under a Tukey taper (:data:`TAPER`), ``δ = Σ w x y / Σ w x²``, a
Gauss–Newton step repeated with the knowledge advanced by the estimate so far
(:data:`ITERATIONS`). Its uncertainty is the larger of a delete-one-block jackknife over
:data:`BLOCKS` stretches of the record and the spread the residuals' spectrum gives it
(:func:`spectral_sigma`): band-limited series a few hertz wide over 1.6 s are correlated
from one stretch to the next, and the jackknife alone was about 2.8 × too small (each axis's own
estimate, compared with the joint one, keeps the jackknife). Where the attitude has no power in the band, ``x`` is small
and δ is not measured — but then a latency costs nothing either.

It is taken out (:func:`restore.knowledge_dephasing.advance_samples`) where
the knowledge's derivative in the band is the attitude's, not its white noise's
(:data:`MIN_SIGNAL_TO_NOISE`), within the first-order model's reach
(:data:`MAX_PHASE_RAD` at the band's top) and the same on every axis
(:data:`AXES_AGREE_SIGMAS`) — shrunk by its σ, not all or nothing: the
advance is the estimate's empirical-Bayes posterior mean, ``δ (1 − σ²/δ²)``
and nothing within one σ of zero (:attr:`LatencyEstimate.applied_s`; the
positive-part James–Stein rule for one estimate). A threshold errs most where a
true latency sits near it: causal_knowledge's 15 ms came out 13.7 ± 4.0 ms on
one draw of the knowledge's noise (taken at 3 σ) and 12.2 ± 4.6 ms on another
(not taken, the whole 15 ms left in the knowledge: 0.046 → 0.093 px of pitch
error). The shrunk estimate's mean square error is at most 1.5 σ² whatever the
latency (at 2.5 σ; a 3 σ threshold's reaches 5 σ² at 3 σ), for 0.34 σ² with no
latency at all (the threshold's 0.03 σ²: a small advance taken on a third of
latency-free records).
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

__all__ = ["LatencyEstimate", "latency_band", "knowledge_latency", "MIN_GAIN", "BLOCKS", "ITERATIONS",
           "MIN_SIGNAL_TO_NOISE", "MAX_PHASE_RAD", "SMOOTH_BINS", "spectral_sigma",
           "AXES_AGREE_SIGMAS"]

#: the band ends where the knowledge's filter passes less than this of the attitude
MIN_GAIN = 0.9
#: stretches of the record the jackknife leaves out one at a time
BLOCKS = 8
#: Gauss–Newton steps (each with the knowledge advanced by the estimate so far)
ITERATIONS = 3
#: the knowledge's derivative in the band must hold at least this many times the power its white noise puts
#: there: where it is the noise's (phr_cmg: 1.3–1.6 ×, its attitude nothing between 2 and 7.6 Hz), the regression
#: measures how the noise correlates with itself through the pairs, not a latency (−5.1 ± 1.0 ms there)
MIN_SIGNAL_TO_NOISE = 4.0
#: the Gauss–Newton steps reach this phase at the band's top [rad]: a larger estimate is not a
#: latency the model can measure (low_frequencies' 2 Hz knowledge, lines at 3.3–7.7 Hz above its 0.4–1.6 Hz band:
#: 765 ± 143 ms, its restored angle 0.030 / 0.039 → 0.142 / 0.169 px once taken)
MAX_PHASE_RAD = 1.0
#: each axis's own estimate must lie within this many of its σ from the joint one
AXES_AGREE_SIGMAS = 3.0
#: the regression's weights fall to zero over this fraction of the record at its ends (a Tukey window: the
#: band-limited series leak least there)
TAPER = 0.2
#: the residuals' cross-spectrum is averaged over the in-band bins within this many of each (:func:`spectral_sigma`)
SMOOTH_BINS = 3


@dataclass(frozen=True)
class LatencyEstimate:
    """The knowledge's latency as the images measure it: ``delay_s`` (the knowledge at t describes t −
    delay_s), ``sigma_s`` (the larger of the jackknife and :func:`spectral_sigma`), the band [Hz] and the axes it was measured on."""

    delay_s: float
    sigma_s: float
    band_hz: tuple
    axes: tuple
    #: the power of the knowledge's derivative in the band over what its own white noise puts there (inf when
    #: the noise is not given)
    signal_to_noise: float = float("inf")
    #: each axis's own estimate and its jackknife σ [s]: ``{axis: (delay, sigma)}`` (a time tag is late on every
    #: axis alike)
    axis_delays_s: dict | None = None

    @property
    def max_delay_s(self) -> float:
        """The largest latency the first-order model holds: :data:`MAX_PHASE_RAD` at the band's top [s]."""
        return MAX_PHASE_RAD / (2 * np.pi * float(self.band_hz[1]))

    @property
    def axes_agree(self) -> bool:
        """Every axis's own estimate within :data:`AXES_AGREE_SIGMAS` of its σ from the joint one."""
        return all(abs(d - self.delay_s) <= AXES_AGREE_SIGMAS * sg for d, sg in (self.axis_delays_s or {}).values())

    @property
    def measured(self) -> bool:
        """A latency the regression can measure: on an attitude, not on the knowledge's noise
        (:data:`MIN_SIGNAL_TO_NOISE`), within the model's reach (:attr:`max_delay_s`), the same on every axis
        (:attr:`axes_agree`), with a finite σ."""
        return bool(np.isfinite(self.delay_s) and np.isfinite(self.sigma_s) and self.sigma_s > 0
                    and self.signal_to_noise >= MIN_SIGNAL_TO_NOISE
                    and abs(self.delay_s) <= self.max_delay_s and self.axes_agree)

    @property
    def shrinkage(self) -> float:
        """The share of the estimate taken out: ``1 − σ²/δ²``, 0 within one σ of zero or where not
        :attr:`measured` (the posterior mean under a zero-mean Gaussian prior whose variance the estimate itself
        gives, ``max(0, δ² − σ²)``: module docstring)."""
        if not self.measured or not abs(self.delay_s) > self.sigma_s:
            return 0.0
        return float(1.0 - (self.sigma_s / self.delay_s) ** 2)

    @property
    def applied_s(self) -> float:
        """The advance taken out of the knowledge [s]: ``shrinkage × delay_s``."""
        return self.shrinkage * float(self.delay_s)

    @property
    def taken(self) -> bool:
        """Whether the knowledge is advanced at all (:attr:`applied_s` not 0)."""
        return self.applied_s != 0.0

    def to_dict(self) -> dict:
        d = asdict(self)
        d["band_hz"] = list(self.band_hz)
        d["axes"] = list(self.axes)
        d["axis_delays_s"] = {a: list(v) for a, v in (self.axis_delays_s or {}).items()}
        d["measured"] = self.measured
        d["shrinkage"] = self.shrinkage
        d["applied_s"] = self.applied_s
        d["taken"] = self.taken
        return d


def latency_band(highpass_hz: float, gain, *, top_hz: float) -> tuple[float, float] | None:
    """``(lo, hi)`` [Hz]: from the high-pass to where ``gain(f)`` (the knowledge filter's modulus) falls below
    :data:`MIN_GAIN`; None when that leaves less than an octave's fifth (``hi < 1.15 lo``)."""
    f = np.linspace(0.0, float(top_hz), 4001)
    below = np.nonzero(np.abs(np.asarray(gain(f))) < MIN_GAIN)[0]
    hi = float(top_hz)
    if below.size:
        fine = np.linspace(f[max(below[0] - 1, 0)], f[below[0]], 1001)
        hi = float(fine[np.nonzero(np.abs(np.asarray(gain(fine))) < MIN_GAIN)[0][0]])
    lo = float(highpass_hz)
    return (lo, hi) if lo > 0 and hi >= 1.15 * lo else None


def _band_derivative(k: np.ndarray, dt: float, band) -> np.ndarray:
    """``d/dt`` of ``k`` band-limited to ``band`` (:func:`_band_filtered`)."""
    return _band_filtered(k, dt, band, derivative=True)


def _band_filtered(y: np.ndarray, dt: float, band, *, derivative: bool = False) -> np.ndarray:
    """``y`` (or its derivative) band-limited to ``band`` by FFT of the record extended by its mirror image."""
    n = y.size
    f = np.fft.rfftfreq(2 * n, dt)
    gain = ((f >= band[0]) & (f <= band[1])) * ((2j * np.pi * f) if derivative else 1.0)
    return np.fft.irfft(np.fft.rfft(np.concatenate([y, y[::-1]])) * gain, 2 * n)[:n]


def _band_passed(y: np.ndarray, dt: float, band) -> np.ndarray:
    """``y`` band-limited to ``band`` (gaps bridged linearly for the FFT, NaN again after)."""
    n = y.size
    ok = np.isfinite(y)
    if np.count_nonzero(ok) < 2:
        return np.full(n, np.nan)
    i = np.arange(n)
    return np.where(ok, _band_filtered(np.where(ok, y, np.interp(i, i[ok], y[ok])), dt, band), np.nan)


def _differential(series: np.ndarray, tau: float, dt: float, lag) -> np.ndarray:
    from .method_choice import predicted_differential

    return predicted_differential(series, tau, dt, lag)


def _sums(ys, xs, ws, edges):
    """Per block: Σ w x y and Σ w x² (over pairs and axes)."""
    sxy = np.zeros(len(edges) - 1)
    sxx = np.zeros(len(edges) - 1)
    for y, x, w in zip(ys, xs, ws):
        ok = np.isfinite(y) & np.isfinite(x) & (w > 0)
        wy, wx = np.where(ok, w * x * y, 0.0), np.where(ok, w * x * x, 0.0)
        for b in range(len(edges) - 1):
            sxy[b] += wy[edges[b]:edges[b + 1]].sum()
            sxx[b] += wx[edges[b]:edges[b + 1]].sum()
    return sxy, sxx


def knowledge_latency(records: dict, knowledge: dict, band, *, noise_psd=None) -> LatencyEstimate | None:
    """The knowledge's latency from the differentials of ``records`` (module docstring).

    Parameters
    ----------
    records : dict
        ``{axis: IntegrationRecord}`` of the restored axes (their remaining differentials, σ, delays, lags,
        line period and the estimate they started from).
    knowledge : dict
        ``{axis: (line,)}``: the knowledge the records' differentials remain from [rad].
    band : (float, float)
        Where both the images and the knowledge see the attitude [Hz] (:func:`latency_band`).
    noise_psd : callable, optional
        ``f [Hz] -> two-sided PSD [rad²/Hz]`` of the knowledge's white noise at the lines
        (:func:`restore.knowledge_prior.knowledge_noise_floor`): sets ``signal_to_noise``.

    Returns
    -------
    LatencyEstimate or None
        None without a record, a band, or any weight in it.
    """
    from .knowledge_dephasing import advance_samples

    axes = tuple(a for a in sorted(records) if a in knowledge)
    if not axes or band is None:
        return None
    dt = float(records[axes[0]].line_period_s)
    n = np.asarray(knowledge[axes[0]]).size
    from scipy.signal.windows import tukey

    taper = tukey(n, TAPER)
    ys0, lay = [], []
    for a in axes:
        rec = records[a]
        prev = np.nan_to_num(np.asarray(rec.previous, dtype=np.float64)) if rec.previous is not None else np.zeros(n)
        inc = np.nan_to_num(np.asarray(rec.increment, dtype=np.float64)) if rec.increment is not None \
            else np.zeros(n)
        # what the integration explained out of the band is taken out of the differentials before they are
        # band-limited: bridging a gap of a 9 Hz line's differentials puts power in the band
        explained = _band_passed(prev + inc, dt, band)
        for j in range(len(rec.taus)):
            lag = rec.lags_s[j] if rec.lags_s is not None else None
            s = np.asarray(rec.sigmas[j], dtype=np.float64)
            w = np.where(np.isfinite(s) & (s > 0), 1.0 / np.where(s > 0, s, 1.0) ** 2, 0.0) * taper
            ys0.append(np.asarray(rec.diffs[j], dtype=np.float64) - _differential(inc, rec.taus[j], dt, lag)
                       + _differential(explained, rec.taus[j], dt, lag))
            lay.append((a, float(rec.taus[j]), lag, w))
    edges = np.linspace(0, n, BLOCKS + 1).astype(int)
    delay, sxy, sxx = 0.0, None, None
    for _ in range(ITERATIONS):
        shifted = {a: advance_samples(np.asarray(knowledge[a], dtype=np.float64), dt, delay) if delay else
                   np.asarray(knowledge[a], dtype=np.float64) for a in axes}
        ys, xs, ws = [], [], []
        for y0, (a, tau, lag, w) in zip(ys0, lay):
            moved = shifted[a] - np.asarray(knowledge[a], dtype=np.float64)
            ys.append(_band_passed(y0 - _differential(moved, tau, dt, lag) if delay else y0, dt, band))
            xs.append(_differential(_band_derivative(shifted[a], dt, band), tau, dt, lag))
            ws.append(w)
        sxy, sxx = _sums(ys, xs, ws, edges)
        if not sxx.sum() > 0:
            return None
        delay += float(sxy.sum() / sxx.sum())
    step = float(sxy.sum() / sxx.sum())
    sigma = max(_jackknife(sxy, sxx), spectral_sigma(ys, xs, ws, step, dt, band))
    per_axis = {}
    if len(axes) > 1:
        for a in axes:
            mine = [i for i, item in enumerate(lay) if item[0] == a]
            axy, axx = _sums([ys[i] for i in mine], [xs[i] for i in mine], [ws[i] for i in mine], edges)
            if axx.sum() > 0:
                per_axis[a] = (delay - step + float(axy.sum() / axx.sum()), _jackknife(axy, axx))
    snr = float("inf")
    if noise_psd is not None:
        f = np.linspace(float(band[0]), float(band[1]), 2001)
        noise = 2.0 * np.trapezoid(np.asarray(noise_psd(f)) * (2 * np.pi * f) ** 2, f)
        power = np.mean([np.mean(_band_derivative(np.asarray(knowledge[a], dtype=np.float64), dt, band) ** 2)
                         for a in axes])
        snr = float(power / noise) if noise > 0 else float("inf")
    return LatencyEstimate(delay_s=delay, sigma_s=sigma, band_hz=(float(band[0]), float(band[1])), axes=axes,
                           signal_to_noise=snr, axis_delays_s=per_axis or None)


def spectral_sigma(ys, xs, ws, step: float, dt: float, band, *, half_width: int = SMOOTH_BINS) -> float:
    """The regression's σ from the residuals' spectrum, smoothed over the band's neighbouring frequencies.

    With ``a_i = w_i x_i`` and the residuals ``r_i = y_i − step · x_i`` of every pair and axis ``i`` (NaN as 0),
    ``Σ_i Σ_t a_i r_i = (2/n) Σ_k Re(A_k^T R_k*)`` over the positive frequencies ``k`` of their DFTs, and for
    residuals whose spectrum varies slowly with frequency

        Var δ = (2 / n²) Σ_k A_k^H S_k A_k / (Σ w x²)²,

    ``S_k`` the residuals' cross-spectral matrix (pairs and axes move together: the same attitude error scaled by
    each delay) averaged over the in-band bins within ``half_width`` of ``k``. The delete-one-block jackknife
    assumes its blocks independent, which band-limited series a few hertz wide over a 1.6 s record are not
    (on broadband, 1–200 Hz jitter and no latency, it gave 0.50 ms where each axis alone gave 1.1 and 1.6 ms,
    and a latency of 2.5 ms, 5 of its σ, was taken out of a knowledge that had none); and the regressor is
    often one line, whose error is the residuals' power at one frequency, which its neighbours estimate.

    Parameters
    ----------
    ys, xs, ws : list of ndarray (lines,)
        Per pair (and axis): the band-limited differentials of what the knowledge misses (NaN where unknown),
        those of the knowledge's derivative, and the weights.
    step : float
        The regression's last estimate [s] (the residuals are taken about it).
    dt : float
        Line period [s].
    band : (float, float)
        The regression's band [Hz].
    """
    a_rows, r_rows, sxx = [], [], 0.0
    for y, x, w in zip(ys, xs, ws):
        ok = np.isfinite(y) & np.isfinite(x) & (w > 0)
        wx = np.where(ok, w * x, 0.0)
        sxx += float(np.sum(wx * np.where(ok, x, 0.0)))
        a_rows.append(wx)
        r_rows.append(np.where(ok, y - step * x, 0.0))
    if not sxx > 0 or not a_rows:
        return float("inf")
    n = a_rows[0].size
    f = np.fft.rfftfreq(n, dt)
    k_in = np.nonzero((f >= band[0]) & (f <= band[1]) & (f > 0))[0]
    if not k_in.size:
        return float("inf")
    a = np.fft.rfft(np.array(a_rows), axis=1)[:, k_in]          # (series, bins)
    r = np.fft.rfft(np.array(r_rows), axis=1)[:, k_in]
    cross = np.einsum("ik,jk->kij", r, r.conj())                 # per bin R R^H
    var = 0.0
    for b in range(k_in.size):
        near = np.abs(k_in - k_in[b]) <= int(half_width)
        s = cross[near].mean(axis=0)
        var += float(np.real(a[:, b].conj() @ s @ a[:, b]))
    return float(np.sqrt(max(2.0 * var / n ** 2, 0.0)) / sxx)


def _jackknife(sxy: np.ndarray, sxx: np.ndarray) -> float:
    """Delete-one-block jackknife σ of ``Σ sxy / Σ sxx`` over the blocks."""
    left_out = np.array([(sxy.sum() - sxy[b]) / (sxx.sum() - sxx[b]) if sxx.sum() - sxx[b] > 0 else np.nan
                         for b in range(sxy.size)])
    left_out = left_out[np.isfinite(left_out)]
    k = left_out.size
    return float(np.sqrt((k - 1) / k * np.sum((left_out - left_out.mean()) ** 2))) if k > 2 else float("inf")
