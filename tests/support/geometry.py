"""Analytic test scenes shared by the geometry tests."""
import numpy as np

from simsat.instrument import Detector, Instrument, Radiometry
from simsat.platform import Platform
from simsat.terrain.dem import Dem

F = 12.905
PITCH = 52e-6
H = 694000.0
TE = 4e-4
V = H * PITCH / F / TE


class SpotTexture:
    """Gaussian spots of known ground positions on a uniform background (same in every band)."""

    bands = ("blue", "green", "red", "nir", "pan")

    def __init__(self, centres, *, sigma_m=4.0, texel_m=0.5, background=0.2, peak=0.6):
        self.centres = np.asarray(centres, dtype=float)
        self.sigma = sigma_m
        self.texel_m = texel_m
        self.background = background
        self.peak = peak

    def grid(self, x0_m, y0_m, texel_m, nx, ny):
        x = x0_m + (np.arange(nx) + 0.5) * texel_m
        y = y0_m + (np.arange(ny) + 0.5) * texel_m
        img = np.full((ny, nx), self.background, dtype=np.float64)
        for cx, cy in self.centres:
            gx = np.exp(-0.5 * ((x - cx) / self.sigma) ** 2)
            gy = np.exp(-0.5 * ((y - cy) / self.sigma) ** 2)
            img += self.peak * gy[:, None] * gx[None, :]
        return np.repeat(img[None].astype(np.float32), len(self.bands), axis=0)


class WaveTexture:
    """Band-limited random texture: a sum of random plane waves (exactly shiftable)."""

    bands = ("blue", "green", "red", "nir", "pan")

    def __init__(self, *, seed=0, n=60, texel_m=1.0, min_wavelength_m=9.0, max_wavelength_m=120.0):
        rng = np.random.default_rng(seed)
        lam = np.exp(rng.uniform(np.log(min_wavelength_m), np.log(max_wavelength_m), n))
        th = rng.uniform(0, np.pi, n)
        self.kx = 2 * np.pi / lam * np.cos(th)
        self.ky = 2 * np.pi / lam * np.sin(th)
        self.ph = rng.uniform(0, 2 * np.pi, n)
        self.amp = 0.15 / np.sqrt(n) * np.ones(n)
        self.texel_m = texel_m

    def grid(self, x0_m, y0_m, texel_m, nx, ny):
        x = x0_m + (np.arange(nx) + 0.5) * texel_m
        y = y0_m + (np.arange(ny) + 0.5) * texel_m
        img = np.full((ny, nx), 0.35)
        for kx, ky, ph, a in zip(self.kx, self.ky, self.ph, self.amp):
            img += a * np.cos(ky * y[:, None] + kx * x[None, :] + ph)
        return np.repeat(img[None].astype(np.float32), len(self.bands), axis=0)


def flat_dem(z=0.0, half_x=3000.0, half_y=1500.0, step=25.0):
    x = np.arange(-half_x, half_x + 0.1, step)
    y = np.arange(-half_y, half_y + 0.1, step)
    return Dem(x0_m=x[0], y0_m=y[0], dx_m=step, dy_m=step, z=np.full((y.size, x.size), float(z)))


def small_instrument(*, pixels=96, along=(0.962e-3, 0.0), bands=("green", "blue"), names=("B1", "B0"),
                     time_subsamples=4, mtf_nyquist=0.3):
    dets = tuple(Detector(n, b, a, 0.0, pixels, PITCH) for n, b, a in zip(names, bands, along))
    return Instrument(focal_length_m=F, line_period_s=TE, detectors=dets, mtf_nyquist=mtf_nyquist,
                      time_subsamples=time_subsamples, radiometry=Radiometry(enabled=False))


def centred_platform(instrument, n_lines):
    along = np.mean([d.along_m for d in instrument.detectors])
    return Platform.straight(altitude_m=H, ground_speed_m_s=V).centred(t_mid_s=0.5 * (n_lines - 1) * TE,
                                                              along_angle_rad=np.arctan(along / F))


def spot_centroid(img, l0, c0, half=7):
    """Centroid (line, column) of a bright spot near (l0, c0): background (window border median) removed."""
    li, ci = int(round(l0)), int(round(c0))
    win = img[li - half:li + half + 1, ci - half:ci + half + 1].astype(np.float64)
    win = win - np.median(np.r_[win[0], win[-1], win[:, 0], win[:, -1]])
    ll, cc = np.mgrid[li - half:li + half + 1, ci - half:ci + half + 1]
    w = np.clip(win, 0, None)
    return (w * ll).sum() / w.sum(), (w * cc).sum() / w.sum()


def spot_errors(sm, images, bands, ground, n_lines, *, margin=10):
    """Measured minus inverse-located (line, column) of every spot inside the images of ``bands``, (N, 2)."""
    errs = []
    for band in bands:
        lp, cp = sm.inverse_location(band, ground)
        width = images[band].shape[1]
        for l0, c0 in zip(lp, cp):
            if margin < l0 < n_lines - margin and margin < c0 < width - margin:
                lm, cm = spot_centroid(images[band], l0, c0)
                errs.append((lm - l0, cm - c0))
    return np.array(errs)
