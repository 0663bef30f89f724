"""What the images can and cannot restore, from the pairs, the sampling and the estimated spectra alone.

A pair of delay τ_j sees the attitude through ``G_j(f) = e^{2πifτ_j} − 1``:
blind at ``f = k/τ_j``. With a prior PSD ``S(f)`` of the attitude (two-sided,
rad²/Hz) and white differential noise of σ_j per line (PSD ``N_j = σ_j² Δt``),
the fused signal-to-noise ratio at ``f`` is

    SNR(f) = Σ_j |G_j(f)|² S(f) / N_j

and the least mean-square error any linear estimator can reach (the Wiener
filter; for a Gaussian prior the Bayesian Cramér–Rao bound) has the PSD

    E(f) = S(f) / (1 + SNR(f)).

Two figures per axis, over the frequencies the images must supply (above the
estimate's high-pass; below, the AOCS knowledge answers):

* **unobservable** — the attitude power where ``SNR < 1``: near the
  frequencies where every pair is blind no method gets more than half of it
  back; it is physics (the τ set), not the algorithm;
* **floor** — ``√(2 ∫ E df)``: the error of the best linear restoration with
  these pairs, this prior and this noise.

Two more parts of the attitude are out of the images' reach whatever the
spectrum (with truth, :func:`reports.metrics.unobservable_split` takes them
out of a measured error):

* **the record's trend** (:func:`record_trend`) — an attitude ``a + b t`` gives
  every pair the constant differential ``b τ_j``, which a static band-to-band
  misregistration gives too; the restoration removes each pair's mean, so the
  offset and the slope over the record are the AOCS knowledge's or the star
  tracker's (their σ is the anchoring's, :func:`restore.stages.anchoring_sigma`);
* **yaw seen as pitch** off nadir — the line moves along track by
  ``c × ψ`` (``c`` = :func:`restore.stages.yaw_pitch_coupling`, ≈ tan of the
  roll tilt) exactly as by a pitch; across a field of a few hundred pixels
  the rotation that would tell them apart is a thousandth of a pixel, so the
  restored pitch is pitch + ``c`` × (the yaw the AOCS knowledge misses). Tilted along
  track by θ₀ the line looks ahead and a yaw sweeps it across track: the same with
  roll, ``c ≈ sin θ₀`` (:func:`restore.stages.yaw_coupling`).

And one more, which depends on the scene, so that no figure of the product
gives its size (:func:`scene_offset_band`):

* **the scene's band-to-band offset** — each band is a different blend of
  the scene's sunlit and shaded features (crowns, shadows filled by a bluish
  sky), so the bands are offset towards the sun by amounts that follow the
  scene's large features; where the pairs see the attitude through about
  ``2π f τ`` (below about ``1 / (2π τ_max)``) an offset proportional to a
  band's place on the focal plane is an attitude's differential. Where the
  AOCS knowledge stops below that band, the images alone restore it and the
  offset passes into the restored axis along the sun (:func:`sun_offset_shares`).

The prior is what the restoration estimated from the differentials (the
Wiener method reports it); near common blind frequencies it is an
extrapolation by construction, which these figures inherit.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .integration.transfer import fused_snr

__all__ = ["Observability", "fused_snr", "observability", "record_observability", "band_power", "record_trend",
           "scene_offset_band", "knowledge_filter_error_below", "sun_offset_shares", "track_azimuth_deg", "offset_misfit", "OFFSET_MISFIT", "NotchContinuum",
           "notch_continuum", "record_notch_continuum", "wiener_error"]


@dataclass
class Observability:
    """Per axis: the frequency grid, the fused SNR, and the unobservable and floor RMS [rad]."""

    freq: np.ndarray
    snr: np.ndarray
    unobservable_band: np.ndarray
    unobservable_rms_rad: float
    floor_rms_rad: float


def band_power(freq, psd, mask) -> float:
    """``2 ∫ S df`` over the one-sided grid ``freq`` where ``mask`` holds (two-sided PSD → variance)."""
    f = np.asarray(freq, dtype=np.float64)
    df = float(np.median(np.diff(f))) if f.size > 1 else 0.0
    return float(2.0 * np.sum(np.where(mask, psd, 0.0)) * df)


def observability(freq, psd, noise_std, taus, dt: float, *, highpass_hz: float = 0.0) -> Observability:
    """Unobservable power and Wiener floor of one axis (see the module's docstring).

    Parameters
    ----------
    freq : ndarray
        One-sided frequency grid [Hz], uniform.
    psd : ndarray
        Prior PSD of the attitude on ``freq`` (two-sided) [rad²/Hz].
    noise_std : float or ndarray (pairs,)
        White noise of each pair's differentials [rad per line].
    taus : sequence of float
        Pair delays [s].
    dt : float
        Line period [s].
    highpass_hz : float
        Frequencies below are the AOCS knowledge's, not the images'.
    """
    f = np.asarray(freq, dtype=np.float64)
    s = np.asarray(psd, dtype=np.float64)
    snr = fused_snr(f, s, noise_std, taus, dt)
    images = f >= highpass_hz
    band = images & (snr < 1.0)
    err = s / (1.0 + snr)
    return Observability(freq=f, snr=snr, unobservable_band=band,
                         unobservable_rms_rad=float(np.sqrt(band_power(f, s, band))),
                         floor_rms_rad=float(np.sqrt(band_power(f, err, images))))


def record_observability(record) -> Observability:
    """:func:`observability` of an axis's integration record: its prior (or, for a method that reports
    none, the spectrum estimated from its differentials), its noise, pairs, sampling and high-pass."""
    prior = record.spectrum
    if prior is None:
        from .integration.wiener import spectrum_for_lines
        prior = spectrum_for_lines(list(record.diffs), list(record.taus), record.line_period_s)
    return observability(prior.freq, prior.psd, prior.noise_std, record.taus, record.line_period_s,
                         highpass_hz=record.highpass_hz)


@dataclass(frozen=True)
class NotchContinuum:
    """A notch round a common blind frequency whose bridged prior lies below the continuum on both its sides
    (:func:`notch_continuum`): band [Hz], the prior's level inside and the sides' [rad²/Hz, two-sided], and the
    error the low bridge adds over the notch, as an RMS [rad]."""

    band_hz: tuple
    bridged: float
    sides: float
    missing_rms_rad: float


def wiener_error(true_psd, assumed_psd, unit_snr) -> np.ndarray:
    """Error PSD of the Wiener filter built on ``assumed_psd`` when the attitude's PSD is ``true_psd``.

    With the fused SNR per unit of PSD ``u`` (:func:`fused_snr` of a PSD of 1), the filter keeps
    ``k = S_a u / (1 + S_a u)`` of the fused measurement: error ``(1 − k)² S_t + k² / u``; with ``S_a = S_t``
    this is the floor ``S_t / (1 + S_t u)``.
    """
    st = np.asarray(true_psd, dtype=np.float64)
    sa = np.asarray(assumed_psd, dtype=np.float64)
    u = np.asarray(unit_snr, dtype=np.float64)
    k = sa * u / (1.0 + sa * u)
    with np.errstate(divide="ignore", invalid="ignore"):
        noise = np.where(u > 0, k ** 2 / u, 0.0)
    return (1.0 - k) ** 2 * st + noise


def notch_continuum(freq, psd, noise_std, taus, dt: float, *, highpass_hz: float = 0.0) -> list[NotchContinuum]:
    """The notches whose prior was bridged below the continuum on both their sides.

    Round every frequency all pairs are blind to, the spectrum estimate does
    not estimate the prior (:func:`restore.integration.spectrum.notch_mask`, the
    same notches): it bridges it from the notch's edge bins, the smaller one, so
    that a line's skirt on one side does not raise it. Under a continuum the
    gated estimate's edge bin is as often 0 as the level, and the prior inside
    then says there is nothing there: the filter restores nothing of what the
    pairs' flanks still see, and σ, drawn from that prior, holds none of it.
    This reads each side's level as the median of the prior over the notch's
    width beside it (a line's few bins do not move a median; a side that is
    mostly undetected reads 0), takes the smaller side, and reports the error
    the filter built on the bridge adds over the notch to the best the pairs
    allow were the continuum at that level (:func:`wiener_error`, true PSD
    the larger of the prior and the level): what the flanks could have given
    back and did not. Deep in the notch, where no pair sees it, the continuum
    is unobservable either way and is not counted.

    Parameters
    ----------
    freq, psd
        The axis's prior (one-sided grid [Hz], two-sided PSD [rad²/Hz]), as the integration record holds it.
    noise_std : float or ndarray (pairs,)
        The pairs' white noise [rad per line].
    taus, dt
        Pair delays and line period [s].
    highpass_hz : float
        Notches below it are the AOCS knowledge's.

    Returns
    -------
    list of NotchContinuum
        Only notches where the sides' level exceeds the bridge; empty otherwise.
    """
    from .integration.spectrum import notch_mask

    f = np.asarray(freq, dtype=np.float64)
    s = np.asarray(psd, dtype=np.float64)
    taus = np.atleast_1d(np.asarray(taus, dtype=np.float64))
    sd = np.broadcast_to(np.asarray(noise_std, dtype=np.float64), taus.shape)
    if f.size < 3 or not np.all(sd > 0):
        return []
    poor = notch_mask(f, taus, sd ** 2 * float(dt))
    unit_snr = fused_snr(f, np.ones(f.size), sd, taus, dt)
    edges = np.diff(np.r_[0, poor.astype(np.int8), 0])
    out = []
    for a, b in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)):
        if f[a] < highpass_hz:
            continue
        w = b - a
        levels = []
        for lo, hi in ((max(a - w, 0), a), (b, min(b + w, s.size))):
            side = s[lo:hi][~poor[lo:hi]]
            levels.append(float(np.median(side)) if side.size else 0.0)
        level = min(levels)
        bridged = float(np.median(s[a:b]))
        if not level > bridged:
            continue
        inside = np.zeros(f.size, dtype=bool)
        inside[a:b] = True
        true_s = np.maximum(s, level)
        extra = wiener_error(true_s, s, unit_snr) - wiener_error(true_s, true_s, unit_snr)
        out.append(NotchContinuum(band_hz=(float(f[a]), float(f[b - 1])), bridged=bridged, sides=level,
                                  missing_rms_rad=float(np.sqrt(max(band_power(f, extra, inside), 0.0)))))
    return out


def record_notch_continuum(record) -> list[NotchContinuum]:
    """:func:`notch_continuum` of an axis's integration record (empty for a method that reports no prior)."""
    prior = record.spectrum
    if prior is None:
        return []
    return notch_continuum(prior.freq, prior.psd, prior.noise_std, record.taus, record.line_period_s,
                           highpass_hz=record.highpass_hz)


