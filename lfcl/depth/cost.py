"""The photo-consistency cost volume of a lenslet mosaic (the heavy part of :mod:`lfcl.depth`).

For centre-view lens ``(s, t)`` and a candidate disparity ``d`` (lenses per view step, HCI's
sign), view ``(u, v)`` sees the same scene point at the fractional lens

    y = s - d (u - uc),    x = t - d (v - vc),    uc = (U - 1) / 2,  vc = (V - 1) / 2.

Every raw sample of view ``(u, v)`` in the four lenses around ``(y, x)`` is gathered with its
bilinear weight ``w`` and its *own* CFA colour (no demosaic: a sample is never mixed with a
neighbour of another colour). Its place in the centre view, relative to lens ``(s, t)``, is
``p = (s' - y, t' - x)`` (each in (-1, 1)). Per colour ``c`` a plane ``a + g . p`` is fitted by
weighted least squares (a ridge ``RIDGE * W_c`` on the slope ``g``: at ``d = 0`` all samples sit
at ``p = 0`` and only the mean is defined); the penalised residual ``RSS_c`` is what is left.
With Poisson-Gaussian noise of variance ``nv_c = gain * mean_c + floor`` its noise-only
expectation is ``nv_c (W_c - tr((A_c + R_c)^-1 B_c))`` (``A = sum w phi phi^T``,
``B = sum w^2 phi phi^T``, ``phi = (1, p_y, p_x)``), so

    excess[d, s, t] = sum_c RSS_c / nv_c - (W_c - tr_c)      (0 in expectation for pure noise)
    weight[d, s, t] = sum_c W_c

is an unbiased measure of how badly ``d`` explains the samples, in noise units, whatever the
number of samples of each colour (at odd integer ``d`` every sample that lands on a lens
shares one row and column parity: one colour only; that colour's fit still counts, with
its own expectation). A colour with ``W_c < MIN_WEIGHT`` is left out. Samples at or above
``saturation`` are left out of the fit (a clipped sample is no measurement of the radiance).

**Clipped samples** still say something: the radiance there is at least ``saturation``. A candidate whose line
gathers clipped samples of a colour together with unclipped ones far below the clip (a pure red lens's clipped red
samples and the next, blue, lens's dark red ones, on a line that crosses both) is wrong, and without this every
candidate explained a lens whose one colour clips: only its dark colours were fitted. So each colour with a fit pays
``W_clip,c * max(saturation - f_c - sd, 0)^2 / nv(saturation)``, ``W_clip,c`` the weight of its clipped samples
gathered, ``f_c`` the colour's fitted plane at their weighted mean place (its mean for ``model="mean"``; texture that
rises into the clip is no conflict) and ``sd = sqrt(nv(saturation))`` one sample's noise at the clip (a fit near the
clip, whose unclipped samples are biased low, pays nothing). A colour with only clipped samples pays nothing.
``clipped=False`` leaves the bound out.

**The colour penalty** (``colour`` = eta > 0). The per-colour fits let a candidate explain the samples as a colour the
scene does not have: an in-focus grey checker of 2-lens squares is fitted exactly at ``d = 0`` (grey) and at
``d = +-2`` (red and blue white, green black: every line's colours fall on one square each), and the prior along the
lines at ``+-2`` then paints that colour. So the candidate's weighted per-colour means ``m_c`` (weights
``k_c = W_c / nv_c``) are compared with the lens's own colour ``r_c`` (the mean of each colour's samples in the
lens's micro-image, :func:`lens_colour_np`): what no grey offset and no non-negative multiple of the lens's colour
explains,

    penalty = min_{alpha >= 0, beta} sum_c k_c (m_c - alpha r_c - beta)^2 - (n - 1 - [alpha fitted]),

``n`` the kept colours (at most 1 dof is left of 3; none with 2 or fewer, so a one-colour candidate has none), less
its noise-only expectation; ``alpha >= 0``: a negative multiple would explain a colour opposite to the lens's (with
equal red and blue gains, a grey checker's raw at d = +-2 is one: (0.45, 0, 0.45) against the lens's (0.45, 1,
0.45)); ``alpha`` is fitted only where the lens's colour differs from grey by more than
``COLOURED_CHI2`` (its chi-square in noise units, 2 dof: about 1 % of grey lenses by chance), and a lens with a
colour it has no unsaturated sample of has no penalty. ``excess += colour * penalty``. At ``d = 0`` the candidate
gathers the lens's own samples: no penalty; the true ``d`` of a uniformly coloured patch: none either.

The plane (``model="plane"``) removes the first-order texture inside the gather footprint, which
otherwise biases the cost towards integer ``d`` (where the footprint shrinks to one lens);
``model="mean"`` fits the mean only.

:func:`cost_volume_np` is the float64 reference; :class:`CostVolume` runs ``lfcl/kernels/depth.cl``.
Both return ``[2, ND, S, T]`` float32: excess, weight.
"""

