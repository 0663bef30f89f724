"""The matching noise the pairs' differentials show in the AOCS knowledge's band, and the weight it leaves them.

A band's own matching error common to a line's points moves every pair the
way an attitude does (the scene's band offset: spectral differences of the
bands in shading and shadows, :mod:`restore.observability`), so no fit
residual shows it: the estimate absorbs it. Where the record's prior is
conditioned on the AOCS knowledge, the differentials themselves do: there
the integration restores ``e' = θ − k − E[e | k]``, whose prior ``V`` the
knowledge's noise model fixes, and pair ``j``'s differential holds
``|G_j|² V`` of it plus its noise. Its power against the same record's
Monte Carlo draws — the prior through the pair (``A``) plus the white noise
of the integration's model (``N``) — measures the noise's colour there:

    c = 1 + (real / q − simulated) / N,

the factor on the white noise that makes the draws' differentials as large
as the real ones (both Hann-tapered, mean removed, averaged over the bands
of :func:`restore.posterior._band_edges`; ``q`` below; 1 where the real
ones are no larger). Weighing the MAP by it (:func:`restore.stages.knowledge_band_weighted`)
lets the knowledge-conditioned prior, not the offset, decide that band; σ is
predicted again through the new filter. Measured on unseen rendered products
(forty-third session, roll / pitch px outside the unobservable part):
a quiet scene 0.0240 / 0.0286 → 0.0226 / 0.0268, a causal 4 Hz knowledge's
0.0290 / 0.0407 → 0.0295 / 0.0350 and 0.0305 / 0.0549 → 0.0305 / 0.0530,
notch lines 0.0261 / 0.0327 → 0.0257 / 0.0320; nothing moved where the
differentials show no excess (a noisy knowledge's).

The factor is read as a lower bound: ``q`` is the :data:`CONFIDENCE` point
of the real power's χ² scatter over its mean. Unbiased (``q = 1``), a white
band read up to 4 × where the draws were mostly attitude, and a false colour
weighs good data down; as a lower bound a 40 × slow noise reads 0.2–0.7 of it.

One factor serves every pair, read from their powers summed (``pooled``,
the default; the χ² scatter then has the pairs' degrees of freedom
together). Each pair's own read rests on a few bins, and the scatter
between the reads weighs the pairs against each other by chance: on an
unseen product with a real AOCS's knowledge (forty-fourth session) pitch's
reads at 5.5–9 Hz were 8.8 / 1.0 / 38.8 (B1/B0, B1/B2, B0/B2) where its
differentials less the truth's showed 4.5 / 3.5 / 2.6, the longest pair
was weighed down for the others, and the error outside the unobservable
part rose 0.0229 → 0.0260 px (pooled: 0.0240). Pooled, the pairs keep the
weights their residuals gave them; the read decides only how far the band
follows the knowledge-conditioned prior rather than the pairs. On seventeen
unseen products (roll / pitch px, per pair → pooled): that one
0.0235 / 0.0260 → 0.0229 / 0.0240, a causal knowledge's
0.0295 / 0.0350 → 0.0283 / 0.0349, four scenes' roll +0.0006 each, one
pitch +0.0004, one −0.0003, eleven others within ± 0.0001.

σ's draws do not take this colour as a noise of each pair (they keep the
residual's colour). Drawn that way (aaa4606), the suite's huge_amplitude
(12 px CMG lines) predicted 0.045 / 0.059 px against 0.034 / 0.041 without,
while its error stayed 0.016 / 0.025 outside the unobservable part (σ × 0.77
/ 0.80 → 0.59 / 0.56); elsewhere the draws moved by ≤ 6 %: the weighted MAP
keeps such a noise out. What it does not keep out is the excess as what it
is, an offset that moves every pair as an attitude does: σ's draws carry
one (:func:`knowledge_band_offset_psd`: the pooled colour read unbiased,
``S = (c − 1) Σ ν_j / Σ |G_j|²`` in the band), and the MAP passes part of it
as it would an attitude (forty-fourth session; on synthetic records with
such an offset the actual error is 1.07 × σ with it, 1.25 × without; on
unseen products causal 777's pitch × 1.69 → 1.42, real_aocs 777's roll
1.76 → 1.40, quiet 777's pitch 1.47 → 1.32, the suite's ratios 0.70–1.46).

Outside the conditioned band the differentials hold the attitude itself,
whose prior the data set: there nothing is measured (colour 1). The colour
combines with the one the record already carries (its residual's, which
sees the part of the noise the pairs disagree on) by the larger of the two:
both measure the same noise against white.
"""
from __future__ import annotations

