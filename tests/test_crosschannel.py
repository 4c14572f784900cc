"""The cross-channel operator D C (gradients of the colour differences): device vs numpy,
the definition, adjoint dot tests, and the stacked prior K = [D; D C] of the reference."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from conftest import relative_dot_error

from lfcl.layout import DIMS
from lfcl.ops.crosschannel import (
    COLOUR_GRAM,
    CrossGradient,
    colour_differences_adjoint_np,
    colour_differences_np,
    cross_gradient_adjoint_np,
    cross_gradient_np,
    stacked_prior_np,
)
from lfcl.ops.gradient import gradient_np

SUBSETS = ["u", "v", "s", "t", "uv", "st", "uvst", "vt", "us"]
# (S, T, U, V): odd pitches, a single lens, sizes that fit no 16-column run.
GEOMETRIES = [(3, 5, 9, 9), (1, 1, 9, 9), (4, 3, 3, 5), (7, 2, 1, 4)]


def planes(rng, S, T, U, V, dtype=np.float32):
    return rng.standard_normal((3, S * U, T * V)).astype(dtype)


def loop_cross_gradient(x: np.ndarray, pitch, dims) -> np.ndarray:
    """D C x one sample at a time, from the definition: differences of (R - G) and (B - G)."""
    U, V = pitch
    _, H, W = x.shape
    S, T = H // U, W // V
    x5 = x.reshape(3, S, U, T, V)
    axis = {"s": 1, "u": 2, "t": 3, "v": 4}
    out = np.zeros((len(dims), 2, S, U, T, V))
    for block, d in enumerate(d for d in DIMS if d in dims):
        for p, colour in enumerate((0, 2)):
            for index in np.ndindex(S, U, T, V):
                nxt = list(index)
                nxt[axis[d] - 1] += 1
                if nxt[axis[d] - 1] < x5.shape[axis[d]]:
                    here = x5[(colour, *index)] - x5[(1, *index)]
                    there = x5[(colour, *nxt)] - x5[(1, *nxt)]
                    out[(block, p, *index)] = there - here
    return out.reshape(len(dims), 2, H, W)


@pytest.mark.parametrize("dims", ["u", "t", "uvst"])
def test_numpy_twin_matches_the_definition(rng, dims):
    x = planes(rng, 3, 2, 3, 5, np.float64)
    expected = loop_cross_gradient(x, (3, 5), dims)
    np.testing.assert_allclose(cross_gradient_np(x, (3, 5), dims), expected, rtol=0, atol=1e-12)


def test_colour_gram_is_c_transpose_c(rng):
    # C^T C by probing C with unit colour vectors.
    probes = np.eye(3)[:, :, None, None]
    columns = [colour_differences_adjoint_np(colour_differences_np(e))[:, 0, 0] for e in probes]
    np.testing.assert_array_equal(np.stack(columns, axis=1), COLOUR_GRAM)


def test_any_grey_or_constant_hue_edge_has_no_cross_gradient(rng):
    # x_c = base + offset_c: the colour differences are constant, however sharp the edges.
    base = rng.standard_normal((18, 27))
    x = base[None] + np.array([0.3, -0.1, 0.5])[:, None, None]
    assert np.abs(cross_gradient_np(x, (9, 9), "uvst")).max() < 1e-12
    assert np.abs(gradient_np(x, (9, 9), "uvst")).max() > 0.1  # TV sees them


@pytest.mark.parametrize("dims", SUBSETS)
@pytest.mark.parametrize("geometry", GEOMETRIES, ids=str)
def test_device_matches_numpy(runtime, rng, dims, geometry):
    S, T, U, V = geometry
    x = planes(rng, S, T, U, V)
    op = CrossGradient(runtime, x.shape, (U, V), dims)
    z = rng.standard_normal(op.gradient_shape).astype(np.float32)
    np.testing.assert_allclose(op.forward(runtime.to_device(x)).get(), cross_gradient_np(x, (U, V), dims),
                               rtol=0, atol=1e-6)
    np.testing.assert_allclose(op.adjoint(runtime.to_device(z)).get(), cross_gradient_adjoint_np(z, (U, V), dims),
                               rtol=0, atol=1e-5)


def test_adjoint_accumulates_into_out(runtime, rng):
    x = planes(rng, 3, 4, 9, 9)
    op = CrossGradient(runtime, x.shape, (9, 9), "uvst")
    z = rng.standard_normal(op.gradient_shape).astype(np.float32)
    out = runtime.to_device(x)
    op.adjoint(runtime.to_device(z), out=out, accumulate=True)
    np.testing.assert_allclose(out.get(), x + cross_gradient_adjoint_np(z, (9, 9), "uvst"), rtol=0, atol=1e-5)
    with pytest.raises(ValueError, match="accumulate needs an out"):
        op.adjoint(runtime.to_device(z), accumulate=True)


@pytest.mark.parametrize("dims", ["uv", "st", "uvst"])
def test_adjoint_dot_test(runtime, rng, dims):
    x = planes(rng, 5, 6, 9, 9)
    op = CrossGradient(runtime, x.shape, (9, 9), dims)
    y = rng.standard_normal(op.gradient_shape).astype(np.float32)
    kx = op.forward(runtime.to_device(x)).get().astype(np.float64)
    kty = op.adjoint(runtime.to_device(y)).get().astype(np.float64)
    assert relative_dot_error(np.vdot(kx, y), np.vdot(x, kty)) <= 1e-5
    x64, y64 = x.astype(np.float64), y.astype(np.float64)
    lhs = np.vdot(cross_gradient_np(x64, (9, 9), dims), y64)
    rhs = np.vdot(x64, cross_gradient_adjoint_np(y64, (9, 9), dims))
    assert relative_dot_error(lhs, rhs) <= 1e-12


@pytest.mark.parametrize("dims", ["uv", "uvst"])
def test_stacked_prior_adjoint_dot_test(rng, dims):
    x = planes(rng, 3, 2, 9, 9, np.float64)
    forward, adjoint, split = stacked_prior_np(x.shape, (9, 9), dims)
    kx = forward(x)
    assert kx.size == split * 5 // 3
    np.testing.assert_array_equal(kx[:split], gradient_np(x, (9, 9), dims).ravel())
    np.testing.assert_array_equal(kx[split:], cross_gradient_np(x, (9, 9), dims).ravel())
    y = rng.standard_normal(kx.size)
    assert relative_dot_error(np.vdot(kx, y), np.vdot(x, adjoint(y))) <= 1e-12


@pytest.mark.parametrize("dims", [c for r in (1, 2) for c in itertools.combinations(DIMS, r)][:6], ids="".join)
def test_gram_diagonal_is_the_colour_weighted_neighbour_count(rng, dims):
    # diag((D C)^T D C) = (C^T C)[c, c] * diag(D^T D): what the Jacobi preconditioner adds.
    from lfcl.solvers.reference import neighbour_count

    shape, pitch = (3, 6, 6), (3, 3)
    count = neighbour_count(shape, pitch, dims)
    for i in rng.choice(np.prod(shape), 30, replace=False):
        e = np.zeros(np.prod(shape))
        e[i] = 1
        e = e.reshape(shape)
        c = np.unravel_index(i, shape)[0]
        diagonal = cross_gradient_adjoint_np(cross_gradient_np(e, pitch, dims), pitch, dims).ravel()[i]
        assert diagonal == COLOUR_GRAM[c, c] * count.ravel()[i]


def test_bad_arguments_raise(runtime):
    with pytest.raises(ValueError, match="3 colour planes"):
        CrossGradient(runtime, (2, 9, 9), (9, 9), "uv")
    with pytest.raises(ValueError, match="whole number"):
        CrossGradient(runtime, (3, 10, 9), (9, 9), "uv")
    op = CrossGradient(runtime, (3, 9, 9), (9, 9), "uv")
    with pytest.raises(ValueError, match="z must be float32"):
        op.adjoint(runtime.to_device(np.zeros((2, 3, 9, 9), np.float32)))
    with pytest.raises(ValueError, match="must have shape \\[3, H, W\\]"):
        colour_differences_np(np.zeros((2, 4, 4)))


@pytest.mark.parametrize("dims", ["uv", "uvst"])
def test_masked_device_matches_numpy(runtime, rng, dims):
    w = np.ones((9, 9), np.float32)
    w[0, :2] = w[-1, -1] = w[4, 4] = 0
    x = planes(rng, 3, 4, 9, 9)
    op = CrossGradient(runtime, x.shape, (9, 9), dims)
    op.set_lens_weights(w)
    z = rng.standard_normal(op.gradient_shape).astype(np.float32)
    kx = op.forward(runtime.to_device(x)).get()
    np.testing.assert_allclose(kx, cross_gradient_np(x, (9, 9), dims, w), rtol=0, atol=1e-6)
    kty = op.adjoint(runtime.to_device(z)).get()
    np.testing.assert_allclose(kty, cross_gradient_adjoint_np(z, (9, 9), dims, w), rtol=0, atol=1e-5)
    assert relative_dot_error(np.vdot(kx.astype(np.float64), z), np.vdot(x, kty.astype(np.float64))) <= 1e-5
    assert not kx[:, :, np.tile(w == 0, (3, 4))].any()  # no difference leaves a dark pixel