from __future__ import annotations

import numpy as np

from ..layout import packed_pattern, pattern_channels
from . import _checks

RIDGE = 0.02
MIN_WEIGHT = 1.5
MODELS = {"mean": 0, "plane": 1}
# Variance floor (normalised units^2) so that a noise model of 0 never divides by 0.
MIN_VARIANCE = 1e-12
# The lens's colour counts as coloured (its multiple is fitted by the colour penalty) above this chi-square.
COLOURED_CHI2 = 9.0


def _parse_model(model: str) -> int:
    if model not in MODELS:
        raise ValueError(f"unknown cost model {model!r}: choose from {', '.join(MODELS)}")
    return MODELS[model]


def half_apertures(U: int, V: int) -> list[tuple[int, int, int, int]]:
    """The four half apertures ``(u_lo, u_hi, v_lo, v_hi)`` of a ``U x V`` lens: the views above, below, left
    and right of the centre, each with the centre row or column (both centre rows or columns of an even pitch)."""
    uc, vc = U // 2, V // 2
    return [(0, uc, 0, V - 1), (U - 1 - uc, U - 1, 0, V - 1), (0, U - 1, 0, vc), (0, U - 1, V - 1 - vc, V - 1)]


def _views(views, U, V) -> tuple[int, int, int, int]:
    """The gathered views ``(u_lo, u_hi, v_lo, v_hi)``, clipped to the lens; ``ValueError`` if empty."""
    if views is None:
        return 0, U - 1, 0, V - 1
    u_lo, u_hi, v_lo, v_hi = (int(n) for n in views)
    u_lo, u_hi, v_lo, v_hi = max(u_lo, 0), min(u_hi, U - 1), max(v_lo, 0), min(v_hi, V - 1)
    if u_lo > u_hi or v_lo > v_hi:
        raise ValueError(f"views {tuple(views)} select no view of a {U}x{V} lens")
    return u_lo, u_hi, v_lo, v_hi


def _taps(d, offset):
    """The floor and fraction of the taps of a view ``offset`` views from the centre at disparity ``d``:
    ``-d * offset`` rounded to float32 (as the kernels compute it), then split exactly (float64)."""
    shift = float(np.float32(-np.float32(d)) * np.float32(offset))
    return np.floor(shift), shift - np.floor(shift)


def lens_colour_np(mosaic, pattern: str, pitch, *, origin=(0, 0), noise=(0.0, 1.0),
                   saturation: float = np.inf) -> np.ndarray:
    """The lens's own colour for the colour penalty: ``[4, S, T]`` float32, the mean of each colour's unsaturated
    samples in the micro-image (R, G, B), then its kind: 2 (unknown) where a colour has no such sample, 1 (coloured)
    where the three means differ from one grey by more than :data:`COLOURED_CHI2` (chi-square, each mean's
    variance ``nv / n``), else 0. The twin of lfcl/kernels/depth.cl ``depth_lens_colour``."""
    mosaic = np.asarray(mosaic, dtype=np.float64)
    U, V, S, T = _checks.grid(mosaic.shape, pitch)
    gain, floor = (float(n) for n in noise)
    cells = pattern_channels(pattern, origin)
    channel = cells[(np.arange(S * U) % 2)[:, None], (np.arange(T * V) % 2)[None, :]]
    usable = mosaic < saturation
    out = np.zeros((4, S, T))
    n = np.stack([((channel == c) & usable).reshape(S, U, T, V).sum(axis=(1, 3)) for c in range(3)])
    for c in range(3):
        total = np.where((channel == c) & usable, mosaic, 0.0).reshape(S, U, T, V).sum(axis=(1, 3))
        out[c] = np.where(n[c] > 0, total / np.maximum(n[c], 1), 0.0)
    w = n / np.maximum(gain * np.maximum(out[:3], 0.0) + floor, MIN_VARIANCE)
    grey = (w * out[:3]).sum(axis=0) / np.maximum(w.sum(axis=0), MIN_VARIANCE)
    chi = (w * (out[:3] - grey) ** 2).sum(axis=0)
    out[3] = np.where((n == 0).any(axis=0), 2.0, np.where(chi > COLOURED_CHI2, 1.0, 0.0))
    return out.astype(np.float32)


