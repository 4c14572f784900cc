"""Differences along the epipolar lines ``D_epi(d)`` and the exact adjoint (the prior of ``admm-epi``).

A Lambertian point seen at lens (s, t) in the centre view (uc, vc) = ((U - 1) / 2, (V - 1) / 2)
is seen by view (u, v) at lens (s - d (u - uc), t - d (v - vc)), d its disparity in lenses per
view step (the sign of HCI's ``gt_disp_lowres.pfm`` and of lfcl.sim.planes). On the
sensor-shaped planes of docs/layout.md, ``[C, S*U, T*V]``, sample i = (s, t, u, v) gets two
differences with its neighbours along that line, ``[C, H, W] -> [2, C, H, W]``:

    u-block: w_i (x(s - d_i, t, u + 1, v) - x(s, t, u, v)),   0 at u = U - 1
    v-block: w_i (x(s, t - d_i, u, v + 1) - x(s, t, u, v)),   0 at v = V - 1

x at the fractional lens s - d_i is Catmull-Rom (Keys a = -1/2) cubic interpolation over the
four lenses floor(s - d_i) - 1 .. + 2 along s (along t for the v-block), lens indices clamped to
the frame (a Neumann boundary). The independent numpy prototype of ../shared/notes/
light-field-structure.md found linear interpolation 0.04-0.14 dB worse (it blurs aliased texture).

``d_i`` and the weight ``w_i`` (a confidence in [0, 1]; None: 1) are the per-lens maps [S, T] read
at the lens the ray sees in the centre view, ``(s, t) + d0 (u - uc, v - vc)`` rounded to the nearest
lens and clamped, d0 the disparity of the sample's own lens: both samples of a difference see that
point, so it is the lens whose depth they share (the prototype measured +0.03 dB centre view,
+0.18 dB mean image against reading d at the sample's own lens). With d = 0 and w = 1 the operator
is exactly the (u, v) forward differences of lfcl/ops/gradient.py.

The index arithmetic (which lenses a ray reads, which taps) is done in float32 with every operation
rounded on its own, here and in lfcl/kernels/epi.cl, so that the twin and the device pick the same lenses
(the taps' floor(s - d) = s + floor(-d) and their fraction -d - floor(-d) are exact); the weights and values
are in the twin's dtype (float64 capable). The device's adjoint evaluates each weight from its distance
|d - k| instead (the same Catmull-Rom kernel, equal up to float32 rounding; lfcl/kernels/epi.cl keys_at).

The numpy twin builds the operator as a sparse matrix (one per sensor geometry and maps, shared by the
channels). The device computes the forward and the adjoint as gathers (lfcl/kernels/epi.cl) from the
per-sample (d_i, w_i) read from the maps once per map (kernel ``epi_ray_maps``, twin :func:`ray_maps_np`), on
runs of 16 columns with vector loads only, looping over the lens offsets the taps reach, tabulated once per map
(:func:`offset_table`, from the per-lens spans of kernel ``epi_lens_tap_spans``, twin :func:`lens_tap_spans_np`:
0.38 -> 0.05 s per 191x500 lenses against the same in numpy); the adjoint's target gathers from the sources whose
taps land on it: no atomics, deterministic. ``diag(D^T D)``, which the preconditioner of
the solver needs, comes from the same gather.

Example::

    >>> import numpy as np
    >>> from lfcl.ops.epi import epi_gradient_np
    >>> epi_gradient_np(np.zeros((3, 18, 18)), np.zeros((2, 2), np.float32), (9, 9)).shape
    (2, 3, 18, 18)
"""

from __future__ import annotations

import numpy as np
import scipy.sparse

from ..device import grid_defines
from . import check_device_array, output
from .crosschannel import COLOUR_GRAM

#: The largest |disparity| (lenses per view step) the operator takes.
MAX_DISPARITY = 16.0


def check_maps(disparity, confidence, lenses) -> tuple[np.ndarray, np.ndarray]:
    """The disparity and confidence maps as float32 [S, T] (confidence None: ones); ``ValueError`` otherwise."""
    S, T = lenses
    d = np.asarray(disparity)
    if d.shape != (S, T):
        raise ValueError(f"disparity must be a map of {S}x{T} lenses, got shape {d.shape}")
    d = np.ascontiguousarray(d, dtype=np.float32)
    if not np.all(np.isfinite(d)) or np.any(np.abs(d) > MAX_DISPARITY):
        raise ValueError(f"disparity must be finite with |d| <= {MAX_DISPARITY:g} lenses per view step")
    if confidence is None:
        return d, np.ones((S, T), np.float32)
    w = np.asarray(confidence)
    if w.shape != (S, T):
        raise ValueError(f"confidence must be a map of {S}x{T} lenses, got shape {w.shape}")
    w = np.ascontiguousarray(w, dtype=np.float32)
    if not np.all(np.isfinite(w)) or np.any(w < 0) or np.any(w > 1):
        raise ValueError("confidence must be finite and within [0, 1]")
    return d, w


