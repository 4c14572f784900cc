"""Differences along the epipolar lines (lfcl/ops/epi.py): a loop definition, device vs numpy twin,
dot tests, the diagonal of the gram, and the EPI ADMM (lfcl/solvers/epi.py) against its float64 reference."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from conftest import relative_dot_error

from lfcl.ops.epi import (
    EpiGradient,
    epi_adjoint_np,
    epi_diagonal_np,
    epi_gradient_np,
    epi_gram_np,
    epi_matrix_np,
    epi_mixed_gradient_np,
    keys_weights_np,
)
from lfcl.ops.gradient import gradient_np

# (channels, S, T, U, V): odd and even pitches, a single lens row, sizes that fit no work-group size.
GEOMETRIES = [(3, 5, 6, 9, 9), (1, 4, 3, 3, 5), (2, 1, 7, 4, 3), (3, 6, 5, 2, 2)]
# rows of 136 runs of 16 columns, the last one partial: the adjoint's 3 tiles of 46, 46 and 44 runs (lfcl/kernels/epi.cl run_at)
WIDE = (3, 3, 241, 9, 9)


def keys(f: float) -> list[float]:
    """Catmull-Rom weights written out (Keys 1981, a = -1/2), independently of keys_weights_np."""
    a = -0.5

    def kernel(x):
        x = abs(x)
        if x < 1:
            return (a + 2) * x**3 - (a + 3) * x**2 + 1
        if x < 2:
            return a * x**3 - 5 * a * x**2 + 8 * a * x - 4 * a
        return 0.0

    return [kernel(f + 1), kernel(f), kernel(1 - f), kernel(2 - f)]


def loop_epi(x5: np.ndarray, disparity: np.ndarray, confidence: np.ndarray) -> np.ndarray:
    """D_epi on [C, S, U, T, V], one sample at a time (the definition in lfcl/ops/epi.py)."""
    C, S, U, T, V = x5.shape
    f32 = np.float32
    out = np.zeros((2, *x5.shape))
    for s, u, t, v in np.ndindex(S, U, T, V):
        d0 = disparity[s, t]
        # the lens the ray sees in the centre view, float32 arithmetic as documented
        sc = min(max(math.floor((f32(s) + d0 * (f32(u) - f32(0.5) * f32(U - 1))) + f32(0.5)), 0), S - 1)
        tc = min(max(math.floor((f32(t) + d0 * (f32(v) - f32(0.5) * f32(V - 1))) + f32(0.5)), 0), T - 1)
        d, w = disparity[sc, tc], float(confidence[sc, tc])
        for block, (own, n, last) in enumerate(((s, S, u == U - 1), (t, T, v == V - 1))):
            if last:
                continue
            # p = own - d exactly: floor(p) = own + floor(-d), fraction -d - floor(-d) (exact in float32)
            whole = math.floor(-d)
            i0 = own + whole
            for c in range(C):
                value = 0.0
                for k, weight in zip(range(-1, 3), keys(float(-d - f32(whole)))):
                    lens = min(max(i0 + k, 0), n - 1)
                    value += weight * (x5[c, lens, u + 1, t, v] if block == 0 else x5[c, s, u, lens, v + 1])
                out[block, c, s, u, t, v] = w * (value - x5[c, s, u, t, v])
    return out


def maps(rng, S, T, spread=1.3):
    disparity = rng.uniform(-spread, spread, (S, T)).astype(np.float32)
    disparity[0, 0] = 1.0  # an integer disparity: the taps at f = 0
    confidence = rng.uniform(0, 1, (S, T)).astype(np.float32)
    return disparity, confidence


def test_keys_weights_are_catmull_rom():
    for f in (0.0, 0.25, 0.5, 0.9):
        np.testing.assert_allclose(keys_weights_np(f), keys(f), atol=1e-14)
    np.testing.assert_allclose(keys_weights_np(np.linspace(0, 1, 7)).sum(-1), 1.0, atol=1e-14)


@pytest.mark.parametrize("geometry", GEOMETRIES[:2], ids=str)
def test_numpy_twin_matches_the_definition(rng, geometry):
    C, S, T, U, V = geometry
    x = rng.standard_normal((C, S * U, T * V))
    disparity, confidence = maps(rng, S, T, spread=2.5)  # far enough that the clamped boundary matters
    expected = loop_epi(x.reshape(C, S, U, T, V), disparity, confidence).reshape(2, C, S * U, T * V)
    np.testing.assert_allclose(epi_gradient_np(x, disparity, (U, V), confidence), expected, atol=1e-12)


def test_zero_disparity_is_the_uv_gradient(rng):
    x = rng.standard_normal((3, 4 * 9, 5 * 9))
    zeros = np.zeros((4, 5), np.float32)
    np.testing.assert_allclose(epi_gradient_np(x, zeros, (9, 9)), gradient_np(x, (9, 9), "uv"), atol=1e-12)


def test_integer_disparity_is_a_lens_shift(rng):
    """d = 1 everywhere: the u-neighbour of (s, u) is (s - 1, u + 1) (lens 0 clamps to itself)."""
    U = V = 3
    x = rng.standard_normal((1, 4 * U, 4 * V))
    z = epi_gradient_np(x, np.ones((4, 4), np.float32), (U, V))
    x5 = x.reshape(1, 4, U, 4, V)
    np.testing.assert_allclose(z[0].reshape(x5.shape)[0, 2, 0, 1, 2], x5[0, 1, 1, 1, 2] - x5[0, 2, 0, 1, 2])
    np.testing.assert_allclose(z[1].reshape(x5.shape)[0, 2, 0, 1, 1], x5[0, 2, 0, 0, 2] - x5[0, 2, 0, 1, 1])


def test_a_scene_on_its_disparity_plane_has_no_differences():
    """A light field rendered from one textured plane at disparity d (lfcl.sim) is constant along
    the epipolar lines: D_epi(d) of it is small where D_uv (d = 0) is not."""
    from lfcl.sim.planes import Plane, render_planes

    def texture(x, y):
        return np.stack([0.5 + 0.4 * np.sin(0.9 * x) * np.cos(0.7 * y)] * 3, axis=-1)

    S = T = 12
    lf = render_planes([Plane("p", 0.4, texture)], (S, T), (9, 9), supersample=1)
    x = lf.transpose(4, 0, 2, 1, 3).reshape(3, S * 9, T * 9).astype(np.float64)
    inner = (slice(None), slice(None), slice(3 * 9, 9 * 9), slice(3 * 9, 9 * 9))  # away from the frame
    along = np.abs(epi_gradient_np(x, np.full((S, T), 0.4, np.float32), (9, 9))[inner]).mean()
    across = np.abs(epi_gradient_np(x, np.zeros((S, T), np.float32), (9, 9))[inner]).mean()
    assert along < 0.05 * across


@pytest.mark.parametrize("in_lens", [False, True], ids=["lines", "in-lens"])
@pytest.mark.parametrize("geometry", [*GEOMETRIES, WIDE], ids=str)
def test_device_matches_numpy(runtime, rng, geometry, in_lens):
    """Every disparity 0 (``in_lens``: the fall-back and in-lens blocks, some lenses weighted 0) builds the kernels
    as in-lens stencils (epi.cl EPI_IN_LENS); both against the twin."""
    C, S, T, U, V = geometry
    x = rng.standard_normal((C, S * U, T * V)).astype(np.float32)
    z = rng.standard_normal((2, *x.shape)).astype(np.float32)
    disparity, confidence = maps(rng, S, T, spread=2.5)
    if in_lens:
        disparity[:] = 0.0
        confidence[rng.uniform(size=confidence.shape) < 0.3] = 0.0
    op = EpiGradient(runtime, x.shape, (U, V))
    op.set_maps(disparity, confidence)
    M = epi_matrix_np(disparity, (U, V), confidence)
    x64, z64 = x.astype(np.float64), z.astype(np.float64)
    np.testing.assert_allclose(op.forward(runtime.to_device(x)).get(),
                               epi_gradient_np(x64, disparity, (U, V), matrix=M), atol=2e-6)
    np.testing.assert_allclose(op.adjoint(runtime.to_device(z)).get(),
                               epi_adjoint_np(z64, disparity, (U, V), matrix=M), atol=2e-5)
    np.testing.assert_allclose(op.gram(runtime.to_device(x)).get(), epi_gram_np(x64, disparity, (U, V), confidence),
                               atol=2e-5)
    np.testing.assert_allclose(op.diagonal().get(), epi_diagonal_np(disparity, (U, V), matrix=M), atol=2e-6)
    # accumulate adds into out
    base = rng.standard_normal(x.shape).astype(np.float32)
    total = op.adjoint(runtime.to_device(z), out=runtime.to_device(base), accumulate=True).get()
    np.testing.assert_allclose(total, base + epi_adjoint_np(z64, disparity, (U, V), matrix=M), atol=2e-5)
    if C == 3:  # the colour mix of the normal operator
        np.testing.assert_allclose(op.forward(runtime.to_device(x), mixed=True).get(),
                                   epi_mixed_gradient_np(x64, disparity, (U, V), matrix=M), atol=1e-5)
    else:
        with pytest.raises(ValueError, match="3 channels"):
            op.forward(runtime.to_device(x), mixed=True)


def test_in_lens_stencils_give_the_general_kernels_numbers(runtime, rng):
    """At d = 0 everywhere the in-lens build (EPI_IN_LENS) and the general gathers compute the same operator: the
    general kernels' Catmull-Rom weight is exactly 1 on the own lens there."""
    C, S, T, U, V = WIDE
    x = runtime.to_device(rng.standard_normal((C, S * U, T * V)).astype(np.float32))
    z = runtime.to_device(rng.standard_normal((2, C, S * U, T * V)).astype(np.float32))
    confidence = rng.uniform(0, 1, (S, T)).astype(np.float32)
    op = EpiGradient(runtime, x.shape, (U, V))
    op.set_maps(np.zeros((S, T), np.float32), confidence)
    assert ("EPI_IN_LENS", 1) in op._defines
    stencil = [op.forward(x).get(), op.forward(x, mixed=True).get(), op.adjoint(z).get(), op.diagonal().get()]
    op._defines = op._grid_defines  # the same maps through the general kernels
    general = [op.forward(x).get(), op.forward(x, mixed=True).get(), op.adjoint(z).get(), op.diagonal().get()]
    for got, expected in zip(stencil, general):
        np.testing.assert_allclose(got, expected, rtol=0, atol=1e-6)
    op.set_maps(np.full((S, T), 0.5, np.float32), confidence)  # any other disparity: the general build
    assert op._defines == op._grid_defines