def colour_penalty_np(means, k, lens) -> np.ndarray:
    """The colour penalty (module docstring) per lens: ``means`` [3, ...] the candidate's per-colour means, ``k``
    [3, ...] their weights ``W / nv`` (0: the colour is not kept), ``lens`` [4, ...] :func:`lens_colour_np`'s."""
    kept = k > 0
    n = kept.sum(axis=0)
    K = np.maximum(k.sum(axis=0), MIN_VARIANCE)
    r = lens[:3]
    dm = np.where(kept, means - (k * means).sum(axis=0) / K, 0.0)
    dr = np.where(kept, r - (k * r).sum(axis=0) / K, 0.0)
    rr = (k * dr * dr).sum(axis=0)
    fit = (lens[3] > 0.5) & (lens[3] < 1.5) & (rr > 0)
    alpha = np.where(fit, np.maximum((k * dm * dr).sum(axis=0) / np.where(rr > 0, rr, 1.0), 0.0), 0.0)
    e = dm - alpha * dr
    penalty = (k * e * e).sum(axis=0) - (n - 1 - fit)
    return np.where((n >= 2) & (lens[3] < 1.5), penalty, 0.0)


def _solve_stats(acc, ref, gain, floor, plane: bool, colour: float = 0.0, lens=None, clipped=None,
                 saturation: float = np.inf):
    """excess and weight from the per-colour sums ``acc[16, 3, ...]`` of values less ``ref`` (see
    :func:`cost_volume_np`); ``colour`` > 0 adds that times the colour penalty against ``lens``
    (:func:`lens_colour_np`); ``clipped`` [3 (sum w, sum w p_y, sum w p_x), 3 colours, ...] of the clipped samples
    adds their bound (module docstring)."""
    W, Sy, Sx, Syy, Sxx, Syx, M, My, Mx, X, Q, Qy, Qx, Qyy, Qxx, Qyx = acc
    keep = W >= MIN_WEIGHT
    Wsafe = np.where(keep, W, 1.0)
    mean = M / Wsafe + ref  # the colour's mean value (the sums are of values less ref)
    nv = np.maximum(gain * np.maximum(mean, 0.0) + floor, MIN_VARIANCE)
    if plane:
        r = RIDGE * Wsafe
        A = np.stack([np.stack([Wsafe, Sy, Sx], -1), np.stack([Sy, Syy + r, Syx], -1),
                      np.stack([Sx, Syx, Sxx + r], -1)], -2)
        B = np.stack([np.stack([Q, Qy, Qx], -1), np.stack([Qy, Qyy, Qyx], -1), np.stack([Qx, Qyx, Qxx], -1)], -2)
        b = np.stack([M, My, Mx], -1)
        Ainv = np.linalg.inv(A)
        rss = X - np.einsum("...i,...ij,...j->...", b, Ainv, b)
        trace = np.einsum("...ij,...ji->...", Ainv, B)
        coef = np.einsum("...ij,...j->i...", Ainv, b)  # the plane: value less ref, slopes along p_y, p_x
    else:
        rss = X - M * M / Wsafe
        trace = Q / Wsafe
        coef = None
    excess = np.where(keep, rss / nv - (W - trace), 0.0).sum(axis=0)
    weight = np.where(keep, W, 0.0).sum(axis=0)
    if clipped is not None and np.isfinite(saturation):
        Wc = clipped[0]
        fit = M / Wsafe + ref
        if coef is not None:  # the plane at the clipped samples' weighted mean place
            at = np.where(Wc > 0, 1.0 / np.where(Wc > 0, Wc, 1.0), 0.0)
            fit = ref + coef[0] + coef[1] * clipped[1] * at + coef[2] * clipped[2] * at
        nv_clip = max(gain * max(saturation, 0.0) + floor, MIN_VARIANCE)
        gap = np.maximum(saturation - fit - np.sqrt(nv_clip), 0.0)
        excess = excess + np.where(keep & (Wc > 0), Wc * gap * gap / nv_clip, 0.0).sum(axis=0)
    if colour > 0:
        excess = excess + colour * colour_penalty_np(M / Wsafe + ref, np.where(keep, W / nv, 0.0), lens)
    return excess, weight


