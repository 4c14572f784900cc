"""Forward differences ``D`` over a subset of (u, v, s, t) and the adjoint ``D^T``.

On the sensor-shaped planes of docs/layout.md (``[C, S*U, T*V]``), ``D_d x`` is
``x[next sample along d] - x`` with a Neumann boundary (0 at the last sample).
``D`` stacks one block per selected dim in (u, v, s, t) order: its output has
shape ``[k, C, H, W]``. ``D^T`` is the exact adjoint (a negative divergence),
and ``D^T D`` a 4D Laplacian.

With ``lens_weights`` [U, V] (the white image's data-term weights, repeating from
lens to lens) the operators are masked: ``M D``, ``D^T M`` and ``D^T M D``, where
``M`` keeps only the differences whose two samples both have weight > 0, so that
dark (vignetted) pixels are left out of the prior (docs/admm.md).

Example::

    >>> import numpy as np
    >>> from lfcl.ops.gradient import gradient_np
    >>> gradient_np(np.zeros((3, 18, 18), np.float32), (9, 9), "uv").shape
    (2, 3, 18, 18)
"""

from __future__ import annotations

import numpy as np

from ..device import grid_defines
from ..layout import dims_mask, ordered_dims
from . import check_device_array, output


def _as_4d(x: np.ndarray, pitch):
    """View ``[C, S*U, T*V]`` planes as ``[C, S, U, T, V]``; axis of each dim."""
    U, V = pitch
    C, H, W = x.shape
    if H % U or W % V:
        raise ValueError(f"planes {H}x{W} are not a whole number of {U}x{V} microlenses")
    return x.reshape(C, H // U, U, W // V, V), {"s": 1, "u": 2, "t": 3, "v": 4}


def link_mask_np(lens_weights, pitch, dims, sensor_shape) -> np.ndarray:
    """M: 1 where the difference along each dim joins two samples of weight > 0: ``[k, 1, H, W]``.

    The difference stored at a sample joins it to its next sample along the dim; at
    the last sample (Neumann boundary) the difference is 0 anyway and M is 1 there.
    """
    U, V = pitch
    active = np.asarray(lens_weights, dtype=np.float64) > 0
    if active.shape != (U, V):
        raise ValueError(f"lens weights must be {U}x{V}, got shape {active.shape}")
    H, W = sensor_shape
    blocks = []
    for d in ordered_dims(dims):
        nxt = active.copy()
        if d == "u":
            nxt[:-1] = active[1:]
        elif d == "v":
            nxt[:, :-1] = active[:, 1:]
        blocks.append(np.tile(active & nxt, (H // U, W // V)))
    return np.stack(blocks)[:, None].astype(np.float64)


def link_table(lens_weights, pitch) -> np.ndarray:
    """The device's table of kept differences (common.cl ``linked``): float32 [8, U, V, 16].

    Entry [2 * dim + (dir > 0), u, phase, lane] is 1 when the sample in lens row ``u`` and
    lens column ``(phase + lane) % V`` and its neighbour one step along dim (0: u, 1: v,
    2: s, 3: t) in direction dir are both lit (weight > 0), else 0. A neighbour outside
    the lens (along u or v) counts as unlit; the kernels also check that it exists.
    """
    U, V = pitch
    lit = np.asarray(lens_weights, dtype=np.float64).reshape(U, V) > 0
    table = np.zeros((8, U, V, 16), np.float32)
    v = (np.arange(V)[:, None] + np.arange(16)[None, :]) % V  # [phase, lane]
    for dim in range(4):
        for forward in (0, 1):
            step = 1 if forward else -1
            for u in range(U):
                own = lit[u, v]
                if dim == 0:
                    other = lit[u + step, v] if 0 <= u + step < U else np.zeros_like(own)
                elif dim == 1:
                    inside = (v + step >= 0) & (v + step < V)
                    other = inside & lit[u, np.clip(v + step, 0, V - 1)]
                else:  # s and t: the same lens pixel of the next lens
                    other = own
                table[2 * dim + forward, u] = own & other
    return table


def linked_count_np(planes_shape, pitch, dims, lens_weights=None) -> np.ndarray:
    """diag(D^T M D): per sample, how many kept differences touch it (M = 1 without weights)."""
    _, H, W = planes_shape
    U, V = pitch
    weights = np.ones((U, V)) if lens_weights is None else lens_weights
    axis = {"s": 0, "u": 1, "t": 2, "v": 3}
    count = np.zeros((H // U, U, W // V, V))
    for block, d in zip(link_mask_np(weights, pitch, dims, (H, W)), ordered_dims(dims)):
        kept = block[0].reshape(count.shape).copy()
        ax, n = axis[d], count.shape[axis[d]]
        first, rest = [slice(None)] * 4, [slice(None)] * 4
        first[ax], rest[ax] = slice(0, n - 1), slice(1, n)
        last = [slice(None)] * 4
        last[ax] = slice(n - 1, n)
        kept[tuple(last)] = 0  # no difference leaves the last sample
        count += kept  # the difference's own sample
        count[tuple(rest)] += kept[tuple(first)]  # and its next one
    return np.broadcast_to(count.reshape(H, W), planes_shape).copy()


def gradient_np(x: np.ndarray, pitch, dims, lens_weights=None) -> np.ndarray:
    """D x (``M D x`` with ``lens_weights``): ``[C, H, W]`` -> ``[k, C, H, W]``."""
    if x.ndim != 3:
        raise ValueError(f"x must have shape [C, H, W], got {x.shape}")
    x5, axis = _as_4d(x, pitch)
    blocks = []
    for d in ordered_dims(dims):
        diff = np.zeros_like(x5)
        ax = axis[d]
        lead = [slice(None)] * 5
        lead[ax] = slice(0, -1)
        diff[tuple(lead)] = np.diff(x5, axis=ax)
        blocks.append(diff.reshape(x.shape))
    result = np.stack(blocks)
    if lens_weights is not None:
        result = result * link_mask_np(lens_weights, pitch, dims, x.shape[1:]).astype(x.dtype)
    return result


def gradient_adjoint_np(z: np.ndarray, pitch, dims, lens_weights=None) -> np.ndarray:
    """D^T z (``D^T M z`` with ``lens_weights``): ``[k, C, H, W]`` -> ``[C, H, W]``."""
    dims = ordered_dims(dims)
    if z.ndim != 4 or z.shape[0] != len(dims):
        raise ValueError(f"z must have shape [{len(dims)}, C, H, W], got {z.shape}")
    if lens_weights is not None:
        z = z * link_mask_np(lens_weights, pitch, dims, z.shape[2:]).astype(z.dtype)
    result = np.zeros(z.shape[1:], dtype=z.dtype)
    r5, axis = _as_4d(result, pitch)
    for block, d in zip(z, dims):
        z5, _ = _as_4d(block, pitch)
        ax = axis[d]
        n = z5.shape[ax]
        head = [slice(None)] * 5
        tail = [slice(None)] * 5
        head[ax] = slice(0, n - 1)
        tail[ax] = slice(1, n)
        r5[tuple(head)] -= z5[tuple(head)]
        r5[tuple(tail)] += z5[tuple(head)]
    return result


def gradient_gram_np(x: np.ndarray, pitch, dims, lens_weights=None) -> np.ndarray:
    """D^T D x (``D^T M D x`` with ``lens_weights``)."""
    return gradient_adjoint_np(gradient_np(x, pitch, dims, lens_weights), pitch, dims)


class Gradient:
    """D, D^T and D^T D on the device for ``[C, H, W]`` planes of ``pitch``-sized lenses.

    After :meth:`set_lens_weights` with [U, V] weights, the masked ``M D``, ``D^T M``
    and ``D^T M D`` (see the module docstring).
    """

    def __init__(self, runtime, planes_shape, pitch, dims):
        self.runtime = runtime
        self.channels, self.height, self.width = (int(n) for n in planes_shape)
        self.U, self.V = (int(p) for p in pitch)
        if self.height % self.U or self.width % self.V:
            raise ValueError(f"planes {self.height}x{self.width} are not a whole number of {self.U}x{self.V} microlenses")
        self.dims = ordered_dims(dims)
        self.mask = np.int32(dims_mask(self.dims))
        self.planes_shape = (self.channels, self.height, self.width)
        self.gradient_shape = (len(self.dims), *self.planes_shape)
        self.links = LinkMask(runtime, (self.U, self.V))

    def set_lens_weights(self, lens_weights=None):
        """Leave out the differences that touch a pixel of lens weight 0 ([U, V]; None: none)."""
        self.links.set(lens_weights)

    def _run(self, kernel, src, out):
        self.runtime.launch(
            "gradient", kernel, ((self.width + 15) // 16, self.height, self.channels), src.data, out.data,
            np.int32(self.height), np.int32(self.width), np.int32(self.channels), self.links.buffer(src).data,
            defines=(*grid_defines((self.U, self.V), self.mask), ("PRIOR_MASK", int(self.links.active))),
        )
        return out

    def forward(self, x, out=None):
        check_device_array(x, self.planes_shape, "x")
        return self._run("grad_forward", x, output(self.runtime, out, self.gradient_shape))

    def adjoint(self, z, out=None):
        check_device_array(z, self.gradient_shape, "z")
        return self._run("grad_adjoint", z, output(self.runtime, out, self.planes_shape))

    def gram(self, x, out=None):
        check_device_array(x, self.planes_shape, "x")
        return self._run("grad_gram", x, output(self.runtime, out, self.planes_shape))


class LinkMask:
    """The device table of kept differences (:func:`link_table`) for one lens pitch.

    ``active`` is False until weights with a zero are set: then the kernels are built
    with PRIOR_MASK=1 and read :meth:`buffer`. Re-uploads only when the weights change.
    """

    def __init__(self, runtime, pitch):
        self.runtime = runtime
        self.U, self.V = (int(p) for p in pitch)
        self._key = None
        self._table = None

    @property
    def active(self) -> bool:
        return self._key is not None

    def set(self, lens_weights=None):
        if lens_weights is None:
            self._key = None
            return
        weights = np.asarray(lens_weights, dtype=np.float64)
        if weights.shape != (self.U, self.V) or not np.all(np.isfinite(weights)):
            raise ValueError(f"lens weights must be a finite {self.U}x{self.V} array, got shape {weights.shape}")
        lit = tuple(bool(w > 0) for w in weights.ravel())
        if all(lit):  # nothing to leave out
            self._key = None
            return
        if lit != self._key:
            self._table = self.runtime.to_device(link_table(weights, (self.U, self.V)))
            self._key = lit

    def buffer(self, fallback):
        """The table, or ``fallback`` (any buffer: the kernels do not read it) when inactive."""
        return self._table if self.active else fallback
