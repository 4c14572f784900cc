"""ADMM-TV: the OpenCL solver against the numpy float64 reference, and the method layer."""

from __future__ import annotations

import numpy as np
import pytest

from lfcl.ops.malvar import malvar_np
from lfcl.solvers.admm import AdmmSolver
from lfcl.solvers.params import AdmmParams
from lfcl.solvers.reference import admm_reference, neighbour_count
from lfcl.ops.gradient import gradient_gram_np


def smooth_lightfield_mosaic(rng, S, T, U, V, pattern="GRBG", noise=0.02):
    """A noisy mosaic of a smooth random scene, and its Malvar start."""
    H, W = S * U, T * V
    yy, xx = np.mgrid[0:H, 0:W] / max(H, W)
    planes = np.stack([0.4 + 0.3 * np.sin(3 * xx + c) * np.cos(2 * yy - c) for c in range(3)])
    from lfcl.ops.cfa import cfa_sample_np

    b = cfa_sample_np(planes, pattern) + noise * rng.standard_normal((H, W))
    b = b.astype(np.float32)
    return b, malvar_np(b, pattern)


@pytest.mark.parametrize("dims", ["uv", "st", "uvst"])
@pytest.mark.parametrize("pattern", ["GRBG", "BGGR"])
def test_device_matches_numpy_reference(runtime, rng, dims, pattern):
    S, T, U, V = 4, 5, 9, 9
    b, x0 = smooth_lightfield_mosaic(rng, S, T, U, V, pattern)
    params = AdmmParams(lam=0.01, rho=0.3, max_iter=12, cg_steps=4, cg_tol=0.0, x_update="cg")
    expected = admm_reference(b, pattern, (U, V), dims, params, x0)
    solver = AdmmSolver(runtime, b.shape, pattern, (U, V), dims)
    got = solver.solve(runtime.to_device(b), runtime.to_device(x0), params)
    x = got.x.get()
    relative = np.linalg.norm(x - expected.x) / np.linalg.norm(expected.x)
    assert relative <= 1e-4, relative
    assert got.iterations == expected.iterations == 12
    for mine, ref in zip(got.history, expected.history):
        assert mine.objective == pytest.approx(ref.objective, rel=1e-4)
        assert mine.primal_residual == pytest.approx(ref.primal_residual, rel=1e-3, abs=1e-6)
        assert mine.dual_residual == pytest.approx(ref.dual_residual, rel=1e-3, abs=1e-6)


@pytest.mark.parametrize("pattern", ["RGGB", "GBRG"])
@pytest.mark.parametrize("pitch", [(9, 9), (4, 5)])
def test_exact_lens_solve_matches_converged_cg(runtime, rng, pattern, pitch):
    # The per-lens inverse must give what CG gives when run to convergence.
    U, V = pitch
    b, x0 = smooth_lightfield_mosaic(rng, 3, 5, U, V, pattern)  # odd T: a lens without a pair
    exact = AdmmParams(lam=0.01, rho=0.3, max_iter=8, x_update="lens")
    converged = AdmmParams(lam=0.01, rho=0.3, max_iter=8, cg_steps=400, cg_tol=1e-13)
    expected = admm_reference(b, pattern, pitch, "uv", converged, x0)
    solver = AdmmSolver(runtime, b.shape, pattern, pitch, "uv")
    got = solver.solve(runtime.to_device(b), runtime.to_device(x0), exact)
    relative = np.linalg.norm(got.x.get() - expected.x) / np.linalg.norm(expected.x)
    assert relative <= 1e-5, relative
    assert all(r.cg_steps == 0 for r in got.history)


def test_lens_solve_needs_a_uv_prior(runtime, rng):
    b, x0 = smooth_lightfield_mosaic(rng, 2, 2, 9, 9)
    solver = AdmmSolver(runtime, b.shape, "GRBG", (9, 9), "uvst")
    with pytest.raises(ValueError, match="needs a prior over"):
        solver.solve(runtime.to_device(b), runtime.to_device(x0), AdmmParams(x_update="lens"))


