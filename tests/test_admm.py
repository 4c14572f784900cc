"""ADMM-TV: the OpenCL solver against the numpy float64 reference, and the method layer."""

from __future__ import annotations

import numpy as np
import pytest

from lfcl.ops.gradient import gradient_gram_np
from lfcl.ops.lensfill import lens_fill_np
from lfcl.ops.malvar import malvar_np
from lfcl.solvers.admm import AdmmSolver
from lfcl.solvers.params import AdmmParams
from lfcl.solvers.reference import admm_reference, neighbour_count


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


def test_lens_solve_at_a_large_pitch_on_a_large_frame(runtime, rng):
    # Each lens's solve holds 2 (U V) floats in private arrays; PoCL, choosing the work-group itself, overflowed its
    # thread stack from about 64x64 lenses at pitch 13 (a segmentation fault). With the (u, v) prior alone every lens
    # is solved on its own, so the frame's result is its lenses' results: a crop of it solved alone must agree.
    S, T, U, V = 64, 64, 13, 13
    b, x0 = smooth_lightfield_mosaic(rng, S, T, U, V)
    params = AdmmParams(lam=0.01, rho=0.3, max_iter=2, x_update="lens")
    whole = AdmmSolver(runtime, b.shape, "GRBG", (U, V), "uv").solve(runtime.to_device(b), runtime.to_device(x0),
                                                                       params)
    rows, cols = slice(0, 4 * U), slice(0, 6 * V)
    crop = AdmmSolver(runtime, (4 * U, 6 * V), "GRBG", (U, V), "uv").solve(
        runtime.to_device(np.ascontiguousarray(b[rows, cols])), runtime.to_device(np.ascontiguousarray(x0[:, rows, cols])),
        params)
    assert np.all(np.isfinite(whole.x.get()))
    np.testing.assert_allclose(whole.x.get()[:, rows, cols], crop.x.get(), rtol=0, atol=1e-6)


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
    from lfcl.demosaic.driver import demosaic_grid
    from lfcl.grid.model import AlignedGrid
    from lfcl.noise.model import NoiseEstimate

    b, _ = smooth_lightfield_mosaic(rng, 7, 5, 9, 9, noise=0.03)
    noise = NoiseEstimate(0.0, 0.03**2, 0.03, "test")
    whole = demosaic_grid(b, "GRBG", AlignedGrid((9, 9)), "admm-uv", iterations=6, noise=noise)
    bands = demosaic_grid(b, "GRBG", AlignedGrid((9, 9)), "admm-uv", iterations=6, noise=noise, max_memory=150_000)
    assert "bands of lens rows" in bands.stop_reason and "bands" not in whole.stop_reason
    assert len({h["band"] for h in bands.history}) > 2
    np.testing.assert_allclose(bands.planes, whole.planes, rtol=0, atol=2e-6)
    # recorded as admm-epi records its bands (a user cannot tell them from the stop reason alone)
    record = bands.parameters["bands"]
    assert sum(record["rows"]) == b.shape[0] and len(record["rows"]) > 2
    assert record["iterations"] == [6] * len(record["rows"])
    assert "bands" not in whole.parameters and " 6 iterations" in bands.stop_reason  # not "6-6"


def test_coupled_priors_say_why_they_cannot_run_in_bands(rng):
    from lfcl.demosaic.driver import demosaic_grid
    from lfcl.grid.model import AlignedGrid

    b, _ = smooth_lightfield_mosaic(rng, 4, 4, 9, 9)
    with pytest.raises(ValueError, match="couples\\s+neighbouring lenses|couples neighbouring lenses"):
        demosaic_grid(b, "GRBG", AlignedGrid((9, 9)), "admm-st", iterations=2, max_memory=100_000)
    # sizes a user can act on (a frame this small needed "0.0 GiB" of "0.0 GiB")
    with pytest.raises(ValueError, match=r"needs about \d+\.\d MiB .* allows 0\.1 MiB"):
        demosaic_grid(b, "GRBG", AlignedGrid((9, 9)), "admm-st", iterations=2, max_memory=100_000)


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


# -- the cross-channel prior: K = [D; D C], lam ||D x||_1 + lam_xc ||D C x||_1 ----------------


