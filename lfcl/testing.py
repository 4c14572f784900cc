"""Test helpers for lfcl's linear operators, in the manner of PyLops' ``dottest``.

Every linear operator of :mod:`lfcl.ops` has ``forward(x)`` and ``adjoint(y)`` on device arrays; its
input and output shapes are ``in_shape`` / ``out_shape`` or, for the operators on colour planes,
``planes_shape`` and ``gradient_shape`` / ``mosaic_shape``. :func:`dottest` checks that the adjoint is
the adjoint: ``<A x, y> == <x, A^T y>`` for random ``x`` and ``y``, the sums taken in float64 on the
host.

Example::

    >>> from lfcl.device import get_runtime
    >>> from lfcl.ops.gradient import Gradient
    >>> from lfcl.testing import dottest
    >>> rt = get_runtime()
    >>> error = dottest(Gradient(rt, (3, 18, 27), (9, 9), "uvst"), rt)
    >>> error < 1e-5
    True
"""

from __future__ import annotations

import numpy as np


def operator_shapes(op) -> tuple[tuple[int, ...], tuple[int, ...]]:
    """(input shape, output shape) of a linear operator of :mod:`lfcl.ops` (module docstring)."""
    if hasattr(op, "in_shape") and hasattr(op, "out_shape"):
        return tuple(op.in_shape), tuple(op.out_shape)
    for out_name in ("gradient_shape", "mosaic_shape"):
        if hasattr(op, "planes_shape") and hasattr(op, out_name):
            return tuple(op.planes_shape), tuple(getattr(op, out_name))
    raise ValueError(f"{type(op).__name__} does not say its input and output shapes (in_shape/out_shape, or "
                     "planes_shape with gradient_shape or mosaic_shape)")


def dottest(op, runtime, *, rng=None, rtol: float = 1e-5, raise_error: bool = True) -> float:
    """The relative dot-test error ``|<A x, y> - <x, A^T y>| / max(|<A x, y>|, |<x, A^T y>|)`` of ``op``.

    ``x`` and ``y`` are standard normal float32 arrays of the operator's shapes (``rng``: a numpy
    Generator, default seeded 0). With ``raise_error``, an error above ``rtol`` raises AssertionError.
    """
    rng = np.random.default_rng(0) if rng is None else rng
    in_shape, out_shape = operator_shapes(op)
    x = rng.standard_normal(in_shape).astype(np.float32)
    y = rng.standard_normal(out_shape).astype(np.float32)
    ax = op.forward(runtime.to_device(x)).get().astype(np.float64)
    aty = op.adjoint(runtime.to_device(y)).get().astype(np.float64)
    lhs, rhs = float(np.vdot(ax, y.astype(np.float64))), float(np.vdot(x.astype(np.float64), aty))
    error = abs(lhs - rhs) / max(abs(lhs), abs(rhs), 1e-30)
    if raise_error and error > rtol:
        raise AssertionError(f"{type(op).__name__}: dot test <A x, y> = {lhs:.9g}, <x, A^T y> = {rhs:.9g}, "
                             f"relative error {error:.3g} > {rtol:g}")
    return error
