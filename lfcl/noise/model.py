"""Noise level of a lenslet raw, estimated from the raw itself.

Each microlens sees a small, smooth patch of the scene through its inner pixels.
Per lens and colour we fit a plane ``a + b*u + c*v`` to that colour's samples in
the inner ``(U-2) x (V-2)`` pixels (the rim is vignetted) and keep the residual
variance; smooth patches leave almost pure noise. Binned by brightness, the
variances follow the Poisson-Gaussian model ``var = gain * mean + floor``, fitted
robustly (a low quantile per bin, see QUANTILE). ``sigma`` is the rms noise per raw pixel over the whole
mosaic, in the normalised units of (raw - black) / (white - black).

A DNG NoiseProfile (``var = S * x + O`` per plane), where present, gives the same
model directly and takes precedence (see :func:`from_noise_profile`).
"""

from __future__ import annotations

import dataclasses
import itertools
import math

import numpy as np
import scipy.special

from ..layout import channel_map


@dataclasses.dataclass(frozen=True)
class NoiseEstimate:
    gain: float  # variance per unit signal (shot noise)
    floor: float  # variance at zero signal (read noise, dark current)
    sigma: float  # rms noise per pixel over the mosaic
    source: str  # "raw" (estimated) or "dng-noise-profile"
    method: str = ""  # of a "raw" estimate: "plane fit" (inside the micro-images), "epipolar pairs" or "epipolar fit"

    def sigma_at(self, level: float) -> float:
        return math.sqrt(max(self.gain * level + self.floor, 0.0))


# Lenses whose view of the scene is textured inflate the residual variance; flat
# ones show only noise. So per brightness bin we take a low quantile of the lens
# variances and rescale it by the same quantile of the pure-noise distribution
# (sigma^2 chi^2_dof / dof), which is unbiased when at least that share of the lenses
# in the bin is flat.
QUANTILE = 0.02  # fitted on training captures: research/fit_noise.py (docs/noise.md)
#: The noise line is refitted this many times with each brightness bin weighed by 1 / var^2 (its quantile's error is
#: about one share of its variance), the line's variance floored at WEIGHT_FLOOR x the bins' median so that a bin at
#: 0 does not take all the weight. Unweighted, the bright bins' scatter set the floor: 0 to 70x the truth (docs/noise.md).
REWEIGHTS = 5
WEIGHT_FLOOR = 0.05
#: Lens colours an estimate along the epipolar lines (lfcl.noise.epipolar) needs: 64 lenses' worth.
MIN_LENS_COLOURS = 3 * 64


def _plane_residual_variances(block: np.ndarray, mask: np.ndarray):
    """Per lens: (mean, residual variance) of the samples where ``mask`` is set.

    block: [n_lenses, h, w] inner pixels of each lens; mask: [h, w] bool. The
    variances come rescaled so that their QUANTILE-quantile is sigma^2 for pure noise.
    """
    rows, cols = np.nonzero(mask)
    design = np.stack([np.ones(rows.size), rows - rows.mean(), cols - cols.mean()], axis=1)
    projection = np.eye(rows.size) - design @ np.linalg.pinv(design)
    samples = block[:, rows, cols].astype(np.float64)
    residual = samples @ projection.T
    dof = rows.size - design.shape[1]
    to_sigma2 = dof / scipy.special.chdtri(dof, 1 - QUANTILE)  # the chi-square QUANTILE-quantile
    return samples.mean(axis=1), (residual**2).sum(axis=1) / dof * to_sigma2


def estimate_noise(mosaic: np.ndarray, pattern: str, pitch, origin=(0, 0), bins: int = 16,
                   light_field: bool = True, device=None) -> NoiseEstimate:
    """Poisson-Gaussian noise model of a normalised lenslet mosaic [H, W].

    Three estimates, each of which texture can only inflate: the plane fit inside each micro-image (module
    docstring) and, with ``light_field``, two along the epipolar lines (:mod:`lfcl.noise.epipolar`, its
    disparity on ``device``), each where it has at least :data:`MIN_LENS_COLOURS` lens colours: the same-point
    sample pairs, and a quadratic fit to each lens's samples in the scene's coordinates. The one with the lowest
    sigma is returned (``method`` says which).
    """
    U, V = pitch
    H, W = mosaic.shape
    S, T = H // U, W // V
    if S < 2 or T < 2 or U < 4 or V < 4:
        raise ValueError(f"too few lenses or pixels per lens ({S}x{T} lenses of {U}x{V}) to estimate the noise")
    channels = channel_map((H, W), pattern, origin)
    means, variances = [], []
    # Lenses whose first pixel has the same Bayer parity share one sample layout.
    for ps in range(min(2, S)):
        for pt in range(min(2, T)):
            rows = slice(ps * U, S * U, 2 * U) if U % 2 else slice(0, S * U, U)
            cols = slice(pt * V, T * V, 2 * V) if V % 2 else slice(0, T * V, V)
            lens_rows = np.arange(S * U)[rows]
            lens_cols = np.arange(T * V)[cols]
            if lens_rows.size == 0 or lens_cols.size == 0:
                continue
            r0, c0 = lens_rows[0], lens_cols[0]
            lenses = np.stack([
                mosaic[r + 1:r + U - 1, c + 1:c + V - 1] for r in lens_rows for c in lens_cols
            ])
            layout = channels[r0 + 1:r0 + U - 1, c0 + 1:c0 + V - 1]
            for colour in range(3):
                mask = layout == colour
                if mask.sum() > 4:
                    m, v = _plane_residual_variances(lenses, mask)
                    means.append(m)
                    variances.append(v)
            if U % 2 == 0 and V % 2 == 0:
                break
        if U % 2 == 0 and V % 2 == 0:
            break
    means = np.concatenate(means)
    variances = np.concatenate(variances)
    keep = np.isfinite(means) & np.isfinite(variances)
    means, variances = means[keep], variances[keep]
    gain, floor = fit_noise_model(means, variances, bins)
    level = float(np.mean(mosaic))
    plane = NoiseEstimate(gain, floor, math.sqrt(max(gain * level + floor, 0.0)), "raw", "plane fit")
    if not light_field:
        return plane
    from .epipolar import tile_variances

    best = plane
    found = tile_variances(np.asarray(mosaic, np.float32), pattern, (U, V), origin, plane, device)
    for method, (levels, variances, dof) in zip(("epipolar pairs", "epipolar fit"), found):
        if levels.size < MIN_LENS_COLOURS:
            continue
        gain, floor = fit_noise_model(levels, variances * dof / scipy.special.chdtri(dof, 1 - QUANTILE), bins)
        estimate = NoiseEstimate(gain, floor, math.sqrt(max(gain * level + floor, 0.0)), "raw", method)
        best = estimate if estimate.sigma < best.sigma else best
    return best


