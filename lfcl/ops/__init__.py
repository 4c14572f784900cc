"""Operators: each family has a plain numpy twin and an OpenCL version side by side.

The numpy functions (suffix ``_np``) are the reference: same arguments, same
layout (docs/layout.md), float64-friendly. The device classes hold a
:class:`lfcl.device.Runtime` and work on ``pyopencl.array.Array`` buffers,
writing into a preallocated ``out`` when one is given.
"""

from __future__ import annotations

import numpy as np


def lens_grid(sensor_shape, pitch) -> tuple[int, int, tuple[int, int], tuple[int, int]]:
    """(height, width, pitch, lenses (S, T)) of a sensor of whole lenses; ``ValueError`` otherwise."""
    height, width = (int(n) for n in sensor_shape)
    U, V = (int(p) for p in pitch)
    if height % U or width % V:
        raise ValueError(f"mosaic {height}x{width} is not a whole number of {U}x{V} lenses")
    return height, width, (U, V), (height // U, width // V)


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


def lens_weights_or_ones(lens_weights, pitch) -> np.ndarray:
    """The data-term weights [U, V] float32 of every lens (None: ones); ``ValueError`` unless finite, >= 0, U x V."""
    U, V = (int(p) for p in pitch)
    if lens_weights is None:
        return np.ones((U, V), np.float32)
    weights = np.asarray(lens_weights, dtype=np.float32)
    if weights.shape != (U, V) or not np.all(np.isfinite(weights)) or np.any(weights < 0):
        raise ValueError(f"lens weights must be a finite, non-negative {U}x{V} array, got shape {weights.shape}")
    return weights
