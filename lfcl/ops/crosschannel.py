"""The cross-channel operator ``D C``: gradients of the colour differences, and its adjoint.

The cross-channel prior (docs/admm.md; after Heide et al. 2014, FlexISP, the
paper's ref [8]) penalises ``||D (x_R - x_G)||_1 + ||D (x_B - x_G)||_1``: colour
edges that one channel has and the others lack, i.e. the colour fringes a
demosaicer leaves at high frequencies. FlexISP's own term
``||D x_k . x_l - D x_l . x_k||`` is bilinear; this is its linear, hue-independent
cousin (it asks the colour *differences* to be piecewise constant, the classic
demosaicing assumption of Hamilton-Adams and Malvar), so it fits the ADMM
framework as one more linear block of K = [D; D C].

``C x = (x_R - x_G, x_B - x_G)`` maps ``[3, H, W]`` planes to ``[2, H, W]``; ``D``
is lfcl/ops/gradient.py's forward difference, so ``D C x`` has shape
``[k, 2, H, W]`` (one block per chosen dim, in u, v, s, t order). ``C^T C`` is
``[[1, -1, 0], [-1, 2, -1], [0, -1, 1]]``, hence
``(D C)^T (D C) = (C^T C) (x) D^T D``, used by the fused solver kernels.

Example::

    >>> import numpy as np
    >>> from lfcl.ops.crosschannel import cross_gradient_np
    >>> grey = np.ones((3, 18, 18)) * np.arange(18)  # a grey ramp: no colour edge
    >>> float(np.abs(cross_gradient_np(grey, (9, 9), "uv")).max())
    0.0
"""

from __future__ import annotations

import numpy as np

from ..device import grid_defines
from ..layout import dims_mask, ordered_dims
from . import check_device_array, output
from .gradient import LinkMask, gradient_adjoint_np, gradient_np
from .linalg import elementwise_size

# C^T C: the colour coupling of (D C)^T (D C) = C^T C (x) D^T D.
COLOUR_GRAM = np.array([[1.0, -1.0, 0.0], [-1.0, 2.0, -1.0], [0.0, -1.0, 1.0]])


def colour_differences_np(x: np.ndarray) -> np.ndarray:
    """C x = (x_R - x_G, x_B - x_G): ``[3, H, W]`` -> ``[2, H, W]``."""
    if x.ndim != 3 or x.shape[0] != 3:
        raise ValueError(f"x must have shape [3, H, W], got {x.shape}")
    return np.stack([x[0] - x[1], x[2] - x[1]])


def colour_differences_adjoint_np(y: np.ndarray) -> np.ndarray:
    """C^T y: ``[2, H, W]`` -> ``[3, H, W]`` (R = y_0, G = -y_0 - y_1, B = y_1)."""
    if y.ndim != 3 or y.shape[0] != 2:
        raise ValueError(f"y must have shape [2, H, W], got {y.shape}")
    return np.stack([y[0], -y[0] - y[1], y[1]])


class ColourDifferences:
    """C and C^T on the device (lfcl/kernels/colourdiff.cl): ``[3, H, W]`` <-> ``[2, H, W]``, or with
    ``batch`` B > 1 ``[B, 3, H, W]`` <-> ``[B, 2, H, W]`` (each of B images on its own: the u and v halves of
    an EPI gradient).

    The twins are :func:`colour_differences_np` and :func:`colour_differences_adjoint_np`; admm-epi's
    cross-channel block applies it to the EPI differences (lfcl/solvers/epi.py).
    """

    def __init__(self, runtime, planes_shape, batch: int = 1):
        self.runtime = runtime
        channels, height, width = (int(n) for n in planes_shape)
        if channels != 3:
            raise ValueError(f"the colour differences need 3 colour planes, got {channels}")
        if isinstance(batch, bool) or not isinstance(batch, int) or batch < 1:
            raise ValueError(f"batch must be an integer >= 1, got {batch!r}")
        lead = (batch,) if batch > 1 else ()
        self.in_shape, self.out_shape = (*lead, 3, height, width), (*lead, 2, height, width)
        self._n, self._batch = height * width, batch

    def _size(self):
        return (*elementwise_size(self._n), self._batch)

    def forward(self, x, out=None):
        """out = C x."""
        check_device_array(x, self.in_shape, "x")
        out = output(self.runtime, out, self.out_shape)
        if self._n:
            self.runtime.launch("colourdiff", "colour_differences", self._size(), x.data, out.data,
                                np.uint64(self._n))
        return out

    def adjoint(self, y, out=None, accumulate: bool = False):
        """out = C^T y, or out += C^T y with ``accumulate`` (``out`` required then)."""
        check_device_array(y, self.out_shape, "y")
        if accumulate and out is None:
            raise ValueError("accumulate needs an out array to add to")
        out = output(self.runtime, out, self.in_shape)
        if self._n:
            self.runtime.launch("colourdiff", "colour_differences_adjoint", self._size(), y.data,
                                out.data, np.uint64(self._n), np.int32(bool(accumulate)))
        return out


