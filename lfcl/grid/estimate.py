"""Estimate the lens grid and the weight model from a white image (docs/calibration.md).

1. **Normalise.** Each CFA colour is divided by its median over the lit pixels
   (those above 20 % of the colour's 99th percentile), so the Bayer pattern does
   not dominate. Refuse images whose 99th percentile is below 2 % of full scale.
2. **Coarse lattice.** The power spectrum of a Hann-windowed central crop (at
   most 2048 x 2048) has peaks at the reciprocal lattice. The shortest strong
   peak and the shortest strong peak in another direction are the reciprocal
   basis (located to a fraction of a frequency bin by a log-parabola); the angle
   between them (90 or 60 degrees) tells square from hex. The offset comes from
   folding the central pixels into one lattice cell: the centre of the (heavily
   smoothed) bright micro-image in the mean cell is a lens centre.
3. **Refinement.** Repeat: assign every pixel to its nearest lens; average the
   white image over the offset from the lens centre into a fine template (0.25 px
   bins, bilinear deposit), made point-symmetric (``T(d) = T(-d)``: a lens's
   micro-image is symmetric about its centre) and smoothed just enough to bridge
   the gaps between the sub-pixel phases the lenses are sampled at; one
   Gauss-Newton step per lens against the template gives each lens centre; fit
   the lattice (origin and two basis vectors, 6 parameters) to all lens centres
   by weighted least squares, rejecting outliers. The first pass uses the centre
   of the sensor (where the coarse lattice is best), the next ones all of it,
   until the grid moves less than 0.002 px anywhere. A slow sensor-wide falloff
   (main-lens vignetting) is divided out first. Above ``max_pixels`` the
   refinement uses an even grid of tiles, not every pixel.
4. **Weight model.** Mean white response per colour on a small table over the
   offset from the lens centre, and a coarse sensor-wide map.
"""

from __future__ import annotations

import math
import time

import numpy as np
import scipy.fft
from scipy import ndimage

from ..layout import channel_map, parse_pattern
from .calibration import Calibration, WeightModel
from .lattice import LensGrid, check_packing

DARK_LIMIT = 0.02  # 99th percentile of the white (normalised) must reach this
FFT_CROP = 2048
SIGNIFICANCE = 100.0  # lattice peak power / median spectral power in the search band
MIN_PITCH = 3.0
TEMPLATE_STEP = 0.25  # px
SMOOTH_PX = (0.12, 0.4)  # template smoothing (Gaussian sigma, px): least / most (see _smoothing)
TABLE_STEPS_PER_PITCH = 16
MAX_PIXELS = 1_500_000
CONVERGED_PX = 0.002  # stop when the grid moves less than this anywhere on the sensor
#: The most the fitted lens centres may scatter around the lattice (rms, px): simulated whites of pitch 4-31, dim
#: and hex included, scatter 0.01-0.05 px, the aligned simulator's white of 10 % contrast 0.30 (its lattice within
#: 0.05 px); a photograph or scene raw taken for a white image 1.4-2.8 px, a 5x5-lens white 0.90, and a lattice
#: fitted from a wrong --pitch hint (45 degrees off, pitch / sqrt 2) 0.66 px, whose light field is garbage.
MAX_LENS_SCATTER_PX = 0.5


class CalibrationError(ValueError):
    """A white image from which no lens grid can be estimated (a user error: one line)."""


# --------------------------------------------------------------------------- helpers

def _colour_index(rows: np.ndarray, cols: np.ndarray, pattern: str | None) -> np.ndarray:
    if pattern is None:
        return np.zeros(np.broadcast(rows, cols).shape, np.int64)
    cells = channel_map((2, 2), pattern)
    return cells[rows % 2, cols % 2]


