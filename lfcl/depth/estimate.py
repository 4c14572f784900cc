"""Disparity per centre-view lens from the lenslet raw itself (docs/depth.md).

:func:`estimate_disparity` runs four steps:

1. the cost volume of :mod:`lfcl.depth.cost` over candidates ``d`` in ``[-dmax, dmax]`` (step
   ``step``): per lens and ``d``, how badly one plane per colour explains the ~81 raw samples
   gathered along the lens's epipolar lines, in noise units (0 for pure noise);
2. aggregation over a ``(2 radius + 1)^2`` window of lenses, each lens weighted by how much it
   resembles the centre lens (a guide image: the centre 3x3 pixels of each micro-image, per
   colour; ``exp(-z^2 / guide_sigma^2)``, z the difference in noise units; the default
   ``guide_sigma`` is wide: a narrower one measured worse, docs/depth.md);
   ``occlusion`` (on) also aggregates the cost of the four half apertures (views above, below,
   left, right of the centre, each with the centre row or column) and keeps, per lens, the curve
   whose minimum is lowest, a half having to win by twice its cost noise: near an occlusion edge
   one half still sees the background;
3. the best candidate and a parabola through it and its neighbours (sub-step precision), and a
   confidence from the cost curve: how much higher the lowest cost at least ``exclusion`` away
   from the best (a second minimum, or the walls of a broad valley) lies, in units of the cost's
   own noise plus half the best cost (flat, texture-less lenses, and lenses no candidate
   explains: ~0), times the share of unsaturated samples of the lens;
4. optional (``smooth > 0``; off by default, it cost BadPix at occlusion edges in the
   measurements of docs/depth.md): confidence-weighted least squares with an edge-aware
   smoothness term, so that lenses of low confidence take their neighbours' value; the returned
   ``confidence`` stays the step-3 one (0 = unknown).

Steps 1 and 2 (the window weights too) and step 3's choice between apertures run on the device
(lfcl/kernels/depth.cl, depth_aggregate.cl; only the chosen cost curve comes back), the rest on the host;
``backend="numpy"`` runs their float64 twins.

Units and sign: ``d`` in lenses per view step; a point seen at lens ``(s, t)`` in the centre view
``(uc, vc)`` is seen by view ``(u, v)`` at lens ``(s - d (u - uc), t - d (v - vc))`` (HCI's sign).
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from ..layout import parse_pattern, pattern_channels
from . import _checks
from .cost import (
    MODELS,
    CostVolume,
    WindowAggregate,
    aggregate_window_np,
    cost_volume_np,
    half_apertures,
    window_offsets,
)

DEFAULTS = {
    "dmax": 2.0,  # search range [-dmax, dmax], lenses per view step
    "step": 0.05,  # candidate spacing
    "radius": 4,  # aggregation window (2 radius + 1)^2 lenses
    "guide_sigma": 30.0,  # guide-image difference (noise units) at which a neighbour's weight falls to 1/e
    "model": "plane",  # per-colour model of the gathered samples: "plane" or "mean"
    "saturation": 0.99,  # samples at or above this (normalised raw) are left out
    "smooth": 0.0,  # step 4's smoothness weight; 0: off (measured: it costs BadPix at occlusion edges)
    "smooth_sigma": 1.0,  # smallest Gaussian scale (lenses) of step 4
    "exclusion": 0.25,  # the confidence compares the best cost with the lowest one this far away
    "confidence_z": 4.0,  # distinctiveness (noise units) at which the confidence reaches 1 - 1/e
    "occlusion": True,  # also try the four half apertures (top, bottom, left, right views) per lens
    "colour": 0.03,  # the colour penalty's weight (lfcl.depth.cost): a candidate pays for colour its lens lacks; 0: off
    "clipped": True,  # clipped samples bound their colour's fit from below (lfcl.depth.cost, "Clipped samples")
    "backend": "device",  # "device" (lfcl/kernels/depth.cl) or "numpy" (the float64 twin)
}


@dataclasses.dataclass
class DisparityMap:
    """A disparity per centre-view lens and how far to trust it.

    ``disparity`` float32 [S, T]: lenses per view step, HCI's sign (module docstring).
    ``confidence`` float32 [S, T] in [0, 1]: 0 = unknown (no texture, occlusion, saturated).
    ``disparities``: the candidates searched; ``options``, ``noise`` and ``seconds``: what
    was used (:meth:`as_dict`).
    """

    disparity: np.ndarray
    confidence: np.ndarray
    dmax: float
    step: float
    options: dict
    noise: dict
    seconds: dict

    @property
    def disparities(self) -> np.ndarray:
        return candidates(self.dmax, self.step)

    def as_dict(self) -> dict:
        """Metadata: units, sign, search range and step, options, noise model, seconds."""
        return {
            "units": "lenses per view step",
            "sign": "a point at lens (s, t) of the centre view (uc, vc) is seen by view (u, v) at lens "
                    "(s - d (u - uc), t - d (v - vc)) (HCI benchmark sign)",
            "search_range": [-float(self.dmax), float(self.dmax)],
            "step": float(self.step),
            "lenses": list(self.disparity.shape),
            "options": dict(self.options),
            "noise": dict(self.noise),
            "seconds": dict(self.seconds),
        }


def candidates(dmax: float, step: float) -> np.ndarray:
    """The searched disparities: ``-dmax .. dmax`` in steps of ``step`` (symmetric about 0)."""
    n = int(np.floor(dmax / step + 1e-6))
    return (np.arange(-n, n + 1) * step).astype(np.float32)


def _validate_mosaic(mosaic) -> np.ndarray:
    array = np.asarray(mosaic)
    if array.dtype == np.bool_ or not (np.issubdtype(array.dtype, np.integer)
                                       or np.issubdtype(array.dtype, np.floating)):
        raise ValueError(f"mosaic must have a real numeric dtype, got {array.dtype}")
    if array.ndim != 2:
        raise ValueError(f"mosaic must have shape [H, W], got {array.shape}")
    array = np.ascontiguousarray(array, dtype=np.float32)
    if not np.all(np.isfinite(array)):
        raise ValueError("mosaic holds NaN or Inf values: depth needs a finite raw")
    return array


def _options(options: dict) -> dict:
    unknown = sorted(set(options) - set(DEFAULTS))
    if unknown:
        raise ValueError(f"unknown disparity options {', '.join(unknown)}: choose from {', '.join(DEFAULTS)}")
    out = {**DEFAULTS, **options}
    for name in ("dmax", "step", "guide_sigma", "smooth_sigma", "confidence_z", "saturation"):
        value = out[name]
        if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)) \
                or not np.isfinite(value) or value <= 0:
            raise ValueError(f"disparity option {name} must be a finite number > 0, got {value!r}")
        out[name] = float(value)
    for name in ("smooth", "exclusion", "colour"):
        value = out[name]
        if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)) \
                or not np.isfinite(value) or value < 0:
            raise ValueError(f"disparity option {name} must be a finite number >= 0, got {value!r}")
        out[name] = float(value)
    if out["step"] > out["dmax"]:
        raise ValueError(f"disparity step {out['step']:g} is larger than dmax {out['dmax']:g}")
    if isinstance(out["radius"], bool) or not isinstance(out["radius"], (int, np.integer)) or out["radius"] < 0:
        raise ValueError(f"disparity option radius must be an integer >= 0, got {out['radius']!r}")
    out["radius"] = int(out["radius"])
    for name in ("occlusion", "clipped"):
        if not isinstance(out[name], bool):
            raise ValueError(f"disparity option {name} must be true or false, got {out[name]!r}")
    if out["model"] not in MODELS:
        raise ValueError(f"disparity option model must be one of {', '.join(MODELS)}, got {out['model']!r}")
    if out["backend"] not in ("device", "numpy"):
        raise ValueError(f"disparity option backend must be 'device' or 'numpy', got {out['backend']!r}")
    return out


def _noise_model(mosaic, pattern, pitch, origin, noise, device=None) -> tuple[float, float, dict]:
    """(gain, floor, metadata) of the Poisson-Gaussian model ``var = gain * x + floor``.

    ``noise`` given (lfcl.noise.model.NoiseEstimate): used as is. Else estimated from the raw
    (lfcl.noise.model.estimate_noise); a raw too small for that (fewer than 2x2 lenses of 4x4)
    gets a constant variance from the median absolute difference of same-colour neighbours
    two columns apart (said in the metadata as ``source: "mad"``).
    """
    if noise is not None:
        gain, floor = float(noise.gain), float(noise.floor)
        if not (np.isfinite(gain) and np.isfinite(floor)) or gain < 0 or floor < 0:
            raise ValueError(f"noise model must be finite and >= 0, got gain {gain!r}, floor {floor!r}")
        return gain, floor, {"gain": gain, "floor": floor, "source": str(noise.source)}
    from ..noise.model import estimate_noise

    try:
        est = estimate_noise(mosaic, pattern, pitch, origin, device=device)
        return float(est.gain), float(est.floor), {"gain": est.gain, "floor": est.floor, "source": est.source}
    except ValueError:
        pass
    if mosaic.shape[1] >= 3:
        diff = (mosaic[:, 2:] - mosaic[:, :-2]).ravel()
    elif mosaic.shape[0] >= 3:
        diff = (mosaic[2:] - mosaic[:-2]).ravel()
    else:
        diff = np.zeros(1)
    mad = float(np.median(np.abs(diff - np.median(diff))))
    floor = max((1.4826 * mad) ** 2 / 2.0, 1e-8)
    return 0.0, floor, {"gain": 0.0, "floor": floor, "source": "mad"}


def _guide(mosaic, pattern, pitch, origin, S, T) -> np.ndarray:
    """Per lens and colour: the mean of that colour's samples in the centre 3x3 (at most) pixels: [3, S, T]."""
    U, V = pitch
    r0, r1 = max(0, U // 2 - 1), min(U, U // 2 + 2)
    c0, c1 = max(0, V // 2 - 1), min(V, V // 2 + 2)
    m4 = mosaic.reshape(S, U, T, V)[:, r0:r1, :, c0:c1]
    # The colours of just those pixels (a whole-sensor channel map took most of this function's time).
    cells = pattern_channels(pattern, origin)
    rows = (np.arange(S)[:, None] * U + np.arange(r0, r1)[None, :]) % 2  # [S, rows]
    cols = (np.arange(T)[:, None] * V + np.arange(c0, c1)[None, :]) % 2  # [T, cols]
    ch = cells[rows[:, :, None, None], cols[None, None, :, :]]
    out = np.empty((3, S, T), np.float64)
    overall = m4.mean(axis=(1, 3))
    for c in range(3):
        sel = ch == c
        count = sel.sum(axis=(1, 3))
        total = np.where(sel, m4, 0.0).sum(axis=(1, 3))
        out[c] = np.where(count > 0, total / np.maximum(count, 1), overall)
    return out


def _guide_scale(guide, sigma, gain, floor):
    """Per colour and lens, 1 / (3 nv sigma^2): a neighbour's ``z^2 / sigma^2`` is the sum over colours of its
    squared guide difference times it (nv the lens's noise variance per colour)."""
    nv = gain * np.maximum(guide, 0) + floor
    # The guide averages ~2-5 samples per colour: its noise variance is about nv / 2.
    return 1.0 / (3.0 * sigma * sigma * np.maximum(nv, 1e-12))


def _window_weights(guide, radius, sigma, gain, floor):
    """Per offset (dy, dx) in the window: [n, S, T] weights exp(-(guide difference / noise)^2 / sigma^2), the mean
    over colours of the squared differences in noise units; 0 for a neighbour outside the frame. The twin of
    lfcl/kernels/depth_aggregate.cl ``depth_window_weights``."""
    _, S, T = guide.shape
    scale = _guide_scale(guide, sigma, gain, floor)
    offsets = window_offsets(radius)
    weights = np.empty((len(offsets), S, T))
    pad = np.pad(guide, ((0, 0), (radius, radius), (radius, radius)), mode="edge")
    valid = np.pad(np.ones((S, T)), radius)
    diff = np.empty_like(guide)
    for n, (dy, dx) in enumerate(offsets):  # the buffers reused: one pass per operation
        np.subtract(pad[:, radius + dy:radius + dy + S, radius + dx:radius + dx + T], guide, out=diff)
        np.multiply(diff, diff, out=diff)
        np.multiply(diff, scale, out=diff)
        np.sum(diff, axis=0, out=weights[n])
        np.exp(np.negative(weights[n], out=weights[n]), out=weights[n])
        weights[n] *= valid[radius + dy:radius + dy + S, radius + dx:radius + dx + T]
    return offsets, weights


def take_aperture_np(best, agg_excess, agg_weight, half: bool):
    """Step 3's choice between apertures, one at a time: an aperture's cost curve ``excess / weight`` (its window
    sums ``[ND, S, T]``), the cost's noise ``sqrt(2 / largest weight)`` (excess / weight of pure noise has a
    standard deviation ~ sqrt(2 / weight)) and its score, the curve's minimum, plus twice the noise for a half
    aperture (it must beat the full one by more than its own noise). Returns ``(curve, score, noise)``, taking this
    aperture's where its score is lower than ``best``'s (None: the first aperture). The twin of
    lfcl/kernels/depth_aggregate.cl ``depth_take_aperture``."""
    curve = agg_excess / np.maximum(agg_weight, 1e-12)
    noise = np.sqrt(2.0 / np.maximum(agg_weight.max(axis=0), 1e-12))
    score = curve.min(axis=0) + (2.0 * noise if half else 0.0)
    if best is None:
        return curve, score, noise
    take = score < best[1]
    return np.where(take[None], curve, best[0]), np.where(take, score, best[1]), np.where(take, noise, best[2])


def _best(cost, ds, exclusion):
    """Argmin + parabola (sub-step), and the lowest cost at least ``exclusion`` away: per lens."""
    ND = cost.shape[0]
    k = np.argmin(cost, axis=0)
    S, T = k.shape
    ii, jj = np.meshgrid(np.arange(S), np.arange(T), indexing="ij")
    c0 = cost[k, ii, jj]
    km, kp = np.clip(k - 1, 0, ND - 1), np.clip(k + 1, 0, ND - 1)
    cm, cp = cost[km, ii, jj], cost[kp, ii, jj]
    curv = cm - 2 * c0 + cp
    inner = (k > 0) & (k < ND - 1) & (curv > 0)
    offset = np.where(inner, 0.5 * (cm - cp) / np.where(inner, curv, 1.0), 0.0)
    step = float(ds[1] - ds[0]) if ND > 1 else 0.0
    disparity = ds[k] + np.clip(offset, -0.5, 0.5) * step
    # The lowest cost at least `exclusion` from the best: a second minimum, or the walls of a broad
    # valley (a texture-less lens's curve is flat, so both count as "not sure").
    far = np.abs(ds[:, None, None] - ds[k][None]) >= exclusion - 1e-6
    other = np.where(far, cost, np.inf).min(axis=0)
    # The search range is narrower than `exclusion`: the curve's largest value instead.
    other = np.where(np.isfinite(other), other, cost.max(axis=0))
    return disparity, c0, other


def _normalised_convolution(values, weights, sigma):
    from scipy.ndimage import gaussian_filter

    num = gaussian_filter(values * weights, sigma, mode="constant")
    den = gaussian_filter(weights, sigma, mode="constant")
    return num, den


def _fill(disparity, confidence, sigma0, centre):
    """Multi-scale normalised convolution: each lens gets the confidence-weighted mean of its
    neighbours at the smallest Gaussian scale with enough confident support (``centre`` where none)."""
    S, T = disparity.shape
    filled = np.full((S, T), np.nan)
    sigma = sigma0
    while True:
        num, den = _normalised_convolution(disparity, confidence, sigma)
        ok = np.isnan(filled) & (den > 0.2)
        filled[ok] = num[ok] / den[ok]
        if not np.isnan(filled).any() or sigma > 2 * max(S, T):
            break
        sigma *= 2
    rest = np.isnan(filled)
    if rest.any():  # little confidence anywhere: whatever support there is, else the range's centre
        num, den = _normalised_convolution(disparity, confidence, sigma)
        filled[rest] = np.where(den[rest] > 1e-9, num[rest] / np.maximum(den[rest], 1e-30), centre)
    return filled


def _smooth(disparity, confidence, links, strength, sigma0, centre, iterations=300):
    """Step 4: confidence-weighted least squares with edge-aware smoothness (a weighted Laplacian).

    min_d sum_i a_i (d_i - r_i)^2 + strength * sum_(i,j) w_ij (d_i - d_j)^2 over 4-neighbours,
    ``a_i = c_i / (1 - c_i + 0.001)`` (a confident lens keeps its own value, an unknown one takes its
    neighbours'),
    ``w_ij`` from the guide (``links``: weights to the lens below and to the right, [2, S, T]);
    solved by Jacobi-preconditioned conjugate gradients from the multi-scale fill.
    """
    c = confidence.astype(np.float64)
    c = c / (1.0 - np.minimum(c, 1.0) + 1e-3) + 1e-6
    wd = strength * links[0, :-1, :]  # (i, j) -- (i + 1, j)
    wr = strength * links[1, :, :-1]  # (i, j) -- (i, j + 1)
    diag = c.copy()
    diag[:-1] += wd
    diag[1:] += wd
    diag[:, :-1] += wr
    diag[:, 1:] += wr

    def apply(x):
        out = c * x
        dd = wd * (x[:-1] - x[1:])
        out[:-1] += dd
        out[1:] -= dd
        dr = wr * (x[:, :-1] - x[:, 1:])
        out[:, :-1] += dr
        out[:, 1:] -= dr
        return out

    b = c * disparity
    x = _fill(disparity, confidence, sigma0, centre)
    x = np.where(confidence > 0.5, disparity, x)
    r = b - apply(x)
    z = r / diag
    p = z.copy()
    rz = float(np.vdot(r, z))
    norm_b = float(np.sqrt(np.vdot(b, b))) + 1e-30
    for _ in range(iterations):
        ap = apply(p)
        alpha = rz / max(float(np.vdot(p, ap)), 1e-300)
        x += alpha * p
        r -= alpha * ap
        if np.sqrt(np.vdot(r, r)) < 1e-6 * norm_b:
            break
        z = r / diag
        rz_new = float(np.vdot(r, z))
        p = z + (rz_new / max(rz, 1e-300)) * p
        rz = rz_new
    return x


def _links(guide, sigma, gain, floor):
    """Edge-aware weights between each lens and the lens below / to the right: [2, S, T] in (0, 1]."""
    nv = np.maximum(gain * np.maximum(guide, 0) + floor, 1e-12)
    out = np.zeros((2,) + guide.shape[1:])
    dz = ((guide[:, 1:] - guide[:, :-1]) ** 2 / (nv[:, 1:] + nv[:, :-1])).mean(axis=0)
    out[0, :-1] = np.exp(-dz / (sigma * sigma))
    dz = ((guide[:, :, 1:] - guide[:, :, :-1]) ** 2 / (nv[:, :, 1:] + nv[:, :, :-1])).mean(axis=0)
    out[1, :, :-1] = np.exp(-dz / (sigma * sigma))
    return out


def estimate_disparity(mosaic, pattern, pitch, *, origin=(0, 0), noise=None, device=None, **options) -> DisparityMap:
    """Disparity and confidence per centre-view lens of a normalised lenslet mosaic (module docstring).

    ``mosaic`` [S*U, T*V] (whole lenses of an aligned grid whose first lens starts at pixel 0, 0 of
    the array), ``pattern`` a Bayer name, ``pitch`` an int or (U, V), ``origin`` the sensor
    (row, col) of the array's first pixel (CFA phase), ``noise`` a :class:`lfcl.noise.model.NoiseEstimate`
    (None: estimated from the raw), ``device`` as :func:`lfcl.device.get_runtime`. ``options``:
    see :data:`DEFAULTS`.
    """
    t_start = time.perf_counter()
    pattern = parse_pattern(pattern)
    mosaic = _validate_mosaic(mosaic)
    U, V, S, T = _checks.grid(mosaic.shape, pitch)
    opts = _options(options)
    origin = (int(origin[0]), int(origin[1]))
    gain, floor, noise_meta = _noise_model(mosaic, pattern, (U, V), origin, noise, device)
    ds = candidates(opts["dmax"], opts["step"])
    seconds = {"noise": time.perf_counter() - t_start}

    subsets = [None] + (half_apertures(U, V) if opts["occlusion"] else [])
    cost_seconds = 0.0
    guide = _guide(mosaic, pattern, (U, V), origin, S, T)
    if opts["backend"] == "numpy":
        offsets, wwin = _window_weights(guide, opts["radius"], opts["guide_sigma"], gain, floor)
        best = None
        for index, views in enumerate(subsets):  # one aperture at a time
            start = time.perf_counter()
            volume = cost_volume_np(mosaic, pattern, (U, V), ds, origin=origin, noise=(gain, floor),
                                    saturation=opts["saturation"], model=opts["model"], views=views,
                                    colour=opts["colour"], clipped=opts["clipped"])
            if index == 0:
                seen = volume[1].max(axis=0) > 0  # lenses that gathered any sample (the full aperture)
            best = take_aperture_np(best, aggregate_window_np(volume[0], offsets, wwin),
                                    aggregate_window_np(volume[1], offsets, wwin), half=index > 0)
            cost_seconds += time.perf_counter() - start
        cost, _, sigma_c = best
    else:  # the volumes, their window sums and the choice between apertures stay on the device
        from ..device import get_runtime

        start = time.perf_counter()
        runtime = get_runtime(device)
        op = CostVolume(runtime, mosaic.shape, pattern, (U, V), ds, origin=origin, model=opts["model"],
                        halves=opts["occlusion"], colour=opts["colour"], clipped=opts["clipped"])
        window = WindowAggregate(runtime, 2 * ds.size, (S, T), opts["radius"])
        data = runtime.to_device(mosaic)
        weights = window.weights(guide, _guide_scale(guide, opts["guide_sigma"], gain, floor))
        volumes = op.forward(data, (gain, floor), opts["saturation"]).reshape(len(subsets) * 2 * ds.size, S, T)
        best = (runtime.empty((ds.size, S, T)), runtime.empty((S, T)), runtime.empty((S, T)))
        sums = runtime.empty((2 * ds.size, S, T))
        for index in range(len(subsets)):
            window.forward(volumes, weights, out=sums, first=index * 2 * ds.size)
            window.take_aperture(sums, best, half=index > 0, first=index == 0)
        seen = volumes[ds.size:2 * ds.size].get().max(axis=0) > 0  # lenses that gathered any sample (full aperture)
        cost, sigma_c = best[0].get().astype(np.float64), best[2].get().astype(np.float64)
        cost_seconds += time.perf_counter() - start
    seconds["cost_and_window"] = cost_seconds
    raw_d, c_best, c_other = _best(cost, ds.astype(np.float64), opts["exclusion"])
    z = (c_other - c_best) / (sigma_c + 0.5 * np.maximum(c_best, 0.0))
    confidence = 1.0 - np.exp(-(np.maximum(z, 0.0) / opts["confidence_z"]) ** 2)
    # Saturated lenses: scale by the unsaturated share of the lens's own samples.
    unsat = (mosaic.reshape(S, U, T, V) < opts["saturation"]).mean(axis=(1, 3))
    confidence = confidence * unsat
    confidence = np.where(seen, confidence, 0.0)
    if opts["smooth"] > 0:
        links = _links(guide, opts["guide_sigma"], gain, floor)
        disparity = _smooth(raw_d, confidence, links, opts["smooth"], opts["smooth_sigma"], 0.0)
    else:
        disparity = raw_d
    seconds["total"] = time.perf_counter() - t_start
    seconds["select"] = seconds["total"] - seconds["noise"] - seconds["cost_and_window"]
    disparity = np.clip(disparity, -opts["dmax"], opts["dmax"])
    return DisparityMap(np.ascontiguousarray(disparity, np.float32), np.ascontiguousarray(confidence, np.float32),
                        float(opts["dmax"]), float(opts["step"]), opts, noise_meta, seconds)
