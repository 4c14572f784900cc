"""CFA sampling ``A`` of a 4D RGB light field and its adjoint ``A^T``.

``A`` keeps, at every sensor pixel, the one colour its Bayer filter passes:
``(A x)[row, col] = x[c(row, col), row, col]`` on the sensor-shaped planes of
docs/layout.md. ``A^T`` puts each raw value back into its colour's plane and
zeros the other two. ``A^T A`` is the diagonal 0/1 mask of measured samples.

Example::

    >>> import numpy as np
    >>> from lfcl.ops.cfa import cfa_sample_np
    >>> cfa_sample_np(np.ones((3, 2, 2), np.float32), "GRBG").shape
    (2, 2)
"""

from __future__ import annotations

import numpy as np

from ..layout import channel_map, packed_pattern
from . import check_device_array, output


def _check_planes(x: np.ndarray, name: str = "x"):
    if x.ndim != 3 or x.shape[0] != 3:
        raise ValueError(f"{name} must have shape [3, H, W], got {x.shape}")


def cfa_sample_np(x: np.ndarray, pattern: str, origin=(0, 0)) -> np.ndarray:
    """A x: ``[3, H, W]`` planes -> ``[H, W]`` mosaic."""
    _check_planes(x)
    channels = channel_map(x.shape[1:], pattern, origin)
    return np.take_along_axis(x, channels[None], axis=0)[0]


def cfa_adjoint_np(b: np.ndarray, pattern: str, origin=(0, 0)) -> np.ndarray:
    """A^T b: ``[H, W]`` mosaic -> ``[3, H, W]`` planes (zeros where not measured)."""
    if b.ndim != 2:
        raise ValueError(f"b must have shape [H, W], got {b.shape}")
    channels = channel_map(b.shape, pattern, origin)
    return np.stack([np.where(channels == c, b, 0) for c in range(3)]).astype(b.dtype, copy=False)


def cfa_gram_np(x: np.ndarray, pattern: str, origin=(0, 0)) -> np.ndarray:
    """A^T A x."""
    return cfa_adjoint_np(cfa_sample_np(x, pattern, origin), pattern, origin)


class CfaSampling:
    """A and A^T on the device for an ``(H, W)`` sensor with a Bayer ``pattern``."""

    def __init__(self, runtime, sensor_shape, pattern: str, origin=(0, 0)):
        self.runtime = runtime
        self.height, self.width = (int(n) for n in sensor_shape)
        self.pattern = packed_pattern(pattern, origin)
        self.planes_shape = (3, self.height, self.width)
        self.mosaic_shape = (self.height, self.width)

    def _run(self, kernel, src, out):
        # cfa_sample works on runs of 16 columns, the others per pixel
        columns = (self.width + 15) // 16 if kernel == "cfa_sample" else self.width
        self.runtime.launch(
            "cfa", kernel, (columns, self.height), src.data, out.data,
            np.int32(self.height), np.int32(self.width), self.pattern,
        )
        return out

    def forward(self, x, out=None):
        check_device_array(x, self.planes_shape, "x")
        return self._run("cfa_sample", x, output(self.runtime, out, self.mosaic_shape))

    def adjoint(self, b, out=None):
        check_device_array(b, self.mosaic_shape, "b")
        return self._run("cfa_adjoint", b, output(self.runtime, out, self.planes_shape))

    def gram(self, x, out=None):
        check_device_array(x, self.planes_shape, "x")
        return self._run("cfa_gram", x, output(self.runtime, out, self.planes_shape))