def record_trend(series) -> np.ndarray:
    """The least-squares offset + slope of ``series`` over its finite samples, sampled like it (NaN elsewhere).

    Samples are taken as equally spaced (lines). Fewer than 3 finite samples:
    their mean (or NaN when none).
    """
    y = np.asarray(series, dtype=np.float64)
    ok = np.isfinite(y)
    x = np.arange(y.size, dtype=np.float64)
    if ok.sum() < 3:
        return np.where(ok, np.mean(y[ok]) if ok.any() else np.nan, np.nan)
    coef = np.polyfit(x[ok], y[ok], 1)
    return np.where(ok, np.polyval(coef, x), np.nan)


#: the part of a band offset proportional to the bands' places that the attitude's signature leaves unexplained,
#: in amplitude, up to the top of :func:`scene_offset_band` (0.1: the attitude holds 99 % of its power)
OFFSET_MISFIT = 0.1


def offset_misfit(taus, freq) -> np.ndarray:
    """Part of a band offset proportional to the bands' places that no attitude at ``freq`` explains.

    Bands at along-track places ``x_k`` (delays ``τ_AB = (x_A − x_B) / v``) offset by ``c x_k`` give pair AB the
    differential ``c v τ_AB``; an attitude ``θ`` at ``f`` gives ``(e^{2πifτ_AB} − 1) θ``. Returns, per
    frequency, the norm of the offset's least-squares residual on that signature over its own norm (0: the
    offset is exactly an attitude to every pair; 1: orthogonal to it).
    """
    t = np.asarray(taus, dtype=np.float64).ravel()
    f = np.atleast_1d(np.asarray(freq, dtype=np.float64))
    g = np.exp(2j * np.pi * np.outer(f, t)) - 1.0                     # (freq, pairs)
    gg = np.sum(np.abs(g) ** 2, axis=1)
    proj = np.where(gg > 0, np.abs(g.conj() @ t) ** 2 / np.where(gg > 0, gg, 1.0), 0.0)
    return np.sqrt(np.maximum(1.0 - proj / np.dot(t, t), 0.0))