@pytest.mark.parametrize("dims,pattern", [("uv", "GRBG"), ("st", "BGGR"), ("uvst", "RGGB")])
def test_cross_channel_device_matches_numpy_reference(runtime, rng, dims, pattern):
    U, V = 9, 9
    b, x0 = smooth_lightfield_mosaic(rng, 3, 4, U, V, pattern)
    params = AdmmParams(lam=0.01, lam_xc=0.03, max_iter=10, cg_steps=4, cg_tol=0.0, x_update="cg")
    expected = admm_reference(b, pattern, (U, V), dims, params, x0)
    solver = AdmmSolver(runtime, b.shape, pattern, (U, V), dims)
    got = solver.solve(runtime.to_device(b), runtime.to_device(x0), params)
    relative = np.linalg.norm(got.x.get() - expected.x) / np.linalg.norm(expected.x)
    assert relative <= 1e-4, relative
    plain = admm_reference(b, pattern, (U, V), dims, AdmmParams(lam=0.01, max_iter=10, cg_tol=0.0), x0)
    assert np.linalg.norm(plain.x - expected.x) > 100 * np.linalg.norm(got.x.get() - expected.x)  # xc matters
    for mine, ref in zip(got.history, expected.history):
        assert mine.objective == pytest.approx(ref.objective, rel=1e-4)
        assert mine.primal_residual == pytest.approx(ref.primal_residual, rel=1e-3, abs=1e-6)
        assert mine.dual_residual == pytest.approx(ref.dual_residual, rel=1e-3, abs=1e-6)


@pytest.mark.parametrize("pattern,pitch", [("GRBG", (9, 9)), ("GBRG", (4, 5))])
def test_cross_channel_exact_lens_solve_matches_converged_cg(runtime, rng, pattern, pitch):
    # The 3UV x 3UV per-lens inverse must give what CG gives when run to convergence.
    U, V = pitch
    b, x0 = smooth_lightfield_mosaic(rng, 3, 5, U, V, pattern)
    exact = AdmmParams(lam=0.01, lam_xc=0.02, max_iter=6, x_update="lens")
    converged = AdmmParams(lam=0.01, lam_xc=0.02, max_iter=6, cg_steps=600, cg_tol=1e-13)
    expected = admm_reference(b, pattern, pitch, "uv", converged, x0)
    solver = AdmmSolver(runtime, b.shape, pattern, pitch, "uv")
    got = solver.solve(runtime.to_device(b), runtime.to_device(x0), exact)
    relative = np.linalg.norm(got.x.get() - expected.x) / np.linalg.norm(expected.x)
    assert relative <= 1e-5, relative
    assert all(r.cg_steps == 0 for r in got.history)
    # the same solver object then runs the plain prior again, exactly as before
    plain = AdmmParams(lam=0.01, max_iter=6, x_update="lens")
    again = solver.solve(runtime.to_device(b), runtime.to_device(x0), plain).x.get()
    fresh = AdmmSolver(runtime, b.shape, pattern, pitch, "uv").solve(runtime.to_device(b), runtime.to_device(x0), plain)
    np.testing.assert_array_equal(again, fresh.x.get())


@pytest.mark.parametrize("dims,x_update", [("uv", "lens"), ("uvst", "cg")])
def test_cross_channel_with_weighted_data_term(runtime, rng, dims, x_update):
    U, V = 9, 9
    b, x0 = smooth_lightfield_mosaic(rng, 3, 4, U, V, "GRBG")
    weights = vignetting_weights(U, V, floor=0.3)
    steps, tol = (600, 1e-13) if x_update == "lens" else (4, 0.0)
    expected = admm_reference(b, "GRBG", (U, V), dims, AdmmParams(lam=0.01, lam_xc=0.02, max_iter=5, cg_steps=steps,
                                                                    cg_tol=tol), x0, lens_weights=weights)
    params = AdmmParams(lam=0.01, lam_xc=0.02, max_iter=5, cg_steps=4, cg_tol=0.0, x_update=x_update)
    got = AdmmSolver(runtime, b.shape, "GRBG", (U, V), dims).solve(
        runtime.to_device(b), runtime.to_device(x0), params, lens_weights=weights)
    relative = np.linalg.norm(got.x.get() - expected.x) / np.linalg.norm(expected.x)
    assert relative <= 1e-4, relative


def test_cross_channel_reference_solves_the_problem_it_states(rng):
    from lfcl.ops.cfa import cfa_sample_np
    from lfcl.ops.crosschannel import cross_gradient_np
    from lfcl.ops.gradient import gradient_np

    b, x0 = smooth_lightfield_mosaic(rng, 2, 2, 3, 3, noise=0.05)
    params = AdmmParams(lam=0.01, lam_xc=0.03, rho=1.0, max_iter=3000, cg_steps=50, cg_tol=1e-12,
                        abs_tol=1e-9, rel_tol=1e-7)
    result = admm_reference(b, "GRBG", (3, 3), "uv", params, x0)

    def objective(x):
        return (0.5 * np.sum((cfa_sample_np(x, "GRBG") - b) ** 2) + 0.01 * np.abs(gradient_np(x, (3, 3), "uv")).sum()
                + 0.03 * np.abs(cross_gradient_np(x, (3, 3), "uv")).sum())

    best = objective(result.x)
    assert result.history[-1].objective == pytest.approx(best, rel=1e-9)
    for _ in range(50):
        assert objective(result.x + 1e-3 * rng.standard_normal(result.x.shape)) >= best - 1e-9
    assert result.stop_reason.startswith("primal and dual")


