"""Forward differences D, adjoint D^T and D^T D: device vs numpy, a loop reference, dot tests."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from conftest import relative_dot_error

from lfcl.layout import DIMS
from lfcl.ops.gradient import Gradient, gradient_adjoint_np, gradient_gram_np, gradient_np

SUBSETS = [c for r in range(1, 5) for c in itertools.combinations(DIMS, r)]
# (channels, S, T, U, V): odd pitches, a single lens, sizes that fit no work-group size.
GEOMETRIES = [(3, 3, 5, 9, 9), (3, 1, 1, 9, 9), (1, 4, 3, 3, 5), (2, 7, 2, 1, 4)]


def loop_gradient(x5: np.ndarray, dim: str) -> np.ndarray:
    """D_d on a [C, S, U, T, V] array, one sample at a time (the definition)."""
    axis = {"s": 1, "u": 2, "t": 3, "v": 4}[dim]
    out = np.zeros_like(x5)
    for index in np.ndindex(x5.shape):
        if index[axis] + 1 < x5.shape[axis]:
            nxt = list(index)
            nxt[axis] += 1
            out[index] = x5[tuple(nxt)] - x5[index]
    return out


def planes(rng, C, S, T, U, V, dtype=np.float32):
    return rng.standard_normal((C, S * U, T * V)).astype(dtype)


@pytest.mark.parametrize("dim", DIMS)
def test_numpy_twin_matches_the_definition(rng, dim):
    C, S, T, U, V = 2, 3, 4, 3, 5
    x = planes(rng, C, S, T, U, V, np.float64)
    expected = loop_gradient(x.reshape(C, S, U, T, V), dim).reshape(x.shape)
    np.testing.assert_array_equal(gradient_np(x, (U, V), dim)[0], expected)


def test_gradient_blocks_follow_uvst_order(rng):
    x = planes(rng, 3, 2, 2, 3, 3, np.float64)
    both = gradient_np(x, (3, 3), "tu")  # given out of order
    np.testing.assert_array_equal(both[0], gradient_np(x, (3, 3), "u")[0])
    np.testing.assert_array_equal(both[1], gradient_np(x, (3, 3), "t")[0])


@pytest.mark.parametrize("dims", SUBSETS, ids="".join)
@pytest.mark.parametrize("geometry", GEOMETRIES, ids=str)
def test_device_matches_numpy(runtime, rng, dims, geometry):
    C, S, T, U, V = geometry
    x = planes(rng, C, S, T, U, V)
    op = Gradient(runtime, x.shape, (U, V), dims)
    z = rng.standard_normal(op.gradient_shape).astype(np.float32)
    np.testing.assert_array_equal(op.forward(runtime.to_device(x)).get(), gradient_np(x, (U, V), dims))
    np.testing.assert_allclose(op.adjoint(runtime.to_device(z)).get(), gradient_adjoint_np(z, (U, V), dims), atol=1e-5)
    np.testing.assert_allclose(op.gram(runtime.to_device(x)).get(), gradient_gram_np(x, (U, V), dims), atol=1e-5)


@pytest.mark.parametrize("dims", SUBSETS, ids="".join)
def test_adjoint_dot_test(runtime, rng, dims):
    C, S, T, U, V = 3, 5, 6, 9, 9
    x = planes(rng, C, S, T, U, V)
    op = Gradient(runtime, x.shape, (U, V), dims)
    y = rng.standard_normal(op.gradient_shape).astype(np.float32)
    dx = op.forward(runtime.to_device(x)).get().astype(np.float64)
    dty = op.adjoint(runtime.to_device(y)).get().astype(np.float64)
    assert relative_dot_error(np.vdot(dx, y), np.vdot(x, dty)) <= 1e-5
    x64, y64 = x.astype(np.float64), y.astype(np.float64)
    lhs = np.vdot(gradient_np(x64, (U, V), dims), y64)
    rhs = np.vdot(x64, gradient_adjoint_np(y64, (U, V), dims))
    assert relative_dot_error(lhs, rhs) <= 1e-12


def test_gram_is_symmetric_positive_semidefinite(runtime, rng):
    x = planes(rng, 3, 4, 4, 9, 9)
    y = planes(rng, 3, 4, 4, 9, 9)
    op = Gradient(runtime, x.shape, (9, 9), "uvst")
    gx = op.gram(runtime.to_device(x)).get().astype(np.float64)
    gy = op.gram(runtime.to_device(y)).get().astype(np.float64)
    assert relative_dot_error(np.vdot(gx, y), np.vdot(x, gy)) <= 1e-5
    assert np.vdot(gx, x) >= 0


def test_constant_light_field_has_zero_gradient(runtime):
    x = np.full((3, 18, 27), 0.7, np.float32)
    op = Gradient(runtime, x.shape, (9, 9), "uvst")
    assert not op.forward(runtime.to_device(x)).get().any()


def test_bad_arguments_raise(runtime):
    with pytest.raises(ValueError, match="subset of u, v, s, t"):
        Gradient(runtime, (3, 9, 9), (9, 9), "uvx")
    with pytest.raises(ValueError, match="subset of u, v, s, t"):
        Gradient(runtime, (3, 9, 9), (9, 9), "uu")
    with pytest.raises(ValueError, match="whole number"):
        Gradient(runtime, (3, 10, 9), (9, 9), "uv")
    op = Gradient(runtime, (3, 9, 9), (9, 9), "uv")
    with pytest.raises(ValueError, match="z must be float32"):
        op.adjoint(runtime.to_device(np.zeros((3, 3, 9, 9), np.float32)))


# -- the masked operator M D: dark pixels (lens weight 0) left out of the prior ---------------


def dark_corner_weights(U, V):
    """Lens weights with zero corners (and one zero pixel inside, to test both ends of a link)."""
    w = np.ones((U, V), np.float32)
    w[0, 0] = w[-1, -1] = w[0, -1] = 0
    if U > 2 and V > 2:
        w[U // 2, 1] = 0
    return w


def loop_masked_gradient(x: np.ndarray, pitch, dim: str, weights: np.ndarray) -> np.ndarray:
    """M D_d by the definition: a difference is kept only if both its samples have weight > 0."""
    U, V = pitch
    C, H, W = x.shape
    d = loop_gradient(x.reshape(C, H // U, U, W // V, V), dim).reshape(x.shape)
    step = {"u": (1, 0), "v": (0, 1), "s": (U, 0), "t": (0, V)}[dim]
    out = d.copy()
    for r in range(H):
        for c in range(W):
            r2, c2 = min(r + step[0], H - 1), min(c + step[1], W - 1)
            if weights[r % U, c % V] <= 0 or weights[r2 % U, c2 % V] <= 0:
                out[:, r, c] = 0
    return out


@pytest.mark.parametrize("dim", DIMS)
def test_masked_numpy_twin_matches_the_definition(rng, dim):
    U, V = 3, 5
    x = planes(rng, 2, 3, 4, U, V, np.float64)
    w = dark_corner_weights(U, V)
    expected = loop_masked_gradient(x, (U, V), dim, w)
    np.testing.assert_array_equal(gradient_np(x, (U, V), dim, w)[0], expected)


@pytest.mark.parametrize("dims", ["u", "v", "s", "t", "uv", "uvst"])
@pytest.mark.parametrize("geometry", [(3, 3, 5, 9, 9), (2, 4, 3, 3, 5)], ids=str)
def test_masked_device_matches_numpy(runtime, rng, dims, geometry):
    C, S, T, U, V = geometry
    x = planes(rng, C, S, T, U, V)
    w = dark_corner_weights(U, V)
    op = Gradient(runtime, x.shape, (U, V), dims)
    op.set_lens_weights(w)
    z = rng.standard_normal(op.gradient_shape).astype(np.float32)
    np.testing.assert_array_equal(op.forward(runtime.to_device(x)).get(), gradient_np(x, (U, V), dims, w))
    np.testing.assert_allclose(op.adjoint(runtime.to_device(z)).get(), gradient_adjoint_np(z, (U, V), dims, w),
                               atol=1e-5)
    np.testing.assert_allclose(op.gram(runtime.to_device(x)).get(), gradient_gram_np(x, (U, V), dims, w), atol=1e-5)
    # dark pixels have no kept difference: D^T M D is zero on them whatever x holds
    dark = np.tile(w == 0, (S, T))
    assert not gradient_gram_np(x, (U, V), dims, w)[:, dark].any()


def test_masked_adjoint_dot_test(runtime, rng):
    x = planes(rng, 3, 4, 5, 9, 9)
    w = dark_corner_weights(9, 9)
    op = Gradient(runtime, x.shape, (9, 9), "uvst")
    op.set_lens_weights(w)
    y = rng.standard_normal(op.gradient_shape).astype(np.float32)
    dx = op.forward(runtime.to_device(x)).get().astype(np.float64)
    dty = op.adjoint(runtime.to_device(y)).get().astype(np.float64)
    assert relative_dot_error(np.vdot(dx, y), np.vdot(x, dty)) <= 1e-5
    x64, y64 = x.astype(np.float64), y.astype(np.float64)
    lhs = np.vdot(gradient_np(x64, (9, 9), "uvst", w), y64)
    rhs = np.vdot(x64, gradient_adjoint_np(y64, (9, 9), "uvst", w))
    assert relative_dot_error(lhs, rhs) <= 1e-12


@pytest.mark.parametrize("weights", [None, "dark"])
def test_linked_count_is_the_gram_diagonal(rng, weights):
    from lfcl.ops.gradient import linked_count_np
    from lfcl.solvers.reference import neighbour_count

    shape, pitch = (2, 6, 10), (3, 5)
    w = None if weights is None else dark_corner_weights(*pitch)
    count = linked_count_np(shape, pitch, "uvst", w)
    for i in range(np.prod(shape)):
        e = np.zeros(np.prod(shape))
        e[i] = 1
        assert gradient_gram_np(e.reshape(shape), pitch, "uvst", w).ravel()[i] == count.ravel()[i]
    if w is None:
        np.testing.assert_array_equal(count, neighbour_count(shape, pitch, "uvst"))


def test_link_table_matches_the_mask(rng):
    # The device's per-run table says, for every lane, what link_mask_np says for that sample.
    from lfcl.ops.gradient import link_mask_np, link_table

    U, V = 3, 5
    w = dark_corner_weights(U, V)
    table = link_table(w, (U, V))
    H, W = 2 * U, 4 * V
    for dim_index, dim in enumerate("uvst"):
        forward = link_mask_np(w, (U, V), dim, (H, W))[0, 0]
        for row in range(H):
            for col0 in range(0, W, 16):
                for lane in range(min(16, W - col0)):
                    col = col0 + lane
                    last = {"u": row % U == U - 1, "v": col % V == V - 1, "s": row >= H - U, "t": col >= W - V}[dim]
                    if not last:  # a forward link exists: the table's forward entry is the mask
                        assert table[2 * dim_index + 1, row % U, col0 % V, lane] == forward[row, col]