def scene_offset_band(taus, knowledge_cutoff_hz) -> tuple[float, float] | None:
    """The band [Hz] where the images alone restore the attitude and the scene's band offset looks like one.

    Up to the highest frequency where :func:`offset_misfit` stays within :data:`OFFSET_MISFIT` (about
    ``1 / (2π τ_max)``), an offset between the bands proportional to their place on the focal plane gives the
    pairs an attitude's differentials (99 % of its power), and neither a residual nor any method tells the two
    apart (the module's notes). The AOCS knowledge holds the attitude up to its cut-off (gain ½ there); above
    it, up to that top, the images are alone.

    Parameters
    ----------
    taus : sequence of float
        The pairs' delays [s].
    knowledge_cutoff_hz : float or None
        The AOCS knowledge's cut-off (product.nc's ``knowledge_cutoff_hz``); None: unknown.

    Returns
    -------
    (low, high) or None
        ``(cut-off, top)``; None when the knowledge reaches the top, or the cut-off or the delays are unknown.

    Examples
    --------
    >>> lo, hi = scene_offset_band([0.0074, 0.0222, 0.0148], 2.0)
    >>> lo, round(hi, 1)
    (2.0, 6.8)
    >>> scene_offset_band([0.0074, 0.0222, 0.0148], 10.0) is None
    True
    """
    t = np.abs(np.asarray(taus, dtype=np.float64)).ravel()
    t = t[np.isfinite(t) & (t > 0)]
    if knowledge_cutoff_hz is None or not np.isfinite(knowledge_cutoff_hz) or knowledge_cutoff_hz <= 0 or not t.size:
        return None
    f = np.linspace(0.0, 1.0 / (2.0 * float(t.max())), 2049)[1:]
    over = offset_misfit(t, f) > OFFSET_MISFIT
    high = float(f[max(int(np.argmax(over)) - 1, 0)] if over.any() else f[-1])   # the last within the misfit
    lo = float(knowledge_cutoff_hz)
    return (lo, high) if lo < high else None


