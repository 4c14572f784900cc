"""Soft thresholding and the fused z/u step of scaled-form ADMM (paper, section 3.4).

``S_kappa(v) = sign(v) max(|v| - kappa, 0)`` with ``kappa = lambda / rho``; one
ADMM iteration then sets, element-wise,

    v = D x + u,   z' = S_kappa(v),   u' = v - z',   dz = z' - z,

``dz`` being what the dual residual ``rho D^T (z' - z)`` needs. The device
version does all four in one pass, in place on ``z`` and ``u``.

Example::

    >>> import numpy as np
    >>> from lfcl.ops.shrink import soft_threshold_np
    >>> soft_threshold_np(np.array([-3, -1, 0.5, 2], np.float32), 1.0)
    array([-2., -0.,  0.,  1.], dtype=float32)
"""

from __future__ import annotations

import math

import numpy as np

from . import check_device_array, output
from .linalg import elementwise_size


def check_kappa(kappa) -> np.float32:
    """kappa as float32; ``ValueError`` unless finite and >= 0."""
    value = float(kappa)
    if not math.isfinite(value) or value < 0:
        raise ValueError(f"kappa must be finite and >= 0, got {kappa!r}")
    return np.float32(value)


def soft_threshold_np(v: np.ndarray, kappa: float) -> np.ndarray:
    """S_kappa(v) = sign(v) max(|v| - kappa, 0), float32 (NaN stays NaN)."""
    kappa = check_kappa(kappa)
    v = np.asarray(v, dtype=np.float32)
    return np.copysign(np.maximum(np.abs(v) - kappa, np.float32(0)), v)


def zu_update_np(dx: np.ndarray, z: np.ndarray, u: np.ndarray, kappa: float):
    """(z', u', dz) of one ADMM step: v = dx + u, z' = S_kappa(v), u' = v - z', dz = z' - z."""
    kappa = check_kappa(kappa)
    dx, z, u = (np.asarray(a, dtype=np.float32) for a in (dx, z, u))
    if z.shape != dx.shape or u.shape != dx.shape:
        raise ValueError(f"dx, z and u must have one shape, got {dx.shape}, {z.shape}, {u.shape}")
    v = dx + u
    z_new = soft_threshold_np(v, kappa)
    return z_new, v - z_new, z_new - z


class Shrinkage:
    """S_kappa and the fused ADMM z/u update on float32 device arrays of any shape.

    Example::

        >>> from lfcl.device import get_runtime
        >>> rt = get_runtime()
        >>> v = rt.to_device(np.array([-3, -1, 0.5, 2], np.float32))
        >>> Shrinkage(rt).soft_threshold(v, 1.0).get()
        array([-2., -0.,  0.,  1.], dtype=float32)
    """

    def __init__(self, runtime):
        self.runtime = runtime

    def soft_threshold(self, v, kappa: float, out=None):
        """out = S_kappa(v); ``out`` may be ``v`` itself."""
        kappa = check_kappa(kappa)
        check_device_array(v, v.shape, "v")
        out = output(self.runtime, out, v.shape)
        if v.size:
            self.runtime.launch(
                "shrink", "soft_threshold", elementwise_size(v.size), v.data, out.data, kappa, np.uint64(v.size)
            )
        return out

    def zu_update(self, dx, z, u, dz, kappa: float):
        """In place: z <- S_kappa(dx + u), u <- dx + u - z_new, dz <- z_new - z_old.

        ``dx`` is D x; ``dz`` is a caller-given buffer and may be ``dx`` itself
        (each element is read before it is written), but not ``z`` or ``u``.
        Returns ``(z, u, dz)``.
        """
        kappa = check_kappa(kappa)
        check_device_array(dx, dx.shape, "dx")
        for array, name in ((z, "z"), (u, "u"), (dz, "dz")):
            check_device_array(array, dx.shape, name)
        if dx.size:
            if dz.data == z.data or dz.data == u.data or z.data == u.data:
                raise ValueError("z, u and dz must be three distinct buffers (dz may be dx)")
            self.runtime.launch(
                "shrink", "zu_update", elementwise_size(dx.size),
                dx.data, z.data, u.data, dz.data, kappa, np.uint64(dx.size),
            )
        return z, u, dz
