"""The σ checked against the smoothed AOCS knowledge: what the two disagree by, beyond both predictions.

The predicted σ (:mod:`restore.posterior`) is the error of the images'
estimate under a model: a stationary attitude from the prior the integration
estimated, and matching noise calibrated on the fit residual. An error the
residual cannot show — one that moves like an attitude in every pair, such as
a sun-driven shading of the texture that shifts all bands' matches alike at a
few hertz — is missing from it (an unseen scene with 25 % cloud and a low
sun: actual / predicted σ 1.59 on roll).

The AOCS knowledge sees the same attitude independently. The restored angle
is ``r = LP(k_s) + H(k + ê)`` (``H`` the restoration's Gaussian high-pass,
``LP = 1 − H``, ``k_s`` the smoothed knowledge), so its difference from the
smoothed knowledge holds the two errors only, through the high-pass:

    D = r − k_s = H (e_I − e_K),   E|D|² = H² (P_I + P_K − 2 C),

``e_I`` the images' error, ``P_I`` its power: the posterior draws' error less
the smoothing's noise below the high-pass they hold (``(1 − H)² P_K``);
``P_K`` the smoothed knowledge's: the Wiener error its smoothing leaves
(:meth:`~restore.knowledge_smoothing.KnowledgeSmoothing.error_draw`, the
draws the σ takes below the high-pass), plus the AOCS filter's own error ``|1 − F|² S_θ``, ``S_θ`` from the
knowledge's periodogram above its noise floor divided by ``|F|²`` (a causal
filter's lag, a strong sweep at the filter's edge). The errors' covariance
``C`` is left out: both hold part of the knowledge's noise with the same sign,
so ``P_I + P_K`` is an upper bound and the test errs on the side of not firing.

The band runs from ``1.25 ×`` the high-pass (where ``H`` passes 42 %) to
``0.7 ×`` the knowledge's cut-off (the filter's flat part). Every power is
a periodogram with the quadratic trend removed and a Hann taper
(:func:`tapered_power`): untapered, the raw knowledge's offset and drift
leaked into the band (real_aocs: 0.079 px of "filter error" predicted there,
0.011 tapered), and so did the restored angle's and the draws' slow errors.
Where ``D``'s power exceeds the prediction beyond its sampling spread (a sum
of ``m`` tapered bins has a relative spread ``1/√(m / ENBW)``; the threshold
is two of them), one of the two predictions is short by at least the excess,
and which one the data cannot tell.

Above the knowledge's cut-off ``D`` holds the attitude the AOCS filter leaves
out, lines of many times the band's power; the taper's sidelobes and the
trend's fit put a share of each in the band, which no per-bin prediction
does (on a 1.6 s record under a 4 Hz knowledge a 20 µrad line at 6 Hz
raised the check 3.7–6.1 × on 20 seeds of 20 with nothing to find): such
lines are fitted and taken out of ``D`` first (:func:`without_strong_lines`).

The check is recorded on every axis it can be made on (restoration.nc, the
report). ``restoration.sigma_knowledge_check`` (on by default) adds to σ the
images' share of the excess as measured, ``P_I / (P_I + P_K)`` of it
(:attr:`KnowledgeCheck.booked_rad2`): each prediction taken short in
proportion to its size. The excess σ takes is the measured one, significant
or not (the threshold says when the two *disagree*, which the report states;
a shortfall under it was never counted, and σ was low on average: the
stress suite's actual / predicted σ centred on 1.18 on pitch, 1.00 on
roll). All of it would be right when the images' side is short (the
restored error then rises by exactly ``D``'s excess) and wrong
when the knowledge's is: on geo_noisy_knowledge, whose knowledge noise
dominates the band (images' share 1–2 %) and errs more than predicted there,
booking the whole excess took actual / predicted σ from 1.34 / 1.50 to
0.35 / 0.42; the share takes it to 1.19 / 1.41. The check needs the
knowledge's noise and filter (product.nc) and at least :data:`MIN_BINS` bins
in the band (three: a 1.6 s record under a 4 Hz knowledge); otherwise
nothing is checked.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .knowledge_prior import knowledge_noise_floor, knowledge_response
from .knowledge_smoothing import samples_at_lines
from .synthesis import highpass_gain

__all__ = ["KnowledgeCheck", "line_power", "tapered_power", "tapered_power_rows", "check_band", "smoothed_knowledge_at",
           "knowledge_error_power",
           "filter_error_power", "without_strong_lines", "threshold_ratio", "excess_variance", "knowledge_check", "MIN_BINS", "SIGNIFICANCE",
           "LOW_FACTOR", "HIGH_FRACTION", "ENBW"]

#: fewer periodogram bins than this in the band: no check (a 1.6 s record has 8 between 2.5 and 7 Hz, 3 between
#: 1.0 and 2.8 Hz under a 4 Hz knowledge)
MIN_BINS = 3
#: the excess counts beyond this many relative spreads (``1/√(m / ENBW)``) of the band's power
SIGNIFICANCE = 2.0
#: equivalent noise bandwidth of the Hann taper [bins]: ``m`` tapered bins are worth ``m / ENBW`` independent ones
ENBW = 1.5
#: the band starts at this multiple of the high-pass (where the Gaussian high-pass passes 42 %: below it ``D``
#: holds little of either error)
LOW_FACTOR = 1.25
#: the band ends at this fraction of the knowledge's cut-off (the filter's flat part)
HIGH_FRACTION = 0.7
#: draws of the smoothing's error averaged into ``P_K``
KNOWLEDGE_DRAWS = 16


@dataclass(frozen=True)
class KnowledgeCheck:
    """The images against the smoothed knowledge in one axis's band (:func:`knowledge_check`).

    Attributes
    ----------
    band_hz : (float, float)
        The band checked [Hz].
    observed_rad2, images_rad2, knowledge_rad2 : float
        Power in the band [rad², mean square over the lines checked] of ``r − k_s``, the images' predicted
        error and the smoothed knowledge's predicted error (smoothing noise plus AOCS filter error).
    bins : int
        Periodogram bins in the band.
    excess_rad2 : float
        The observed power beyond the sum of the predictions where that is significant, else 0 (what the report
        states as a disagreement; σ books the measured excess, :attr:`booked_rad2`).
    """

    band_hz: tuple
    observed_rad2: float
    images_rad2: float
    knowledge_rad2: float
    bins: int
    excess_rad2: float

    def as_dict(self) -> dict:
        """Plain values (RMS in rad) as restoration.nc records them (:meth:`from_dict` reads them back)."""
        return {"band_hz": [float(v) for v in self.band_hz], "bins": int(self.bins),
                "observed_rms_rad": float(np.sqrt(self.observed_rad2)),
                "images_rms_rad": float(np.sqrt(self.images_rad2)),
                "knowledge_rms_rad": float(np.sqrt(self.knowledge_rad2)),
                "excess_rms_rad": float(np.sqrt(self.excess_rad2)), "ratio": self.ratio,
                "booked_rms_rad": float(np.sqrt(self.booked_rad2)),
                "threshold": self.threshold}

    @classmethod
    def from_dict(cls, d: dict) -> "KnowledgeCheck":
        """The check :meth:`as_dict` wrote."""
        return cls(band_hz=tuple(float(v) for v in d["band_hz"]), observed_rad2=float(d["observed_rms_rad"]) ** 2,
                   images_rad2=float(d["images_rms_rad"]) ** 2, knowledge_rad2=float(d["knowledge_rms_rad"]) ** 2,
                   bins=int(d["bins"]), excess_rad2=float(d["excess_rms_rad"]) ** 2)

    @property
    def images_share(self) -> float:
        """The images' share of the predicted power, ``P_I / (P_I + P_K)``."""
        p = self.images_rad2 + self.knowledge_rad2
        return float(self.images_rad2 / p) if p > 0 else 0.0

    @property
    def measured_excess_rad2(self) -> float:
        """The observed power beyond the sum of the predictions as measured, whether significant or not (≥ 0)."""
        return max(float(self.observed_rad2 - self.images_rad2 - self.knowledge_rad2), 0.0)

    @property
    def booked_rad2(self) -> float:
        """What σ takes: the images' share of the measured excess (the data cannot tell which prediction is
        short; each is taken short in proportion to its size).

        The excess as measured, not only beyond the significance threshold (:attr:`excess_rad2`, which the
        report states): as for the noise colour (:func:`restore.posterior.noise_colour_estimate`), a tested
        estimate drops every shortfall below the test's threshold (× 1.87 the prediction on a 1.6 s record) and
        is low on average. The positive part of a noisy excess is biased high where both predictions are right;
        the prediction it is compared with leaves out the errors' covariance (an upper bound, module docstring),
        which pulls the other way.

        Tried (thirty-fifth session) and not kept: booking past the threshold at least ``O − P_I − q P_K``, what the knowledge's side
        could not hold if its prediction were exact. It is not: the smoothing's error (``W σ²`` per DCT
        coefficient, with ``W`` estimated from the coefficients themselves) is short where the gains are
        mid-way, and on geo_noisy_knowledge (58 samples, 0.3 px each) the smoothed knowledge erred by 0.119 px
        in the band against 0.073 predicted — that floor took its σ ratio to 0.61 / 0.19."""
        return self.measured_excess_rad2 * self.images_share

    @property
    def ratio(self) -> float:
        """Observed over predicted power."""
        p = self.images_rad2 + self.knowledge_rad2
        return float(self.observed_rad2 / p) if p > 0 else float("inf")

    @property
    def threshold(self) -> float:
        """Ratio beyond which the excess counts (:func:`threshold_ratio`)."""
        return threshold_ratio(self.bins)