def _lenses_of(planes_shape, pitch) -> tuple[int, int]:
    _, H, W = planes_shape
    U, V = pitch
    if H % U or W % V:
        raise ValueError(f"planes {H}x{W} are not a whole number of {U}x{V} microlenses")
    return H // U, W // V


def keys_weights_np(f: np.ndarray) -> np.ndarray:
    """Catmull-Rom weights [..., 4] of the taps floor(p) - 1 .. floor(p) + 2 for f = p - floor(p)."""
    f = np.asarray(f, dtype=np.float64)
    f2, f3 = f * f, f * f * f
    return np.stack([-0.5 * f3 + f2 - 0.5 * f, 1.5 * f3 - 2.5 * f2 + 1.0, -1.5 * f3 + 2.0 * f2 + 0.5 * f,
                     0.5 * f3 - 0.5 * f2], axis=-1)


def ray_maps_np(disparity, confidence, pitch) -> tuple[np.ndarray, np.ndarray]:
    """(d_i, w_i) of every sample as float32 [S, U, T, V]: the maps read at the lens the ray sees
    in the centre view (float32 index arithmetic, as lfcl/kernels/epi.cl epi_ray_maps)."""
    U, V = pitch
    S, T = disparity.shape
    f32 = np.float32
    s = np.arange(S, dtype=f32)[:, None, None, None]
    t = np.arange(T, dtype=f32)[None, None, :, None]
    ku = (np.arange(U, dtype=f32) - f32(0.5) * f32(U - 1))[None, :, None, None]
    kv = (np.arange(V, dtype=f32) - f32(0.5) * f32(V - 1))[None, None, None, :]
    d0 = disparity[:, None, :, None]
    sc = np.clip(np.floor((s + d0 * ku) + f32(0.5)), 0, S - 1).astype(np.intp)
    tc = np.clip(np.floor((t + d0 * kv) + f32(0.5)), 0, T - 1).astype(np.intp)
    return disparity[sc, tc], confidence[sc, tc]


def lens_taps_np(own: np.ndarray, d: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """The 4 clamped lens indices [..., 4] and Catmull-Rom weights [..., 4] (float64) of p = own - d, own whole
    lens indices: floor(p) = own + floor(-d) and the fraction -d - floor(-d), both exact in float32 (as the kernels
    compute them)."""
    d = np.asarray(d, dtype=np.float32)
    whole = np.floor(-d)
    base = np.asarray(own, dtype=np.float32) + whole
    index = np.clip(base[..., None] + np.arange(-1, 3, dtype=np.float32), 0, n - 1).astype(np.intp)
    return index, keys_weights_np(-d - whole)


def epi_matrix_np(disparity, pitch, confidence=None) -> scipy.sparse.csr_matrix:
    """D_epi as a float64 sparse matrix [2 H W, H W] acting on one flattened [H, W] plane."""
    U, V = pitch
    S, T = np.shape(disparity)
    d, w = check_maps(disparity, confidence, (S, T))
    H, W = S * U, T * V
    dr, wr = ray_maps_np(d, w, pitch)
    s, u, t, v = np.meshgrid(np.arange(S), np.arange(U), np.arange(T), np.arange(V), indexing="ij")
    own = ((s * U + u) * W + t * V + v)
    rows, cols, vals = [], [], []
    for block, (along, last) in enumerate(((u, U - 1), (v, V - 1))):
        keep = along < last
        r = own[keep] + block * H * W
        weight = wr[keep].astype(np.float64)
        if block == 0:
            index, taps = lens_taps_np(s[keep], dr[keep], S)
            target = (index * U + (u[keep] + 1)[:, None]) * W + (t[keep] * V + v[keep])[:, None]
        else:
            index, taps = lens_taps_np(t[keep], dr[keep], T)
            target = ((s[keep] * U + u[keep]) * W)[:, None] + index * V + (v[keep] + 1)[:, None]
        rows += [r, np.repeat(r, 4)]
        cols += [own[keep], target.ravel()]
        vals += [-weight, (weight[:, None] * taps).ravel()]
    matrix = scipy.sparse.coo_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                                     shape=(2 * H * W, H * W))
    return matrix.tocsr()  # sums the taps that clamping put on one lens


