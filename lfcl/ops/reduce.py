"""Accurate reductions: dot product, squared 2-norm and sum of float32 arrays.

The device versions use the compensated Dot2 / Sum2 scheme of Ogita, Rump and
Oishi (lfcl/kernels/reduce.cl): a fixed number ``G`` of work-items each carry a
(sum, error) float pair per SIMD lane, and the host adds the ``G`` pairs in
float64 with :func:`math.fsum`. The result is as accurate as a float64
accumulation (relative error ~1e-7 or better even for 1e8 random-sign terms),
at the speed of one streaming read. The numpy twins accumulate in float64.

Example::

    >>> import numpy as np
    >>> from lfcl.ops.reduce import dot_np, norm2_np
    >>> dot_np(np.array([1, 2], np.float32), np.array([3, 4], np.float32))
    11.0
    >>> norm2_np(np.array([3, 4], np.float32))
    25.0
"""

from __future__ import annotations

import math

import numpy as np
import pyopencl as cl

from . import check_device_array

# float64 accumulation of the numpy twins, in slices of this many elements so a
# 1e8-element float32 array never gets a 800 MB float64 copy.
_NP_BLOCK = 1 << 22


def _check_host(x: np.ndarray, name: str, shape=None) -> np.ndarray:
    """``x`` flattened; ``ValueError`` unless floating point (and of ``shape``)."""
    x = np.asarray(x)
    if shape is not None and x.shape != tuple(shape):
        raise ValueError(f"{name} must have shape {tuple(shape)} like x, got {x.shape}")
    if x.dtype.kind != "f":
        raise ValueError(f"{name} must be a floating-point array, got {x.dtype}")
    return x.ravel()


def dot_np(x: np.ndarray, y: np.ndarray) -> float:
    """<x, y> = sum x_i y_i, accumulated in float64."""
    y = _check_host(y, "y", np.shape(x))
    x = _check_host(x, "x")
    return math.fsum(
        float(np.dot(x[i:i + _NP_BLOCK].astype(np.float64), y[i:i + _NP_BLOCK].astype(np.float64)))
        for i in range(0, x.size, _NP_BLOCK)
    )


def norm2_np(x: np.ndarray) -> float:
    """||x||^2 = sum x_i^2, accumulated in float64."""
    return dot_np(x, x)


def diff_norm2_np(x: np.ndarray, y: np.ndarray) -> float:
    """||x - y||^2, accumulated in float64."""
    y = _check_host(y, "y", np.shape(x))
    x = _check_host(x, "x")
    return math.fsum(
        float(np.sum((x[i:i + _NP_BLOCK].astype(np.float64) - y[i:i + _NP_BLOCK]) ** 2))
        for i in range(0, x.size, _NP_BLOCK)
    )


def abs_sum_np(x: np.ndarray) -> float:
    """sum |x_i|, accumulated in float64."""
    x = _check_host(x, "x")
    return math.fsum(float(np.abs(x[i:i + _NP_BLOCK]).sum(dtype=np.float64)) for i in range(0, x.size, _NP_BLOCK))


def sum_np(x: np.ndarray) -> float:
    """sum x_i, accumulated in float64."""
    x = _check_host(x, "x")
    return math.fsum(float(x[i:i + _NP_BLOCK].sum(dtype=np.float64)) for i in range(0, x.size, _NP_BLOCK))


def default_work_items(device: cl.Device) -> int:
    """How many work-items (partial pairs) a reduction uses on ``device``.

    A CPU runs each work-item's chunk run as one streaming read; a few hundred per
    core balance the load (256 per core measured best on PoCL, 2 cores, n = 1e4
    .. 1e8). A GPU needs thousands in flight to hide memory latency.
    """
    if device.type & cl.device_type.CPU:
        return min(256 * device.max_compute_units, 4096)
    return 4096