def _colour_gains(data: np.ndarray, pattern: str | None) -> tuple[np.ndarray, float]:
    """Per-colour normalisers (median of the lit pixels) and the 99th percentile of the image."""
    H, W = data.shape
    stride = 2 * max(1, int(math.sqrt(H * W / 5e5) / 2))
    cells = channel_map((2, 2), pattern) if pattern is not None else np.zeros((2, 2), np.int64)
    phases = {(y, x): np.asarray(data[y::stride, x::stride], np.float64).ravel() for y in range(2) for x in range(2)}
    p99 = float(np.percentile(np.concatenate(list(phases.values())), 99))
    if not math.isfinite(p99) or p99 < DARK_LIMIT:
        raise CalibrationError(
            f"the white image is too dark: 99 % of its pixels are at or below {max(p99, 0) * 100:.2f} % of full scale "
            f"(need at least {DARK_LIMIT * 100:g} %; expose a flat white field at 50-90 %)")
    ncol = 1 if pattern is None else 3
    names = "RGB" if pattern else "Y"
    gains = np.zeros(ncol)
    for c in range(ncol):
        values = np.concatenate([v for (y, x), v in phases.items() if cells[y, x] == c])
        top = np.percentile(values, 99)
        lit = values[values > 0.2 * top]
        gains[c] = float(np.median(lit)) if lit.size else 0.0
        if not gains[c] > 0.2 * DARK_LIMIT:
            raise CalibrationError(f"the white image is too dark in {names[c]} (median {gains[c]:.4f} of full scale)")
    return gains, p99


def _normalised(data: np.ndarray, rows: np.ndarray, cols: np.ndarray, pattern, gains) -> np.ndarray:
    """``data[rows][:, cols]`` divided by the colour gains (float32)."""
    sub = data[np.ix_(rows, cols)].astype(np.float32)
    colour = _colour_index(rows[:, None], cols[None, :], pattern)
    sub /= gains.astype(np.float32)[colour]
    return sub


def _parabolic(lm: float, l0: float, lp: float) -> float:
    denom = lm - 2 * l0 + lp
    if denom >= 0:
        return 0.0
    return float(np.clip(0.5 * (lm - lp) / denom, -0.5, 0.5))


# --------------------------------------------------------------------------- coarse lattice