def epi_gradient_np(x, disparity, pitch, confidence=None, matrix=None) -> np.ndarray:
    """D_epi x: ``[C, H, W]`` -> ``[2, C, H, W]`` (``matrix``: a prebuilt :func:`epi_matrix_np`)."""
    x = np.asarray(x)
    if x.ndim != 3:
        raise ValueError(f"x must have shape [C, H, W], got {x.shape}")
    _lenses_of(x.shape, pitch)
    M = matrix if matrix is not None else epi_matrix_np(disparity, pitch, confidence)
    C, H, W = x.shape
    out = (M @ x.reshape(C, H * W).T).T  # [C, 2 H W]
    return np.ascontiguousarray(out.reshape(C, 2, H, W).transpose(1, 0, 2, 3)).astype(
        np.result_type(x.dtype, np.float32), copy=False)


def epi_adjoint_np(z, disparity, pitch, confidence=None, matrix=None) -> np.ndarray:
    """D_epi^T z: ``[2, C, H, W]`` -> ``[C, H, W]``."""
    z = np.asarray(z)
    if z.ndim != 4 or z.shape[0] != 2:
        raise ValueError(f"z must have shape [2, C, H, W], got {z.shape}")
    _, C, H, W = z.shape
    _lenses_of((C, H, W), pitch)
    M = matrix if matrix is not None else epi_matrix_np(disparity, pitch, confidence)
    flat = z.transpose(1, 0, 2, 3).reshape(C, 2 * H * W)
    return (M.T @ flat.T).T.reshape(C, H, W).astype(np.result_type(z.dtype, np.float32), copy=False)


#: I + C^T C for the colour differences C = (R - G, B - G): the per-pixel mix of :func:`epi_mixed_gradient_np`.
COLOUR_MIX = np.eye(3) + COLOUR_GRAM


def epi_mixed_gradient_np(x, disparity, pitch, confidence=None, matrix=None) -> np.ndarray:
    """(I + C^T C) D_epi x per pixel (``[3, H, W]`` -> ``[2, 3, H, W]``), C the colour differences (R - G, B - G):
    ``D^T`` of it is ``D^T D x + (D C)^T (D C) x``, the EPI and cross-channel blocks' share of the normal
    operator (the device's ``forward(..., mixed=True)``)."""
    g = epi_gradient_np(x, disparity, pitch, confidence, matrix)
    if g.shape[1] != 3:
        raise ValueError(f"the colour mix needs 3 channels, got {g.shape[1]}")
    return np.einsum("ij,bjhw->bihw", COLOUR_MIX, g).astype(g.dtype, copy=False)


def epi_gram_np(x, disparity, pitch, confidence=None) -> np.ndarray:
    """D_epi^T D_epi x."""
    M = epi_matrix_np(disparity, pitch, confidence)
    return epi_adjoint_np(epi_gradient_np(x, disparity, pitch, matrix=M), disparity, pitch, matrix=M)


def epi_diagonal_np(disparity, pitch, confidence=None, matrix=None) -> np.ndarray:
    """diag(D_epi^T D_epi) as [H, W] (the same for every channel)."""
    U, V = pitch
    S, T = np.shape(disparity)
    M = matrix if matrix is not None else epi_matrix_np(disparity, pitch, confidence)
    return np.asarray(M.multiply(M).sum(axis=0)).reshape(S * U, T * V)


def lens_tap_spans_np(d_rays: np.ndarray) -> np.ndarray:
    """Per lens, the offsets (relative to the lens, before clamping) of the first and last lens a tap of nonzero
    weight of any of its rays lands on: int32 [4, S, T] of (u-block first, last, v-block first, last), the u-block
    over the rows u < U - 1, the v-block over the columns v < V - 1 (first > last when there are none). p = own - d:
    the taps floor(p) - 1 .. floor(p) + 2, only floor(p) when p is whole (:func:`lens_taps_np`). ``d_rays``
    [S, U, T, V] (:func:`ray_maps_np`). The twin of lfcl/kernels/epi.cl ``epi_lens_tap_spans``."""
    S, U, T, V = d_rays.shape
    d = np.asarray(d_rays, dtype=np.float32)
    whole = np.floor(-d)
    exact = (-d - whole) == 0
    lo, hi = np.where(exact, whole, whole - 1), np.where(exact, whole, whole + 2)
    spans = np.empty((4, S, T), np.int32)
    spans[0::2], spans[1::2] = 1 << 20, -(1 << 20)  # no rows (columns) in a block: first > last
    if U > 1:
        spans[0], spans[1] = lo[:, :U - 1].min(axis=(1, 3)), hi[:, :U - 1].max(axis=(1, 3))
    if V > 1:
        spans[2], spans[3] = lo[..., :V - 1].min(axis=(1, 3)), hi[..., :V - 1].max(axis=(1, 3))
    return spans