import numpy as np
from scipy.signal.windows import hann
from scipy.stats import chi2

from .integration.transfer import pair_transfer
from .posterior import _band_edges, draw_differentials

__all__ = ["COLOUR_LIMIT", "MIN_NOISE_SHARE", "HANN_ENBW", "CONFIDENCE", "tapered_band_power", "colour_from_differentials",
           "knowledge_band_colour", "knowledge_band_offset_psd"]

#: the largest factor on the white noise taken (a band whose real power is dominated by something else)
COLOUR_LIMIT = 64.0
#: equivalent noise bandwidth of the Hann taper [bins]
HANN_ENBW = 1.5
#: the real power is read at the lower end of this one-sided confidence (its χ² scatter divided out): a band whose
#: noise is white passes for coloured in no more than 1 − CONFIDENCE of the records, by little when it does
CONFIDENCE = 0.9
#: the noise's share of the draws' power is taken as at least this (the excess is divided by it: a band where the
#: draws are all attitude cannot tell how much of an excess is the noise's, and would multiply it without bound)
MIN_NOISE_SHARE = 0.25


def tapered_band_power(x, edges: list) -> np.ndarray:
    """Mean Hann-tapered periodogram of each row of ``x`` (pair, line) in the bands ``edges`` (pair, band).

    NaN samples count as the row's mean (removed first); the taper keeps a
    strong line outside a band from leaking into it through a rectangular
    window's sidelobes.
    """
    x = np.atleast_2d(np.asarray(x, dtype=np.float64))
    ok = np.isfinite(x)
    mean = np.where(ok, x, 0.0).sum(axis=1) / np.maximum(ok.sum(axis=1), 1)
    y = np.where(ok, x - mean[:, None], 0.0) * hann(x.shape[1], sym=False)[None, :]
    per = np.abs(np.fft.rfft(y, axis=-1)) ** 2
    return np.array([[per[j, a:b].mean() for a, b in zip(edges[:-1], edges[1:])] for j in range(x.shape[0])])