def line_power(x) -> np.ndarray:
    """Periodogram of a series over the lines, per bin of ``rfftfreq(n)``, summing to its mean square.

    NaN (lines not restored) count as zero after the mean of the finite ones is removed, so that series
    with the same gaps are compared on the same footing.
    """
    v = np.asarray(x, dtype=np.float64)
    ok = np.isfinite(v)
    if not ok.any():
        return np.zeros(v.size // 2 + 1)
    v = np.where(ok, v - v[ok].mean(), 0.0)
    p = np.abs(np.fft.rfft(v)) ** 2 / v.size ** 2
    p[1:(v.size + 1) // 2] *= 2.0   # both signs of every frequency but 0 and Nyquist
    return p


def tapered_power(x, mask) -> np.ndarray:
    """Periodogram of ``x`` on the lines of ``mask`` (others zero), like :func:`line_power`, but with its quadratic
    trend removed and a Hann taper (normalised so that a stationary series keeps its power): the raw knowledge
    holds an offset, a drift and slow motions of pixels whose leakage would pass for power at a few hertz, and
    so may the draws' errors and the restored angle; every power the check compares is taken this way."""
    v = np.asarray(x, dtype=np.float64)
    m = np.asarray(mask, dtype=bool) & np.isfinite(v)
    if np.count_nonzero(m) < 3:
        return np.zeros(v.size // 2 + 1)
    u = np.linspace(-1.0, 1.0, v.size)
    v = v - np.polyval(np.polyfit(u[m], v[m], 2), u)
    w = np.hanning(v.size)
    return line_power(np.where(m, v * w, np.nan)) / np.mean(w ** 2)


def tapered_power_rows(x, mask) -> np.ndarray:
    """:func:`tapered_power` of each row of ``x`` (row, line) on the same lines ``mask`` (each row finite there),
    summed over the rows."""
    v = np.atleast_2d(np.asarray(x, dtype=np.float64))
    m = np.asarray(mask, dtype=bool)
    n = v.shape[1]
    if np.count_nonzero(m) < 3:
        return np.zeros(n // 2 + 1)
    u = np.linspace(-1.0, 1.0, n)
    a = np.vander(u, 3)
    coef, *_ = np.linalg.lstsq(a[m], v[:, m].T, rcond=None)
    w = np.hanning(n)
    y = (v - (a @ coef).T) * w
    y = np.where(m, y - y[:, m].mean(axis=1, keepdims=True), 0.0)
    p = np.abs(np.fft.rfft(y, axis=1)) ** 2 / n ** 2
    p[:, 1:(n + 1) // 2] *= 2.0
    return p.sum(axis=0) / np.mean(w ** 2)


def check_band(n: int, dt: float, highpass_hz: float, cutoff_hz: float) -> np.ndarray | None:
    """Boolean mask over ``rfftfreq(n, dt)`` of the band checked, or None when it has fewer than MIN_BINS bins."""
    if not (highpass_hz > 0 and cutoff_hz > 0):
        return None
    f = np.fft.rfftfreq(n, dt)
    band = (f >= LOW_FACTOR * highpass_hz) & (f <= HIGH_FRACTION * cutoff_hz)
    return band if np.count_nonzero(band) >= MIN_BINS else None


def smoothed_knowledge_at(smoothing, values, line_time) -> np.ndarray:
    """The smoothed knowledge samples read at ``line_time`` (cubic, as the knowledge is read; clamped) [rad]."""
    return samples_at_lines(smoothing.apply(values), smoothing.time, line_time)


def knowledge_error_power(smoothing, line_time, mask, rng: np.random.Generator,
                          draws: int = KNOWLEDGE_DRAWS) -> np.ndarray:
    """Mean periodogram (:func:`tapered_power`) over ``draws`` of the smoothed knowledge's error
    (:meth:`~restore.knowledge_smoothing.KnowledgeSmoothing.error_draw`), read at the lines of ``mask`` (others
    zero)."""
    out = 0.0
    for _ in range(draws):
        e = samples_at_lines(smoothing.error_draw(rng), smoothing.time, line_time)
        out = out + tapered_power(e, mask)
    return out / draws


def filter_error_power(knowledge_power, freq, *, cutoff_hz: float, order: int, kind: str, noise_rad: float,
                       rate_hz: float, n: int, dt: float, fraction: float = 1.0) -> np.ndarray:
    """The AOCS filter's own error in the knowledge, per bin: ``|1 − F|² · max(P_k − floor, 0) / |F|²``.

    ``knowledge_power`` is the knowledge's periodogram (:func:`tapered_power`) over the lines checked (a
    ``fraction`` of the ``n``), ``floor`` its white noise (:func:`restore.knowledge_prior.knowledge_noise_floor`)
    in the same units.
    """
    g = knowledge_response(freq, cutoff_hz, order, kind)
    floor = knowledge_noise_floor(freq, rate_hz=rate_hz, noise_rad=noise_rad) * 2.0 / (n * dt) * fraction
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.maximum(np.asarray(knowledge_power) - floor, 0.0) / np.abs(g) ** 2
    return np.where(np.abs(g) > 1e-6, np.abs(1.0 - g) ** 2 * s, 0.0)


#: a line outside the band is taken out of ``D`` when that lowers the band's power by this share or more
LINE_LEAK_SHARE = 0.01
#: at most this many lines are taken out; the strongest few outside the band are tried each time
MAX_LINES = 8
LINE_CANDIDATES = 3
#: lines within this many bins of the band are left in (their main lobe is the band's own content)
LINE_GUARD_BINS = 3


def _sine_fit(v, m, t, f) -> tuple[float, np.ndarray]:
    """Least-squares sine at frequency ``f`` [cycles per line] on the lines ``m``: (residual sum of squares, the
    fitted sine over all lines)."""
    c, s = np.cos(2.0 * np.pi * f * t), np.sin(2.0 * np.pi * f * t)
    a = np.stack([c[m], s[m]], axis=1)
    coef, *_ = np.linalg.lstsq(a, v[m], rcond=None)
    fit = coef[0] * c + coef[1] * s
    return float(np.sum((v[m] - fit[m]) ** 2)), fit


def _fitted_line(v, m, t, j: int, n: int) -> np.ndarray:
    """The sine of the line whose periodogram top is bin ``j``, its frequency refined within a bin of it."""
    from scipy.optimize import minimize_scalar

    res = minimize_scalar(lambda f: _sine_fit(v, m, t, f)[0], bounds=((j - 1.0) / n, (j + 1.0) / n),
                          method="bounded", options={"xatol": 1e-4 / n})
    return _sine_fit(v, m, t, float(res.x))[1]


def without_strong_lines(x, mask, band) -> np.ndarray:
    """``x`` less the sines outside ``band`` whose removal lowers the band's tapered power
    (:func:`tapered_power`) by :data:`LINE_LEAK_SHARE` or more, strongest first (NaN and lines off ``mask``: 0).

    ``D = r − k_s`` holds, above the knowledge's cut-off, the attitude the AOCS filter leaves out: lines of
    many times the band's power, legitimately there. Through the taper's sidelobes and the quadratic trend
    :func:`tapered_power` removes (a strong sine's fit over a record of a few cycles), a share of each lands in
    the band — on a 1.6 s record a 20 µrad line 5 bins above it holds several times the errors checked —
    where no per-bin prediction puts it. Each such line is fitted (least squares, its frequency refined
    within a bin of its periodogram's top) and kept out where that lowers the band's power; lines within
    :data:`LINE_GUARD_BINS` of the band are its own content and stay.
    """
    v = np.asarray(x, dtype=np.float64)
    m = np.asarray(mask, dtype=bool) & np.isfinite(v)
    n = v.size
    v = np.where(m, v, 0.0)
    b = np.flatnonzero(np.asarray(band, dtype=bool))
    if np.count_nonzero(m) < 8 or not b.size:
        return v
    t = np.arange(n, dtype=np.float64)
    bins = np.arange(n // 2 + 1)
    far = (bins < b[0] - LINE_GUARD_BINS) | (bins > b[-1] + LINE_GUARD_BINS)
    far[0] = False
    for _ in range(MAX_LINES):
        p = tapered_power(v, m)
        inside = float(np.sum(p[b]))
        tops = np.flatnonzero(far[1:-1] & (p[1:-1] >= p[:-2]) & (p[1:-1] >= p[2:])) + 1
        best, best_inside = None, (1.0 - LINE_LEAK_SHARE) * inside
        for j in tops[np.argsort(p[tops])[::-1][:LINE_CANDIDATES]]:
            w = np.where(m, v - _fitted_line(v, m, t, int(j), n), 0.0)
            wi = float(np.sum(tapered_power(w, m)[b]))
            if wi < best_inside:
                best, best_inside = w, wi
        if best is None:
            break
        v = best
    return v


def threshold_ratio(bins: int) -> float:
    """Observed over predicted power beyond which the excess counts: ``1 + SIGNIFICANCE / √(bins / ENBW)`` (two
    relative spreads of a sum of ``bins`` tapered periodogram bins)."""
    return 1.0 + SIGNIFICANCE / np.sqrt(max(bins, 1) / ENBW)


def excess_variance(observed: float, images: float, knowledge: float, bins: int) -> float:
    """The observed power beyond ``images + knowledge`` when the ratio exceeds :func:`threshold_ratio`, else 0."""
    predicted = images + knowledge
    if bins < 1 or not observed > predicted * threshold_ratio(bins):
        return 0.0
    return float(observed - predicted)


def knowledge_check(restored, smoothed_knowledge, knowledge, images_power, smoothing, *, line_period_s: float,
                    highpass_hz: float, cutoff_hz: float, order: int, kind: str, noise_rad: float, rate_hz: float,
                    seed: int = 0) -> KnowledgeCheck | None:
    """Check one axis's restored angle against its smoothed knowledge (module docstring); None: no band.

    Parameters
    ----------
    restored : ndarray (lines,)
        The restored angle [rad] (NaN: not restored).
    smoothed_knowledge, knowledge : ndarray (lines,)
        The smoothed and the raw knowledge at the lines [rad].
    images_power : ndarray (lines // 2 + 1,)
        The images' predicted error periodogram (:func:`tapered_power` of the posterior draws, averaged).
    smoothing : restore.knowledge_smoothing.KnowledgeSmoothing
        The knowledge's smoothing (its times from the first line).
    line_period_s, highpass_hz : float
        Line period and the restoration's high-pass.
    cutoff_hz, order, kind, noise_rad, rate_hz
        The knowledge as product.nc records it.
    seed : int
        Seed of the smoothing's error draws.
    """
    r = np.asarray(restored, dtype=np.float64)
    n, dt = r.size, float(line_period_s)
    band = check_band(n, dt, highpass_hz, cutoff_hz)
    ok = np.isfinite(r)
    if band is None or not ok.any():
        return None
    freq = np.fft.rfftfreq(n, dt)
    fraction = float(np.mean(ok))
    observed = tapered_power(without_strong_lines(r - np.asarray(smoothed_knowledge, dtype=np.float64), ok, band),
                             ok)
    t = np.arange(n) * dt
    p_k = knowledge_error_power(smoothing, t, ok, np.random.default_rng(np.random.SeedSequence([int(seed), 0x4B43])))
    p_f = filter_error_power(tapered_power(knowledge, ok), freq, cutoff_hz=cutoff_hz, order=order,
                             kind=kind, noise_rad=noise_rad, rate_hz=rate_hz, n=n, dt=dt, fraction=fraction)
    # the draws' error is H e_I + (1 − H) e_K (the images' error through the high-pass H, and the smoothing's
    # pooled noise below it), D's is H (e_I − e_K): the images' part is the draws' less the knowledge's they hold
    h = highpass_gain(freq, highpass_hz)
    images = np.maximum(np.asarray(images_power) - (1.0 - h) ** 2 * p_k, 0.0)
    m = int(np.count_nonzero(band))
    # mean squares over the restored lines (the gaps count as zeros in the periodograms)
    obs, img, kn = (float(np.sum(np.asarray(p)[band])) / fraction for p in (observed, images, h ** 2 * (p_k + p_f)))
    lo, hi = float(freq[band][0]), float(freq[band][-1])
    return KnowledgeCheck(band_hz=(lo, hi), observed_rad2=obs, images_rad2=img, knowledge_rad2=kn, bins=m,
                          excess_rad2=excess_variance(obs, img, kn, m))