def cost_volume_np(mosaic, pattern: str, pitch, disparities, *, origin=(0, 0), noise=(0.0, 1.0),
                   saturation: float = np.inf, model: str = "plane", views=None, colour: float = 0.0,
                   clipped: bool = True) -> np.ndarray:
    """The cost volume ``[2, ND, S, T]`` (excess, weight; module docstring) in float64, as float32.

    ``mosaic`` [S*U, T*V] (whole lenses), ``pattern`` a Bayer name, ``origin`` the sensor
    (row, col) of its first pixel, ``disparities`` [ND], ``noise`` ``(gain, floor)`` of the
    Poisson-Gaussian model ``var = gain * x + floor`` (normalised units), ``views``
    ``(u_lo, u_hi, v_lo, v_hi)`` (inclusive; None: all) the views gathered, ``colour`` the colour penalty's
    weight (0: none), ``clipped`` whether clipped samples bound their colour's fit from below (module docstring).
    """
    mosaic = np.asarray(mosaic, dtype=np.float64)
    U, V, S, T = _checks.grid(mosaic.shape, pitch)
    plane = bool(_parse_model(model))
    gain, floor = (float(n) for n in noise)
    disparities = np.asarray(disparities, dtype=np.float32).astype(np.float64).ravel()
    # Work on the reference-shifted values exactly as the kernel does (conditioning only).
    m4 = mosaic.reshape(S, U, T, V)
    ref = m4[:, U // 2, :, V // 2]
    cells = pattern_channels(pattern, origin)
    rows = np.arange(S * U).reshape(S, U) % 2
    cols = np.arange(T * V).reshape(T, V) % 2
    uc, vc = (U - 1) / 2.0, (V - 1) / 2.0
    u_lo, u_hi, v_lo, v_hi = _views(views, U, V)
    out = np.zeros((2, disparities.size, S, T), np.float64)
    eta = float(colour)  # (`colour` names each sample's CFA colour below)
    lens = lens_colour_np(mosaic, pattern, (U, V), origin=origin, noise=noise, saturation=saturation) \
        if eta > 0 else None
    s_idx, t_idx = np.arange(S), np.arange(T)
    for k, d in enumerate(disparities):
        acc = np.zeros((16, 3, S, T))
        clipped_sums = np.zeros((3, 3, S, T))  # per colour, the clipped samples gathered: sum w, w p_y, w p_x
        for u in range(u_lo, u_hi + 1):
            y0, fy = _taps(d, u - uc)  # the taps' floor and fraction as the kernels compute them
            y0, fy = s_idx + y0, np.full(S, fy)
            for v in range(v_lo, v_hi + 1):
                x0, fx = _taps(d, v - vc)
                x0, fx = t_idx + x0, np.full(T, fx)
                for a in (0, 1):
                    sp = (y0 + a).astype(int)
                    wy = fy if a else 1.0 - fy
                    py = a - fy
                    vs = (sp >= 0) & (sp < S) & (wy > 0)
                    spc = np.clip(sp, 0, S - 1)
                    for b in (0, 1):
                        tp = (x0 + b).astype(int)
                        wx = fx if b else 1.0 - fx
                        px = b - fx
                        vt = (tp >= 0) & (tp < T) & (wx > 0)
                        tpc = np.clip(tp, 0, T - 1)
                        raw = m4[spc[:, None], u, tpc[None, :], v]
                        value = raw - ref
                        tap = (wy[:, None] * wx[None, :]) * (vs[:, None] & vt[None, :])
                        w = tap * (raw < saturation)
                        colour = cells[rows[spc, u][:, None], cols[tpc, v][None, :]]
                        pyb = np.broadcast_to(py[:, None], w.shape)
                        pxb = np.broadcast_to(px[None, :], w.shape)
                        w2 = w * w
                        feats = (w, w * pyb, w * pxb, w * pyb * pyb, w * pxb * pxb, w * pyb * pxb,
                                 w * value, w * value * pyb, w * value * pxb, w * value * value,
                                 w2, w2 * pyb, w2 * pxb, w2 * pyb * pyb, w2 * pxb * pxb, w2 * pyb * pxb)
                        for c in range(3):
                            sel = colour == c
                            for j, f in enumerate(feats):
                                acc[j, c] += np.where(sel, f, 0.0)
                            hit = sel & (raw >= saturation)
                            for j, f in enumerate((tap, tap * pyb, tap * pxb)):
                                clipped_sums[j, c] += np.where(hit, f, 0.0)
        out[0, k], out[1, k] = _solve_stats(acc, ref, gain, floor, plane, eta, lens,
                                            clipped_sums if clipped else None, saturation)
    return out.astype(np.float32)


COST_LANES = 8  # lenses per work-item of depth_cost_interior (lfcl/kernels/depth.cl)
# The cost kernels' work-group: small, because a work-item holds 1-2.5 KB of private arrays and PoCL, left to choose,
# made groups of ~4000 work-items that overflowed its thread's stack (a segmentation fault at 200x200 lenses).
COST_GROUP = (8, 1, 1)


def _whole_groups(size, group):
    """``size`` rounded up to whole work-groups of ``group`` (the kernels check their own bounds)."""
    return tuple(-(-int(n) // int(g)) * int(g) for n, g in zip(size, group))


def tap_reach(disparities, U: int, V: int) -> tuple[int, int, int, int]:
    """The lens rows and columns, relative to a lens, that its taps read at any of ``disparities``:
    ``(row_lo, row_hi, col_lo, col_hi)``, inclusive (the second tap of each pair included, weight 0 or not)."""
    floors = [[_taps(d, n - (N - 1) / 2.0)[0] for d in np.asarray(disparities, np.float32).ravel() for n in range(N)]
              for N in (U, V)]
    return int(min(floors[0])), int(max(floors[0])) + 1, int(min(floors[1])), int(max(floors[1])) + 1


def cost_geometry(disparities, U: int, V: int, packed: int, apertures) -> np.ndarray:
    """The sums of the cost that depend only on the taps' places and weights, for a lens all of whose taps are
    inside the frame and unsaturated: ``[ND, apertures, 4 parities (2 (s & 1) + (t & 1)), 3 colours, 12]``
    float32, the 12 being W, Sy, Sx, Syy, Sxx, Syx and their w^2 twins Q, Qy, Qx, Qyy, Qxx, Qyx
    (:func:`cost_volume_np`'s ``acc`` rows 0-5 and 10-15). ``packed`` the kernels' packed pattern,
    ``apertures`` a list of ``(u_lo, u_hi, v_lo, v_hi)``. depth_cost_interior adds the value sums."""
    ds = np.asarray(disparities, np.float32).ravel()
    # Per candidate k and view u (v): the taps' floor and fraction, as the kernels compute them.
    y0, fy = (np.array([[_taps(d, u - (U - 1) / 2.0)[i] for u in range(U)] for d in ds]) for i in (0, 1))
    x0, fx = (np.array([[_taps(d, v - (V - 1) / 2.0)[i] for v in range(V)] for d in ds]) for i in (0, 1))
    u, v = np.arange(U), np.arange(V)
    masks = np.zeros((len(apertures), U, V))
    for n, (u_lo, u_hi, v_lo, v_hi) in enumerate(apertures):
        masks[n, u_lo:u_hi + 1, v_lo:v_hi + 1] = 1.0
    cells = np.array([(int(packed) >> (2 * i)) & 3 for i in range(4)]).reshape(2, 2)
    out = np.zeros((ds.size, len(apertures), 4, 3, 12))
    for a in (0, 1):
        for b in (0, 1):
            wy, py = (fy if a else 1.0 - fy)[:, :, None], (a - fy)[:, :, None]  # [ND, U, 1]
            wx, px = (fx if b else 1.0 - fx)[:, None, :], (b - fx)[:, None, :]  # [ND, 1, V]
            w = wy * wx
            phi = [np.broadcast_to(f, w.shape) for f in (1.0, py, px, py * py, px * px, py * px)]
            feats = np.stack([w * f for f in phi] + [w * w * f for f in phi])  # [12, ND, U, V]
            for ps in (0, 1):
                rows = ((ps + y0 + a).astype(np.int64) * U + u) & 1  # [ND, U]
                for pt in (0, 1):
                    cols = ((pt + x0 + b).astype(np.int64) * V + v) & 1  # [ND, V]
                    colour = cells[rows[:, :, None], cols[:, None, :]]  # [ND, U, V]
                    onehot = (colour[None] == np.arange(3)[:, None, None, None]).astype(np.float64)
                    out[:, :, 2 * ps + pt] += np.einsum("ckuv,nuv,jkuv->kncj", onehot, masks, feats)
    return out.astype(np.float32)


class CostVolume:
    """The cost volume on the device (``lfcl/kernels/depth.cl``) for an ``[S*U, T*V]`` mosaic.

    ``halves``: one gather gives the full aperture's volume and those of the four :func:`half_apertures`,
    ``[5, 2, ND, S, T]`` (the twin: :func:`cost_volume_np` of each aperture); the shared views are gathered once
    (at 128x128 lenses, 41 candidates, 2-core PoCL: docs/depth.md, "Timing").

    Two kernels share the lenses: ``depth_cost_interior`` the box of lenses whose taps all lie inside the frame (at
    every candidate), 8 lenses along a row per work-item on a view-major copy of the mosaic, with the sums that do
    not depend on the samples' values from a table (:func:`cost_geometry`); ``depth_cost`` the rest (the frame's
    edge, the box's last columns, and lenses whose taps reach a saturated sample), one lens per work-item
    (docs/depth.md, "Timing")."""

    def __init__(self, runtime, sensor_shape, pattern: str, pitch, disparities, *, origin=(0, 0),
                 model: str = "plane", halves: bool = False, colour: float = 0.0, clipped: bool = True):
        self.runtime = runtime
        self.clipped = bool(clipped)
        self.colour = float(colour)
        if not (np.isfinite(self.colour) and self.colour >= 0):
            raise ValueError(f"the colour penalty's weight must be a finite number >= 0, got {colour!r}")
        self.U, self.V, self.S, self.T = _checks.grid(tuple(int(n) for n in sensor_shape), pitch)
        self.sensor_shape = (self.S * self.U, self.T * self.V)
        self.pattern = packed_pattern(pattern, origin)
        self.plane = _parse_model(model)
        self.disparities = np.ascontiguousarray(np.asarray(disparities, dtype=np.float32).ravel())
        if self.disparities.size < 1 or not np.all(np.isfinite(self.disparities)):
            raise ValueError("disparities must be a non-empty finite list")
        self._disparities = runtime.to_device(self.disparities)
        self.halves = bool(halves)
        self.shape = (5,) * self.halves + (2, self.disparities.size, self.S, self.T)
        self.reach = tap_reach(self.disparities, self.U, self.V)
        row_lo, row_hi, col_lo, col_hi = self.reach
        # The interior box: every tap inside the frame; its width a whole number of work-items.
        self.box = (max(0, -row_lo), min(self.S, self.S - row_hi), max(0, -col_lo), min(self.T, self.T - col_hi))
        s0, s1, t0, t1 = self.box
        self.box = (s0, s1, t0, t0 + max(0, t1 - t0) // COST_LANES * COST_LANES) if s1 > s0 else (0, 0, 0, 0)
        self._geometry = {}

    def _defines(self):
        from ..device import grid_defines

        return (*grid_defines((self.U, self.V), 0), ("PLANE_MODEL", self.plane), ("RIDGE_PPM", round(RIDGE * 1e6)),
                ("MIN_WEIGHT_PPM", round(MIN_WEIGHT * 1e6)), ("HALVES", int(self.halves)))

    def view_major(self, mosaic):
        """The view-major copy ``[U*V, S, T]`` (views[u V + v][s][t]) of an ``[S*U, T*V]`` device mosaic, on the device
        (depth_cost_interior reads it; the twin: ``mosaic.reshape(S, U, T, V).transpose(1, 3, 0, 2)``)."""
        out = self.runtime.empty((self.U * self.V, self.S, self.T))
        self.runtime.launch("depth", "depth_views", (self.T * self.V, self.S * self.U), mosaic.data, out.data,
                            np.int32(self.S), np.int32(self.T), defines=self._defines())
        return out

    def unusable_lenses(self, mosaic, saturation) -> np.ndarray:
        """``[S, T]`` bool on the host: the lenses holding a sample the cost leaves out (at or above ``saturation``,
        or not a number; the twin: ``~(mosaic.reshape(S, U, T, V) < saturation).all(axis=(1, 3))``)."""
        flags = self.runtime.empty((self.S, self.T), np.uint8)
        self.runtime.launch("depth", "depth_lens_unusable", (self.T, self.S), mosaic.data, flags.data,
                            np.int32(self.S), np.int32(self.T), np.float32(saturation), defines=self._defines())
        return flags.get().astype(bool)

    def lens_colour(self, mosaic, noise, saturation):
        """``[4, S, T]`` device array: the lens's own colour and its kind (the twin: :func:`lens_colour_np`)."""
        out = self.runtime.empty((4, self.S, self.T))
        self.runtime.launch("depth", "depth_lens_colour", (self.T, self.S), mosaic.data, out.data, np.int32(self.S),
                            np.int32(self.T), self.pattern, np.float32(noise[0]), np.float32(noise[1]),
                            np.float32(saturation), np.float32(COLOURED_CHI2), defines=self._defines())
        return out

    def _listed(self, mosaic, saturation):
        """Flat indices (s T + t) of the lenses for depth_cost: outside the box, or reaching an unusable sample."""
        S, T = self.S, self.T
        s0, s1, t0, t1 = self.box
        general = np.ones((S, T), bool)
        general[s0:s1, t0:t1] = False
        if s1 > s0 and t1 > t0:
            bad = self.unusable_lenses(mosaic, saturation)
            if bad.any():  # the lenses whose taps reach a flagged lens: a box sum of the flags over the reach
                row_lo, row_hi, col_lo, col_hi = self.reach
                pad = np.pad(bad, ((-row_lo, row_hi), (-col_lo, col_hi))).astype(np.int32).cumsum(0).cumsum(1)
                pad = np.pad(pad, ((1, 0), (1, 0)))
                h, w = row_hi - row_lo + 1, col_hi - col_lo + 1
                near = pad[h:h + S, w:w + T] - pad[:S, w:w + T] - pad[h:h + S, :T] + pad[:S, :T]
                general |= near > 0
        return np.flatnonzero(general).astype(np.int32)

    def forward(self, mosaic, noise=(0.0, 1.0), saturation: float = np.inf, views=None, out=None):
        """``[S*U, T*V]`` float32 device mosaic -> ``[2, ND, S, T]`` float32 device cost volume
        (``views``: as :func:`cost_volume_np`), or with ``halves`` ``[5, 2, ND, S, T]``: the full aperture,
        then the four :func:`half_apertures` (no ``views``)."""
        from ..ops import check_device_array, output

        check_device_array(mosaic, self.sensor_shape, "mosaic")
        out = output(self.runtime, out, self.shape)
        gain, floor = (float(n) for n in noise)
        if not all(np.isfinite(v) and abs(v) < 3.0e38 for v in (gain, floor)):  # float32 would make them Inf
            raise ValueError(f"depth: the noise model (gain {gain:.3g}, floor {floor:.3g}) lies beyond float32: "
                             "a normalised raw should lie near [0, 1]")
        sat = np.float32(min(float(saturation), 3.0e38))
        if self.halves and views is not None:
            raise ValueError("a cost volume with the half apertures gathers every view: no views")
        u_lo, u_hi, v_lo, v_hi = _views(views, self.U, self.V)
        S, T, ND = self.S, self.T, self.disparities.size
        common = (np.int32(S), np.int32(T), np.int32(ND), self.pattern, np.float32(gain), np.float32(floor))
        view_range = (np.int32(u_lo), np.int32(u_hi), np.int32(v_lo), np.int32(v_hi))
        # The lens's colour for the colour penalty (without it the kernels read nothing of this buffer).
        lens = self.lens_colour(mosaic, (gain, floor), sat) if self.colour > 0 else self.runtime.empty((4,))
        penalty = (lens.data, np.float32(self.colour))
        s0, s1, t0, t1 = self.box
        if s1 > s0 and t1 > t0:
            key = (u_lo, u_hi, v_lo, v_hi)
            if key not in self._geometry:
                apertures = [key, *half_apertures(self.U, self.V)] if self.halves else [key]
                self._geometry[key] = self.runtime.to_device(
                    cost_geometry(self.disparities, self.U, self.V, self.pattern, apertures))
            view_major = self.view_major(mosaic)
            self.runtime.launch("depth", "depth_cost_interior", _whole_groups(((t1 - t0) // COST_LANES, s1 - s0, ND),
                                                                           COST_GROUP),
                                view_major.data, self._disparities.data, self._geometry[key].data, out.data, *common,
                                np.int32(s0), np.int32(t0), np.int32(s1), np.int32(t1), *view_range, *penalty,
                                local_size=COST_GROUP, defines=self._defines())
        listed = self._listed(mosaic, sat)
        if listed.size:
            lenses = self.runtime.to_device(listed)
            self.runtime.launch("depth", "depth_cost", _whole_groups((listed.size, ND), COST_GROUP[:2]),
                                mosaic.data, self._disparities.data, lenses.data, out.data, np.int32(listed.size),
                                *common, sat, *view_range, *penalty, np.int32(self.clipped), local_size=COST_GROUP[:2],
                                defines=self._defines())
        return out


def window_offsets(radius: int) -> list[tuple[int, int]]:
    """The ``(dy, dx)`` of a ``(2 radius + 1)^2`` window, row by row: the order of the weights' first axis."""
    return [(dy, dx) for dy in range(-radius, radius + 1) for dx in range(-radius, radius + 1)]


def aggregate_window_np(maps: np.ndarray, offsets, weights: np.ndarray) -> np.ndarray:
    """Window sums of lens maps ``[..., S, T]`` with per-offset weights ``[n, S, T]`` (those of the window's
    centre lens), lenses outside the frame as 0: float64. The twin of :class:`WindowAggregate`."""
    S, T = maps.shape[-2:]
    radius = max(max(abs(dy), abs(dx)) for dy, dx in offsets)
    pad_width = [(0, 0)] * (maps.ndim - 2) + [(radius, radius), (radius, radius)]
    pad = np.pad(maps, pad_width)
    out = np.zeros(maps.shape, np.float64)
    for (dy, dx), w in zip(offsets, weights, strict=True):
        out += w * pad[..., radius + dy:radius + dy + S, radius + dx:radius + dx + T]
    return out


AGGREGATE_CHUNK = 8  # planes per work-item of lfcl/kernels/depth_aggregate.cl
AGGREGATE_LANES = 8  # lenses along a row per work-item of it


class WindowAggregate:
    """:func:`aggregate_window_np` on the device (lfcl/kernels/depth_aggregate.cl) for a stack of
    ``planes`` lens maps [S, T] and the weights of :func:`window_offsets` ``(radius)``. At 500x500 lenses
    (81 candidates, radius 4) the numpy twin took 12.4 s of admm-epi's 20 s on an H200's host (BENCHMARKS.md)."""

    def __init__(self, runtime, planes: int, lenses, radius: int):
        self.runtime = runtime
        self.planes, (self.S, self.T), self.radius = int(planes), (int(n) for n in lenses), int(radius)
        if self.planes < 1 or self.S < 1 or self.T < 1 or self.radius < 0:
            raise ValueError(f"aggregation needs planes, lenses >= 1 and a radius >= 0, got {planes}, {lenses}, {radius}")
        self.maps_shape = (self.planes, self.S, self.T)
        self.weights_shape = ((2 * self.radius + 1) ** 2, self.S, self.T)

    def _defines(self):
        from ..device import grid_defines

        return (*grid_defines((1, 1), 0), ("CHUNK", AGGREGATE_CHUNK))

    def weights(self, guide, scale):
        """The window weights ``[(2R + 1)^2, S, T]`` on the device from the host guide and its scale ``[3, S, T]``
        (kernel ``depth_window_weights``; twin :func:`lfcl.depth.estimate._window_weights`, 0.55 s on the host at
        500x500 lenses, then 81 MB to upload)."""
        out = self.runtime.empty(((2 * self.radius + 1) ** 2, self.S, self.T))
        guide, scale = (self.runtime.to_device(np.ascontiguousarray(a, dtype=np.float32)) for a in (guide, scale))
        self.runtime.launch("depth_aggregate", "depth_window_weights", (self.T, self.S, out.shape[0]), guide.data,
                            scale.data, out.data, np.int32(self.S), np.int32(self.T), np.int32(self.radius),
                            defines=self._defines())
        return out

    def take_aperture(self, sums, best, half: bool, first: bool):
        """Step 3's choice between apertures on the device (kernel ``depth_take_aperture``; twin
        :func:`lfcl.depth.estimate.take_aperture_np`): ``sums`` an aperture's window sums ``[2 ND, S, T]`` (excess,
        weight; ``planes`` = 2 ND), ``best`` the device arrays (curve ``[ND, S, T]``, score ``[S, T]``, noise
        ``[S, T]``) updated in place where this aperture's score is lower (``first``: everywhere)."""
        from ..ops import check_device_array

        ND = self.planes // 2
        check_device_array(sums, (2 * ND, self.S, self.T), "sums")
        curve, score, noise = best
        check_device_array(curve, (ND, self.S, self.T), "curve")
        for name, array in (("score", score), ("noise", noise)):
            check_device_array(array, (self.S, self.T), name)
        self.runtime.launch("depth_aggregate", "depth_take_aperture", (self.T, self.S), sums.data, curve.data,
                            score.data, noise.data, np.int32(self.S), np.int32(self.T), np.int32(ND),
                            np.int32(bool(half)), np.int32(bool(first)),
                            defines=self._defines())

    def forward(self, maps, weights, out=None, first: int = 0):
        """``[P, S, T]`` float32 device maps, ``[(2R + 1)^2, S, T]`` device weights -> ``[P, S, T]`` window sums;
        ``first``: the P maps start at that plane of a larger ``[N, S, T]`` stack (one aperture of a
        :class:`CostVolume` with the half apertures, without a copy)."""
        from ..ops import check_device_array, output

        stack = max(maps.shape[0], self.planes) if len(maps.shape) == 3 else self.planes
        check_device_array(maps, (stack, self.S, self.T), "maps")
        if not (isinstance(first, (int, np.integer)) and first >= 0 and first + self.planes <= stack):
            raise ValueError(f"maps: no planes {first}..{first + self.planes - 1} in a stack of {stack}")
        check_device_array(weights, self.weights_shape, "weights")
        out = output(self.runtime, out, self.maps_shape)
        chunks = -(-self.planes // AGGREGATE_CHUNK)
        self.runtime.launch("depth_aggregate", "depth_aggregate", (-(-self.T // AGGREGATE_LANES), self.S, chunks),
                            maps.data, weights.data, out.data, np.int32(self.S), np.int32(self.T),
                            np.int32(self.planes), np.int32(self.radius), np.int32(first),
                            defines=self._defines())
        return out