def test_mixed_gradient_is_the_epi_and_cross_blocks_gram(rng):
    """D^T (I + C^T C) D x = D^T D x + (D C)^T (D C) x: what the solver's normal operator relies on."""
    from lfcl.solvers.epi import epi_cross_adjoint_np, epi_cross_gradient_np

    S, T, U, V = 4, 5, 9, 9
    x = rng.standard_normal((3, S * U, T * V))
    disparity, confidence = maps(rng, S, T)
    M = epi_matrix_np(disparity, (U, V), confidence)
    got = epi_adjoint_np(epi_mixed_gradient_np(x, disparity, (U, V), matrix=M), disparity, (U, V), matrix=M)
    expected = epi_adjoint_np(epi_gradient_np(x, disparity, (U, V), matrix=M), disparity, (U, V), matrix=M) + \
        epi_cross_adjoint_np(epi_cross_gradient_np(x, disparity, (U, V), matrix=M), disparity, (U, V), matrix=M)
    np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("in_lens", [False, True], ids=["lines", "in-lens"])
def test_adjoint_dot_test(runtime, rng, in_lens):
    C, S, T, U, V = 3, 7, 6, 9, 9
    x = rng.standard_normal((C, S * U, T * V)).astype(np.float32)
    y = rng.standard_normal((2, *x.shape)).astype(np.float32)
    disparity, confidence = maps(rng, S, T, spread=3.0)
    if in_lens:  # the in-lens stencils (epi.cl EPI_IN_LENS)
        disparity[:] = 0.0
    op = EpiGradient(runtime, x.shape, (U, V))
    op.set_maps(disparity, confidence)
    dx = op.forward(runtime.to_device(x)).get().astype(np.float64)
    dty = op.adjoint(runtime.to_device(y)).get().astype(np.float64)
    assert relative_dot_error(np.vdot(dx, y), np.vdot(x, dty)) <= 1e-5
    x64, y64 = x.astype(np.float64), y.astype(np.float64)
    lhs = np.vdot(epi_gradient_np(x64, disparity, (U, V), confidence), y64)
    rhs = np.vdot(x64, epi_adjoint_np(y64, disparity, (U, V), confidence))
    assert relative_dot_error(lhs, rhs) <= 1e-12


def test_diagonal_is_the_gram_diagonal(rng):
    S, T, U, V = 4, 3, 3, 3
    disparity, confidence = maps(rng, S, T, spread=2.0)
    eye = np.eye(S * U * T * V)
    columns = [epi_gram_np(eye[j].reshape(1, S * U, T * V), disparity, (U, V), confidence).ravel()
               for j in range(eye.shape[0])]
    np.testing.assert_allclose(epi_diagonal_np(disparity, (U, V), confidence).ravel(), np.diag(np.stack(columns, 1)),
                               atol=1e-12)


def test_bad_maps_are_refused(runtime):
    op = EpiGradient(runtime, (3, 18, 18), (9, 9))
    with pytest.raises(ValueError, match="disparity must be a map of 2x2"):
        op.set_maps(np.zeros((3, 2), np.float32))
    with pytest.raises(ValueError, match="finite"):
        op.set_maps(np.full((2, 2), np.nan, np.float32))
    with pytest.raises(ValueError, match="within"):
        op.set_maps(np.zeros((2, 2), np.float32), np.full((2, 2), 1.5, np.float32))
    with pytest.raises(ValueError, match="set_maps"):
        op.forward(runtime.to_device(np.zeros((3, 18, 18), np.float32)))


# --- the EPI ADMM (lfcl/solvers/epi.py) ---------------------------------------------------------------


def plane_scene_mosaic(rng, S, T, U, V, disparity=0.4, pattern="GRBG", noise=0.02):
    """A noisy mosaic of a textured plane at ``disparity`` (lfcl.sim), and its Malvar start."""
    from lfcl.ops.cfa import cfa_sample_np
    from lfcl.ops.malvar import malvar_np
    from lfcl.sim.planes import Plane, render_planes

    def texture(x, y):
        return np.stack([0.4 + 0.3 * np.sin(1.1 * x + c) * np.cos(0.8 * y - c) for c in range(3)], axis=-1)

    lf = render_planes([Plane("p", disparity, texture)], (S, T), (U, V), supersample=1)
    planes = lf.transpose(4, 0, 2, 1, 3).reshape(3, S * U, T * V)
    b = (cfa_sample_np(planes, pattern) + noise * rng.standard_normal((S * U, T * V))).astype(np.float32)
    return b, malvar_np(b, pattern), planes


def assert_matches_the_reference(got, expected, iterations):
    """The device's run against the float64 twin's: x, the iterations and every record of the history."""
    relative = np.linalg.norm(got.x.get() - expected.x) / np.linalg.norm(expected.x)
    assert relative <= 1e-4, relative
    assert got.iterations == expected.iterations == iterations
    for mine, ref in zip(got.history, expected.history):
        assert mine.objective == pytest.approx(ref.objective, rel=1e-4)
        assert mine.primal_residual == pytest.approx(ref.primal_residual, rel=1e-3, abs=1e-6)
        assert mine.dual_residual == pytest.approx(ref.dual_residual, rel=1e-3, abs=1e-6)
        assert mine.rms_change == pytest.approx(ref.rms_change, rel=1e-3, abs=1e-7)


@pytest.mark.parametrize("pattern", ["GRBG", "BGGR"])
@pytest.mark.parametrize("lam_fb", [0.0, 0.02])
def test_solver_matches_the_float64_reference(runtime, rng, pattern, lam_fb):
    from lfcl.solvers.epi import EpiAdmmSolver, EpiPrior, admm_epi_reference
    from lfcl.solvers.params import AdmmParams

    S, T, U, V = 5, 4, 9, 9
    b, x0, _ = plane_scene_mosaic(rng, S, T, U, V, pattern=pattern)
    disparity, confidence = maps(rng, S, T, spread=1.0)
    prior = EpiPrior(disparity, confidence, lam_fb=lam_fb)
    params = AdmmParams(lam=0.01, rho=0.5, max_iter=8, cg_steps=4, cg_tol=0.0)
    weights = np.ones((U, V))
    weights[0, 0] = 0.0  # a dark corner out of the data term
    weights[4, 4] = 0.5
    expected = admm_epi_reference(b, pattern, (U, V), params, x0, prior, lens_weights=weights)
    solver = EpiAdmmSolver(runtime, b.shape, pattern, (U, V))
    got = solver.solve(runtime.to_device(b), runtime.to_device(x0), params, prior, lens_weights=weights)
    assert solver.cross is None and len(solver.blocks) == (2 if lam_fb else 1)  # lam_xc = 0: no cross block
    assert_matches_the_reference(got, expected, iterations=8)


@pytest.mark.parametrize("lam_xc, lam_fb", [(0.0, 0.0), (0.015, 0.02)])
def test_extrapolated_warm_start_matches_the_float64_reference(runtime, rng, lam_xc, lam_fb):
    """CG from x_k + beta (x_k - x_{k-1}) with its residual carried (epi_extrapolate), over more iterations than
    EPI_REFRESH, against the reference's CG from that point with its residual computed; and it is not the run
    without it."""
    from lfcl.solvers.epi import EPI_REFRESH, EpiAdmmSolver, EpiPrior, admm_epi_reference
    from lfcl.solvers.params import AdmmParams, extrapolate

    S, T, U, V = 5, 4, 9, 9
    b, x0, _ = plane_scene_mosaic(rng, S, T, U, V)
    disparity, confidence = maps(rng, S, T, spread=1.0)
    prior = EpiPrior(disparity, confidence, lam_fb=lam_fb)
    iterations = EPI_REFRESH + 4
    params = AdmmParams(lam=0.01, lam_xc=lam_xc, rho=0.5, max_iter=iterations, cg_steps=3, cg_tol=0.0,
                        extrapolation=0.8)
    expected = admm_epi_reference(b, "GRBG", (U, V), params, x0, prior)
    solver = EpiAdmmSolver(runtime, b.shape, "GRBG", (U, V))
    got = solver.solve(runtime.to_device(b), runtime.to_device(x0), params, prior)
    assert_matches_the_reference(got, expected, iterations=iterations)
    plain = admm_epi_reference(b, "GRBG", (U, V), dataclasses.replace(params, extrapolation=0.0), x0, prior)
    assert np.linalg.norm(plain.x - expected.x) > 1e-3 * np.linalg.norm(expected.x)
    # the run took both branches: x-updates from the extrapolated point, and a restart after a growing change
    starts = [extrapolate(expected.history[:k]) for k in range(1, iterations)]
    assert any(starts) and not all(starts)


def test_extrapolation_restarts_after_a_growing_change():
    from lfcl.solvers.params import IterationRecord, extrapolate

    def history(*changes):
        return [IterationRecord(iteration=i + 1, objective=0.0, primal_residual=0.0, dual_residual=0.0, rms_change=c,
                                cg_steps=3) for i, c in enumerate(changes)]

    assert extrapolate(history(1.0)) and extrapolate(history(1.0, 0.5)) and extrapolate(history(1.0, 0.5, 0.5))
    assert not extrapolate(history(1.0, 1.5)) and not extrapolate(history(1.0, 0.5, 0.6))


