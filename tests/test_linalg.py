"""Vector updates axpby / copy: device vs numpy, aliasing, sizes that fit no work-group."""

from __future__ import annotations

import numpy as np
import pytest

from lfcl.ops.linalg import VectorOps, axpby_np, copy_np, elementwise_size

SIZES = [1, 7, 17, 1000, 12345, 1_000_003]
COEFFICIENTS = [(1.0, 1.0), (2.5, -0.75), (0.0, 1.0), (1.0, 0.0), (-1.0, 1e-3)]


@pytest.fixture(scope="module")
def ops(runtime):
    return VectorOps(runtime)


def assert_axpby(got, a, x, b, y):
    """Within an ulp or two of the terms (the device may fuse a x + b y into one fma)."""
    expected = axpby_np(a, x, b, y)
    scale = np.abs(np.float32(a) * x) + np.abs(np.float32(b) * y)
    assert np.all(np.abs(got - expected) <= 2.0**-22 * scale), np.max(np.abs(got - expected) / scale)


def test_numpy_twins(rng):
    x, y = rng.standard_normal((2, 100)).astype(np.float32)
    np.testing.assert_allclose(axpby_np(2, x, -3, y), 2 * x.astype(np.float64) - 3 * y, rtol=1e-5, atol=1e-6)
    out = x.copy()
    assert axpby_np(1, x, 1, y, out=out) is out
    np.testing.assert_array_equal(out, x + y)
    c = copy_np(x)
    assert c is not x and c.dtype == np.float32
    np.testing.assert_array_equal(c, x)
    with pytest.raises(ValueError, match="y must have shape"):
        axpby_np(1, x, 1, y[:5])


def test_elementwise_size_covers_n():
    for n in [1, 15, 16, 17, 1023, 1024, 1025, 1_000_003]:
        (g,) = elementwise_size(n)
        assert g * 16 >= n and g % 64 == 0 and (g - 64) * 16 < n


@pytest.mark.parametrize("n", SIZES)
@pytest.mark.parametrize("a, b", COEFFICIENTS)
def test_axpby_matches_numpy(runtime, ops, rng, n, a, b):
    x, y = (rng.standard_normal(n).astype(np.float32) for _ in range(2))
    dx, dy = runtime.to_device(x), runtime.to_device(y)
    assert_axpby(ops.axpby(a, dx, b, dy).get(), a, x, b, y)
    np.testing.assert_array_equal(dx.get(), x)
    np.testing.assert_array_equal(dy.get(), y)


@pytest.mark.parametrize("n", [17, 12345])
def test_axpby_in_place_and_into_out(runtime, ops, rng, n):
    x, y = (rng.standard_normal((n, 1)).astype(np.float32) for _ in range(2))
    dx, dy = runtime.to_device(x), runtime.to_device(y)
    assert ops.axpby(0.5, dx, 2.0, dy, out=dx) is dx  # x <- 0.5 x + 2 y
    assert_axpby(dx.get(), 0.5, x, 2.0, y)
    x1 = dx.get()
    assert ops.axpby(-1.0, dx, 3.0, dy, out=dy) is dy  # y <- -x1 + 3 y
    assert_axpby(dy.get(), -1.0, x1, 3.0, y)
    out = runtime.zeros((n, 1))
    assert ops.axpby(1.0, dx, 1.0, dx, out=out) is out  # 2 x1, exactly
    np.testing.assert_array_equal(out.get(), 2 * x1)


@pytest.mark.parametrize("n", SIZES)
def test_copy(runtime, ops, rng, n):
    x = rng.standard_normal((n,)).astype(np.float32)
    dx = runtime.to_device(x)
    fresh = ops.copy(dx)
    assert fresh.data != dx.data
    np.testing.assert_array_equal(fresh.get(), x)
    out = runtime.zeros((n,))
    assert ops.copy(dx, out=out) is out
    np.testing.assert_array_equal(out.get(), x)
    assert ops.copy(dx, out=dx) is dx
    np.testing.assert_array_equal(dx.get(), x)


@pytest.mark.parametrize("n", SIZES)
def test_zero(runtime, ops, rng, n):
    x = rng.standard_normal((2, n)).astype(np.float32) + 1.0
    dx = runtime.to_device(x)
    assert ops.zero(dx) is dx
    np.testing.assert_array_equal(dx.get(), np.zeros_like(x))
    # A view with an offset: only its own floats are zeroed.
    dx = runtime.to_device(x)
    ops.zero(dx[1])
    np.testing.assert_array_equal(dx.get(), np.stack([x[0], np.zeros(n, np.float32)]))


def test_empty_and_bad_arguments(runtime, ops):
    empty = runtime.empty((0, 3))
    assert ops.axpby(1.0, empty, 1.0, empty).shape == (0, 3)
    assert ops.copy(empty).shape == (0, 3)
    x = runtime.zeros((4, 5))
    with pytest.raises(ValueError, match="y must be float32 of shape"):
        ops.axpby(1.0, x, 1.0, runtime.zeros((5, 4)))
    with pytest.raises(ValueError, match="x must be float32"):
        ops.axpby(1.0, runtime.zeros((4, 5), np.float64), 1.0, x)
    with pytest.raises(ValueError, match="out must be float32 of shape"):
        ops.axpby(1.0, x, 1.0, x, out=runtime.zeros((20,)))
    with pytest.raises(ValueError, match="out must be float32"):
        ops.copy(x, out=runtime.zeros((4, 5), np.float64))
