"""Values for the dark pixels of each lens: the harmonic extension of its lit pixels.

Once the prior leaves out every difference that touches a pixel of lens weight 0
(docs/admm.md, issue #6), such a pixel has neither data nor prior and the solver
leaves it at its start value. That value is a Malvar interpolation of an unlit,
un-flat-fielded raw value: finite but far too dark, and it drags the mean image
down. After the solve each dark pixel therefore gets, per lens and colour, the
harmonic extension of the lens's lit pixels: the minimiser of ``||D_uv x||^2``
over the dark pixels with the lit ones fixed,

    x_dark = -L_dd^{-1} L_dl x_lit,    L = D_uv^T D_uv of one lens,

a fixed linear map per lens (the same for every lens of an aligned grid). It is
defined whenever the lens has a lit pixel: the U x V grid is connected, so every
dark region touches one. Lit pixels are unchanged.
"""

from __future__ import annotations

import functools

import numpy as np

from ..device import grid_defines
from . import check_device_array
from .gradient import gradient_gram_np


@functools.lru_cache(maxsize=8)
def _fill_matrix(pitch, lit: tuple) -> np.ndarray:
    U, V = pitch
    eye = np.eye(U * V)
    laplacian = np.stack([gradient_gram_np(eye[j].reshape(1, U, V), (U, V), "uv").ravel() for j in range(U * V)],
                         axis=1)
    lit = np.asarray(lit, bool)
    fill = np.zeros((U * V, U * V))
    if lit.any() and not lit.all():
        dark = ~lit
        fill[np.ix_(dark, lit)] = -np.linalg.solve(laplacian[np.ix_(dark, dark)], laplacian[np.ix_(dark, lit)])
    fill.setflags(write=False)
    return fill


def fill_matrix(lens_weights, pitch) -> np.ndarray:
    """The [UV, UV] map from a lens's values to its dark pixels' (rows of lit pixels are 0)."""
    U, V = pitch
    weights = np.asarray(lens_weights, dtype=np.float64)
    if weights.shape != (U, V):
        raise ValueError(f"lens weights must be {U}x{V}, got shape {weights.shape}")
    lit = weights.ravel() > 0
    if not lit.any():
        raise ValueError("every lens pixel has weight 0: there is nothing to fill the lens from")
    return _fill_matrix((U, V), tuple(bool(v) for v in lit))


def lens_fill_np(planes: np.ndarray, lens_weights, pitch) -> np.ndarray:
    """``planes`` [C, S*U, T*V] with every dark pixel replaced by the harmonic extension."""
    U, V = pitch
    C, H, W = planes.shape
    fill = fill_matrix(lens_weights, pitch)
    dark = np.asarray(lens_weights).ravel() <= 0
    lenses = planes.reshape(C, H // U, U, W // V, V).transpose(0, 1, 3, 2, 4).reshape(C, H // U, W // V, U * V)
    out = lenses.copy()
    out[..., dark] = lenses @ fill[dark].T.astype(lenses.dtype)
    return out.reshape(C, H // U, W // V, U, V).transpose(0, 1, 3, 2, 4).reshape(planes.shape)


class LensFill:
    """lens_fill_np on the device, in place on float32 planes [C, S*U, T*V]."""

    def __init__(self, runtime, planes_shape, pitch):
        self.runtime = runtime
        self.channels, self.height, self.width = (int(n) for n in planes_shape)
        self.U, self.V = (int(p) for p in pitch)
        if self.height % self.U or self.width % self.V:
            raise ValueError(f"planes {self.height}x{self.width} are not a whole number of {self.U}x{self.V} microlenses")
        self._fill = None  # (weights key, device matrix)

    def __call__(self, x, lens_weights: np.ndarray, lens_weights_device):
        """Fill x's dark pixels in place; ``lens_weights`` [U, V] on the host and the same
        U*V weights on the device. Returns x."""
        check_device_array(x, (self.channels, self.height, self.width), "x")
        key = tuple(float(w) for w in np.asarray(lens_weights).ravel())
        if self._fill is None or self._fill[0] != key:
            matrix = fill_matrix(np.asarray(lens_weights).reshape(self.U, self.V), (self.U, self.V))
            self._fill = (key, self.runtime.to_device(matrix.astype(np.float32)))
        self.runtime.launch(
            "lensfill", "lens_fill", (self.width // self.V, self.height // self.U, self.channels),
            x.data, self._fill[1].data, lens_weights_device.data, np.int32(self.height), np.int32(self.width),
            defines=grid_defines((self.U, self.V), 3),
        )
        return x