def cross_gradient_np(x: np.ndarray, pitch, dims, lens_weights=None) -> np.ndarray:
    """D C x (``M D C x`` with ``lens_weights``, lfcl/ops/gradient.py): ``[3, H, W]`` -> ``[k, 2, H, W]``."""
    return gradient_np(colour_differences_np(x), pitch, dims, lens_weights)


def cross_gradient_adjoint_np(z: np.ndarray, pitch, dims, lens_weights=None) -> np.ndarray:
    """C^T D^T z (``C^T D^T M z`` with ``lens_weights``): ``[k, 2, H, W]`` -> ``[3, H, W]``."""
    return colour_differences_adjoint_np(gradient_adjoint_np(z, pitch, dims, lens_weights))


class CrossGradient:
    """D C and C^T D^T on the device for ``[3, H, W]`` planes of ``pitch``-sized lenses.

    After :meth:`set_lens_weights` ([U, V]), the masked ``M D C`` and ``C^T D^T M`` (lfcl/ops/gradient.py).
    """

    def __init__(self, runtime, planes_shape, pitch, dims):
        self.runtime = runtime
        channels, self.height, self.width = (int(n) for n in planes_shape)
        self.U, self.V = (int(p) for p in pitch)
        if channels != 3:
            raise ValueError(f"the cross-channel operator needs 3 colour planes, got {channels}")
        if self.height % self.U or self.width % self.V:
            raise ValueError(f"planes {self.height}x{self.width} are not a whole number of {self.U}x{self.V} microlenses")
        self.dims = ordered_dims(dims)
        self.planes_shape = (3, self.height, self.width)
        self.gradient_shape = (len(self.dims), 2, self.height, self.width)
        self._grid_defines = grid_defines((self.U, self.V), dims_mask(self.dims))
        self.links = LinkMask(runtime, (self.U, self.V))

    def set_lens_weights(self, lens_weights=None):
        """Leave out the differences that touch a pixel of lens weight 0 ([U, V]; None: none)."""
        self.links.set(lens_weights)

    def _weights_and_defines(self, fallback):
        return self.links.buffer(fallback), (*self._grid_defines, ("PRIOR_MASK", int(self.links.active)))

    def forward(self, x, out=None):
        """out = D C x."""
        check_device_array(x, self.planes_shape, "x")
        out = output(self.runtime, out, self.gradient_shape)
        weights, defines = self._weights_and_defines(x)
        self.runtime.launch(
            "crosschannel", "xc_forward", ((self.width + 15) // 16, self.height, 2), x.data, out.data,
            np.int32(self.height), np.int32(self.width), weights.data, defines=defines,
        )
        return out

    def adjoint(self, z, out=None, accumulate: bool = False):
        """out = C^T D^T z, or out += C^T D^T z with ``accumulate`` (``out`` required then)."""
        check_device_array(z, self.gradient_shape, "z")
        if accumulate and out is None:
            raise ValueError("accumulate needs an out array to add to")
        out = output(self.runtime, out, self.planes_shape)
        weights, defines = self._weights_and_defines(z)
        self.runtime.launch(
            "crosschannel", "xc_adjoint", ((self.width + 15) // 16, self.height, 3), z.data, out.data,
            np.int32(self.height), np.int32(self.width), np.int32(bool(accumulate)), weights.data, defines=defines,
        )
        return out


def stacked_prior_np(planes_shape, pitch, dims, lens_weights=None):
    """K = [D; D C] and K^T as flat-vector callables (the float64 reference's prior).

    ``K(x)`` is ``D x`` (``[k, 3, H, W]``) and ``D C x`` (``[k, 2, H, W]``) raveled and
    concatenated; ``K^T`` splits such a vector and returns ``D^T z + C^T D^T zc``.
    With ``lens_weights``, both blocks are masked (``M D``, ``M D C``).
    Also returns the size of the ``D x`` part (where the cross-channel entries start).
    """
    k = len(ordered_dims(dims))
    C, H, W = planes_shape
    split = k * C * H * W

    def forward(x):
        return np.concatenate([gradient_np(x, pitch, dims, lens_weights).ravel(),
                               cross_gradient_np(x, pitch, dims, lens_weights).ravel()])

    def adjoint(z):
        tv, xc = z[:split].reshape(k, C, H, W), z[split:].reshape(k, 2, H, W)
        return (gradient_adjoint_np(tv, pitch, dims, lens_weights)
                + cross_gradient_adjoint_np(xc, pitch, dims, lens_weights))

    return forward, adjoint, split
