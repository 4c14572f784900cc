"""ADMM with the resampling inside A (lfcl/solvers/resampled.py) against its float64 reference, and the
grid demosaic entry point (lfcl/demosaic/resampled.py)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse

from lfcl.demosaic.driver import demosaic_grid
from lfcl.grid.model import ResampledGrid
from lfcl.grid.resampling import sampling_model
from lfcl.layout import planes_to_exchange
from lfcl.noise.resampled import estimate_grid_noise
from lfcl.ops.gradient import gradient_gram_np
from lfcl.ops.malvar import malvar_np
from lfcl.sim.geometry import GridGeometry
from lfcl.solvers.params import AdmmParams
from lfcl.solvers.reference import admm_resampled_reference
from lfcl.solvers.resampled import ResampledAdmmSolver, normal_diagonal

SMALL = {
    "rotated": GridGeometry((47, 53), "square", 5.4, 0.7, (0.3, -0.2)),
    "hex": GridGeometry((45, 51), "hex", 5.6, -0.6, (0.1, 0.3)),
}


def smooth_problem(rng, name, pattern="GRBG", noise=0.01):
    """A sampling model, noisy measurements of a smooth light field, and the malvar-then-resample start."""
    geometry = SMALL[name]
    model = sampling_model(geometry, pattern)
    H, W = geometry.sensor_shape
    yy, xx = np.mgrid[0:H, 0:W] / max(H, W)
    sensor = np.stack([0.4 + 0.3 * np.sin(3 * xx + c) * np.cos(2 * yy - c) for c in range(3)])
    from lfcl.ops.cfa import cfa_sample_np

    raw = (cfa_sample_np(sensor, pattern) * model.response + noise * rng.standard_normal((H, W))).astype(np.float32)
    b, weights = model.data(raw)
    start = malvar_np(model.flat_field(raw), pattern)
    M = model.resample_matrix()
    x0 = np.stack([M @ start[c].ravel() for c in range(3)]).reshape(model.planes_shape).astype(np.float32)
    return model, raw, b, weights, x0


@pytest.mark.parametrize("dims", ["uv", "st", "uvst"])
@pytest.mark.parametrize("name", sorted(SMALL))
def test_device_matches_float64_reference(runtime, rng, name, dims):
    model, _, b, weights, x0 = smooth_problem(rng, name)
    A = model.forward_matrix()
    shape = (*model.lenses, *model.views)
    params = AdmmParams(lam=0.01, rho=0.3, max_iter=10, cg_steps=4, cg_tol=0.0, x_update="cg")
    expected = admm_resampled_reference(b, weights, A, shape, dims, params, x0)
    solver = ResampledAdmmSolver(runtime, A, shape, dims)
    got = solver.solve(runtime.to_device(b), runtime.to_device(weights), runtime.to_device(x0), params)
    x = got.x.get()
    relative = np.linalg.norm(x - expected.x) / np.linalg.norm(expected.x)
    assert relative <= 1e-4, relative
    assert np.linalg.norm(x - x0) > 100 * np.linalg.norm(x - expected.x)  # it moved, and moved the same way
    assert got.iterations == expected.iterations == 10
    for mine, ref in zip(got.history, expected.history):
        assert mine.objective == pytest.approx(ref.objective, rel=1e-4)
        assert mine.primal_residual == pytest.approx(ref.primal_residual, rel=1e-3, abs=1e-6)
        assert mine.dual_residual == pytest.approx(ref.dual_residual, rel=1e-3, abs=1e-6)
        assert mine.rms_change == pytest.approx(ref.rms_change, rel=1e-3, abs=1e-7)


def test_stopping_rule_and_second_solve_agree_with_the_reference(runtime, rng):
    model, _, b, weights, x0 = smooth_problem(rng, "hex")
    A = model.forward_matrix()
    shape = (*model.lenses, *model.views)
    params = AdmmParams(lam=0.002, rho=0.3, max_iter=60, cg_steps=4, change_tol=2e-4, x_update="cg")
    expected = admm_resampled_reference(b, weights, A, shape, "uv", params, x0)
    solver = ResampledAdmmSolver(runtime, A, shape, "uv")
    solver.solve(runtime.to_device(b), runtime.to_device(2 * weights), runtime.to_device(x0), params)  # other data
    got = solver.solve(runtime.to_device(b), runtime.to_device(weights), runtime.to_device(x0), params)
    assert 2 < got.iterations == expected.iterations < 60
    assert got.stop_reason.startswith("rms change")
    relative = np.linalg.norm(got.x.get() - expected.x) / np.linalg.norm(expected.x)
    assert relative <= 1e-4, relative


def test_normal_diagonal_is_the_diagonal(rng):
    model = sampling_model(SMALL["hex"], "RGGB")
    A = model.forward_matrix()
    w = rng.random(A.shape[0])
    shape, pitch = model.planes_shape, model.views
    n = A.shape[1]
    picks = rng.choice(n, 40, replace=False)
    dense = []
    for j in picks:  # column j of A^T W A + rho D^T D
        e = np.zeros(n)
        e[j] = 1.0
        col = A.T @ (w * (A @ e)) + 0.7 * gradient_gram_np(e.reshape(shape), pitch, "uvst").ravel()
        dense.append(col[j])
    got = normal_diagonal(A, w, shape, pitch, "uvst", 0.7).ravel()[picks]
    np.testing.assert_allclose(got, dense, rtol=1e-12)


def test_solver_refuses_what_it_cannot_do(runtime):
    A = scipy.sparse.eye(10, 3 * 16, format="csr")
    solver = ResampledAdmmSolver(runtime, A, (2, 2, 2, 2), "uv")
    b = runtime.to_device(np.zeros(10, np.float32))
    w = runtime.to_device(np.ones(10, np.float32))
    x0 = runtime.to_device(np.zeros((3, 4, 4), np.float32))
    with pytest.raises(ValueError, match="aligned grid"):
        solver.solve(b, w, x0, AdmmParams(x_update="lens"))
    with pytest.raises(ValueError, match="non-negative"):
        solver.solve(b, runtime.to_device(-np.ones(10, np.float32)), x0, AdmmParams())
    with pytest.raises(ValueError, match="columns"):
        ResampledAdmmSolver(runtime, A, (2, 2, 3, 2), "uv")


# --- the entry point ------------------------------------------------------------------------------

def test_malvar_is_2d_malvar_then_resampling(rng):
    model, raw, _, _, x0 = smooth_problem(rng, "rotated", pattern="BGGR")
    result = demosaic_grid(raw, "BGGR", ResampledGrid.of(SMALL["rotated"], "BGGR"), "malvar")
    np.testing.assert_allclose(result.planes, x0, atol=2e-5)
    assert result.lightfield.shape == (*model.lenses, *model.views, 3)
    np.testing.assert_array_equal(result.lightfield, planes_to_exchange(result.planes, model.shape))
    assert result.iterations == 0 and result.stop_reason == "direct"


def test_admm_uv_entry_point_follows_the_method_defaults(rng):
    from lfcl.demosaic.methods import ADMM_DEFAULTS
    from lfcl.demosaic.resampled import GRID_TUNING
    from lfcl.noise.model import NoiseEstimate

    _, raw, _, _, _ = smooth_problem(rng, "hex")
    noise = NoiseEstimate(gain=0.0, floor=1e-4, sigma=123.0, source="test")  # sigma_at(level) = 0.01
    result = demosaic_grid(raw, "GRBG", ResampledGrid.of(SMALL["hex"], "GRBG"), "admm-uv", noise=noise, strength=1.5)
    d, g = ADMM_DEFAULTS["admm-uv"], GRID_TUNING["admm-uv"]
    assert result.parameters["sigma"] == pytest.approx(0.01)
    assert result.parameters["lam"] == pytest.approx(1.5 * g.strength * d.lam_per_sigma * 0.01)
    assert result.parameters["change_tol"] == pytest.approx(g.change_factor * d.change_per_sigma * 0.01)
    assert result.parameters["interpolation_weight"] == g.interpolation_weight
    assert 1 < result.iterations < d.max_iter and result.stop_reason.startswith("rms change")
    assert np.all(np.isfinite(result.lightfield)) and result.lightfield.dtype == np.float32
    fixed = demosaic_grid(raw, "GRBG", ResampledGrid.of(SMALL["hex"], "GRBG"), "admm-uvst", noise=noise, iterations=3,
                          lam=0.001)
    assert fixed.iterations == 3 and fixed.parameters["lam"] == 0.001


@pytest.mark.parametrize("kwargs, words", [
    ({"method": "linear4d"}, "does not run on"),
    ({"raw": np.zeros((10, 10), np.float32)}, "sensor"),
    ({"raw": np.full((45, 51), np.nan, np.float32)}, "NaN"),
    ({"pattern": "XYZW"}, "pattern"),
])
def test_entry_point_bad_input(kwargs, words):
    args = {"raw": np.zeros((45, 51), np.float32), "pattern": "GRBG", "method": "malvar", **kwargs}
    with pytest.raises(ValueError, match=words):
        demosaic_grid(args["raw"], args["pattern"], ResampledGrid.of(SMALL["hex"], args["pattern"]), args["method"])


def test_grid_noise_estimate_recovers_the_sensor_noise():
    from lfcl.sim.capture import simulate_grid
    from lfcl.sim.planes import Plane

    levels = np.random.default_rng(5).uniform(0.05, 1.0, (8, 8, 3)).astype(np.float32)

    def patches(x, y):  # flat patches of 3x3 lenses at many levels (the estimator's premise: flat lenses)
        return levels[np.clip((y // 3).astype(int), 0, 7), np.clip((x // 3).astype(int), 0, 7)]

    cap = simulate_grid("charts", "hex", 9.4, 0.7, (0.3, -0.2), lenses=(24, 24), lux=12, seed=3,
                        planes=[Plane("patches", 0.0, patches)])
    raw = cap.normalised_raw()
    estimate = estimate_grid_noise(raw, cap.sampling)
    level = float(raw.ravel()[cap.sampling.measured_pixels()].mean())
    s, o = cap.sensor.noise_profile()
    assert estimate.sigma == pytest.approx(np.sqrt(s * level + o), rel=0.25)