def fit_noise_model(means: np.ndarray, variances: np.ndarray, bins: int) -> tuple[float, float]:
    """(gain, floor) of var = gain * mean + floor, fitted to per-lens (mean, residual variance) pairs.

    The pairs are binned by brightness (quantile bins with at least 8 members) and each
    bin keeps a low quantile of its variances: textured lenses inflate the variance, flat
    ones do not. Both coefficients are clipped at 0.

    A bin must hold one brightness: one that straddles a gap in the levels (pure-colour content, whose lit and unlit
    samples are far apart) is split at its widest gap where that is over half its span; else its low quantile is the
    dark members' and its centre lies between them and the lit ones (the fit along the disparity read a red/blue
    checker at 0.83x its gain and 0.58x its floor; docs/noise.md).
    """
    edges = np.unique(np.quantile(means, np.linspace(0, 1, bins + 1)))
    centres, levels = [], []
    for lo, hi in itertools.pairwise(edges):
        inside = np.sort(means[(means >= lo) & (means <= hi)])
        gaps = np.diff(inside)
        parts = [(lo, hi)]
        if gaps.size and gaps.max() > (hi - lo) / 2:
            cut = int(np.argmax(gaps))
            parts = [(lo, inside[cut]), (inside[cut + 1], hi)]
        for a, b in parts:
            inside = (means >= a) & (means <= b)
            if inside.sum() >= 8:
                centres.append(np.median(means[inside]))
                levels.append(np.quantile(variances[inside], QUANTILE))
    if len(centres) < 2:
        return 0.0, float(np.quantile(variances, QUANTILE))
    x, y = np.asarray(centres, np.float64), np.asarray(levels, np.float64)
    gain, floor = _non_negative_line(x, y)
    for _ in range(REWEIGHTS):  # each bin's quantile errs by about one share of its variance: weigh by 1 / var^2
        line = gain * x + floor
        if not np.median(line) > 0:
            break
        gain, floor = _non_negative_line(x, y, 1.0 / np.maximum(line, WEIGHT_FLOOR * float(np.median(line))) ** 2)
    if gain == 0.0 and floor <= 0.0:
        floor = float(np.quantile(variances, QUANTILE))
    return gain, floor


def _non_negative_line(x: np.ndarray, y: np.ndarray, w: np.ndarray | None = None) -> tuple[float, float]:
    """(gain, floor) of the (``w``-weighted) least-squares line y = gain x + floor with both coefficients >= 0.

    Where the free fit puts one below 0, the optimum lies on a face (gain = 0 or floor = 0): the better of the two.
    Clipping the free fit instead kept its other coefficient, which on a raw of one brightness (a flat wall)
    extrapolates a noise-steep line to 0: a floor several times the noise (docs/noise.md).
    """
    w = np.ones_like(x) if w is None else w
    gain, floor = (float(c) for c in np.polyfit(x, y, 1, w=np.sqrt(w)))
    if gain >= 0 and floor >= 0:
        return gain, floor
    wxx = float((w * x) @ x)
    faces = [(0.0, max(float(w @ y) / float(w.sum()), 0.0)), (max(float((w * x) @ y) / wxx, 0.0) if wxx > 0 else 0.0, 0.0)]
    return min(faces, key=lambda line: float(w @ (line[0] * x + line[1] - y) ** 2))


def from_noise_profile(profile, mosaic: np.ndarray) -> NoiseEstimate:
    """The model of a DNG NoiseProfile ``[S1, O1, S2, O2, ...]`` (averaged over planes)."""
    pairs = np.asarray(profile, dtype=np.float64).reshape(-1, 2)
    gain, floor = float(pairs[:, 0].mean()), float(pairs[:, 1].mean())
    level = float(np.mean(mosaic))
    return NoiseEstimate(gain, floor, math.sqrt(max(gain * level + floor, 0.0)), "dng-noise-profile")