# -- dark pixels out of the prior (issue #6): K = M D, M dropping differences at weight-0 pixels --


@pytest.mark.parametrize("dims,x_update,lam_xc", [("uv", "lens", 0.0), ("uv", "cg", 0.0), ("uvst", "cg", 0.0),
                                                  ("uv", "lens", 0.02), ("uvst", "cg", 0.02)])
def test_prior_mask_matches_the_reference(runtime, rng, dims, x_update, lam_xc):
    U, V = 9, 9
    b, x0 = smooth_lightfield_mosaic(rng, 3, 4, U, V, "GBRG")
    weights = vignetting_weights(U, V, floor=0.3)
    exact = x_update == "lens"
    reference_params = AdmmParams(lam=0.01, lam_xc=lam_xc, max_iter=6, cg_steps=600 if exact else 4,
                                  cg_tol=1e-13 if exact else 0.0)
    expected = admm_reference(b, "GBRG", (U, V), dims, reference_params, x0, lens_weights=weights)
    params = AdmmParams(lam=0.01, lam_xc=lam_xc, max_iter=6, cg_steps=4, cg_tol=0.0, x_update=x_update)
    got = AdmmSolver(runtime, b.shape, "GBRG", (U, V), dims).solve(
        runtime.to_device(b), runtime.to_device(x0), params, lens_weights=weights)
    x = got.x.get()
    relative = np.linalg.norm(x - expected.x) / np.linalg.norm(expected.x)
    assert relative <= 1e-4, relative
    for mine, ref in zip(got.history, expected.history):
        assert mine.objective == pytest.approx(ref.objective, rel=1e-4)
    # dark pixels have neither data nor prior: after the solve, the harmonic extension of their lens
    np.testing.assert_allclose(x, lens_fill_np(x, weights, (U, V)), rtol=0, atol=1e-6)
    np.testing.assert_array_equal(expected.x, lens_fill_np(expected.x, weights, (U, V)))


@pytest.mark.parametrize("dims", ["uv", "uvst"])
def test_masked_dark_pixels_neither_see_nor_touch_the_rest(runtime, rng, dims):
    # Garbage in the start and the mosaic at dark pixels changes nothing, not even the dark
    # pixels (they are filled from their lens's lit pixels after the solve).
    U, V = 9, 9
    b, x0 = smooth_lightfield_mosaic(rng, 3, 4, U, V)
    weights = vignetting_weights(U, V, floor=0.3)
    dark = np.tile(weights == 0, (3, 4))
    b_bad, x0_bad = b.copy(), x0.copy()
    b_bad[dark], x0_bad[:, dark] = 50.0, -7.0
    solver = AdmmSolver(runtime, b.shape, "GRBG", (U, V), dims)
    params = AdmmParams(lam=0.01, lam_xc=0.01, max_iter=5)
    clean = solver.solve(runtime.to_device(b), runtime.to_device(x0), params, lens_weights=weights).x.get()
    dirty = solver.solve(runtime.to_device(b_bad), runtime.to_device(x0_bad), params, lens_weights=weights).x.get()
    np.testing.assert_allclose(dirty, clean, rtol=0, atol=1e-6)
    # with the garbage start kept (no fill: the callback sees the iterates), the dark pixels hold it
    seen = []
    solver.solve(runtime.to_device(b_bad), runtime.to_device(x0_bad), params, lens_weights=weights,
                 callback=lambda record, x: seen.append(x.get()[:, dark]))
    assert all(np.all(s == -7.0) for s in seen)


