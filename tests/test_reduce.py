"""Compensated dot / squared norm / sum: device vs float64, ill-conditioned data, 1e8 elements."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lfcl.ops.reduce import Reductions, abs_sum_np, diff_norm2_np, dot_np, norm2_np, sum_np

# Lengths that are multiples of nothing (chunk = 16 floats, any work-group size).
SIZES = [1, 7, 15, 17, 1000, 12345, 1_000_003]
BIG = 100_000_000
BLOCK = 1 << 22


def exact_dot(x: np.ndarray, y: np.ndarray) -> float:
    """sum x_i y_i, correctly rounded (float32 products are exact in float64)."""
    return math.fsum((x.astype(np.float64) * y.astype(np.float64)).tolist())


def assert_close(got: float, expected: float, rtol: float = 1e-6):
    assert abs(got - expected) <= rtol * abs(expected), (got, expected, abs(got - expected) / abs(expected))


@pytest.fixture(scope="module")
def reductions(runtime):
    return Reductions(runtime)


# -- numpy twins ---------------------------------------------------------------------


def test_numpy_twins_accumulate_in_float64(rng):
    x = rng.standard_normal(4097).astype(np.float32)
    y = rng.standard_normal(4097).astype(np.float32)
    assert dot_np(x, y) == pytest.approx(exact_dot(x, y), rel=1e-14)
    assert norm2_np(x) == pytest.approx(exact_dot(x, x), rel=1e-14)
    assert sum_np(x) == pytest.approx(math.fsum(x.tolist()), rel=1e-12)
    assert dot_np(np.array([1, 2], np.float32), np.array([3, 4], np.float32)) == 11.0


def test_numpy_twins_reject_bad_input():
    with pytest.raises(ValueError, match="y must have shape"):
        dot_np(np.ones(3, np.float32), np.ones(4, np.float32))
    with pytest.raises(ValueError, match="floating-point"):
        norm2_np(np.ones(3, np.int32))


# -- device vs float64 ----------------------------------------------------------------


@pytest.mark.parametrize("n", SIZES)
def test_device_matches_float64(runtime, reductions, rng, n):
    x = rng.standard_normal(n).astype(np.float32)
    y = rng.standard_normal(n).astype(np.float32)
    dx, dy = runtime.to_device(x), runtime.to_device(y)
    # random signs: compare against the scale of the terms, not only the (small) result
    assert abs(reductions.dot(dx, dy) - dot_np(x, y)) <= 1e-6 * abs(dot_np(x, y)) + 1e-12 * dot_np(abs(x), abs(y))
    assert_close(reductions.norm2(dx), norm2_np(x))
    assert abs(reductions.sum(dx) - sum_np(x)) <= 1e-6 * abs(sum_np(x)) + 1e-12 * sum_np(abs(x))
    assert_close(reductions.abs_sum(dx), abs_sum_np(x))
    assert_close(reductions.diff_norm2(dx, dy), diff_norm2_np(x, y))


@pytest.mark.parametrize("work_items", [1, 3, 100, 5000])
@pytest.mark.parametrize("interleaved", [False, True])
def test_any_work_split_gives_the_same_answer(runtime, rng, work_items, interleaved):
    """Contiguous runs (CPU) or interleaved chunks (GPU), more work-items than chunks."""
    reductions = Reductions(runtime, work_items=work_items, interleaved=interleaved)
    for n in (5, 12345):
        x = rng.uniform(0, 1, n).astype(np.float32)
        y = rng.uniform(0, 1, n).astype(np.float32)
        dx, dy = runtime.to_device(x), runtime.to_device(y)
        assert_close(reductions.dot(dx, dy), exact_dot(x, y), 1e-12)
        assert_close(reductions.norm2(dx), exact_dot(x, x), 1e-12)
        assert_close(reductions.sum(dx), math.fsum(x.tolist()), 1e-12)


def test_ill_conditioned_dot_is_compensated(runtime, reductions, rng):
    """Terms of 2^+-12 that cancel to a small remainder: plain float32 loses every digit."""
    n = 50_000
    big = (rng.standard_normal(n) * 2.0 ** rng.integers(-12, 12, n)).astype(np.float32)
    small = rng.uniform(0, 1e-3, 1001).astype(np.float32)
    x = np.concatenate([big, small, -big])
    rng.shuffle(x)
    y = np.ones_like(x)
    expected = exact_dot(x, y)
    naive = float(np.cumsum(x, dtype=np.float32)[-1])  # sequential float32, for scale
    assert abs(naive - expected) > 1e-3 * abs(expected)
    dx, dy = runtime.to_device(x), runtime.to_device(y)
    assert_close(reductions.dot(dx, dy), expected, 1e-6)
    assert_close(reductions.sum(dx), expected, 1e-6)


def test_shapes_and_empty_arrays(runtime, reductions, rng):
    x = rng.standard_normal((3, 18, 27)).astype(np.float32)
    dx = runtime.to_device(x)
    assert_close(reductions.dot(dx, dx), norm2_np(x), 1e-12)
    empty = runtime.empty((0,))
    assert reductions.dot(empty, empty) == 0.0 and reductions.norm2(empty) == 0.0 and reductions.sum(empty) == 0.0


def test_partials_are_allocated_once(runtime, rng):
    reductions = Reductions(runtime)
    dx = runtime.to_device(rng.standard_normal(1000).astype(np.float32))
    reductions.dot(dx, dx)
    slots = [(host, buffer.int_ptr) for host, buffer in reductions._slots]
    for _ in range(3):
        reductions.dot(dx, dx), reductions.norm2(dx), reductions.sum(dx)
    assert [(host, buffer.int_ptr) for host, buffer in reductions._slots] == slots


def test_many_equals_one_at_a_time(runtime, reductions, rng):
    x = rng.standard_normal(12345).astype(np.float32)
    y = rng.standard_normal(12345).astype(np.float32)
    dx, dy = runtime.to_device(x), runtime.to_device(y)
    batched = reductions.many(("dot", dx, dy), ("norm2", dx), ("abs_sum", dy), ("diff_norm2", dx, dy))
    assert batched == [reductions.dot(dx, dy), reductions.norm2(dx), reductions.abs_sum(dy),
                       reductions.diff_norm2(dx, dy)]
    assert_close(batched[3], diff_norm2_np(x, y))


def test_bad_arguments_raise_value_error(runtime, reductions):
    x = runtime.zeros((10,))
    with pytest.raises(ValueError, match="y must be float32 of shape"):
        reductions.dot(x, runtime.zeros((11,)))
    with pytest.raises(ValueError, match="y must be float32"):
        reductions.dot(x, runtime.zeros((10,), np.float64))
    with pytest.raises(ValueError, match="x must be float32"):
        reductions.norm2(runtime.zeros((10,), np.float64))
    with pytest.raises(ValueError, match="work_items"):
        Reductions(runtime, work_items=0)


# -- 1e8 elements: relative error vs float64 <= 1e-6 ------------------------------------


@pytest.fixture(scope="module")
def big(runtime):
    """x, y ~ N(0, 1) float32 of 1e8 elements, on host and device, and |x|, |y| on the device."""
    import pyopencl as cl

    rng = np.random.default_rng(20240611)
    x = rng.standard_normal(BIG, dtype=np.float32)
    y = rng.standard_normal(BIG, dtype=np.float32)
    dx, dy = runtime.to_device(x), runtime.to_device(y)
    ax, ay = runtime.empty((BIG,)), runtime.empty((BIG,))
    for i in range(0, BIG, BLOCK):  # |x|, |y| uploaded slice by slice (no 400 MB temporaries)
        for src, dst in ((x, ax), (y, ay)):
            cl.enqueue_copy(runtime.queue, dst.data, np.abs(src[i:i + BLOCK]), dst_offset=4 * i)
    runtime.queue.finish()
    abs_dot = math.fsum(
        float(np.dot(np.abs(x[i:i + BLOCK]).astype(np.float64), np.abs(y[i:i + BLOCK]).astype(np.float64)))
        for i in range(0, BIG, BLOCK)
    )
    return dict(x=x, y=y, dx=dx, dy=dy, ax=ax, ay=ay, abs_dot=abs_dot)


def test_big_dot_random_signs(reductions, big):
    expected = dot_np(big["x"], big["y"])  # ~ +-1e4, with terms summing in |.| to ~6e7
    assert_close(reductions.dot(big["dx"], big["dy"]), expected)


def test_big_dot_positive(reductions, big):
    assert_close(reductions.dot(big["ax"], big["ay"]), big["abs_dot"])


def test_big_norm2(reductions, big):
    assert_close(reductions.norm2(big["dx"]), norm2_np(big["x"]))


def test_big_abs_sum_and_diff_norm2(reductions, big):
    assert_close(reductions.abs_sum(big["dx"]), abs_sum_np(big["x"]))
    assert_close(reductions.diff_norm2(big["dx"], big["dy"]), diff_norm2_np(big["x"], big["y"]))


def test_diff_norm2_of_nearly_equal_arrays(runtime, reductions, rng):
    # x - y is rounded in float32; the compensation must recover the exact difference.
    x = (1 + rng.random(10_001)).astype(np.float32)
    y = np.nextafter(x, np.float32(3))
    assert_close(reductions.diff_norm2(runtime.to_device(x), runtime.to_device(y)), diff_norm2_np(x, y))
