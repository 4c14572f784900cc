"""Forward differences ``D`` over a subset of (u, v, s, t) and the adjoint ``D^T``.

On the sensor-shaped planes of docs/layout.md (``[C, S*U, T*V]``), ``D_d x`` is
``x[next sample along d] - x`` with a Neumann boundary (0 at the last sample).
``D`` stacks one block per selected dim in (u, v, s, t) order: its output has
shape ``[k, C, H, W]``. ``D^T`` is the exact adjoint (a negative divergence),
and ``D^T D`` a 4D Laplacian.

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


def gradient_np(x: np.ndarray, pitch, dims) -> np.ndarray:
    """D x: ``[C, H, W]`` -> ``[k, C, H, W]``."""
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
    return np.stack(blocks)


def gradient_adjoint_np(z: np.ndarray, pitch, dims) -> np.ndarray:
    """D^T z: ``[k, C, H, W]`` -> ``[C, H, W]``."""
    dims = ordered_dims(dims)
    if z.ndim != 4 or z.shape[0] != len(dims):
        raise ValueError(f"z must have shape [{len(dims)}, C, H, W], got {z.shape}")
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


def gradient_gram_np(x: np.ndarray, pitch, dims) -> np.ndarray:
    """D^T D x."""
    return gradient_adjoint_np(gradient_np(x, pitch, dims), pitch, dims)


class Gradient:
    """D, D^T and D^T D on the device for ``[C, H, W]`` planes of ``pitch``-sized lenses."""

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

    def _run(self, kernel, src, out):
        self.runtime.launch(
            "gradient", kernel, ((self.width + 15) // 16, self.height, self.channels), src.data, out.data,
            np.int32(self.height), np.int32(self.width), np.int32(self.channels),
            defines=grid_defines((self.U, self.V), self.mask),
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
