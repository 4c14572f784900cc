"""The solver's fused iteration kernels (admm.cl zu_step, dual_and_misfit, lens_solve's sums)
against their numpy twins, and the weight table the admm kernels read."""

from __future__ import annotations

import numpy as np
import pytest

from lfcl.ops.cfa import cfa_sample_np
from lfcl.ops.gradient import gradient_adjoint_np, gradient_np
from lfcl.ops.shrink import zu_update_np
from lfcl.solvers.admm import AdmmSolver, weight_runs_np

S, T, U, V = 3, 5, 5, 7


def _weights(masked: bool) -> np.ndarray:
    weights = np.linspace(0.5, 1.5, U * V).reshape(U, V).astype(np.float32)
    if masked:
        weights[0, 0] = weights[U - 1, V - 2] = 0.0
    return weights


def _solver(runtime, dims, masked):
    solver = AdmmSolver(runtime, (S * U, T * V), "GRBG", (U, V), dims)
    solver.set_lens_weights(_weights(masked))
    solver.set_cross_channel(False)
    return solver


def test_weight_runs_repeat_each_lens_row_from_every_phase():
    weights = np.arange(6, dtype=np.float32).reshape(2, 3)
    runs = weight_runs_np(weights).reshape(2, 3, 16)
    for u in range(2):
        for p in range(3):
            expected = np.tile(np.roll(weights[u], -p), 6)[:16]
            np.testing.assert_array_equal(runs[u, p], expected)


@pytest.mark.parametrize("masked", [False, True])
@pytest.mark.parametrize("dims", ["uv", "uvst"])
def test_zu_step_matches_numpy(runtime, rng, dims, masked):
    solver = _solver(runtime, dims, masked)
    x = rng.standard_normal((3, S * U, T * V)).astype(np.float32)
    z = rng.standard_normal(solver.D.gradient_shape).astype(np.float32)
    u = 0.3 * rng.standard_normal(solver.D.gradient_shape).astype(np.float32)
    solver._z.set(z)
    solver._u.set(u)
    kappa = 0.4
    solver.zu_step(runtime.to_device(x), kappa)
    primal2, tv, kx2, *_ = solver._fetch_sums(with_change=False)
    mask = _weights(masked) if masked else None
    dx = gradient_np(x, (U, V), dims, mask).astype(np.float32)
    z_new, u_new, dz = zu_update_np(dx, z, u, kappa)
    np.testing.assert_allclose(solver._z.get(), z_new, atol=1e-6)
    np.testing.assert_allclose(solver._u.get(), u_new, atol=1e-6)
    np.testing.assert_allclose(solver._dz.get(), dz, atol=1e-6)
    dx64 = dx.astype(np.float64)
    assert primal2 == pytest.approx(np.sum((dx64 - z_new) ** 2), rel=1e-5)
    assert tv == pytest.approx(np.abs(dx64).sum(), rel=1e-5)
    assert kx2 == pytest.approx(np.sum(dx64 ** 2), rel=1e-5)


@pytest.mark.parametrize("accumulate", [False, True])
@pytest.mark.parametrize("masked", [False, True])
def test_dual_and_misfit_matches_numpy(runtime, rng, masked, accumulate):
    dims = "uv"
    solver = _solver(runtime, dims, masked)
    x = rng.standard_normal((3, S * U, T * V)).astype(np.float32)
    b = rng.standard_normal((S * U, T * V)).astype(np.float32)
    dz = rng.standard_normal(solver.D.gradient_shape).astype(np.float32)
    before = rng.standard_normal((3, S * U, T * V)).astype(np.float32)
    solver._dz.set(dz)
    solver._tmp.set(before)
    solver.dual_and_misfit(runtime.to_device(x), runtime.to_device(b), accumulate=accumulate)
    _, _, _, dual2, misfit2 = solver._fetch_sums(with_change=False)
    weights = _weights(masked)
    expected = gradient_adjoint_np(dz, (U, V), dims, weights if masked else None).astype(np.float64)
    if accumulate:
        expected += before
    np.testing.assert_allclose(solver._tmp.get(), expected, atol=1e-5)
    assert dual2 == pytest.approx(np.sum(expected ** 2), rel=1e-5)
    pixel_weights = np.tile(weights, (S, T)).astype(np.float64)
    residual = cfa_sample_np(x.astype(np.float64), "GRBG") - b
    assert misfit2 == pytest.approx(np.sum(pixel_weights * residual ** 2), rel=1e-5)


@pytest.mark.parametrize("masked", [False, True])
def test_lens_solve_sums_its_squared_update(runtime, rng, masked):
    solver = _solver(runtime, "uv", masked)
    x0 = rng.standard_normal((3, S * U, T * V)).astype(np.float32)
    x = runtime.to_device(x0)
    rhs = runtime.to_device(rng.standard_normal((3, S * U, T * V)).astype(np.float32))
    solver.lens_solve(rhs, x, 0.5, accumulate=True)
    change2 = solver._fetch_sums(with_change=True)[-1]
    assert change2 == pytest.approx(np.sum((x.get().astype(np.float64) - x0) ** 2), rel=1e-4)
    assert change2 > 0