def test_reference_solves_the_problem_it_states(rng):
    # Run to convergence on a tiny problem: the result must satisfy the optimality
    # condition 0 in A^T(Ax - b) + lam D^T sign(Dx) up to the subgradient's freedom,
    # checked as: the objective is below that of perturbed points.
    from lfcl.ops.cfa import cfa_sample_np
    from lfcl.ops.gradient import gradient_np

    b, x0 = smooth_lightfield_mosaic(rng, 2, 2, 3, 3, noise=0.05)
    params = AdmmParams(lam=0.02, rho=1.0, max_iter=3000, cg_steps=50, cg_tol=1e-12, abs_tol=1e-9, rel_tol=1e-7)
    result = admm_reference(b, "GRBG", (3, 3), "uv", params, x0)

    def objective(x):
        return 0.5 * np.sum((cfa_sample_np(x, "GRBG") - b) ** 2) + 0.02 * np.abs(gradient_np(x, (3, 3), "uv")).sum()

    best = objective(result.x)
    for _ in range(50):
        assert objective(result.x + 1e-3 * rng.standard_normal(result.x.shape)) >= best - 1e-9
    assert result.stop_reason.startswith("primal and dual")


def test_objective_decreases_from_the_malvar_start(runtime, rng):
    b, x0 = smooth_lightfield_mosaic(rng, 6, 6, 9, 9, noise=0.05)
    solver = AdmmSolver(runtime, b.shape, "GRBG", (9, 9), "uv")
    result = solver.solve(runtime.to_device(b), runtime.to_device(x0), AdmmParams(lam=0.02, max_iter=40))
    objectives = [r.objective for r in result.history]
    assert objectives[-1] < objectives[0]
    assert result.history[-1].primal_residual < result.history[0].primal_residual


def test_stops_on_rms_change(runtime, rng):
    b, x0 = smooth_lightfield_mosaic(rng, 4, 4, 9, 9)
    solver = AdmmSolver(runtime, b.shape, "GRBG", (9, 9), "uv")
    result = solver.solve(runtime.to_device(b), runtime.to_device(x0),
                          AdmmParams(lam=0.01, max_iter=200, change_tol=1e-3))
    assert result.iterations < 200
    assert result.history[-1].rms_change <= 1e-3
    assert "rms change" in result.stop_reason


def test_jacobi_diagonal_matches_the_operator(rng):
    # diag(D^T D) by probing unit vectors equals the neighbour count the preconditioner uses.
    shape = (3, 6, 6)
    probes = rng.choice(np.prod(shape), 40, replace=False)
    for i in probes:
        e = np.zeros(np.prod(shape))
        e[i] = 1
        diag = gradient_gram_np(e.reshape(shape), (3, 3), "uvst").ravel()[i]
        assert diag == neighbour_count(shape, (3, 3), "uvst").ravel()[i]


def test_bad_parameters_raise():
    with pytest.raises(ValueError, match="rho must be > 0"):
        AdmmParams(rho=0)
    with pytest.raises(ValueError, match="lam must be a finite"):
        AdmmParams(lam=float("nan"))
    with pytest.raises(ValueError, match="max_iter must be an integer"):
        AdmmParams(max_iter=0)


def test_admm_uv_in_bands_of_lens_rows_equals_the_whole(rng):
    # The (u, v) prior couples no two lenses, so bands (with odd lens-row offsets,
    # hence shifted Bayer phases) must reproduce the single solve.
    from lfcl.methods import demosaic_lightfield
    from lfcl.noise import NoiseEstimate

    b, _ = smooth_lightfield_mosaic(rng, 7, 5, 9, 9, noise=0.03)
    noise = NoiseEstimate(0.0, 0.03**2, 0.03, "test")
    whole = demosaic_lightfield(b, "GRBG", (9, 9), "admm-uv", iterations=6, noise=noise)
    bands = demosaic_lightfield(b, "GRBG", (9, 9), "admm-uv", iterations=6, noise=noise, max_memory=150_000)
    assert "bands of lens rows" in bands.stop_reason and "bands" not in whole.stop_reason
    assert len({h["band"] for h in bands.history}) > 2
    np.testing.assert_allclose(bands.planes, whole.planes, rtol=0, atol=2e-6)


