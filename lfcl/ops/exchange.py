"""Colour planes ``[3, S*U, T*V]`` -> the exchange light field ``[S, T, U, V, 3]`` on the device.

The numpy twin is :func:`lfcl.layout.planes_to_exchange` (docs/layout.md). The solvers keep the
planes; the light field a user or an output file gets is the exchange layout, and transposing it
on the host took longer than the Malvar demosaic itself at the paper's size (BENCHMARKS.md,
``lfcl bench api``), so the device writes it and the host downloads it as it is.

Example::

    >>> import numpy as np
    >>> from lfcl.device import get_runtime
    >>> from lfcl.layout import LightFieldShape, planes_to_exchange
    >>> shape = LightFieldShape(2, 3, 2, 2)
    >>> planes = np.arange(np.prod(shape.planes_shape), dtype=np.float32).reshape(shape.planes_shape)
    >>> runtime = get_runtime()
    >>> got = PlanesToExchange(runtime, shape).forward(runtime.to_device(planes)).get()
    >>> bool(np.array_equal(got, planes_to_exchange(planes, shape)))
    True
"""

from __future__ import annotations

import numpy as np

from ..device import grid_defines
from ..layout import LightFieldShape
from . import check_device_array, output


class PlanesToExchange:
    """``[3, S*U, T*V]`` device planes -> ``[S, T, U, V, 3]`` device light field (a copy, no arithmetic)."""

    def __init__(self, runtime, shape: LightFieldShape):
        self.runtime = runtime
        self.shape = shape
        self.planes_shape = shape.planes_shape
        self.exchange_shape = (shape.S, shape.T, shape.U, shape.V, 3)

    def forward(self, planes, out=None):
        """The light field of ``planes`` (into ``out`` if given)."""
        check_device_array(planes, self.planes_shape, "planes")
        out = output(self.runtime, out, self.exchange_shape)
        self._launch(self.runtime.queue, planes.data, out.data)
        return out

    def _launch(self, queue, planes_buffer, out_buffer):
        _, height, width = self.planes_shape
        kernel = self.runtime.kernel("exchange", "planes_to_exchange",
                                     defines=grid_defines((self.shape.U, self.shape.V), 0))
        return kernel(queue, (width, height), None, planes_buffer, out_buffer, np.int32(height), np.int32(width))


def exchange_from_host_planes(runtime, planes: np.ndarray, shape: LightFieldShape) -> np.ndarray:
    """:func:`lfcl.layout.planes_to_exchange` of host ``planes`` through the device: on a CPU device over
    the host arrays themselves (no copies), elsewhere up, through the kernel and down
    (:meth:`lfcl.device.Runtime.through_device`)."""
    if tuple(planes.shape) != shape.planes_shape:
        raise ValueError(f"planes must have shape {shape.planes_shape}, got {planes.shape}")
    planes = np.ascontiguousarray(planes, dtype=np.float32)
    op = PlanesToExchange(runtime, shape)
    return runtime.through_device(planes, op.exchange_shape, op._launch)