def test_extrapolation_kernel_matches_its_twin(runtime, rng):
    from lfcl.solvers.epi import EpiAdmmSolver, epi_extrapolate_np

    solver = EpiAdmmSolver(runtime, (9, 15), "GRBG", (3, 3))  # 405 floats: the last chunk partly past the end
    x, x_prev, r, dnx = (rng.standard_normal((3, 9, 15)).astype(np.float32) for _ in range(4))
    arrays = [runtime.to_device(v) for v in (x, x_prev, r, dnx)]
    runtime.launch("epi", "epi_extrapolate", (64,), *(a.data for a in arrays), np.float32(0.8), np.uint64(x.size),
                   np.uint64(-(-x.size // 16)), defines=solver._defines)
    for got, want in zip(arrays, epi_extrapolate_np(x, x_prev, r, dnx, 0.8)):
        np.testing.assert_allclose(got.get(), want, rtol=1e-6, atol=1e-6)


def test_other_solvers_refuse_the_extrapolated_warm_start(runtime):
    import scipy.sparse

    from lfcl.solvers.admm import AdmmSolver
    from lfcl.solvers.params import AdmmParams
    from lfcl.solvers.resampled import ResampledAdmmSolver

    params = AdmmParams(extrapolation=0.5)
    with pytest.raises(ValueError, match="admm-epi's"):
        AdmmSolver(runtime, (18, 18), "GRBG", (9, 9), "uv").prepare(params)
    solver = ResampledAdmmSolver(runtime, scipy.sparse.eye(10, 3 * 16, format="csr"), (2, 2, 2, 2), "uv")
    ones = runtime.to_device(np.ones(10, np.float32))
    with pytest.raises(ValueError, match="admm-epi's"):
        solver.solve(ones, ones, runtime.to_device(np.zeros((3, 4, 4), np.float32)), params)
    with pytest.raises(ValueError, match="extrapolation must be a number in"):
        AdmmParams(extrapolation=1.5)


@pytest.mark.parametrize("lam_xc, lam_fb, iterations, beta", [(0.0, 0.0, 6, 0.0), (0.015, 0.02, 6, 0.0),
                                                              (0.015, 0.0, 47, 0.0), (0.015, 0.02, 23, 0.8)])
def test_carried_right_hand_side_and_residual_are_the_ones_they_stand_for(runtime, rng, lam_xc, lam_fb, iterations,
                                                                           beta):
    """iterate carries rhs = A^T W b + rho K^T (z - u) and CG's first residual r = rhs - N x from one iteration
    to the next (epi_carry_rhs) instead of recomputing them, and recomputes them every EPI_REFRESH iterations: after
    a run (short, or long enough to pass several refreshes) both must equal their definitions, computed in float64
    by the twins from the solver's own z, u and x."""
    from lfcl.ops.cfa import cfa_adjoint_np, cfa_sample_np
    from lfcl.solvers.epi import EPI_PROXIMAL, EpiAdmmSolver, EpiPrior, epi_cross_adjoint_np, epi_cross_gradient_np
    from lfcl.solvers.params import AdmmParams

    S, T, U, V = 5, 4, 9, 9
    b, x0, _ = plane_scene_mosaic(rng, S, T, U, V)
    disparity, confidence = maps(rng, S, T, spread=1.0)
    params = AdmmParams(lam=0.01, lam_xc=lam_xc, rho=0.7, max_iter=iterations, cg_steps=3, cg_tol=0.0,
                        extrapolation=beta)
    weights = np.ones((U, V))
    weights[4, 4] = 0.5
    solver = EpiAdmmSolver(runtime, b.shape, "GRBG", (U, V))
    got = solver.solve(runtime.to_device(b), runtime.to_device(x0), params, EpiPrior(disparity, confidence, lam_fb),
                       lens_weights=weights)
    assert len(solver.blocks) == 1 + (lam_xc > 0) + (lam_fb > 0)
    x = got.x.get().astype(np.float64)
    w = np.tile(weights, (S, T))

    def adjoint(op, z):  # K_b^T z in float64, by the twins
        if op is solver.cross:
            return epi_cross_adjoint_np(z, solver.epi.maps[0], (U, V), solver.epi.maps[1])
        return epi_adjoint_np(z, op.maps[0], (U, V), op.maps[1])

    def forward(op, v):
        if op is solver.cross:
            return epi_cross_gradient_np(v, solver.epi.maps[0], (U, V), solver.epi.maps[1])
        return epi_gradient_np(v, op.maps[0], (U, V), op.maps[1])

    states = [(z.get().astype(np.float64), u.get().astype(np.float64)) for z, u in solver._states]
    delta = EPI_PROXIMAL * params.rho  # the proximal term, around the next x-update's warm start: x
    rhs = cfa_adjoint_np(w * b, "GRBG") + params.rho * sum(
        adjoint(op, z - u) for (op, _), (z, u) in zip(solver.blocks, states)) + delta * x
    normal_x = cfa_adjoint_np(w * cfa_sample_np(x, "GRBG"), "GRBG") + params.rho * sum(
        adjoint(op, forward(op, x)) for op, _ in solver.blocks) + delta * x
    scale = np.linalg.norm(rhs)
    assert np.linalg.norm(solver._rhs.get() - rhs) <= 1e-5 * scale
    assert np.linalg.norm(solver._cg[0].get() - (rhs - normal_x)) <= 1e-5 * scale
    if beta:  # and the change of N x over the last x-update, which the next extrapolation takes off the residual
        x_prev = solver._x_prev.get().astype(np.float64)
        normal_prev = cfa_adjoint_np(w * cfa_sample_np(x_prev, "GRBG"), "GRBG") + params.rho * sum(
            adjoint(op, forward(op, x_prev)) for op, _ in solver.blocks) + delta * x_prev
        change = normal_x - normal_prev
        # to the carried residuals' float32 round-off: measured 1.2e-4 of the change
        assert np.linalg.norm(solver._dnx.get() - change) <= 1e-3 * np.linalg.norm(change)


def test_reference_solves_the_problem_it_states(rng):
    """Run to convergence on a tiny problem: perturbed points have a larger objective."""
    from lfcl.ops.cfa import cfa_sample_np
    from lfcl.solvers.epi import EpiPrior, admm_epi_reference
    from lfcl.solvers.params import AdmmParams

    S, T, U, V = 3, 3, 3, 3
    b, x0, _ = plane_scene_mosaic(rng, S, T, U, V, noise=0.05)
    disparity, confidence = maps(rng, S, T, spread=0.8)
    prior = EpiPrior(disparity, confidence, lam_fb=0.01)
    params = AdmmParams(lam=0.02, rho=1.0, max_iter=500, cg_steps=30, cg_tol=1e-12)
    result = admm_epi_reference(b, "GRBG", (U, V), params, x0, prior)
    assert result.history[-1].primal_residual < 1e-3 and result.history[-1].rms_change < 1e-5
    fallback_d = np.zeros_like(disparity)

    def objective(x):
        return (0.5 * np.sum((cfa_sample_np(x, "GRBG") - b) ** 2)
                + 0.02 * np.abs(epi_gradient_np(x, disparity, (U, V), confidence)).sum()
                + 0.01 * np.abs(epi_gradient_np(x, fallback_d, (U, V), 1 - confidence)).sum())

    best = objective(result.x)
    for _ in range(50):
        assert objective(result.x + 1e-3 * rng.standard_normal(result.x.shape)) >= best - 1e-9


def test_the_right_disparity_denoises_more(runtime, rng):
    """On a plane at d = 0.6 the prior along the true lines gets closer to the truth than d = 0 (D_uv)."""
    from lfcl.solvers.epi import EpiAdmmSolver, EpiPrior
    from lfcl.solvers.params import AdmmParams

    S, T, U, V = 8, 8, 9, 9
    b, x0, truth = plane_scene_mosaic(rng, S, T, U, V, disparity=0.6, noise=0.05)
    solver = EpiAdmmSolver(runtime, b.shape, "GRBG", (U, V))
    params = AdmmParams(lam=0.02, rho=1.0, max_iter=15, cg_steps=5)
    errors = {}
    for d in (0.0, 0.6):
        prior = EpiPrior(np.full((S, T), d, np.float32))
        x = solver.solve(runtime.to_device(b), runtime.to_device(x0), params, prior).x.get()
        errors[d] = np.sqrt(np.mean((x - truth) ** 2))
    assert errors[0.6] < 0.8 * errors[0.0], errors
    assert errors[0.6] < 0.5 * np.sqrt(np.mean((x0 - truth) ** 2))


def test_solver_refuses_what_it_cannot_do(runtime, rng):
    from lfcl.solvers.epi import EpiAdmmSolver, EpiPrior
    from lfcl.solvers.params import AdmmParams

    b, x0, _ = plane_scene_mosaic(rng, 2, 2, 9, 9)
    solver = EpiAdmmSolver(runtime, b.shape, "GRBG", (9, 9))
    prior = EpiPrior(np.zeros((2, 2), np.float32))
    with pytest.raises(ValueError, match="x_update 'lens'"):
        solver.solve(runtime.to_device(b), runtime.to_device(x0), AdmmParams(x_update="lens"), prior)
    with pytest.raises(ValueError, match="lam_fb"):
        EpiPrior(np.zeros((2, 2), np.float32), lam_fb=-1.0)


def test_method_admm_epi_runs_and_records_the_disparity(runtime, rng):
    """lfcl.demosaic.methods: admm-epi estimates the disparity from the raw (lfcl.depth), solves, and says what it used."""
    from lfcl.demosaic.driver import demosaic_grid
    from lfcl.depth.estimate import DEFAULTS
    from lfcl.grid.model import AlignedGrid
    from lfcl.noise.model import NoiseEstimate
    from lfcl.solvers.epi import epi_depth_options, epi_setting

    S, T, U, V = 10, 10, 9, 9
    b, _, truth = plane_scene_mosaic(rng, S, T, U, V, disparity=0.5, noise=0.01)
    noise = NoiseEstimate(gain=0.0, floor=1e-4, sigma=0.01, source="test")
    result = demosaic_grid(b, "GRBG", AlignedGrid((U, V)), "admm-epi", noise=noise)
    setting = epi_setting(0.01)  # the defaults follow the noise (EPI_SCHEDULE)
    assert result.planes.shape == truth.shape and np.all(np.isfinite(result.planes))
    assert result.parameters["lam"] == pytest.approx(setting.lam_per_sigma * 0.01)
    assert result.parameters["lam_fb"] == pytest.approx(setting.fb_per_lam * setting.lam_per_sigma * 0.01)
    assert result.parameters["start"] == setting.start
    assert result.parameters["disparity"]["median"] == pytest.approx(0.5, abs=0.1)
    # every option of the estimate is written down, its own defaults with admm-epi's changes over them (the step
    # of the schedule's row at this noise)
    assert result.parameters["disparity"]["options"] == {**DEFAULTS, **epi_depth_options(0.01)}
    assert result.parameters["disparity"]["options"]["step"] == setting.depth_step
    assert result.parameters["disparity"]["options"]["occlusion"] is True
    assert 2 <= result.iterations <= setting.iterations
    assert result.parameters["change_tol"] == pytest.approx(setting.change_per_sigma * 0.01)
    assert result.parameters["max_iter"] == setting.iterations
    explicit = demosaic_grid(b, "GRBG", AlignedGrid((U, V)), "admm-epi", noise=noise, lam=0.002, iterations=3,
                             start="malvar", safety_net=False)
    assert explicit.iterations == 3 and explicit.parameters["lam"] == pytest.approx(0.002)
    assert explicit.parameters["change_tol"] == 0
    dark = NoiseEstimate(gain=0.0, floor=4e-6, sigma=0.002, source="test")  # low light: the guarded start
    low = demosaic_grid(b, "GRBG", AlignedGrid((U, V)), "admm-epi", noise=dark, safety_net=False)
    assert epi_setting(0.002).start == low.parameters["start"] == "guarded" and "start_guard" in low.parameters
    assert explicit.parameters["lam_fb"] == pytest.approx(setting.fb_per_lam * 0.002)
    malvar = demosaic_grid(b, "GRBG", AlignedGrid((U, V)), "malvar")
    inner = (slice(None), slice(2 * U, (S - 2) * U), slice(2 * V, (T - 2) * V))
    assert np.mean((result.planes - truth)[inner] ** 2) < np.mean((malvar.planes - truth)[inner] ** 2)


def test_admm_epi_fills_the_dark_pixels_of_a_white_image(runtime, rng):
    """With a white image's lens response, the pixels below its threshold (data weight 0) get the harmonic
    extension of their lens's lit pixels, as the (u, v) solvers give them: applying the fill again changes nothing,
    and their error is about admm-uv's (measured 0.175 against 0.142 rms; before, keeping what the start made of their
    unflattened raw values, 0.352)."""
    from lfcl.demosaic.driver import demosaic_grid
    from lfcl.grid.model import AlignedGrid
    from lfcl.grid.vignetting import flat_field_gain
    from lfcl.noise.model import NoiseEstimate
    from lfcl.ops.lensfill import lens_fill_np

    S, T, U, V = 10, 10, 9, 9
    b, _, truth = plane_scene_mosaic(rng, S, T, U, V, disparity=0.5, noise=0.005)
    uu, vv = np.meshgrid(np.arange(U) - 4, np.arange(V) - 4, indexing="ij")
    response = (np.cos(np.hypot(uu, vv) / 4.5 * 1.2) ** 4).astype(np.float32)  # corners near black
    _, weights = flat_field_gain(response)
    assert (weights == 0).sum() >= 20
    raw = (b * np.tile(response, (S, T))).astype(np.float32)
    noise = NoiseEstimate(gain=0.0, floor=2.5e-5, sigma=0.005, source="test")
    planes = demosaic_grid(raw, "GRBG", AlignedGrid((U, V), lens_response=response), "admm-epi", noise=noise).planes
    np.testing.assert_allclose(lens_fill_np(planes, weights, (U, V)), planes, atol=1e-5)
    dark = np.tile(weights == 0, (S, T))[None].repeat(3, 0)
    uv = demosaic_grid(raw, "GRBG", AlignedGrid((U, V), lens_response=response), "admm-uv", noise=noise).planes
    assert np.sqrt(np.mean((planes - truth)[dark] ** 2)) < 1.5 * np.sqrt(np.mean((uv - truth)[dark] ** 2))


def test_admm_epi_in_bands_fills_the_dark_pixels_too(rng):
    """The banded path (planes on the host after the bands) fills the dark pixels as the whole-frame one does."""
    from lfcl.demosaic.driver import demosaic_grid
    from lfcl.grid.model import AlignedGrid
    from lfcl.grid.vignetting import flat_field_gain
    from lfcl.noise.model import NoiseEstimate
    from lfcl.ops.lensfill import lens_fill_np

    S, T, U, V = 80, 10, 9, 9
    b, _, _ = plane_scene_mosaic(rng, S, T, U, V, disparity=0.5, noise=0.005)
    uu, vv = np.meshgrid(np.arange(U) - 4, np.arange(V) - 4, indexing="ij")
    response = (np.cos(np.hypot(uu, vv) / 4.5 * 1.2) ** 4).astype(np.float32)
    _, weights = flat_field_gain(response)
    raw = (b * np.tile(response, (S, T))).astype(np.float32)
    noise = NoiseEstimate(gain=0.0, floor=2.5e-5, sigma=0.005, source="test")
    grid = AlignedGrid((U, V), lens_response=response)
    banded = demosaic_grid(raw, "GRBG", grid, "admm-epi", noise=noise, max_memory=2**23, iterations=6)
    assert len(banded.parameters["bands"]["lens_rows"]) > 1
    np.testing.assert_allclose(lens_fill_np(banded.planes, weights, (U, V)), banded.planes, atol=1e-5)
    whole = demosaic_grid(raw, "GRBG", grid, "admm-epi", noise=noise, iterations=6)
    np.testing.assert_allclose(banded.planes, whole.planes, atol=1e-3)


@pytest.mark.parametrize("d_background, d_front", [(3.5, 0.3), (-3.0, 2.5)])
def test_admm_epi_beyond_the_search_range_is_finite_and_above_malvar(d_background, d_front):
    """Issue 20's bad input: planes at disparities beyond the estimate's search range (+-2): admm-epi, as the
    default runs it at 2 lux, stays finite and above Malvar on the centre view and the mean image (measured: +2.29
    and +2.54 dB on the centre view, +1.85 and +3.24 dB on the mean image)."""
    from lfcl.demosaic.driver import demosaic_grid
    from lfcl.evaluation.metrics import psnr
    from lfcl.grid.model import AlignedGrid
    from lfcl.noise.model import from_noise_profile
    from lfcl.sim import simulate
    from lfcl.sim.deadleaves import DeadLeavesTexture, _texture_box
    from lfcl.sim.planes import Plane

    S = T = 24
    box = (6, 6, 18, 18)
    planes = [Plane("front", d_front, DeadLeavesTexture(_texture_box(box, d_front, S, T), np.random.default_rng(1),
                                                        r_max=3.0), box),
              Plane("back", d_background, DeadLeavesTexture(_texture_box(None, d_background, S, T),
                                                            np.random.default_rng(2), r_max=6.0))]
    cap = simulate(planes=planes, lenses=(S, T), pitch=9, lux=2, seed=3)
    raw = cap.normalised_raw()
    scale, offset = cap.sensor.noise_profile()
    noise = from_noise_profile([scale, offset] * 3, raw)
    centre, mean = cap.truth[:, :, 4, 4, :], cap.truth.mean(axis=(2, 3))
    scores = {}
    for method in ("malvar", "admm-epi"):
        lf = demosaic_grid(raw, cap.pattern, AlignedGrid((9, 9)), method, noise=noise).lightfield
        assert np.all(np.isfinite(lf)), method
        scores[method] = (psnr(lf[:, :, 4, 4, :], centre), psnr(lf.mean(axis=(2, 3)), mean))
    assert scores["admm-epi"][0] > scores["malvar"][0] and scores["admm-epi"][1] > scores["malvar"][1], scores


def test_epi_setting_follows_the_noise_in_log_sigma():
    """Between two rows lam / sigma, lam_fb / lam and the iterations are linear in log sigma, the start and the
    disparity's step the nearer row's; outside, the end rows."""
    from lfcl.solvers.epi import EpiSetting, epi_setting

    rows = (EpiSetting(sigma=1e-2, lam_per_sigma=0.4, fb_per_lam=2.0, change_per_sigma=0.2, iterations=18,
                       start="linear4d", xc_per_lam=0.8, depth_step=0.1),
            EpiSetting(sigma=1e-3, lam_per_sigma=0.2, fb_per_lam=1.0, change_per_sigma=0.0, iterations=10,
                       start="malvar", depth_step=0.2))
    quarter = 1e-3 * 10 ** 0.25  # a quarter of the way from 1e-3 to 1e-2 in log sigma
    got = epi_setting(quarter, rows)
    assert got.lam_per_sigma == pytest.approx(0.25) and got.fb_per_lam == pytest.approx(1.25)
    assert got.xc_per_lam == pytest.approx(0.2)
    assert got.change_per_sigma == pytest.approx(0.05)
    assert got.iterations == 12 and got.start == "malvar" and got.sigma == pytest.approx(quarter)
    assert got.depth_step == 0.2
    assert epi_setting(1e-3 * 10 ** 0.75, rows).start == "linear4d"
    assert epi_setting(1e-3 * 10 ** 0.75, rows).depth_step == 0.1
    low, high = epi_setting(1e-5, rows), epi_setting(0.5, rows)
    assert (low.lam_per_sigma, low.iterations, low.start) == (0.2, 10, "malvar")
    assert (high.lam_per_sigma, high.iterations, high.start) == (0.4, 18, "linear4d")


def test_epi_depth_options_follow_the_schedule_and_an_explicit_step_wins(monkeypatch):
    import lfcl.solvers.epi as epi

    assert epi.epi_depth_options(epi.EPI_SCHEDULE[0].sigma)["step"] == epi.EPI_SCHEDULE[0].depth_step
    assert epi.epi_depth_options(epi.EPI_SCHEDULE[-1].sigma)["step"] == epi.EPI_SCHEDULE[-1].depth_step
    assert epi.epi_depth_options(None)["step"] == epi.DEPTH_STEP
    monkeypatch.setattr(epi, "EPI_DEPTH_OPTIONS", {"step": 0.05, "occlusion": False})
    assert epi.epi_depth_options(epi.EPI_SCHEDULE[0].sigma) == {"step": 0.05, "occlusion": False}


def test_epi_setting_refuses_a_sigma_that_is_no_noise_level():
    from lfcl.solvers.epi import EpiSetting, epi_setting

    rows = (EpiSetting(sigma=1e-3, lam_per_sigma=0.2, fb_per_lam=1.0, change_per_sigma=0.0, iterations=10,
                       start="malvar"),)
    for bad in (0.0, -1.0, math.nan, math.inf):
        with pytest.raises(ValueError, match="sigma"):
            epi_setting(bad, rows)


def test_change_rule_stops_device_and_reference_at_the_same_iteration(runtime, rng):
    """admm-epi's default stop (rms change <= change_tol): the device stops where the float64 twin does."""
    from lfcl.solvers.epi import EpiAdmmSolver, EpiPrior, admm_epi_reference
    from lfcl.solvers.params import AdmmParams

    S, T, U, V = 5, 4, 9, 9
    b, x0, _ = plane_scene_mosaic(rng, S, T, U, V)
    disparity, confidence = maps(rng, S, T, spread=1.0)
    prior = EpiPrior(disparity, confidence, lam_fb=0.01)
    params = AdmmParams(lam=0.01, rho=1.0, max_iter=25, cg_steps=4, cg_tol=0.0)
    changes = [r.rms_change for r in admm_epi_reference(b, "GRBG", (U, V), params, x0, prior).history]
    # a tolerance between the change of the 5th (or a later) iteration and every earlier one's, 5 % from both
    k = next(i for i in range(4, len(changes)) if changes[i] < 0.9 * min(changes[1:i]))
    params = dataclasses.replace(params, change_tol=math.sqrt(changes[k] * min(changes[1:k])))
    expected = admm_epi_reference(b, "GRBG", (U, V), params, x0, prior)
    got = EpiAdmmSolver(runtime, b.shape, "GRBG", (U, V)).solve(runtime.to_device(b), runtime.to_device(x0), params,
                                                                prior)
    assert expected.iterations == got.iterations == k + 1 < 25
    assert "rms change" in got.stop_reason
    assert np.linalg.norm(got.x.get() - expected.x) / np.linalg.norm(expected.x) <= 1e-4


def test_epi_start_needs_linear4d_coefficients_for_the_pitch(monkeypatch):
    """The schedule starts from the guarded start, which needs linear4d: on another pitch, Malvar, said in the
    reason; a row that starts from Malvar needs nothing."""
    import dataclasses

    import lfcl.solvers.epi as epi
    from lfcl.ops.linear4d import load_model

    fitted = tuple(load_model().pitch)
    other = (fitted[0] - 2, fitted[1] - 2)
    assert epi.epi_setting(0.002).start == epi.epi_setting(0.02).start == "guarded"  # the shipped rows
    assert epi.epi_start(0.002, fitted) == ("guarded", None) and epi.epi_start(0.02, fitted) == ("guarded", None)
    start, why = epi.epi_start(0.002, other)
    assert start == "malvar" and f"not {other[0]}x{other[1]}" in why
    monkeypatch.setattr(epi, "EPI_SCHEDULE", tuple(dataclasses.replace(r, start="malvar") for r in epi.EPI_SCHEDULE))
    assert epi.epi_start(0.02, other) == ("malvar", None)


@pytest.mark.parametrize("lens_rows, halo, fit", [(10, 2, 10), (10, 2, 5), (37, 5, 14), (3, 0, 1)])
def test_epi_bands_cover_the_lens_rows_with_their_halo(lens_rows, halo, fit):
    import itertools

    from lfcl.solvers.epi import epi_bands

    bands = epi_bands(lens_rows, halo, fit)
    assert bands[0][0] == 0 and bands[-1][1] == lens_rows
    assert all(a[1] == b[0] for a, b in itertools.pairwise(bands))
    for s0, s1, h0, h1 in bands:
        assert h0 == max(0, s0 - halo) and h1 == min(lens_rows, s1 + halo)
        assert h1 - h0 <= fit or len(bands) == 1


def test_epi_bands_refuse_a_memory_that_holds_less_than_the_halo():
    from lfcl.solvers.epi import epi_bands, epi_halo

    assert epi_halo(np.zeros((4, 4)), (9, 9)) == 2  # the cubic taps only
    assert epi_halo(np.full((4, 4), -1.5), (9, 9)) == 6 + 2 + 2  # lookup 1.5 * 4, the difference 2, the taps 2
    with pytest.raises(ValueError, match="halo"):
        epi_bands(40, 6, 12)


def test_admm_epi_in_bands_matches_the_whole_sensor(runtime, rng):
    """A sensor larger than the memory given is solved in bands of lens rows with their halo: the same answer as
    the whole sensor up to what the halo's cut-off changes (measured ~1e-4 after 8 iterations), every band recorded."""
    from lfcl.demosaic.driver import demosaic_grid
    from lfcl.grid.model import AlignedGrid
    from lfcl.noise.model import NoiseEstimate
    from lfcl.solvers.epi import epi_solver_bytes

    S, T, U, V = 30, 6, 9, 9
    b, _, _ = plane_scene_mosaic(rng, S, T, U, V, disparity=0.3, noise=0.01)
    noise = NoiseEstimate(gain=0.0, floor=1e-4, sigma=0.01, source="test")
    grid = AlignedGrid((U, V))
    whole = demosaic_grid(b, "GRBG", grid, "admm-epi", noise=noise, iterations=6, safety_net=False)
    assert "bands" not in whole.parameters
    budget = epi_solver_bytes((15 * U, T * V), True)  # 15 lens rows: 6 bands, equal heights of either row parity
    banded = demosaic_grid(b, "GRBG", grid, "admm-epi", noise=noise, iterations=6, safety_net=False,
                           max_memory=budget)
    bands = banded.parameters["bands"]
    assert len(bands["lens_rows"]) >= 3 and sum(bands["lens_rows"]) == S
    assert sorted({row["band"] for row in banded.history}) == list(range(len(bands["lens_rows"])))
    # each band's own iteration count, as its history has it
    assert bands["iterations"] == [sum(row["band"] == i for row in banded.history) for i in range(len(bands["lens_rows"]))]
    assert "bands of lens rows" in banded.stop_reason
    np.testing.assert_allclose(banded.planes, whole.planes, rtol=0, atol=1e-3)
    with pytest.raises(ValueError, match="halo"):
        demosaic_grid(b, "GRBG", grid, "admm-epi", noise=noise, iterations=2, max_memory=epi_solver_bytes((U, T * V), True))


def test_admm_epi_in_bands_with_the_in_lens_cross_block_matches_the_whole_sensor(runtime, rng):
    """A plane at d = 1 (every lens's lines one colour): the bands cut the block's lens map with the others and count
    its memory, and give the whole sensor's answer up to the halo's cut-off."""
    from lfcl.demosaic.driver import demosaic_grid
    from lfcl.depth import DisparityMap
    from lfcl.grid.model import AlignedGrid
    from lfcl.noise.model import NoiseEstimate
    from lfcl.solvers.epi import epi_solver_bytes

    S, T, U, V = 30, 6, 9, 9
    b, _, _ = plane_scene_mosaic(rng, S, T, U, V, disparity=1.0, noise=0.01)
    depth = DisparityMap(np.ones((S, T), np.float32), np.ones((S, T), np.float32), 2.0, 0.1, {}, {}, {})
    noise = NoiseEstimate(gain=0.0, floor=1e-4, sigma=0.01, source="test")
    grid = AlignedGrid((U, V))
    options = dict(noise=noise, iterations=6, safety_net=False, disparity=depth, start="malvar")
    whole = demosaic_grid(b, "GRBG", grid, "admm-epi", **options)
    assert whole.parameters["one_colour_cross_lenses"] == S * T and "bands" not in whole.parameters
    budget = epi_solver_bytes((22 * U, T * V), False, cross_channel=True, one_colour=True)  # 7 lens rows of halo
    banded = demosaic_grid(b, "GRBG", grid, "admm-epi", max_memory=budget, **options)
    assert len(banded.parameters["bands"]["lens_rows"]) >= 3
    np.testing.assert_allclose(banded.planes, whole.planes, rtol=0, atol=1e-3)


@pytest.mark.parametrize("S, T, U, V", [(7, 9, 9, 9), (5, 6, 4, 5), (3, 4, 1, 5), (4, 3, 3, 1), (1, 1, 1, 1)])
def test_ray_maps_and_tap_spans_on_the_device_match_numpy(runtime, rng, S, T, U, V):
    """The per-sample maps and the per-lens tap spans that set_maps builds on the device, against their twins,
    exactly: disparities with whole values (one tap), clamped rays and fractions; pitch 1 on either axis (no u- or
    v-block: the spans say first > last)."""
    from lfcl.ops.epi import EpiGradient, lens_tap_spans_np, offset_table, ray_maps_np

    d = rng.choice([-2.0, -1.0, -0.35, 0.0, 0.5, 1.25, 2.0], size=(S, T)).astype(np.float32)
    d += rng.uniform(-0.01, 0.01, (S, T)).astype(np.float32) * (rng.random((S, T)) < 0.3)
    w = rng.random((S, T)).astype(np.float32)
    op = EpiGradient(runtime, (3, S * U, T * V), (U, V))
    rays = op.ray_maps(d, w)
    d_rays, w_rays = ray_maps_np(d, w, (U, V))
    np.testing.assert_array_equal(rays.get(), np.stack([d_rays.reshape(S * U, T * V), w_rays.reshape(S * U, T * V)]))
    spans = op.lens_tap_spans(rays)
    np.testing.assert_array_equal(spans, lens_tap_spans_np(d_rays))
    assert (U == 1) == bool(np.all(spans[0] > spans[1])) and (V == 1) == bool(np.all(spans[2] > spans[3]))
    # zero disparity: every tap on the sample's own lens; a block the pitch does not have stays empty (lo > hi)
    table = offset_table(lens_tap_spans_np(np.zeros((S, U, T, V), np.float32)))
    for block, exists in ((0, U > 1), (1, V > 1), (2, U > 1), (3, V > 1)):
        np.testing.assert_array_equal(table[block], [[0, 0] if exists else [0, -1]] * S)


def test_epi_default_budget_caps_a_cpu_device_that_shares_the_host_memory():
    import types

    import pyopencl as cl

    from lfcl.solvers.epi import EPI_CPU_BUDGET, epi_default_budget

    cpu = types.SimpleNamespace(type=cl.device_type.CPU, global_mem_size=10 * 2**30)
    gpu = types.SimpleNamespace(type=cl.device_type.GPU, global_mem_size=10 * 2**30)
    small_cpu = types.SimpleNamespace(type=cl.device_type.CPU, global_mem_size=2**30)
    assert epi_default_budget(cpu) == EPI_CPU_BUDGET == 2 * 2**30
    assert epi_default_budget(gpu) == 8 * 2**30
    assert epi_default_budget(small_cpu) == int(0.8 * 2**30)


# --- the cross-channel block along the epipolar lines: lam_xc ||D_epi(d, w) C x||_1 ------------------------------


def test_colour_differences_device_matches_the_twins(runtime, rng):
    from lfcl.ops.crosschannel import ColourDifferences, colour_differences_adjoint_np, colour_differences_np
    from lfcl.testing import dottest

    H, W = 7, 19  # n = 133: a short last chunk
    x = rng.standard_normal((3, H, W)).astype(np.float32)
    y = rng.standard_normal((2, H, W)).astype(np.float32)
    op = ColourDifferences(runtime, x.shape)
    # one float32 subtraction / negation per entry, as the twins in float32: equal to the bit
    np.testing.assert_array_equal(op.forward(runtime.to_device(x)).get(), colour_differences_np(x))
    np.testing.assert_array_equal(op.adjoint(runtime.to_device(y)).get(), colour_differences_adjoint_np(y))
    np.testing.assert_array_equal(x[0] - x[1], colour_differences_np(x)[0])  # the twin is C as documented
    np.testing.assert_array_equal(x[2] - x[1], colour_differences_np(x)[1])
    base = rng.standard_normal(x.shape).astype(np.float32)
    total = op.adjoint(runtime.to_device(y), out=runtime.to_device(base), accumulate=True).get()
    np.testing.assert_array_equal(total, base + colour_differences_adjoint_np(y))
    with pytest.raises(ValueError, match="accumulate"):
        op.adjoint(runtime.to_device(y), accumulate=True)
    with pytest.raises(ValueError, match="3 colour planes"):
        ColourDifferences(runtime, (2, H, W))
    # a batch: each image on its own (the u and v halves of an EPI gradient)
    batch = rng.standard_normal((2, 3, H, W)).astype(np.float32)
    ys = rng.standard_normal((2, 2, H, W)).astype(np.float32)
    op2 = ColourDifferences(runtime, (3, H, W), batch=2)
    assert op2.in_shape == (2, 3, H, W) and op2.out_shape == (2, 2, H, W)
    np.testing.assert_array_equal(op2.forward(runtime.to_device(batch)).get(),
                                  np.stack([colour_differences_np(b) for b in batch]))
    np.testing.assert_array_equal(op2.adjoint(runtime.to_device(ys)).get(),
                                  np.stack([colour_differences_adjoint_np(y) for y in ys]))
    assert dottest(op2, runtime, rng=np.random.default_rng(3)) <= 1e-6
    with pytest.raises(ValueError, match="batch"):
        ColourDifferences(runtime, (3, H, W), batch=0)


def test_cross_block_device_matches_its_twin_and_the_epi_differences(runtime, rng):
    """D_epi C on the device against its twin, and the twin against D_epi of the planes (D linear:
    D (x_R - x_G) = D x_R - D x_G)."""
    from lfcl.solvers.epi import EpiCrossGradient, epi_cross_gradient_np

    S, T, U, V = 4, 3, 5, 4
    x = rng.standard_normal((3, S * U, T * V))
    z = rng.standard_normal((2, 2, S * U, T * V))
    disparity, confidence = maps(rng, S, T, spread=1.5)
    planes = epi_gradient_np(x, disparity, (U, V), confidence)  # [2, 3, H, W]
    twin = epi_cross_gradient_np(x, disparity, (U, V), confidence)
    np.testing.assert_allclose(twin, np.stack([planes[:, 0] - planes[:, 1], planes[:, 2] - planes[:, 1]], axis=1),
                               atol=1e-12)
    epi = EpiGradient(runtime, x.shape, (U, V))
    epi.set_maps(disparity, confidence)
    op = EpiCrossGradient(runtime, epi)  # D_epi C as C D_epi, on the EPI block's operator
    assert op.gradient_shape == (2, 2, S * U, T * V)
    assert_cross_operator_matches_its_twins(runtime, rng, op, x, z, disparity, (U, V), confidence)


def assert_cross_operator_matches_its_twins(runtime, rng, op, x, z, disparity, pitch, confidence):
    """A [3, H, W] -> [2, 2, H, W] colour-difference operator on the device against epi_cross_gradient_np /
    epi_cross_adjoint_np at ``disparity`` and ``confidence``: forward, adjoint and the accumulating adjoint."""
    from lfcl.solvers.epi import epi_cross_adjoint_np, epi_cross_gradient_np

    x32, z32 = x.astype(np.float32), z.astype(np.float32)
    np.testing.assert_allclose(op.forward(runtime.to_device(x32)).get(),
                               epi_cross_gradient_np(x32.astype(np.float64), disparity, pitch, confidence), atol=1e-5)
    adjoint = epi_cross_adjoint_np(z32.astype(np.float64), disparity, pitch, confidence)
    np.testing.assert_allclose(op.adjoint(runtime.to_device(z32)).get(), adjoint, atol=5e-5)
    base = rng.standard_normal(x.shape).astype(np.float32)
    total = op.adjoint(runtime.to_device(z32), out=runtime.to_device(base), accumulate=True).get()
    np.testing.assert_allclose(total, base + adjoint, atol=5e-5)


def test_cross_block_and_colour_differences_pass_the_dot_test(runtime, rng):
    from lfcl.ops.crosschannel import ColourDifferences
    from lfcl.solvers.epi import EpiCrossGradient, epi_cross_adjoint_np, epi_cross_gradient_np
    from lfcl.testing import dottest

    S, T, U, V = 5, 4, 9, 9
    assert dottest(ColourDifferences(runtime, (3, 7, 19)), runtime, rng=np.random.default_rng(1)) <= 1e-6
    disparity, confidence = maps(rng, S, T, spread=3.0)
    epi = EpiGradient(runtime, (3, S * U, T * V), (U, V))
    epi.set_maps(disparity, confidence)
    op = EpiCrossGradient(runtime, epi)
    assert dottest(op, runtime, rng=np.random.default_rng(2)) <= 1e-5
    with pytest.raises(ValueError, match="3-colour EPI operator"):
        EpiCrossGradient(runtime, EpiGradient(runtime, (2, S * U, T * V), (U, V)))
    x = rng.standard_normal((3, S * U, T * V))
    y = rng.standard_normal((2, 2, S * U, T * V))
    lhs = np.vdot(epi_cross_gradient_np(x, disparity, (U, V), confidence), y)
    rhs = np.vdot(x, epi_cross_adjoint_np(y, disparity, (U, V), confidence))
    assert relative_dot_error(lhs, rhs) <= 1e-12


def test_cross_block_gram_diagonal_is_colour_gram_times_the_epi_diagonal(runtime, rng):
    """diag((D C)^T (D C)) = (1, 2, 1) x diag(D^T D), probed column by column (the cross block's whole per-pixel
    colour block is diag(D^T D) C^T C), and the device's preconditioner solves each pixel's 3x3 colour block of
    A^T W A + rho K^T K + delta with it (delta the proximal term), by the definition and as its twin."""
    from lfcl.ops.cfa import cfa_adjoint_np
    from lfcl.ops.crosschannel import COLOUR_GRAM
    from lfcl.solvers.epi import (
        EPI_PROXIMAL,
        EpiAdmmSolver,
        EpiPrior,
        epi_block_jacobi_np,
        epi_colour_blocks_np,
        epi_cross_adjoint_np,
        epi_cross_gradient_np,
    )
    from lfcl.solvers.params import AdmmParams

    S, T, U, V = 3, 2, 3, 3
    H, W = S * U, T * V
    disparity, confidence = maps(rng, S, T, spread=1.5)
    eye = np.eye(3 * H * W)
    probed = np.array([epi_cross_adjoint_np(epi_cross_gradient_np(eye[j].reshape(3, H, W), disparity, (U, V),
                                                                  confidence), disparity, (U, V), confidence).ravel()[j]
                       for j in range(eye.shape[0])]).reshape(3, H, W)
    epi = epi_diagonal_np(disparity, (U, V), confidence)
    np.testing.assert_allclose(probed, np.stack([epi, 2 * epi, epi]), atol=1e-12)
    weights = np.ones((U, V))
    weights[0, 0] = 0.0
    rho = 0.7
    fallback = epi_diagonal_np(np.zeros_like(disparity), (U, V), 1 - confidence)
    data = cfa_adjoint_np(np.tile(weights, (S, T)), "GRBG")
    # The blocks by their definition, pixel by pixel.
    blocks = np.empty((H, W, 3, 3))
    for i in range(H):
        for j in range(W):
            blocks[i, j] = (np.diag(data[:, i, j]) + (rho * (epi[i, j] + fallback[i, j]) + EPI_PROXIMAL * rho) * np.eye(3)
                            + rho * epi[i, j] * COLOUR_GRAM)
    np.testing.assert_allclose(np.diagonal(blocks, axis1=-2, axis2=-1).transpose(2, 0, 1),
                               data + rho * (epi + fallback + probed) + EPI_PROXIMAL * rho, atol=1e-12)
    np.testing.assert_allclose(epi_colour_blocks_np(data, epi + fallback, epi, rho, EPI_PROXIMAL * rho), blocks, rtol=1e-14)
    solver = EpiAdmmSolver(runtime, (H, W), "GRBG", (U, V))
    solver.prepare(AdmmParams(lam=0.01, lam_xc=0.02, rho=rho), EpiPrior(disparity, confidence, lam_fb=0.01), weights)
    assert [lam for _, lam in solver.blocks] == [0.01, 0.02, 0.01] and solver.blocks[1][0] is solver.cross
    r = rng.standard_normal((3, H, W)).astype(np.float32)
    got = solver.precondition(runtime.to_device(r), runtime.empty((3, H, W)), rho).get()
    want = np.linalg.solve(blocks, np.moveaxis(r, 0, -1)[..., None].astype(np.float64))[..., 0]
    np.testing.assert_allclose(got, np.moveaxis(want, -1, 0), rtol=1e-4, atol=1e-5 * np.abs(want).max())
    np.testing.assert_allclose(epi_block_jacobi_np(blocks, r), np.moveaxis(want, -1, 0), rtol=1e-12)


@pytest.mark.parametrize("pattern, lam_fb", [("GRBG", 0.02), ("BGGR", 0.0)])
def test_solver_with_the_cross_block_matches_the_float64_reference(runtime, rng, pattern, lam_fb):
    from lfcl.solvers.epi import EpiAdmmSolver, EpiPrior, admm_epi_reference
    from lfcl.solvers.params import AdmmParams

    S, T, U, V = 5, 4, 9, 9
    b, x0, _ = plane_scene_mosaic(rng, S, T, U, V, pattern=pattern)
    disparity, confidence = maps(rng, S, T, spread=1.0)
    prior = EpiPrior(disparity, confidence, lam_fb=lam_fb)
    params = AdmmParams(lam=0.01, lam_xc=0.015, rho=0.5, max_iter=8, cg_steps=4, cg_tol=0.0)
    weights = np.ones((U, V))
    weights[0, 0] = 0.0
    weights[4, 4] = 0.5
    expected = admm_epi_reference(b, pattern, (U, V), params, x0, prior, lens_weights=weights)
    solver = EpiAdmmSolver(runtime, b.shape, pattern, (U, V))
    got = solver.solve(runtime.to_device(b), runtime.to_device(x0), params, prior, lens_weights=weights)
    assert len(solver.blocks) == (3 if lam_fb else 2) and solver.blocks[1] == (solver.cross, 0.015)
    assert_matches_the_reference(got, expected, iterations=8)
    # the block changes the answer (it is not a no-op), and its objective counts lam_xc ||D_epi C x||_1
    plain = admm_epi_reference(b, pattern, (U, V), dataclasses.replace(params, lam_xc=0.0), x0, prior,
                               lens_weights=weights)
    assert np.linalg.norm(plain.x - expected.x) > 1e-3 * np.linalg.norm(expected.x)


def test_cross_block_leaves_no_trace_on_a_later_solve_without_it(runtime, rng):
    """One solver run with lam_xc > 0, then without: byte-identical to a fresh solver's run without, and the
    block's state is kept per block (a fall-back block after a cross-only run gets its own shape)."""
    from lfcl.solvers.epi import EpiAdmmSolver, EpiPrior
    from lfcl.solvers.params import AdmmParams

    S, T, U, V = 4, 3, 9, 9
    b, x0, _ = plane_scene_mosaic(rng, S, T, U, V)
    disparity, confidence = maps(rng, S, T, spread=1.0)
    params = AdmmParams(lam=0.01, rho=0.5, max_iter=4, cg_steps=3, cg_tol=0.0)
    with_xc = dataclasses.replace(params, lam_xc=0.02)
    b_dev, x0_dev = runtime.to_device(b), runtime.to_device(x0)
    solver = EpiAdmmSolver(runtime, b.shape, "GRBG", (U, V))
    solver.solve(b_dev, x0_dev, with_xc, EpiPrior(disparity, confidence))  # blocks: epi, cross
    again = solver.solve(b_dev, x0_dev, params, EpiPrior(disparity, confidence, lam_fb=0.02))  # epi, fall-back
    fresh = EpiAdmmSolver(runtime, b.shape, "GRBG", (U, V)).solve(b_dev, x0_dev, params,
                                                                  EpiPrior(disparity, confidence, lam_fb=0.02))
    assert len(solver.blocks) == 2 and solver.blocks[1][0] is solver.fallback
    np.testing.assert_array_equal(again.x.get(), fresh.x.get())
    assert again.history == fresh.history
    both = solver.solve(b_dev, x0_dev, with_xc, EpiPrior(disparity, confidence, lam_fb=0.02))
    assert len(solver.blocks) == 3 and np.all(np.isfinite(both.x.get()))


# --- the in-lens cross block where the lines carry one colour: lam_xc ||D_epi(0, m) C x||_1 ----------------------


def test_in_lens_cross_block_device_matches_its_definition_and_passes_the_dot_test(runtime, rng):
    """m D_uv C on the device against the twin (D_epi at d = 0 with confidence m), the twin against the (u, v)
    differences of the colour differences written out per lens, and the dot test on both."""
    from lfcl.solvers.epi import InLensCrossGradient, epi_cross_adjoint_np, epi_cross_gradient_np
    from lfcl.testing import dottest

    S, T, U, V = 4, 3, 5, 4
    H, W = S * U, T * V
    x = rng.standard_normal((3, H, W))
    z = rng.standard_normal((2, 2, H, W))
    m = (rng.random((S, T)) < 0.5).astype(np.float32)
    m[0, 0], m[1, 1] = 1.0, 0.5  # a fractional weight too
    zero = np.zeros((S, T), np.float32)
    twin = epi_cross_gradient_np(x, zero, (U, V), m)
    c = np.stack([x[0] - x[1], x[2] - x[1]]).reshape(2, S, U, T, V)
    weight = m[:, None, :, None]
    want = np.zeros((2, 2, S, U, T, V))
    want[0, :, :, :U - 1] = weight * (c[:, :, 1:] - c[:, :, :-1])
    want[1, :, :, :, :, :V - 1] = weight * (c[..., 1:] - c[..., :-1])
    np.testing.assert_allclose(twin, want.reshape(2, 2, H, W), atol=1e-12)
    op = InLensCrossGradient(runtime, (3, H, W), (U, V))
    op.set_weights(m)
    assert op.gradient_shape == (2, 2, H, W)
    assert_cross_operator_matches_its_twins(runtime, rng, op, x, z, zero, (U, V), m)
    assert dottest(op, runtime, rng=np.random.default_rng(4)) <= 1e-5
    lhs = np.vdot(twin, z)
    rhs = np.vdot(x, epi_cross_adjoint_np(z, zero, (U, V), m))
    assert relative_dot_error(lhs, rhs) <= 1e-12


@pytest.mark.parametrize("pattern, lam_fb", [("GRBG", 0.02), ("BGGR", 0.0)])
def test_solver_with_the_in_lens_cross_block_matches_the_float64_reference(runtime, rng, pattern, lam_fb):
    """The block after the cross block, its diagonal in the preconditioner's colour blocks: the device's run against
    the float64 twin's, and the block changes the answer."""
    from lfcl.solvers.epi import EpiAdmmSolver, EpiPrior, admm_epi_reference
    from lfcl.solvers.params import AdmmParams

    S, T, U, V = 5, 4, 9, 9
    b, x0, _ = plane_scene_mosaic(rng, S, T, U, V, disparity=1.0, pattern=pattern)
    disparity, confidence = maps(rng, S, T, spread=1.0)
    one_colour = rng.random((S, T)) < 0.5
    prior = EpiPrior(disparity, confidence, lam_fb=lam_fb, one_colour=one_colour)
    params = AdmmParams(lam=0.01, lam_xc=0.015, rho=0.5, max_iter=8, cg_steps=4, cg_tol=0.0)
    weights = np.ones((U, V))
    weights[0, 0] = 0.0
    expected = admm_epi_reference(b, pattern, (U, V), params, x0, prior, lens_weights=weights)
    solver = EpiAdmmSolver(runtime, b.shape, pattern, (U, V))
    got = solver.solve(runtime.to_device(b), runtime.to_device(x0), params, prior, lens_weights=weights)
    assert [op for op, _ in solver.blocks][:3] == [solver.epi, solver.cross, solver.lens_cross]
    assert len(solver.blocks) == (4 if lam_fb else 3) and solver.blocks[2][1] == 0.015
    assert_matches_the_reference(got, expected, iterations=8)
    without = admm_epi_reference(b, pattern, (U, V), params, x0, dataclasses.replace(prior, one_colour=None),
                                 lens_weights=weights)
    assert np.linalg.norm(without.x - expected.x) > 1e-3 * np.linalg.norm(expected.x)
    # no lens of one-colour lines, or no cross term: no block
    solver.prepare(params, dataclasses.replace(prior, one_colour=np.zeros((S, T), bool)))
    assert solver.lens_cross not in [op for op, _ in solver.blocks]
    solver.prepare(dataclasses.replace(params, lam_xc=0.0), prior)
    assert solver.lens_cross not in [op for op, _ in solver.blocks]
    with pytest.raises(ValueError, match="one_colour"):
        solver.prepare(params, dataclasses.replace(prior, one_colour=np.ones((S, T + 1), bool)))


def test_epi_prior_rows_cut_every_map_and_the_solver_memory_counts_the_block():
    from lfcl.solvers.epi import EpiPrior, epi_solver_bytes

    d = np.arange(12, dtype=np.float32).reshape(4, 3) / 10
    prior = EpiPrior(d, d / 2, lam_fb=0.1, one_colour=d > 0.5)
    band = prior.rows(1, 3)
    np.testing.assert_array_equal(band.disparity, d[1:3])
    np.testing.assert_array_equal(band.confidence, d[1:3] / 2)
    np.testing.assert_array_equal(band.one_colour, (d > 0.5)[1:3])
    assert band.lam_fb == 0.1 and EpiPrior(d).rows(0, 2).one_colour is None
    plain = epi_solver_bytes((90, 90), False, cross_channel=True)
    # z and u [2, 2, H, W], C x [2, H, W] and the rays (d, w) per sample, 4 bytes each
    assert epi_solver_bytes((90, 90), False, cross_channel=True, one_colour=True) - plain == 4 * 12 * 90 * 90


def test_one_colour_prior_lenses_are_the_known_ones_near_an_odd_disparity():
    import types

    from lfcl.solvers.epi import ONE_COLOUR_PRIOR_WITHIN, one_colour_prior_lenses

    within = ONE_COLOUR_PRIOR_WITHIN
    d = np.array([[1.0, -1.0 + 0.9 * within, 3.0 - 0.9 * within, 1.0 + 1.1 * within, 2.0, 0.0]] * 3, np.float32)
    confidence = np.ones_like(d)
    depth = types.SimpleNamespace(disparity=d, confidence=confidence)
    np.testing.assert_array_equal(one_colour_prior_lenses(depth, (9, 9))[1], [True, True, True, False, False, False])
    assert not one_colour_prior_lenses(depth, (8, 8)).any()  # an even pitch has no one-colour disparity
    alone = np.zeros_like(d)
    alone[1, 0] = 1.0  # one lens, not confident, no majority of one-colour neighbours: not known
    unsure = types.SimpleNamespace(disparity=alone, confidence=np.zeros_like(d))
    assert not one_colour_prior_lenses(unsure, (9, 9)).any()


def test_epi_prior_gives_the_one_colour_lenses_a_share_of_fall_back():
    import types

    from lfcl.solvers.epi import ONE_COLOUR_FALLBACK_SHARE, ONE_COLOUR_FB_PER_LAM, epi_prior

    d = np.array([[1.0, 0.0, -1.0, 0.5]] * 2, np.float32)
    depth = types.SimpleNamespace(disparity=d, confidence=np.full_like(d, 0.5))
    lines = np.where(np.abs(np.abs(d) - 1) < 0.05, 1.0 - ONE_COLOUR_FALLBACK_SHARE, 1.0)
    prior = epi_prior(depth, (9, 9), 0.01, 0.0, cross_channel=True)
    np.testing.assert_array_equal(prior.one_colour, lines < 1)
    np.testing.assert_allclose(prior.confidence, lines)  # only those lenses leave weight to the fall-back
    assert prior.lam_fb == pytest.approx(ONE_COLOUR_FB_PER_LAM * 0.01)
    given = epi_prior(depth, (9, 9), 0.01, 0.003, cross_channel=True)  # a fall-back of its own keeps its weight
    assert given.lam_fb == 0.003
    np.testing.assert_allclose(given.confidence, 0.5 * lines)
    for plain in (epi_prior(depth, (9, 9), 0.01, 0.0, cross_channel=False), epi_prior(depth, (8, 8), 0.01, 0.0, True)):
        assert plain.confidence is None and plain.lam_fb == 0.0 and not np.any(plain.one_colour)
    np.testing.assert_array_equal(epi_prior(depth, (9, 9), 0.01, 0.003, False).confidence, depth.confidence)


def test_admm_epi_on_a_coloured_grating_at_an_odd_disparity_keeps_its_hue(monkeypatch):
    """A coloured grating of 5.8 lenses at d = 1.03: the in-lens cross block alone made the colours its lines do not
    measure the measured one plus constant colour differences, 5.4 dB below Malvar's centre view at 2 lux. With each
    colour's own share of (u, v) smoothness the hue follows the grating: within 0.5 dB of Malvar's centre view and
    above its mean image, 4 dB better than without. Both arms, as the parameters say."""
    import lfcl.solvers.epi as epi
    from lfcl.evaluation.evaluate import run_method, simulation_capture
    from lfcl.sim import simulate
    from lfcl.sim.periodic import ColourGrating
    from lfcl.sim.planes import Plane

    grating = ColourGrating(5.8, 0.3, 0.5, (0.8, 0.21, 0.28), (0.46, 0.49, 0.25))
    capture = simulation_capture(simulate(planes=[Plane("c", 1.03, grating)], lenses=(24, 24), lux=2, seed=3))
    malvar = run_method(capture, "malvar")
    result = run_method(capture, "admm-epi")
    assert result["parameters"]["one_colour_cross_lenses"] >= 0.9 * 24 * 24
    assert result["parameters"]["lam_fb"] > 0 and result["parameters"]["fallback_block"]
    assert result["psnr_center"] > malvar["psnr_center"] - 0.5
    assert result["psnr_mean"] > malvar["psnr_mean"] + 1.0
    monkeypatch.setattr(epi, "ONE_COLOUR_FALLBACK_SHARE", 0.0)
    without = run_method(capture, "admm-epi")
    assert without["parameters"]["lam_fb"] == 0 and not without["parameters"]["fallback_block"]
    assert without["psnr_center"] < result["psnr_center"] - 4.0


def test_admm_epi_on_a_grating_at_an_odd_disparity_beats_malvar(monkeypatch):
    """A grey grating at d = -1 (every epipolar line one colour at pitch 9): admm-epi's missing colours drifted
    from the start to 0.4 dB below Malvar's centre view at 2 lux; the in-lens cross block takes them from the
    neighbouring lines' colour differences. Both with the block and without, as the parameters say."""
    import lfcl.solvers.epi as epi
    from lfcl.evaluation.evaluate import run_method, simulation_capture
    from lfcl.sim import simulate
    from lfcl.sim.periodic import SineGrating
    from lfcl.sim.planes import Plane

    capture = simulation_capture(simulate(planes=[Plane("g", -1.0, SineGrating(2.5, 0.7))], lenses=(24, 24), lux=2,
                                          seed=3))
    malvar = run_method(capture, "malvar")["psnr_center"]
    result = run_method(capture, "admm-epi")
    assert result["parameters"]["one_colour_cross_lenses"] >= 0.9 * 24 * 24
    assert result["psnr_center"] > malvar + 3.0
    monkeypatch.setattr(epi, "ONE_COLOUR_PRIOR_WITHIN", -1.0)  # no lens
    without = run_method(capture, "admm-epi")
    assert without["parameters"]["one_colour_cross_lenses"] == 0
    assert without["psnr_center"] < result["psnr_center"] - 3.0


def test_admm_epi_from_the_12_lux_row_takes_malvars_colour_in_its_start(monkeypatch):
    """A grey period-2.5 grating at d = -1.5, 12 lux: linear4d misreads its colour over the whole frame (no lens
    stands out for the guard), and admm-epi from linear4d's colour differences ended 6.7 dB below Malvar's mean
    image. The schedule's rows from 12 lux up move the start's colour differences towards Malvar's; the 2-lux row
    does not. Both views above Malvar with it, the mean image below without."""
    import lfcl.solvers.epi as epi
    from lfcl.evaluation.evaluate import run_method, simulation_capture
    from lfcl.sim import simulate
    from lfcl.sim.periodic import SineGrating
    from lfcl.sim.planes import Plane

    rows = {row.sigma: row.malvar_colour for row in epi.EPI_SCHEDULE}
    assert rows[4.6e-3] > 0 and rows[9.24e-3] > 0 and rows[1.03e-3] == rows[1.92e-3] == 0
    capture = simulation_capture(simulate(planes=[Plane("g", -1.5, SineGrating(2.5, 0.7))], lenses=(24, 24), lux=12,
                                          seed=1))
    malvar = run_method(capture, "malvar")
    result = run_method(capture, "admm-epi")
    assert result["parameters"]["start_guard"]["malvar_colour"] == rows[4.6e-3]
    assert result["psnr_center"] > malvar["psnr_center"] and result["psnr_mean"] > malvar["psnr_mean"]
    monkeypatch.setattr(epi, "EPI_SCHEDULE", tuple(dataclasses.replace(row, malvar_colour=0.0)
                                                   for row in epi.EPI_SCHEDULE))
    without = run_method(capture, "admm-epi")
    assert without["parameters"]["start_guard"]["malvar_colour"] == 0.0
    assert without["psnr_mean"] < malvar["psnr_mean"] - 1.0


def test_epi_params_take_the_x_update_of_the_nearer_row(monkeypatch):
    import lfcl.solvers.epi as epi
    from lfcl.solvers.params import AdmmParams

    rows = (epi.EpiSetting(sigma=1e-3, lam_per_sigma=0.2, fb_per_lam=0.0, change_per_sigma=0.05, iterations=20,
                           start="guarded", cg_steps=5, extrapolation=0.0),
            epi.EpiSetting(sigma=4e-3, lam_per_sigma=0.2, fb_per_lam=0.0, change_per_sigma=0.05, iterations=20,
                           start="guarded", cg_steps=3, extrapolation=0.8))
    monkeypatch.setattr(epi, "EPI_SCHEDULE", rows)
    for sigma, steps, beta in ((5e-4, 5, 0.0), (1.9e-3, 5, 0.0), (2.1e-3, 3, 0.8), (9e-3, 3, 0.8)):
        params, _ = epi.epi_params(AdmmParams(cg_steps=4), sigma)
        assert (params.cg_steps, params.extrapolation) == (steps, beta), sigma


def test_epi_params_sets_lam_xc_from_the_schedule(monkeypatch):
    import lfcl.solvers.epi as epi
    from lfcl.solvers.params import AdmmParams

    for sigma in (1.0e-3, 2.6e-3, 1.0e-2):  # the shipped rows: the block at every level, lam_xc = lam
        shipped, _ = epi.epi_params(AdmmParams(), sigma)
        assert shipped.lam_xc == pytest.approx(1.0 * shipped.lam) and shipped.lam > 0
    rows = tuple(dataclasses.replace(row, xc_per_lam=0.0 if i % 2 else 1.0) for i, row in enumerate(epi.EPI_SCHEDULE))
    monkeypatch.setattr(epi, "EPI_SCHEDULE", rows)
    between = math.sqrt(rows[0].sigma * rows[1].sigma)  # halfway in log sigma: half the block
    params, _ = epi.epi_params(AdmmParams(), between)
    assert params.lam_xc == pytest.approx(0.5 * params.lam)
    rows = tuple(dataclasses.replace(row, xc_per_lam=0.5) for row in epi.EPI_SCHEDULE)
    monkeypatch.setattr(epi, "EPI_SCHEDULE", rows)
    params, _ = epi.epi_params(AdmmParams(), 0.01)
    assert params.lam_xc == pytest.approx(0.5 * params.lam) and params.lam > 0
    params, _ = epi.epi_params(AdmmParams(lam=0.004), 0.01, lam=0.004)  # an explicit lam: the ratio to it
    assert params.lam == 0.004 and params.lam_xc == pytest.approx(0.002)
    assert epi.epi_solver_bytes((90, 90), True, True) > epi.epi_solver_bytes((90, 90), True)


def test_fused_cg_step_matches_its_numpy_twin(runtime, rng):
    """CgSteps: q = N p with <p, q>, then x += alpha p, r -= alpha q, pz = (N's per-pixel colour blocks)^-1 r with
    <r, pz> and |r|^2,
    against float64 twins (N = A^T A + rho K^T K + delta with the EPI, cross-channel and fall-back blocks and the
    proximal term), on a frame whose width is not a whole number of 16-column runs."""
    from lfcl.ops.cfa import cfa_adjoint_np, cfa_sample_np
    from lfcl.solvers.epi import (
        EPI_PROXIMAL,
        CgSteps,
        EpiAdmmSolver,
        EpiPrior,
        epi_block_jacobi_np,
        epi_colour_blocks_np,
        epi_cross_adjoint_np,
        epi_cross_gradient_np,
    )
    from lfcl.solvers.params import AdmmParams

    S, T, U, V = 3, 5, 3, 3  # W = 15: one run, partly past the row
    H, W = S * U, T * V
    disparity, confidence = maps(rng, S, T, spread=1.5)
    zeros, fall = np.zeros_like(disparity), 1 - confidence
    rho, alpha = 0.7, 0.37
    solver = EpiAdmmSolver(runtime, (H, W), "GRBG", (U, V))
    solver.prepare(AdmmParams(lam=0.01, lam_xc=0.02, rho=rho), EpiPrior(disparity, confidence, lam_fb=0.01))
    x, p, r = (rng.standard_normal((3, H, W)).astype(np.float32) for _ in range(3))
    p64 = p.astype(np.float64)

    def gram(v, d, w):
        return epi_adjoint_np(epi_gradient_np(v, d, (U, V), w), d, (U, V), w)

    expected_q = cfa_adjoint_np(cfa_sample_np(p64, "GRBG"), "GRBG") + rho * (
        gram(p64, disparity, confidence) + gram(p64, zeros, fall)
        + epi_cross_adjoint_np(epi_cross_gradient_np(p64, disparity, (U, V), confidence), disparity, (U, V),
                               confidence)) + EPI_PROXIMAL * rho * p64
    epi = epi_diagonal_np(disparity, (U, V), confidence)
    blocks = epi_colour_blocks_np(cfa_adjoint_np(np.ones((H, W)), "GRBG"), epi + epi_diagonal_np(zeros, (U, V), fall),
                                  epi, rho, EPI_PROXIMAL * rho)
    steps = CgSteps(solver, rho)
    xd, pd, rd, qd, zd = (runtime.to_device(a) for a in (x, p, r, np.zeros_like(x), np.zeros_like(x)))
    pq = steps.apply_dot(pd, qd)
    np.testing.assert_allclose(qd.get(), expected_q, rtol=1e-5, atol=1e-5)
    assert pq == pytest.approx(float(np.sum(p64 * expected_q)), rel=1e-5)
    rz, r2 = steps.update(alpha, xd, pd, rd, qd, zd)
    r_next = r - alpha * qd.get().astype(np.float64)  # from the device's q: the step's own arithmetic
    z_next = epi_block_jacobi_np(blocks, r_next)
    np.testing.assert_allclose(xd.get(), x + alpha * p64, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(rd.get(), r_next, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(zd.get(), z_next, rtol=1e-5, atol=1e-5)
    assert rz == pytest.approx(float(np.sum(r_next * z_next)), rel=1e-5)
    assert r2 == pytest.approx(float(np.sum(r_next * r_next)), rel=1e-5)