def colour_from_differentials(real, simulated, noise, edges: list, n: int, in_band, *,
                              limit: float = COLOUR_LIMIT, confidence: float | None = CONFIDENCE,
                              rows_summed: int = 1) -> np.ndarray:
    """Per pair and frequency of ``rfftfreq(n)``: the factor on the white noise that makes the draws'
    differentials as large as the real ones, in the bands of ``edges`` that lie wholly inside ``in_band``.

    ``real``, ``simulated`` (mean over the draws) and ``noise`` (the draws' noise alone) are band powers
    (pair, band) as :func:`tapered_band_power` gives them; ``in_band`` a boolean mask over ``rfftfreq(n)``.
    ``c = 1 + (real / q − simulated) / noise`` (the noise's share of the draws taken as at least
    :data:`MIN_NOISE_SHARE`; ``q`` the ``confidence`` quantile of the real power's χ² scatter over its
    mean, so that the factor is a lower bound; 1 with ``confidence=None``), between 1 and ``limit``, interpolated in log-log between the inside bands'
    centres and held flat from the outermost ones to the ends of ``in_band``; 1 outside ``in_band``.
    ``rows_summed``: each row's powers are sums over that many independent rows (pairs pooled), whose χ²
    scatter has that many times the degrees of freedom.
    """
    real, sim, noise = (np.asarray(v, dtype=np.float64) for v in (real, simulated, noise))
    mask = np.asarray(in_band, dtype=bool)
    bounds = list(zip(edges[:-1], edges[1:]))
    inside = np.array([bool(mask[a:b].all()) for a, b in bounds])
    # the real power's own scatter: a band of b tapered bins is worth b / ENBW independent ones, χ² of 2 b / ENBW
    dof = np.array([2.0 * max(b - a, 1) / HANN_ENBW for a, b in bounds]) * max(int(rows_summed), 1)
    q = np.ones(dof.size) if confidence is None else chi2.ppf(confidence, dof) / dof
    with np.errstate(divide="ignore", invalid="ignore"):
        floor = np.maximum(noise, MIN_NOISE_SHARE * sim)
        c = 1.0 + np.maximum(real / q[None, :] - sim, 0.0) / floor
    c = np.clip(np.where(np.isfinite(c), c, 1.0), 1.0, limit)[:, inside]
    if c.shape[1] == 0:
        return np.ones((real.shape[0], n // 2 + 1))
    # in log-log between the inside bands' centres, held flat from the outermost ones to the band's ends (the
    # bands that straddle them are not read, and their 1 would pull the factor down at the band's edges)
    idx = np.arange(n // 2 + 1)
    centres = np.log([np.exp(np.mean(np.log(np.arange(a, b)))) for (a, b), ok in
                      zip(zip(edges[:-1], edges[1:]), inside) if ok])
    on_bins = np.array([np.exp(np.interp(np.log(np.maximum(idx, 1)), centres, np.log(r))) for r in c])
    return np.where(mask[None, :], on_bins, 1.0)


def knowledge_band_colour(record, band_hz, *, samples: int = 8, seed: int = 0, pooled: bool = True,
                          confidence: float | None = CONFIDENCE) -> np.ndarray | None:
    """The noise's colour (pair, ``rfftfreq(lines, Δt)``) the record's differentials show in ``band_hz``
    against its own draws (module docstring); None where no band of the record lies inside it or the record
    cannot be drawn from (no prior). ``pooled``: one colour for every pair, read from the pairs' powers summed
    (the default; the module docstring says why); otherwise each pair's own. ``confidence``: as
    :func:`colour_from_differentials` reads it (None: unbiased)."""
    if getattr(record, "spectrum", None) is None:
        return None
    d = np.asarray(record.diffs, dtype=np.float64)
    n, dt = d.shape[1], float(record.line_period_s)
    f = np.fft.rfftfreq(n, dt)
    lo, hi = float(band_hz[0]), float(band_hz[1])
    in_band = (f >= lo) & (f <= hi)
    edges = _band_edges(n)
    if not any(in_band[a:b].all() for a, b in zip(edges[:-1], edges[1:])):
        return None
    sims, noises = draw_differentials(record, samples=samples, seed=seed)
    simulated = np.mean([tapered_band_power(s, edges) for s in sims], axis=0)
    noise = np.mean([tapered_band_power(z, edges) for z in noises], axis=0)
    real = tapered_band_power(d, edges)
    if not pooled:
        return colour_from_differentials(real, simulated, noise, edges, n, in_band, confidence=confidence)
    one = colour_from_differentials(real.sum(axis=0)[None, :], simulated.sum(axis=0)[None, :],
                                    noise.sum(axis=0)[None, :], edges, n, in_band, confidence=confidence,
                                    rows_summed=real.shape[0])
    return np.repeat(one, real.shape[0], axis=0)


def knowledge_band_offset_psd(record, *, samples: int = 8, seed: int = 0) -> tuple[np.ndarray, np.ndarray] | None:
    """The PSD of an attitude-like offset as large as the excess the record's differentials show in its
    ``knowledge_band_hz``: ``(freq, psd)`` on ``rfftfreq(lines, Δt)`` [Hz, two-sided rad²/Hz], or None where the
    record holds no such band (not weighed by it) or cannot be drawn from.

    ``S(f) = (c(f) − 1) Σ_j ν_j / Σ_j |G_j(f)|²`` in the band, 0 outside: ``c`` the pooled colour read unbiased
    (:func:`knowledge_band_colour` with ``confidence=None``: σ wants the expected size, not a lower bound),
    ``ν_j = σ_j² Δt`` pair ``j``'s white noise level and ``|G_j|²`` its gain on an attitude
    (:func:`restore.integration.transfer.pair_transfer`); an offset of that PSD, seen through every pair as an
    attitude is, raises the pairs' summed band power by the excess. The weighted MAP lets part of it through,
    as it would an attitude: what σ's draws must hold (:func:`restore.posterior.posterior_sigma`; the module
    docstring has the numbers).
    """
    band = getattr(record, "knowledge_band_hz", None)
    if band is None or getattr(record, "spectrum", None) is None:
        return None
    colour = knowledge_band_colour(record, band, samples=samples, seed=seed, confidence=None)
    if colour is None:
        return None
    n, dt = np.asarray(record.diffs).shape[1], float(record.line_period_s)
    f = np.fft.rfftfreq(n, dt)
    taus = np.asarray(record.taus, dtype=np.float64)
    nu = np.broadcast_to(np.asarray(record.spectrum.noise_std, dtype=np.float64), taus.shape) ** 2 * dt
    gain = np.sum([np.abs(pair_transfer(f, tau)) ** 2 for tau in taus], axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        psd = np.where(gain > 0, (colour[0] - 1.0) * float(np.sum(nu)) / gain, 0.0)
    return f, np.where(np.isfinite(psd), np.maximum(psd, 0.0), 0.0)
