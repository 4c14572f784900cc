"""Vector updates for the conjugate-gradient solver: ``out = a x + b y`` and copies.

The arrays are float32, of any shape (all of one shape), treated as flat
vectors. ``out`` may be ``x`` or ``y`` itself (an in-place update).

Example::

    >>> import numpy as np
    >>> from lfcl.ops.linalg import axpby_np
    >>> axpby_np(2.0, np.ones(3, np.float32), -1.0, np.arange(3, dtype=np.float32))
    array([2., 1., 0.], dtype=float32)
"""

from __future__ import annotations

import numpy as np
import pyopencl as cl

from . import check_device_array, output

# The element-wise kernels (linalg.cl, shrink.cl) give each work-item one chunk of
# this many floats, and the global size is padded to a multiple of GROUP chunks so
# the OpenCL runtime can pick a wide work-group whatever n is.
CHUNK = 16
GROUP = 64


def elementwise_size(n: int) -> tuple[int]:
    """The global size of an element-wise kernel over ``n`` floats."""
    chunks = -(-n // CHUNK)
    return (-(-chunks // GROUP) * GROUP,)


def axpby_np(a: float, x: np.ndarray, b: float, y: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """a x + b y in float32 (into ``out`` when given; it may be ``x`` or ``y``)."""
    x, y = np.asarray(x), np.asarray(y)
    if x.shape != y.shape:
        raise ValueError(f"y must have shape {x.shape} like x, got {y.shape}")
    result = np.float32(a) * x.astype(np.float32, copy=False) + np.float32(b) * y.astype(np.float32, copy=False)
    if out is None:
        return result
    out[...] = result
    return out


def copy_np(x: np.ndarray) -> np.ndarray:
    """A float32 copy of x."""
    return np.array(x, dtype=np.float32, copy=True)


class VectorOps:
    """``axpby``, ``zero`` and ``copy`` on float32 device arrays of one shape.

    Example::

        >>> from lfcl.device import get_runtime
        >>> rt = get_runtime()
        >>> ops = VectorOps(rt)
        >>> x = rt.to_device(np.ones(5, np.float32))
        >>> ops.axpby(2.0, x, 1.0, x, out=x).get()  # x <- 3 x, in place
        array([3., 3., 3., 3., 3.], dtype=float32)
    """

    def __init__(self, runtime):
        self.runtime = runtime

    def axpby(self, a: float, x, b: float, y, out=None):
        """out = a x + b y; ``out`` may be ``x`` or ``y`` (else a fresh array)."""
        check_device_array(x, x.shape, "x")
        check_device_array(y, x.shape, "y")
        out = output(self.runtime, out, x.shape)
        if x.size:
            self.runtime.launch(
                "linalg", "axpby", elementwise_size(x.size),
                np.float32(a), x.data, np.float32(b), y.data, out.data, np.uint64(x.size),
            )
        return out

    def zero(self, x):
        """x = 0 through the runtime's buffer fill: no kernel to build (pyopencl's ``Array.fill`` builds one,
        which NVIDIA's compiler answers with a warning on stderr the first time)."""
        check_device_array(x, x.shape, "x")
        if x.size:
            cl.enqueue_fill_buffer(self.runtime.queue, x.base_data, np.float32(0), x.offset, x.nbytes)
        return x

    def copy(self, x, out=None):
        """out = x (a device-to-device copy; a fresh array unless ``out`` is given)."""
        check_device_array(x, x.shape, "x")
        out = output(self.runtime, out, x.shape)
        if x.size and out.data != x.data:
            cl.enqueue_copy(self.runtime.queue, out.data, x.data, byte_count=x.nbytes)
        return out