def test_coupled_priors_say_why_they_cannot_run_in_bands(rng):
    from lfcl.methods import demosaic_lightfield

    b, _ = smooth_lightfield_mosaic(rng, 4, 4, 9, 9)
    with pytest.raises(ValueError, match="couples\\s+neighbouring lenses|couples neighbouring lenses"):
        demosaic_lightfield(b, "GRBG", (9, 9), "admm-st", iterations=2, max_memory=100_000)


def vignetting_weights(U, V, floor=0.0):
    """A white-image-like response: 1 in the middle of the lens, falling towards the corners."""
    u = (np.arange(U) - (U - 1) / 2) / max(U / 2, 1)
    v = (np.arange(V) - (V - 1) / 2) / max(V / 2, 1)
    w = np.clip(1.0 - 0.6 * (u[:, None] ** 2 + v[None, :] ** 2), 0, None)
    w[w < floor] = 0.0  # dark corners left out of the data term
    return w.astype(np.float32)


@pytest.mark.parametrize("dims,x_update", [("uv", "lens"), ("uv", "cg"), ("uvst", "cg")])
def test_weighted_data_term_matches_the_reference(runtime, rng, dims, x_update):
    U, V = 9, 9
    b, x0 = smooth_lightfield_mosaic(rng, 3, 5, U, V, "GBRG")
    weights = vignetting_weights(U, V, floor=0.3)
    assert (weights == 0).any()
    steps = 400 if x_update == "lens" else 4
    reference_params = AdmmParams(lam=0.01, max_iter=6, cg_steps=steps, cg_tol=1e-13 if x_update == "lens" else 0.0)
    expected = admm_reference(b, "GBRG", (U, V), dims, reference_params, x0, lens_weights=weights)
    solver = AdmmSolver(runtime, b.shape, "GBRG", (U, V), dims)
    params = AdmmParams(lam=0.01, max_iter=6, cg_steps=4, cg_tol=0.0, x_update=x_update)
    got = solver.solve(runtime.to_device(b), runtime.to_device(x0), params, lens_weights=weights)
    relative = np.linalg.norm(got.x.get() - expected.x) / np.linalg.norm(expected.x)
    assert relative <= 1e-4, relative
    for mine, ref in zip(got.history, expected.history):
        assert mine.objective == pytest.approx(ref.objective, rel=1e-4)


def test_zero_weight_pixels_do_not_influence_the_result(runtime, rng):
    # Whatever a left-out pixel holds, the solution is the same.
    U, V = 9, 9
    b, x0 = smooth_lightfield_mosaic(rng, 3, 4, U, V)
    weights = vignetting_weights(U, V, floor=0.3)
    corrupted = b.copy()
    dark = np.tile(weights == 0, (3, 4))
    corrupted[dark] = 50.0  # hot garbage in the vignetted corners
    solver = AdmmSolver(runtime, b.shape, "GRBG", (U, V), "uv")
    params = AdmmParams(lam=0.01, max_iter=5)
    clean = solver.solve(runtime.to_device(b), runtime.to_device(x0), params, lens_weights=weights).x.get()
    dirty = solver.solve(runtime.to_device(corrupted), runtime.to_device(x0), params, lens_weights=weights).x.get()
    np.testing.assert_allclose(dirty, clean, atol=1e-6)
    # and unit weights are the paper's unweighted problem
    plain = solver.solve(runtime.to_device(b), runtime.to_device(x0), params).x.get()
    ones = solver.solve(runtime.to_device(b), runtime.to_device(x0), params, lens_weights=np.ones((U, V))).x.get()
    np.testing.assert_array_equal(plain, ones)


def test_bad_lens_weights_raise(runtime, rng):
    b, x0 = smooth_lightfield_mosaic(rng, 2, 2, 9, 9)
    solver = AdmmSolver(runtime, b.shape, "GRBG", (9, 9), "uv")
    for bad in (np.ones((3, 3)), -np.ones((9, 9)), np.full((9, 9), np.nan)):
        with pytest.raises(ValueError, match="lens weights"):
            solver.solve(runtime.to_device(b), runtime.to_device(x0), AdmmParams(max_iter=1), lens_weights=bad)