class Reductions:
    """dot, squared norm and sum of float32 device arrays, any shape and length.

    The ``G`` partial pairs live in one device buffer and one host array, both
    allocated here and reused by every call (a call blocks until its result is
    on the host). One object must not be used from two threads at once.

    Example::

        >>> from lfcl.device import get_runtime
        >>> rt = get_runtime()
        >>> x = rt.to_device(np.arange(5, dtype=np.float32))
        >>> Reductions(rt).norm2(x)
        30.0
    """

    def __init__(self, runtime, work_items: int | None = None, interleaved: bool | None = None):
        self.runtime = runtime
        device = runtime.device
        self.work_items = int(work_items) if work_items is not None else default_work_items(device)
        if self.work_items < 1:
            raise ValueError(f"work_items must be >= 1, got {self.work_items}")
        # contiguous runs per work-item on a CPU, coalesced (interleaved) chunks elsewhere
        if interleaved is None:
            interleaved = not device.type & cl.device_type.CPU
        self.interleaved = np.int32(bool(interleaved))
        # one (host, device) pair of partial buffers per reduction in flight
        self._slots: list[tuple[np.ndarray, cl.Buffer]] = []

    def _slot(self, index: int):
        while len(self._slots) <= index:
            host = np.empty(2 * self.work_items, np.float32)
            self._slots.append((host, cl.Buffer(self.runtime.context, cl.mem_flags.WRITE_ONLY, host.nbytes)))
        return self._slots[index]

    def _enqueue(self, index: int, kernel: str, *arrays) -> bool:
        """Launch a ``*_partials`` kernel into slot ``index``; False for empty arrays."""
        for name, array in zip("xy", arrays):
            check_device_array(array, arrays[0].shape, name)
        if arrays[0].size == 0:
            return False
        host, partial = self._slot(index)
        self.runtime.launch(
            "reduce", kernel, (self.work_items,), *(a.data for a in arrays), np.uint64(arrays[0].size),
            self.interleaved, partial,
        )
        cl.enqueue_copy(self.runtime.queue, host, partial, is_blocking=False)
        return True

    def many(self, *requests) -> list[float]:
        """Several reductions with one wait: ``requests`` are ``(method name, array, ...)``,
        e.g. ``many(("norm2", x), ("dot", x, y))``. Saves a host round trip per reduction."""
        launched = [self.enqueue(i, *request) for i, request in enumerate(requests)]
        self.runtime.queue.finish()
        return self.collect(launched)

    def enqueue(self, index: int, name: str, *arrays) -> bool:
        """Start reduction ``name`` ("dot", "norm2", ...) into slot ``index`` without waiting,
        so that a caller can share one wait with its own transfers; :meth:`collect` after
        the queue has finished. False for an empty array (its result is 0)."""
        return self._enqueue(index, f"{name}_partials", *arrays)

    def collect(self, launched) -> list[float]:
        """The results of the slots started by :meth:`enqueue` (``launched``: its return values,
        slot by slot from 0); the queue must have finished."""
        return [math.fsum(self._slots[i][0].tolist()) if ok else 0.0 for i, ok in enumerate(launched)]

    def _reduce(self, kernel: str, *arrays) -> float:
        """Run one ``*_partials`` kernel over same-shaped float32 arrays; finish in float64."""
        return self.many((kernel.removesuffix("_partials"), *arrays))[0]

    def dot(self, x, y) -> float:
        """<x, y> = sum x_i y_i (x, y: float32 device arrays of one shape)."""
        return self._reduce("dot_partials", x, y)

    def norm2(self, x) -> float:
        """||x||^2 = sum x_i^2, the squared 2-norm."""
        return self._reduce("norm2_partials", x)

    def diff_norm2(self, x, y) -> float:
        """||x - y||^2 without a temporary (x, y: float32 device arrays of one shape)."""
        return self._reduce("diff_norm2_partials", x, y)

    def abs_sum(self, x) -> float:
        """sum |x_i|, the l1 norm."""
        return self._reduce("abs_sum_partials", x)

    def sum(self, x) -> float:
        """sum x_i."""
        return self._reduce("sum_partials", x)
