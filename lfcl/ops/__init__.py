"""Operators: each family has a plain numpy twin and an OpenCL version side by side.

The numpy functions (suffix ``_np``) are the reference: same arguments, same
layout (docs/layout.md), float64-friendly. The device classes hold a
:class:`lfcl.device.Runtime` and work on ``pyopencl.array.Array`` buffers,
writing into a preallocated ``out`` when one is given.
"""

from __future__ import annotations

import numpy as np


def check_device_array(array, shape, name: str):
    """``ValueError`` unless ``array`` is a float32 device array of ``shape``."""
    if tuple(array.shape) != tuple(shape) or array.dtype != np.float32:
        raise ValueError(f"{name} must be float32 of shape {tuple(shape)}, got {array.dtype} {tuple(array.shape)}")
    if not array.flags.c_contiguous:
        raise ValueError(f"{name} must be C-contiguous")


def output(runtime, out, shape, name: str = "out"):
    """``out`` checked against ``shape``, or a fresh float32 device array."""
    if out is None:
        return runtime.empty(shape)
    check_device_array(out, shape, name)
    return out