def knowledge_filter_error_below(knowledge, dt: float, *, highpass_hz: float, cutoff_hz: float, order: int,
                                 kind: str) -> float:
    """RMS [rad] of the AOCS filter's own error that stays in the restored angle below the high-pass, its linear
    trend removed (as the accuracy metric removes it).

    Below ``highpass_hz`` the restored angle is the (smoothed) knowledge ``k = F θ + n``: its noise is in σ, but
    the filter's own error ``(1 − F) θ`` is not — nothing for a zero-phase Butterworth well below its cut-off,
    the lag of a causal one (a 4th-order Butterworth lags by ``2.61 / (2π f_c)``: 0.10 s at 4 Hz, 30° at a
    0.8 Hz high-pass). Estimated from the knowledge itself: ``k`` through ``(1 − F) / F`` where the filter passes
    at least half the attitude (0 beyond, where the high-pass's complement passes nothing anyway) and through the
    complement of the high-pass, on the record extended by its mirror image. The knowledge's noise passes
    through that filter too (``|1 − F|`` of it, small where ``|F| ≈ 1``).

    Parameters
    ----------
    knowledge : ndarray (lines,)
        The knowledge at the lines [rad].
    dt, highpass_hz : float
        Line period [s] and the restoration's high-pass on this axis [Hz].
    cutoff_hz, order, kind
        The knowledge's filter as product.nc records it.
    """
    from .knowledge_prior import knowledge_response
    from .synthesis import highpass_gain

    k = np.asarray(knowledge, dtype=np.float64)
    n = k.size
    if n < 8 or not np.all(np.isfinite(k)) or not highpass_hz > 0:
        return 0.0
    u = np.linspace(-1.0, 1.0, n)
    x = k - np.polyval(np.polyfit(u, k, 1), u)
    xe = np.concatenate([x, x[::-1]])
    f = np.fft.rfftfreq(2 * n, dt)
    g = knowledge_response(f, cutoff_hz, order, kind)
    strong = np.abs(g) >= 0.5
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.where(strong, (1.0 - g) / np.where(strong, g, 1.0), 0.0)
    e = np.fft.irfft(np.fft.rfft(xe) * r * (1.0 - highpass_gain(f, highpass_hz)), 2 * n)[:n]
    e = e - np.polyval(np.polyfit(u, e, 1), u)
    return float(np.sqrt(np.mean(e ** 2)))


def track_azimuth_deg(ephemeris) -> float:
    """The track's azimuth [deg, from the local +x towards +y]: the direction from the first to the last
    platform position of ``ephemeris`` (lines, 3) [m]; 0 (+x) when absent, too short or not moving.

    Examples
    --------
    >>> track_azimuth_deg([[0.0, 0.0, 7e5], [10.0, 10.0, 7e5]]), track_azimuth_deg(None)
    (45.0, 0.0)
    """
    if ephemeris is None:
        return 0.0
    e = np.asarray(ephemeris, dtype=np.float64)
    if e.ndim != 2 or e.shape[0] < 2 or e.shape[1] < 2 or not np.all(np.isfinite(e[[0, -1], :2])):
        return 0.0
    v = e[-1, :2] - e[0, :2]
    return float(np.degrees(np.arctan2(v[1], v[0]))) if np.hypot(*v) > 0 else 0.0


def sun_offset_shares(sun_azimuth_deg: float, track_azimuth_deg: float = 0.0) -> dict:
    """How a band offset along the sun's horizontal direction splits between pitch and roll (power shares).

    Pitch moves the image along the track, roll across it: an offset at ``Δ`` from the track (the sun's
    azimuth less the track's, both from the local +x towards +y) puts ``cos² Δ`` of its power on pitch and
    ``sin² Δ`` on roll.

    Examples
    --------
    >>> {k: round(v, 2) for k, v in sun_offset_shares(150.0).items()}
    {'roll': 0.25, 'pitch': 0.75}
    >>> {k: round(v, 2) for k, v in sun_offset_shares(100.0, 10.0).items()}
    {'roll': 1.0, 'pitch': 0.0}
    """
    d = np.radians(float(sun_azimuth_deg) - float(track_azimuth_deg))
    return {"roll": float(np.sin(d) ** 2), "pitch": float(np.cos(d) ** 2)}