def test_an_isolated_bright_pixel_falls_back_to_cg(runtime, rng):
    # A lit pixel whose neighbours are all dark measures one colour only: its part of the
    # lens is singular for the exact solve, so 'auto' uses CG and 'lens' says why not.
    U, V = 5, 5
    b, x0 = smooth_lightfield_mosaic(rng, 2, 4, U, V)
    weights = np.ones((U, V), np.float32)
    weights[0, 1] = weights[1, 0] = 0  # pixel (0, 0) is cut off from the rest
    solver = AdmmSolver(runtime, b.shape, "GRBG", (U, V), "uv")
    got = solver.solve(runtime.to_device(b), runtime.to_device(x0), AdmmParams(max_iter=3), lens_weights=weights)
    assert any(r.cg_steps > 0 for r in got.history)  # (the first x-update from a Malvar start needs none)
    with pytest.raises(ValueError, match="every connected part"):
        solver.solve(runtime.to_device(b), runtime.to_device(x0), AdmmParams(x_update="lens"), lens_weights=weights)


def test_cross_channel_methods_follow_sigma():
    from lfcl.demosaic.methods import ADMM_DEFAULTS, admm_params

    for method in ("admm-uv-xc", "admm-uvst-xc"):
        d = ADMM_DEFAULTS[method]
        assert d.xc_per_sigma > 0
        params = admm_params(method, 0.02)
        assert params.lam_xc == pytest.approx(d.xc_per_sigma * 0.02) and params.cross_channel
        assert admm_params(method, 0.02, strength=2.0).lam_xc == pytest.approx(2 * params.lam_xc)
        explicit = admm_params(method, 0.0, lam=0.5)  # no sigma needed: lam_xc keeps its ratio to lam
        assert explicit.lam_xc == pytest.approx(0.5 * d.xc_per_sigma / d.lam_per_sigma)
    assert admm_params("admm-uv", 0.02).lam_xc == 0.0


def test_admm_uv_xc_in_bands_of_lens_rows_equals_the_whole(rng):
    # The cross-channel prior over (u, v) couples colours, not lenses: bands stay exact.
    from lfcl.demosaic.driver import demosaic_grid
    from lfcl.grid.model import AlignedGrid
    from lfcl.noise.model import NoiseEstimate

    b, _ = smooth_lightfield_mosaic(rng, 5, 4, 9, 9, noise=0.03)
    noise = NoiseEstimate(0.0, 0.03**2, 0.03, "test")
    whole = demosaic_grid(b, "GRBG", AlignedGrid((9, 9)), "admm-uv-xc", iterations=5, noise=noise)
    bands = demosaic_grid(b, "GRBG", AlignedGrid((9, 9)), "admm-uv-xc", iterations=5, noise=noise, max_memory=150_000)
    assert "bands of lens rows" in bands.stop_reason and whole.parameters["lam_xc"] > 0
    np.testing.assert_allclose(bands.planes, whole.planes, rtol=0, atol=2e-6)


@pytest.mark.parametrize("lam_xc", [0.0, 0.003])
def test_exact_solve_keeps_a_flat_image_flat(runtime, lam_xc):
    # The exact x-update adds M^-1 (rhs - M x): on a flat image the residual is 0, so
    # float32 round-off in the 3UV x 3UV blocks cannot creep in (x = M^-1 rhs drifted by 3e-5).
    b = np.full((36, 45), 0.37, np.float32)
    x0 = np.full((3, 36, 45), 0.37, np.float32)
    solver = AdmmSolver(runtime, b.shape, "GRBG", (9, 9), "uv")
    result = solver.solve(runtime.to_device(b), runtime.to_device(x0), AdmmParams(lam=0.01, lam_xc=lam_xc, max_iter=10))
    assert np.abs(result.x.get() - 0.37).max() <= 1e-6


def test_admm_uv_xc_defaults_are_what_their_fit_chose():
    """The admm-uv-xc entry of ADMM_DEFAULTS is the pair research/fit_uv_xc.py chose on the rows it ran
    (research/fit_uv_xc_48.json; docs/admm.md, "The cross-channel prior"): changing the defaults means refitting."""
    import json
    from pathlib import Path

    from fit_uv_xc import TOLERANCE_DB, chosen, summary  # research/, on sys.path through conftest.py

    from lfcl.demosaic.methods import ADMM_DEFAULTS

    fit = json.loads((Path(__file__).resolve().parents[1] / "research" / "fit_uv_xc_48.json").read_text())
    rows, pairs = fit["rows"], [t["pair"] for t in fit["table"]]
    assert {row["capture"].split()[0] for row in rows} >= {"charts", "deadleaves", "finetexture", "gratings"}
    best = chosen(summary(rows, pairs))
    d = ADMM_DEFAULTS["admm-uv-xc"]
    assert best["pair"] == f"{d.lam_per_sigma:g},{d.xc_per_sigma:g}"
    # never below Malvar (to the net's precision) on any training capture, the gratings included
    assert min(min(row["changes"][best["pair"]][:2]) for row in rows) >= -TOLERANCE_DB