def offset_table_np(d_rays: np.ndarray) -> np.ndarray:
    """The lens offsets the device kernels loop over, per lens row: int32 [4, S, 2] of (lo, hi).

    ``d_rays`` [S, U, T, V] (:func:`ray_maps_np`). Blocks: 0, the forward u-block (m = tap lens - s
    over the rows u < U - 1 of lens row s); 1, the forward v-block (m = tap lens - t, v < V - 1);
    2, the adjoint u-block (k = source lens - target lens s', for the sources whose taps land on s');
    3, the adjoint v-block (k = source lens t - target lens t', within lens row s). Supersets of the
    offsets that carry a weight (the kernels skip zero weights); lo > hi when there are none.
    """
    return offset_table(lens_tap_spans_np(d_rays))


def offset_table(spans: np.ndarray) -> np.ndarray:
    """:func:`offset_table_np` from the lenses' tap spans (:func:`lens_tap_spans_np`, or ``epi_lens_tap_spans`` on the
    device)."""
    _, S, T = spans.shape
    table = np.zeros((4, S, 2), np.int32)
    table[..., 1] = -1
    rows, lenses = np.arange(S), np.arange(T)[None, :]
    if spans[0].min() <= spans[1].max():  # some u-block (U > 1)
        lo_lens = np.clip(rows[:, None] + spans[0], 0, S - 1)  # per source lens [S, T], the taps' first lens
        hi_lens = np.clip(rows[:, None] + spans[1], 0, S - 1)
        table[0, :, 0], table[0, :, 1] = lo_lens.min(axis=1) - rows, hi_lens.max(axis=1) - rows
        span = int(table[0, :, 1].max(initial=0)) - int(table[0, :, 0].min(initial=0)) + 1
        first, last = np.full(S, S, np.int64), np.full(S, -S, np.int64)
        for k in range(-span, span + 1):  # sources s = s' + k
            source = rows + k
            valid = (source >= 0) & (source < S)
            src = np.clip(source, 0, S - 1)
            covered = valid & np.any((lo_lens[src] <= rows[:, None]) & (rows[:, None] <= hi_lens[src]), axis=1)
            first = np.where(covered, np.minimum(first, k), first)
            last = np.where(covered, np.maximum(last, k), last)
        some = first <= last
        table[2, some, 0], table[2, some, 1] = first[some], last[some]
    if spans[2].min() <= spans[3].max():  # some v-block (V > 1)
        lo_lens, hi_lens = np.clip(lenses + spans[2], 0, T - 1), np.clip(lenses + spans[3], 0, T - 1)
        table[1, :, 0], table[1, :, 1] = (lo_lens - lenses).min(axis=1), (hi_lens - lenses).max(axis=1)
        table[3, :, 0], table[3, :, 1] = (lenses - hi_lens).min(axis=1), (lenses - lo_lens).max(axis=1)
    return table


