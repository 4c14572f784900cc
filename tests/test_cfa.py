"""CFA sampling A and A^T: device vs numpy twin, an independent per-pixel check, dot tests."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from conftest import relative_dot_error

from lfcl.layout import PATTERNS
from lfcl.ops.cfa import CfaSampling, cfa_adjoint_np, cfa_gram_np, cfa_sample_np

ORIGINS = [(0, 0), (0, 1), (1, 0), (1, 1)]
SHAPES = [(1, 1), (9, 9), (27, 45), (37, 53)]


def test_numpy_twin_matches_the_pattern_letters():
    # Independent of channel_map: read the letter straight from the pattern string.
    x = np.arange(3 * 4 * 6, dtype=np.float32).reshape(3, 4, 6)
    for pattern, (r0, c0) in itertools.product(PATTERNS, ORIGINS):
        b = cfa_sample_np(x, pattern, (r0, c0))
        for row, col in itertools.product(range(4), range(6)):
            letter = pattern[2 * ((row + r0) % 2) + (col + c0) % 2]
            assert b[row, col] == x["RGB".index(letter), row, col]


def test_odd_pitch_alternates_the_phase_between_lenses():
    # With a 9-pixel pitch, pixel (u=0, v=0) of lens t=1 sits on sensor column 9: odd.
    x = np.stack([np.full((9, 18), c, np.float32) for c in range(3)])
    b = cfa_sample_np(x, "GRBG")
    assert b[0, 0] == 1 and b[0, 9] == 0  # G under lens 0, R under lens 1


@pytest.mark.parametrize("pattern", PATTERNS)
@pytest.mark.parametrize("origin", ORIGINS)
@pytest.mark.parametrize("shape", SHAPES)
def test_device_matches_numpy(runtime, rng, pattern, origin, shape):
    x = rng.standard_normal((3, *shape)).astype(np.float32)
    b = rng.standard_normal(shape).astype(np.float32)
    op = CfaSampling(runtime, shape, pattern, origin)
    np.testing.assert_array_equal(op.forward(runtime.to_device(x)).get(), cfa_sample_np(x, pattern, origin))
    np.testing.assert_array_equal(op.adjoint(runtime.to_device(b)).get(), cfa_adjoint_np(b, pattern, origin))
    np.testing.assert_array_equal(op.gram(runtime.to_device(x)).get(), cfa_gram_np(x, pattern, origin))


@pytest.mark.parametrize("pattern", PATTERNS)
def test_adjoint_dot_test(runtime, rng, pattern):
    shape = (45, 63)
    x = rng.standard_normal((3, *shape)).astype(np.float32)
    y = rng.standard_normal(shape).astype(np.float32)
    op = CfaSampling(runtime, shape, pattern, (1, 0))
    ax = op.forward(runtime.to_device(x)).get().astype(np.float64)
    aty = op.adjoint(runtime.to_device(y)).get().astype(np.float64)
    assert relative_dot_error(np.vdot(ax, y), np.vdot(x, aty)) <= 1e-5
    # And the numpy twin, in float64.
    lhs = np.vdot(cfa_sample_np(x.astype(np.float64), pattern, (1, 0)), y)
    rhs = np.vdot(x, cfa_adjoint_np(y.astype(np.float64), pattern, (1, 0)))
    assert relative_dot_error(lhs, rhs) <= 1e-12


def test_bad_shapes_and_patterns_raise(runtime):
    op = CfaSampling(runtime, (4, 4), "RGGB")
    with pytest.raises(ValueError, match="x must be float32 of shape"):
        op.forward(runtime.to_device(np.zeros((3, 4, 5), np.float32)))
    with pytest.raises(ValueError, match="float32"):
        op.adjoint(runtime.to_device(np.zeros((4, 4), np.float64)))
    with pytest.raises(ValueError, match="unknown Bayer pattern"):
        CfaSampling(runtime, (4, 4), "RGBX")
    with pytest.raises(ValueError, match=r"\[3, H, W\]"):
        cfa_sample_np(np.zeros((4, 4)), "RGGB")