def _spectrum_peaks(crop: np.ndarray, pitch_hint: float | None):
    """Strong local maxima of the power spectrum: list of (power, k_row, k_col) in cycles/px, and the band median."""
    h, w = crop.shape
    win = np.hanning(h)[:, None].astype(np.float32) * np.hanning(w)[None, :].astype(np.float32)
    img = (crop - np.float32(crop.mean())) * win
    spec = scipy.fft.rfft2(img, workers=-1)
    power = (spec.real.astype(np.float64) ** 2 + spec.imag.astype(np.float64) ** 2)
    ky = np.fft.fftfreq(h)[:, None]
    kx = np.fft.rfftfreq(w)[None, :]
    radius = np.hypot(ky, kx)
    if pitch_hint is not None:
        lo, hi = 0.75 / pitch_hint, 1.4 / pitch_hint
    else:
        lo, hi = 3.5 / min(h, w), 1.0 / MIN_PITCH
    band = (radius >= lo) & (radius <= hi)
    if not np.any(band):
        raise CalibrationError("the white image is too small for the lens pitch")
    # Local maxima whose whole 5x5 neighbourhood is in the band (the tail of the DC lobe has none).
    # The half-plane spectrum is extended by two mirrored columns (P(r, -c) = P(-r, c)) so that
    # peaks on the k_col = 0 column are compared with their true neighbours.
    mirror = (-np.arange(h)) % h
    ext = np.concatenate([power[mirror][:, 2:0:-1], power], axis=1)
    ext_band = np.concatenate([band[mirror][:, 2:0:-1], band], axis=1)
    peak_filter = ndimage.maximum_filter(ext, size=5, mode=("wrap", "nearest"))[:, 2:]
    inner = ndimage.binary_erosion(ext_band, np.ones((5, 5), bool), border_value=1)[:, 2:]
    masked = np.where(band, power, 0.0)
    maxima = (power == peak_filter) & inner & (power > 0)
    idx = np.flatnonzero(maxima)
    if idx.size == 0:
        raise CalibrationError("no lenslet structure in the white image (no peak in its spectrum)")
    order = idx[np.argsort(masked.ravel()[idx])[::-1][:40]]
    background = float(np.median(power[band]))
    logp = np.log(ext + 1e-30)  # column c of the spectrum is column c + 2 here
    peaks = []
    for flat in order:
        r, c = divmod(int(flat), power.shape[1])
        e = c + 2
        dr = _parabolic(logp[(r - 1) % h, e], logp[r, e], logp[(r + 1) % h, e])
        dc = _parabolic(logp[r, e - 1], logp[r, e], logp[r, e + 1]) if e + 1 < ext.shape[1] else 0.0
        k_row = (r + dr if r < (h + 1) // 2 else r + dr - h) / h
        k_col = (c + dc) / w
        peaks.append((float(power[r, c]), k_row, k_col))
    return peaks, background


def _reduce(a: np.ndarray, b: np.ndarray, packing: str):
    """Canonical lattice basis: ``b`` the shortest vector nearest the +col direction, ``a`` the row step
    (square) or the row step + b/2 (hex), pointing down."""
    vectors = np.array([m * a + n * b for m in range(-2, 3) for n in range(-2, 3) if (m, n) != (0, 0)])
    lengths = np.hypot(vectors[:, 0], vectors[:, 1])
    short = vectors[lengths < 1.12 * lengths.min()]
    b_new = short[np.argmax(short[:, 1] / np.hypot(short[:, 0], short[:, 1]))]
    cross = short[:, 0] * b_new[1] - short[:, 1] * b_new[0]
    others = short[np.abs(cross) > 0.5 * (b_new @ b_new)]
    if packing == "square":
        return others[np.argmax(others[:, 0])], b_new
    down = others[others[:, 0] > 0]
    return down[np.argmax(down @ b_new)], b_new


def coarse_lattice(norm_crop: np.ndarray, crop_origin, packing: str, pitch_hint: float | None):
    """``(packing, a, b, origin)`` from the spectrum of a normalised crop; origin in sensor pixels."""
    peaks, background = _spectrum_peaks(norm_crop, pitch_hint)
    top = peaks[0][0]
    if top < SIGNIFICANCE * background:
        raise CalibrationError(
            f"no lenslet structure in the white image (strongest periodic component only "
            f"{top / max(background, 1e-300):.0f}x the spectral background; need {SIGNIFICANCE:g}x)")
    strong = [p for p in peaks if p[0] >= 0.03 * top and p[0] >= SIGNIFICANCE * background]
    vecs = np.array([[p[1], p[2]] for p in strong])
    lengths = np.hypot(vecs[:, 0], vecs[:, 1])
    order = np.argsort(lengths)
    k1 = vecs[order[0]]
    k2 = None
    for idx in order[1:]:
        v = vecs[idx]
        cosang = abs(v @ k1) / (np.linalg.norm(v) * np.linalg.norm(k1))
        if cosang < math.cos(math.radians(25)):
            k2 = v
            break
    if k2 is None:
        raise CalibrationError("no lenslet grid in the white image (its spectrum has one direction only: stripes?)")
    ratio = np.linalg.norm(k2) / np.linalg.norm(k1)
    angle = math.degrees(math.acos(min(1.0, abs(k1 @ k2) / (np.linalg.norm(k1) * np.linalg.norm(k2)))))
    if angle > 78 and ratio < 1.15:
        found = "square"
    elif 50 < angle < 70 and ratio < 1.15:
        found = "hex"
    else:
        raise CalibrationError(
            f"no square or hexagonal lens grid in the white image (its two main periodicities are "
            f"{angle:.0f} degrees apart with lengths in ratio {ratio:.2f})")
    if packing != "auto" and packing != found:
        raise CalibrationError(f"--packing {packing}, but the white image shows a {found} lens grid "
                               f"(spectral peaks {angle:.0f} degrees apart)")
    basis = np.linalg.inv(np.stack([k1, k2]))  # columns: real-space vectors dual to k1, k2
    a, b = _reduce(basis[:, 0], basis[:, 1], found)
    pitch = float(np.linalg.norm(b))
    if pitch < MIN_PITCH:
        raise CalibrationError(f"the lens pitch {pitch:.2f} px is below the minimum of {MIN_PITCH:g} px")

    # Offset: fold the central pixels into one lattice cell; the brightest point is a lens centre.
    h, w = norm_crop.shape
    half = int(min(h, w, max(24 * pitch, 64)) // 2)
    r0, c0 = h // 2 - half, w // 2 - half
    patch = norm_crop[r0:r0 + 2 * half, c0:c0 + 2 * half].astype(np.float64)
    rows = np.arange(r0, r0 + 2 * half)[:, None] + crop_origin[0]
    cols = np.arange(c0, c0 + 2 * half)[None, :] + crop_origin[1]
    centre = np.array([crop_origin[0] + h // 2, crop_origin[1] + w // 2], float)
    inv = np.linalg.inv(np.stack([a, b], axis=1))
    dr, dc = rows - centre[0], cols - centre[1]
    fm = (inv[0, 0] * dr + inv[0, 1] * dc) % 1.0
    fn = (inv[1, 0] * dr + inv[1, 1] * dc) % 1.0
    nb = 24
    bins = (np.floor(fm * nb).astype(np.int64) % nb) * nb + (np.floor(fn * nb).astype(np.int64) % nb)
    sums = np.bincount(bins.ravel(), patch.ravel(), nb * nb)
    counts = np.bincount(bins.ravel(), None, nb * nb)
    cell = np.where(counts > 0, sums / np.maximum(counts, 1), np.nan).reshape(nb, nb)
    cell = np.where(np.isnan(cell), np.nanmean(cell), cell)
    # heavy smoothing turns a flat-topped micro-image into a peak at its centre
    cell = ndimage.gaussian_filter(cell, 0.15 * nb, mode="wrap")
    y, x = np.unravel_index(int(np.argmax(cell)), cell.shape)
    fy = (y + 0.5 + _parabolic(cell[(y - 1) % nb, x], cell[y, x], cell[(y + 1) % nb, x])) / nb
    fx = (x + 0.5 + _parabolic(cell[y, (x - 1) % nb], cell[y, x], cell[y, (x + 1) % nb])) / nb
    origin = centre + fy * a + fx * b
    return found, a, b, origin


# --------------------------------------------------------------------------- refinement

def _sample_axes(H: int, W: int, pitch: float, max_pixels: int):
    """Row and column indices of the pixels used by the refinement (all, or an even grid of tiles)."""
    if max_pixels >= H * W:
        return np.arange(H), np.arange(W)
    side = math.sqrt(max_pixels * H / W), math.sqrt(max_pixels * W / H)
    axes = []
    for length, keep in zip((H, W), side):
        tile = int(max(48, math.ceil(4 * pitch)))
        count = max(2, int(keep // tile))
        if count * tile >= length:
            axes.append(np.arange(length))
            continue
        starts = np.round(np.linspace(0, length - tile, count)).astype(np.int64)
        axes.append((starts[:, None] + np.arange(tile)[None, :]).ravel())
    return axes[0], axes[1]


def _global_map(norm: np.ndarray, rows: np.ndarray, cols: np.ndarray, shape, pitch: float):
    """Coarse sensor-wide falloff (max 1) from the sample, and its value at the sample pixels."""
    H, W = shape
    gr = int(np.clip(H // (6 * pitch), 1, 16))
    gc = int(np.clip(W // (6 * pitch), 1, 16))
    # keep cells that contain sample rows/cols
    gr = min(gr, len(np.unique(rows * gr // H)))
    gc = min(gc, len(np.unique(cols * gc // W)))
    cy = (rows * gr // H).astype(np.int64)
    cx = (cols * gc // W).astype(np.int64)
    ids = (cy[:, None] * gc + cx[None, :]).ravel()
    sums = np.bincount(ids, norm.ravel().astype(np.float64), gr * gc)
    counts = np.bincount(ids, None, gr * gc)
    cells = np.where(counts > 0, sums / np.maximum(counts, 1), np.nan).reshape(gr, gc)
    if np.isnan(cells).any():
        _, (iy, ix) = ndimage.distance_transform_edt(np.isnan(cells), return_indices=True)
        cells = cells[iy, ix]
    cells = cells / cells.max()
    probe = WeightModel(1.0, ("Y",), (1.0,), np.ones((1, 1, 1)), cells)
    at = probe.global_at(rows[:, None], cols[None, :], shape)
    return cells, at


def _smoothing(grid: LensGrid, shape) -> tuple[float, float]:
    """Template smoothing (sigma_row, sigma_col), px, from the sub-pixel phases of the lens centres.

    Lenses at many sub-pixel phases sample the mean micro-image densely and need
    little smoothing; when they share a few phases (an aligned grid of integer or
    half-integer pitch) the widest gap between phases must be bridged (sigma = 0.4
    gap). Per axis, between SMOOTH_PX[0] and SMOOTH_PX[1].
    """
    _, _, rows, cols = grid.centres(shape)
    sigmas = []
    for values in (rows, cols):
        phases = np.unique(np.round(np.mod(values, 1.0), 3))
        gaps = np.diff(np.concatenate([phases, phases[:1] + 1.0])) if phases.size else np.array([1.0])
        sigmas.append(float(np.clip(0.4 * gaps.max(), SMOOTH_PX[0], SMOOTH_PX[1])))
    return sigmas[0], sigmas[1]


class _Bins:
    """Bilinear (cloud-in-cell) positions of offsets ``(dr, dc)`` on the grid ``(k - half) * step``."""

    def __init__(self, dr, dc, half: int, step: float):
        n = 2 * half + 1
        fy = dr / step + half
        fx = dc / step + half
        y0 = np.clip(np.floor(fy), 0, n - 2)
        x0 = np.clip(np.floor(fx), 0, n - 2)
        self.wy = np.clip(fy - y0, 0.0, 1.0)
        self.wx = np.clip(fx - x0, 0.0, 1.0)
        self.base = y0.astype(np.int64) * n + x0.astype(np.int64)
        self.n, self.half, self.step = n, half, step

    def corners(self):
        n, wy, wx = self.n, self.wy, self.wx
        yield 0, (1 - wy) * (1 - wx)
        yield 1, (1 - wy) * wx
        yield n, wy * (1 - wx)
        yield n + 1, wy * wx

    def deposit(self, values):
        """Bilinear-weighted sums of ``values`` and of the weights, ``[n, n]`` each."""
        size = self.n * self.n
        sums = np.zeros(size)
        counts = np.zeros(size)
        for shift, w in self.corners():
            ids = self.base + shift
            sums += np.bincount(ids, w * values, size)
            counts += np.bincount(ids, w, size)
        return sums.reshape(self.n, self.n), counts.reshape(self.n, self.n)

    def sample(self, *tables):
        """The tables interpolated at the positions."""
        stacked = np.stack([t.ravel() for t in tables], axis=1)
        out = np.zeros((self.base.size, len(tables)))
        for shift, w in self.corners():
            out += stacked[self.base + shift] * w[:, None]
        return out.T


def _template(bins: _Bins, values, smooth_px):
    """Point-symmetric mean of ``values`` over the offset grid, and its gradient.

    Values are deposited with bilinear (cloud-in-cell) weights, mirrored (``T(d) =
    T(-d)``) and smoothed by normalised convolution with a Gaussian of ``smooth_px``
    (Nadaraya-Watson kernel regression; ``smooth_px``: sigma, or (sigma_row, sigma_col)).
    The smoothing bridges the gaps between the sub-pixel phases at which the lenses are
    sampled, which is what makes the symmetric centre well defined when every lens is
    sampled at the same few phases (an aligned grid): see :func:`_smoothing`.
    """
    sums, counts = bins.deposit(values)
    sums = sums + sums[::-1, ::-1]
    counts = counts + counts[::-1, ::-1]
    step = bins.step
    sigma = np.broadcast_to(np.asarray(smooth_px, np.float64), (2,)) / step
    if np.any(sigma > 0):
        sums = ndimage.gaussian_filter(sums, sigma, mode="constant")
        counts = ndimage.gaussian_filter(counts, sigma, mode="constant")
    filled = counts > 1e-6 * counts.max()
    table = np.where(filled, sums / np.where(filled, counts, 1.0), 0.0)
    if not filled.all() and filled.any():
        _, (jy, jx) = ndimage.distance_transform_edt(~filled, return_indices=True)
        table = table[jy, jx]
    gy, gx = np.gradient(table, step)
    return table, gy, gx


def _fit_lattice(m, n, cr, cc, weights):
    """Weighted least squares ``c = origin + m a + n b`` with outlier rejection; returns params and inlier mask."""
    keep = weights > 0
    for _ in range(4):
        mm, nn = m[keep], n[keep]
        m0, n0 = mm.mean(), nn.mean()
        X = np.stack([np.ones(mm.size), mm - m0, nn - n0], axis=1)
        sw = np.sqrt(weights[keep])[:, None]
        coef_r = np.linalg.lstsq(X * sw, cr[keep] * sw[:, 0], rcond=None)[0]
        coef_c = np.linalg.lstsq(X * sw, cc[keep] * sw[:, 0], rcond=None)[0]
        full = np.stack([np.ones(m.size), m - m0, n - n0], axis=1)
        res = np.hypot(cr - full @ coef_r, cc - full @ coef_c)
        limit = max(5.0 * float(np.median(res[keep])), 0.15)
        new_keep = (weights > 0) & (res <= limit)
        if np.array_equal(new_keep, keep):
            break
        if new_keep.sum() < 6:
            break
        keep = new_keep
    a = np.array([coef_r[1], coef_c[1]])
    b = np.array([coef_r[2], coef_c[2]])
    origin = np.array([coef_r[0], coef_c[0]]) - m0 * a - n0 * b
    return origin, a, b, keep, res


def refine(norm: np.ndarray, rows: np.ndarray, cols: np.ndarray, grid: LensGrid, shape,
           start_radius: float, iterations: int = 6, progress=None):
    """Gauss-Newton lens centres against a symmetric template + lattice fit (module docstring)."""
    H, W = shape
    pr = np.repeat(rows.astype(np.float64), cols.size)
    pc = np.tile(cols.astype(np.float64), rows.size)
    values = norm.ravel().astype(np.float64)
    del norm
    centre = np.array([(H - 1) / 2, (W - 1) / 2])
    radius = start_radius
    full = math.hypot(H, W) / 2 + grid.pitch
    done_full = 0
    history = []
    pix_radius = np.hypot(pr - centre[0], pc - centre[1])
    while True:
        inside = pix_radius <= radius
        if inside.all():
            m, n, dr, dc = grid.nearest_lattice(pr, pc)
            vals = values
        else:
            m, n, dr, dc = grid.nearest_lattice(pr[inside], pc[inside])
            vals = values[inside]
        pitch = grid.pitch
        bins = _Bins(dr, dc, math.ceil(0.65 * pitch / TEMPLATE_STEP), TEMPLATE_STEP)
        del dr, dc
        smooth = 0.8 if not history else _smoothing(grid, shape)
        table, gy, gx = _template(bins, vals, smooth)
        contrast = (table.max() - table.min()) / max(table.max(), 1e-12)
        if contrast < 0.03:
            raise CalibrationError(f"no lenslet structure in the white image (the mean micro-image has "
                                   f"{contrast * 100:.1f} % contrast)")
        t_val, g_r, g_c = bins.sample(table, gy, gx)
        resid = vals - t_val
        del bins, t_val
        sel = slice(None)
        m_lo, n_lo = m[sel].min(), n[sel].min()
        n_span = int(n[sel].max() - n_lo + 1)
        ids = (m[sel] - m_lo) * n_span + (n[sel] - n_lo)
        k = int(ids.max()) + 1
        s_rr = np.bincount(ids, g_r * g_r, k)
        s_rc = np.bincount(ids, g_r * g_c, k)
        s_cc = np.bincount(ids, g_c * g_c, k)
        b_r = np.bincount(ids, g_r * resid, k)
        b_c = np.bincount(ids, g_c * resid, k)
        present = np.flatnonzero(np.bincount(ids, None, k) > 0)
        s_rr, s_rc, s_cc, b_r, b_c = (v[present] for v in (s_rr, s_rc, s_cc, b_r, b_c))
        ids_u = present
        det = s_rr * s_cc - s_rc * s_rc
        info = np.sqrt(np.maximum(det, 0))
        good = info > 0.25 * np.median(info)
        safe = np.where(good, det, 1.0)
        d_r = -(s_cc * b_r - s_rc * b_c) / safe
        d_c = -(s_rr * b_c - s_rc * b_r) / safe
        step = np.hypot(d_r, d_c)
        good &= step < 0.3 * pitch
        lens_m = ids_u // n_span + m_lo
        lens_n = ids_u % n_span + n_lo
        base_r, base_c = grid.lattice_point(lens_m, lens_n)
        cr, cc = base_r + d_r, base_c + d_c
        if good.sum() < 6:  # before the median of the good ones (none: numpy warns on stderr)
            raise CalibrationError("no lenslet grid in the white image (too few lenses could be located)")
        weights = np.where(good, np.minimum(info / np.median(info[good]), 2.0), 0.0)
        origin, a, b, keep, res = _fit_lattice(lens_m.astype(np.float64), lens_n.astype(np.float64), cr, cc,
                                               weights)
        new_grid = LensGrid.from_lattice(grid.packing, origin, a, b)
        # change of the grid over the sensor corners
        cm = np.array([0, 0, H - 1, H - 1], float)
        cn = np.array([0, W - 1, 0, W - 1], float)
        fm, fn = grid.lattice_coords(cm, cn)
        o_r, o_c = grid.lattice_point(fm, fn)
        n_r, n_c = new_grid.lattice_point(fm, fn)
        change = float(np.max(np.hypot(o_r - n_r, o_c - n_c)))
        history.append({"radius": float(min(radius, full)), "lenses": int(good.sum()), "inliers": int(keep.sum()),
                        "change_px": change})
        grid = new_grid
        if progress:
            progress(history[-1])
        if radius >= full:
            done_full += 1
            if done_full >= iterations or (done_full >= 2 and change < CONVERGED_PX):
                break
        radius = full
    stats = {
        "lenses_located": int(good.sum()),
        "lenses_fitted": int(keep.sum()),
        "outliers": int(good.sum() - keep.sum()),
        "lens_rms_px": float(np.sqrt(np.mean(res[keep] ** 2))),
        "iterations": len(history),
        "last_change_px": history[-1]["change_px"],
        "template_contrast": float(contrast),
        "history": history,
    }
    good_frac = keep.sum() / max(good.sum(), 1)
    if good_frac < 0.5:
        raise CalibrationError(f"no consistent lens grid in the white image (only {good_frac * 100:.0f} % of the "
                               "located lenses fit one lattice)")
    if stats["lens_rms_px"] > min(0.25 * grid.pitch, MAX_LENS_SCATTER_PX):
        raise CalibrationError(f"no consistent lens grid in the white image (lens centres scatter by "
                               f"{stats['lens_rms_px']:.2f} px around the best lattice, more than "
                               f"{min(0.25 * grid.pitch, MAX_LENS_SCATTER_PX):.2f}; a white image, or the right --pitch?)")
    return grid, stats


# --------------------------------------------------------------------------- weight model

def weight_model(data, rows, cols, pattern, grid: LensGrid, global_cells, global_at) -> WeightModel:
    values = data[np.ix_(rows, cols)].astype(np.float64) / global_at
    _, _, dr, dc = grid.nearest(rows[:, None], cols[None, :])
    step = grid.pitch / TABLE_STEPS_PER_PITCH
    half = math.ceil(0.6 * TABLE_STEPS_PER_PITCH)
    n = 2 * half + 1
    iy = np.clip(np.rint(dr / step).astype(np.int64) + half, 0, n - 1)
    ix = np.clip(np.rint(dc / step).astype(np.int64) + half, 0, n - 1)
    colour = _colour_index(rows[:, None], cols[None, :], pattern)
    ncol = 1 if pattern is None else 3
    ids = ((colour * n + iy) * n + ix).ravel()
    sums = np.bincount(ids, values.ravel(), ncol * n * n).reshape(ncol, n, n)
    counts = np.bincount(ids, None, ncol * n * n).reshape(ncol, n, n)
    tables, peaks = [], []
    for c in range(ncol):
        empty = counts[c] == 0
        table = np.where(empty, 0.0, sums[c] / np.maximum(counts[c], 1))
        if empty.any() and not empty.all():
            _, (jy, jx) = ndimage.distance_transform_edt(empty, return_indices=True)
            table = table[jy, jx]
        table = np.maximum(table, 0.0)
        peak = float(table.max())
        tables.append(table / peak if peak > 0 else table)
        peaks.append(max(peak, 1e-9))
    return WeightModel(step_px=step, colours=("R", "G", "B") if pattern else ("Y",), peak=tuple(peaks),
                       local=np.array(tables), global_map=global_cells)


# --------------------------------------------------------------------------- entry points

def calibrate_array(data: np.ndarray, pattern: str | None = None, *, packing: str = "auto",
                    pitch: float | None = None, max_pixels: int = MAX_PIXELS, source: str | None = None,
                    progress=None) -> Calibration:
    """Estimate a :class:`Calibration` from a normalised white mosaic ``[H, W]`` (``(raw - black) / (white - black)``).

    ``pattern``: the CFA pattern (None: no CFA). ``packing``: "auto", "square" or
    "hex". ``pitch``: an approximate pitch (px) to look for. Every failure is a
    one-line :class:`CalibrationError` (a ``ValueError``).
    """
    start = time.perf_counter()
    packing = "auto" if packing == "auto" else check_packing(packing)
    pattern = None if pattern is None else parse_pattern(pattern)
    data = np.asarray(data)
    if data.ndim != 2:
        raise ValueError(f"a white image must be a 2-D mosaic, got shape {list(data.shape)}")
    H, W = data.shape
    if min(H, W) < 32:
        raise CalibrationError(f"the white image is too small ({H}x{W}) to calibrate")
    if not np.isfinite(data[:: max(1, H // 512), :: max(1, W // 512)]).all():
        raise ValueError("the white image holds NaN or infinite values")
    if pitch is not None:
        pitch = float(pitch)
        if not math.isfinite(pitch) or pitch < MIN_PITCH or pitch > min(H, W) / 6:
            raise ValueError(f"--pitch {pitch:g} is outside {MIN_PITCH:g}..{min(H, W) / 6:.0f} px for this image")
    gains, p99 = _colour_gains(data, pattern)

    ch, cw = min(H, FFT_CROP), min(W, FFT_CROP)
    r0, c0 = (H - ch) // 2, (W - cw) // 2
    crop = _normalised(data, np.arange(r0, r0 + ch), np.arange(c0, c0 + cw), pattern, gains)
    found, a, b, origin = coarse_lattice(crop, (r0, c0), packing, pitch)
    del crop
    grid = LensGrid.from_lattice(found, origin, a, b)
    if grid.pitch > min(H, W) / 6 + 0.01:  # the coarse pitch of exactly 6 lenses across comes out a hair above
        raise CalibrationError(f"the lens pitch {grid.pitch:.1f} px is too large for a {H}x{W} image "
                               "(fewer than 6 lenses across)")
    t_coarse = time.perf_counter() - start

    rows, cols = _sample_axes(H, W, grid.pitch, max_pixels)
    norm = _normalised(data, rows, cols, pattern, gains)
    cells, at = _global_map(norm, rows, cols, (H, W), grid.pitch)
    norm /= at.astype(np.float32)
    grid, stats = refine(norm, rows, cols, grid, (H, W), start_radius=0.45 * min(ch, cw), progress=progress)
    del norm
    grid = grid.canonical()
    weight = weight_model(data, rows, cols, pattern, grid, cells, at)
    fit = {
        "method": "spectrum peaks -> coarse lattice; symmetric-template Gauss-Newton lens centres -> "
                  "weighted least-squares lattice with outlier rejection",
        "packing_detected": found,
        "packing_requested": packing,
        "pixels_used": int(rows.size * cols.size),
        "colour_normalisers": [float(g) for g in gains],
        "white_p99": p99,
        **stats,
        "seconds": {"coarse": round(t_coarse, 3), "total": round(time.perf_counter() - start, 3)},
    }
    return Calibration(grid=grid, sensor_shape=(H, W), pattern=pattern, weight=weight, fit=fit, source=source)


def calibrate_white(path, pattern: str | None = None, **kwargs) -> Calibration:
    """Read a white image (raw, DNG or image file, via :func:`lfcl.io.raw.read_mosaic`) and calibrate."""
    from ..io.raw import read_mosaic

    mosaic = read_mosaic(path, pattern)
    return calibrate_array(mosaic.data, mosaic.pattern, source=str(path), **kwargs)


def calibration_from_pitch(pitch: float, sensor_shape, packing: str = "square", rotation_deg: float = 0.0,
                           offset=(0.0, 0.0), pattern: str | None = None) -> Calibration:
    """A calibration from the grid parameters alone (no white image, uniform weight)."""
    from ..io.raw import MAX_PIXELS

    values = {"pitch": pitch, "rotation": rotation_deg, "offset row": offset[0], "offset column": offset[1]}
    for name, value in values.items():
        if not (isinstance(value, (int, float)) and math.isfinite(value) and abs(value) <= 1e6):
            raise ValueError(f"{name} must be a finite number of at most 1e6, got {value!r}")
    if abs(rotation_deg) > 45:  # as lfcl simulate: a grid turned 90 degrees is itself, its rows taken for columns
        raise ValueError(f"the rotation must be within +-45 degrees, got {rotation_deg:g} (a grid turned by 90 "
                         "degrees is the same grid, with its lens rows and columns swapped)")
    H, W = (int(v) for v in sensor_shape)
    if H < 1 or W < 1 or H * W > MAX_PIXELS:
        raise ValueError(f"sensor shape {H}x{W} is outside 1 .. {MAX_PIXELS} pixels")
    grid = LensGrid.from_params("square" if packing == "auto" else packing, pitch, rotation_deg, offset)
    cal = Calibration(grid=grid, sensor_shape=tuple(sensor_shape), pattern=pattern, weight=None,
                      fit={"method": "from parameters (no white image)"}, source=None)
    if grid.pitch > min(cal.sensor_shape):
        raise ValueError(f"pitch {pitch:g} px is larger than the {cal.sensor_shape[0]}x{cal.sensor_shape[1]} sensor")
    return cal