class EpiGradient:
    """D_epi, D_epi^T, D_epi^T D_epi and diag(D_epi^T D_epi) on the device for ``[C, H, W]`` planes.

    :meth:`set_maps` uploads the disparity and confidence [S, T] (lens maps) before use.

    Example::

        >>> from lfcl.device import get_runtime
        >>> rt = get_runtime()
        >>> op = EpiGradient(rt, (3, 18, 18), (9, 9))
        >>> op.set_maps(np.full((2, 2), 0.5, np.float32))
        >>> float(op.forward(rt.to_device(np.ones((3, 18, 18), np.float32))).get().max())
        0.0
    """

    def __init__(self, runtime, planes_shape, pitch):
        self.runtime = runtime
        self.channels, self.height, self.width = (int(n) for n in planes_shape)
        if not 1 <= self.channels <= 4:
            raise ValueError(f"the EPI operator takes 1 to 4 channels, got {self.channels}")
        self.U, self.V = (int(p) for p in pitch)
        self.lenses = _lenses_of(planes_shape, (self.U, self.V))
        self.planes_shape = (self.channels, self.height, self.width)
        self.gradient_shape = (2, *self.planes_shape)
        self._grid_defines = grid_defines((self.U, self.V), 3)
        self._defines = self._grid_defines
        self._grid = ((self.width + 15) // 16, self.height)  # runs of 16 columns
        self._rays = self._offsets = None
        self.maps = None  # the host copies (float32) of what was uploaded

    def set_maps(self, disparity, confidence=None):
        """Upload the disparity [S, T] (lenses per view step) and the confidence [S, T] in [0, 1] (None: 1):
        per sample, the d and w its ray reads (:func:`ray_maps_np`), and the kernels' offset table."""
        d, w = check_maps(disparity, confidence, self.lenses)
        # every disparity 0 (the fall-back and in-lens blocks): the kernels built as in-lens stencils (epi.cl)
        self._defines = self._grid_defines + ((("EPI_IN_LENS", 1),) if not np.any(d) else ())
        self._rays = self.ray_maps(d, w)
        self._offsets = self.runtime.to_device(offset_table(self.lens_tap_spans(self._rays)))
        self.maps = (d, w)

    def ray_maps(self, disparity, confidence):
        """Per sample, the d and w its ray reads: device float32 [2, H, W] from host lens maps [S, T]
        (kernel ``epi_ray_maps``; the twin :func:`ray_maps_np`, 0.2-0.3 s per 191x500 lenses on the host)."""
        S, T = self.lenses
        rays = self.runtime.empty((2, self.height, self.width))
        maps = [self.runtime.to_device(np.ascontiguousarray(m, dtype=np.float32)) for m in (disparity, confidence)]
        self.runtime.launch("epi", "epi_ray_maps", (self.width, self.height), maps[0].data, maps[1].data, rays.data,
                            np.int32(S), np.int32(T), defines=self._defines)
        return rays

    def lens_tap_spans(self, rays) -> np.ndarray:
        """:func:`lens_tap_spans_np` of device ray maps [2, H, W] (kernel ``epi_lens_tap_spans``): host int32
        [4, S, T] (the offset table from the per-sample spans took 0.3-0.7 s per 191x500 lenses on the host)."""
        S, T = self.lenses
        spans = self.runtime.empty((4, S, T), np.int32)
        self.runtime.launch("epi", "epi_lens_tap_spans", (T, S), rays.data, spans.data, np.int32(S), np.int32(T),
                            defines=self._defines)
        return spans.get()

    def _args(self):
        if self._rays is None:
            raise ValueError("EpiGradient: call set_maps(disparity, confidence) first")
        return self._rays.data, self._offsets.data, np.int32(self.height), np.int32(self.width)

    def forward(self, x, out=None, mixed: bool = False):
        """D x; with ``mixed`` (3 channels) (I + C^T C) D x per pixel (:func:`epi_mixed_gradient_np`)."""
        check_device_array(x, self.planes_shape, "x")
        if mixed and self.channels != 3:
            raise ValueError(f"the colour mix needs 3 channels, got {self.channels}")
        out = output(self.runtime, out, self.gradient_shape)
        self.runtime.launch("epi", "epi_forward", self._grid, x.data, out.data, *self._args(),
                            np.int32(self.channels), np.int32(bool(mixed)), defines=self._defines)
        return out

    def adjoint(self, z, out=None, accumulate: bool = False):
        """D^T z; with ``accumulate`` added into ``out``."""
        check_device_array(z, self.gradient_shape, "z")
        if accumulate and out is None:
            raise ValueError("accumulate needs an out array")
        out = output(self.runtime, out, self.planes_shape)
        self._gather(z, out, accumulate, squared=False)
        return out

    def gram(self, x, out=None, scratch=None):
        """D^T D x (``scratch``: a gradient-shaped buffer to use for D x)."""
        return self.adjoint(self.forward(x, scratch), out)

    def diagonal(self, out=None, accumulate: bool = False):
        """diag(D^T D) as [H, W] (one plane: the same for every channel); with ``accumulate`` added."""
        if accumulate and out is None:
            raise ValueError("accumulate needs an out array")
        out = output(self.runtime, out, (self.height, self.width))
        self._gather(out, out, accumulate, squared=True)  # z is not read with squared
        return out

    def _gather(self, z, out, accumulate, squared):
        self.runtime.launch("epi", "epi_adjoint", self._grid, z.data, out.data, *self._args(),
                            np.int32(self.channels), np.int32(bool(accumulate)), np.int32(bool(squared)),
                            defines=self._defines)
