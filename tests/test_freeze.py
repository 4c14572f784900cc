"""Freezing converged lenses (lfcl/solvers/freeze.py): lens copies against numpy, and the
frozen solve against the plain device solver and the float64 reference, lens by lens."""

from __future__ import annotations

import json

import numpy as np
import pytest

from lfcl.ops.cfa import cfa_sample_np
from lfcl.ops.crosschannel import cross_gradient_np
from lfcl.ops.gradient import gradient_np
from lfcl.ops.lenscopy import LensCopy, copy_lenses_np, fill_lenses_np
from lfcl.ops.lensfill import lens_fill_np
from lfcl.ops.malvar import malvar_np
from lfcl.solvers.admm import AdmmSolver
from lfcl.solvers.freeze import BLOCK, FreezeSettings, ladder_rows, solve_with_freezing
from lfcl.solvers.params import AdmmParams
from lfcl.solvers.reference import admm_reference

S, T, PITCH = 11, 10, (5, 5)  # odd lens rows and T % 4 != 0: blocks cut at the edges
FLAT_ROWS = 8  # lens rows 0-3 nearly noise-free, 4-7 noisier: they converge at two paces
SETTINGS = FreezeSettings(fraction=0.3, shrink_at=0.75)


def half_flat_mosaic(rng, pattern="GRBG"):
    """A mosaic whose top FLAT_ROWS lens rows see a flat grey (noise 0.002 in the first half of
    them, 0.01 in the second) and the rest a textured scene with noise 0.03; and its Malvar start."""
    U, V = PITCH
    H, W = S * U, T * V
    yy, xx = np.mgrid[0:H, 0:W] / 10
    texture = np.stack([0.45 + 0.3 * np.sin(3 * xx + c) * np.cos(2.3 * yy - c) for c in range(3)])
    flat = np.array([0.3, 0.5, 0.4])[:, None, None] * np.ones((3, H, W))
    lens_row = np.arange(H) // U
    truth = np.where((lens_row < FLAT_ROWS)[None, :, None], flat, texture)
    sd = np.where(lens_row < FLAT_ROWS // 2, 0.002, np.where(lens_row < FLAT_ROWS, 0.01, 0.03))
    noise = sd[:, None] * rng.standard_normal((H, W))
    b = (cfa_sample_np(truth, pattern) + noise).astype(np.float32)
    return b, malvar_np(b, pattern).astype(np.float32)


def params_for(lam_xc=0.0, **changes):
    return AdmmParams(**{"lam": 0.01, "lam_xc": lam_xc, "rho": 0.3, "change_tol": 1e-3, "max_iter": 60, **changes})


def lens_values(planes: np.ndarray) -> np.ndarray:
    """[C, S*U, T*V] -> [S, T, C*U*V]: each lens's samples."""
    U, V = PITCH
    C = planes.shape[0]
    return planes.reshape(C, S, U, T, V).transpose(1, 3, 0, 2, 4).reshape(S, T, -1)


def objective_np(x, b, params, weights, lenses):
    """1/2 ||W^(1/2) (A x - b)||^2 + lam ||M D x||_1 + lam_xc ||M D C x||_1 in float64, and the
    share of the ``lenses`` ([S, T] booleans) in it."""
    U, V = PITCH
    x = np.asarray(x, np.float64)
    w = np.ones(PITCH) if weights is None else np.asarray(weights, np.float64)
    mask = w if (w <= 0).any() else None
    data = 0.5 * np.tile(w, (S, T)) * (cfa_sample_np(x, "GRBG") - b) ** 2  # [H, W]
    prior = (params.lam * np.abs(gradient_np(x, PITCH, "uv", mask)).sum(axis=(0, 1))
             + params.lam_xc * np.abs(cross_gradient_np(x, PITCH, "uv", mask)).sum(axis=(0, 1)))
    per_lens = (data + prior).reshape(S, U, T, V).sum(axis=(1, 3))
    return float(per_lens.sum()), float(per_lens[lenses].sum())


def plain_trajectory(runtime, b, x0, params, iterations, weights=None):
    """The plain device solver's x after each iteration 0..iterations (0: the start), and its history."""
    steps = [x0]
    solver = AdmmSolver(runtime, b.shape, "GRBG", PITCH, "uv")
    fixed = AdmmParams(**{**params.__dict__, "change_tol": 0.0, "max_iter": iterations})
    result = solver.solve(runtime.to_device(b), runtime.to_device(x0), fixed, lens_weights=weights,
                          callback=lambda record, x: steps.append(x.get()))
    return steps, result.history


def run_frozen(runtime, b, x0, params, weights=None, settings=SETTINGS):
    solver = AdmmSolver(runtime, b.shape, "GRBG", PITCH, "uv")
    result, report = solve_with_freezing(solver, runtime.to_device(b), runtime.to_device(x0), params, settings,
                                         lens_weights=weights)
    return result, report


@pytest.mark.parametrize("planes", [(3,), (2, 3), ()])
def test_copy_lenses_matches_numpy(runtime, rng, planes):
    U, V = 3, 4
    src = rng.random((*planes, 5 * U, 7 * V)).astype(np.float32)
    dst = rng.random((*planes, 2 * U, 8 * V)).astype(np.float32)
    pairs = [(0, 15), (34, 0), (12, 7), (-1, 3), (-1, 8)]  # -1: zeros
    device = runtime.to_device(dst)
    LensCopy(runtime, (U, V))(runtime.to_device(src), device, pairs)
    expected = copy_lenses_np(src, dst, pairs, (U, V))
    np.testing.assert_array_equal(device.get(), expected)
    # the twin against a loop over the definition: lens (s, t) = rows s*U.., columns t*V..
    lens = expected.reshape(-1, 2 * U, 8 * V)[:, 0:U, 7 * V:8 * V]  # destination lens 7 = (0, 7)
    np.testing.assert_array_equal(lens, src.reshape(-1, 5 * U, 7 * V)[:, 1 * U:2 * U, 5 * V:6 * V])  # 12 = (1, 5)
    assert not expected.reshape(-1, 2 * U, 8 * V)[:, 0:U, 3 * V:4 * V].any()
    untouched = expected.reshape(-1, 2 * U, 8 * V)[:, U:2 * U, 0:V]  # lens 8 is zeroed, lens 9 kept
    assert not untouched.any()
    np.testing.assert_array_equal(expected.reshape(-1, 2 * U, 8 * V)[:, U:2 * U, V:2 * V],
                                  dst.reshape(-1, 2 * U, 8 * V)[:, U:2 * U, V:2 * V])


@pytest.mark.parametrize("planes", [(3,), ()])
def test_fill_lenses_matches_numpy(runtime, rng, planes):
    U, V = 3, 5  # odd and non-square lenses
    dst = rng.random((*planes, 4 * U, 6 * V)).astype(np.float32)
    lenses = [0, 23, 7, 12]
    values = rng.random((len(lenses), planes[0] if planes else 1)).astype(np.float32)
    device = runtime.to_device(dst)
    LensCopy(runtime, (U, V)).fill(device, lenses, values)
    expected = fill_lenses_np(dst.copy(), lenses, values, (U, V))
    np.testing.assert_array_equal(device.get(), expected)
    # the twin against the definition: lens 7 = (1, 1) holds its values, lens 8 = (1, 2) is untouched
    grid = expected.reshape(-1, 4 * U, 6 * V)
    np.testing.assert_array_equal(grid[:, U:2 * U, V:2 * V], np.broadcast_to(values[2][:, None, None], (len(values[2]), U, V)))
    np.testing.assert_array_equal(grid[:, U:2 * U, 2 * V:3 * V], dst.reshape(-1, 4 * U, 6 * V)[:, U:2 * U, 2 * V:3 * V])


def test_fill_lenses_rejects_bad_lenses_and_values(runtime):
    device = runtime.to_device(np.zeros((3, 4, 4), np.float32))
    with pytest.raises(ValueError, match="outside the 2x2 lenses"):
        LensCopy(runtime, (2, 2)).fill(device, [4], np.zeros((1, 3)))
    with pytest.raises(ValueError, match="values hold 2 planes"):
        LensCopy(runtime, (2, 2)).fill(device, [0], np.zeros((1, 2)))
    with pytest.raises(ValueError, match="outside the 2x2 lenses"):
        fill_lenses_np(np.zeros((3, 4, 4), np.float32), [-1], np.zeros((1, 3)), (2, 2))


def test_copy_lenses_rejects_bad_pairs(runtime):
    with pytest.raises(ValueError, match="lens indices"):
        LensCopy(runtime, (2, 2)).upload([(-2, 0)])
    with pytest.raises(ValueError, match="past the"):
        copy_lenses_np(np.zeros((4, 4), np.float32), np.zeros((4, 4), np.float32), [(4, 0)], (2, 2))


def test_ladder_sizes_shrink_to_one_block_row():
    assert ladder_rows(6, 0.75) == [5, 4, 3, 2, 1]
    assert ladder_rows(1, 0.5) == [1]
    with pytest.raises(ValueError, match="fraction"):
        FreezeSettings(fraction=1.5)


@pytest.mark.parametrize("lam_xc", [0.0, 0.002])
def test_without_freezing_the_solve_is_the_plain_one(runtime, rng, lam_xc):
    b, x0 = half_flat_mosaic(rng)
    params = params_for(lam_xc)
    plain, _ = plain_trajectory(runtime, b, x0, params, 1)  # builds the programs
    solver = AdmmSolver(runtime, b.shape, "GRBG", PITCH, "uv")
    plain = solver.solve(runtime.to_device(b), runtime.to_device(x0), params)
    for fraction in (0.0, 1e-9):  # off, and on with a rule no block meets (the freeze loop, no move)
        result, report = run_frozen(runtime, b, x0, params, settings=FreezeSettings(fraction=fraction))
        np.testing.assert_array_equal(result.x.get(), plain.x.get())
        assert [r.objective for r in result.history] == [r.objective for r in plain.history]
        assert report.frozen_lenses == 0 and report.applied == (fraction > 0)


def test_freezing_needs_the_exact_lens_solve(runtime, rng):
    # CG leaves no per-lens change on the host: the solve runs plain and says why
    b, x0 = half_flat_mosaic(rng)
    params = params_for(x_update="cg")
    plain = AdmmSolver(runtime, b.shape, "GRBG", PITCH, "uv").solve(runtime.to_device(b), runtime.to_device(x0), params)
    result, report = run_frozen(runtime, b, x0, params)
    assert not report.applied and "CG" in report.why and report.frozen_at is None
    np.testing.assert_array_equal(result.x.get(), plain.x.get())


@pytest.mark.parametrize("lam_xc", [0.0, 0.002])
@pytest.mark.parametrize("dark_corner", [False, True])
def test_frozen_lenses_keep_the_plain_trajectory(runtime, rng, lam_xc, dark_corner):
    # Lenses are independent under a (u, v) prior: a frozen lens must hold the plain solver's x
    # of the iteration it froze at, a lens never frozen the plain x of the last iteration.
    b, x0 = half_flat_mosaic(rng)
    weights = None
    if dark_corner:
        weights = np.ones(PITCH, np.float32)
        weights[0, 0] = 0.0
    params = params_for(lam_xc)
    result, report = run_frozen(runtime, b, x0, params, weights)
    K = result.iterations
    assert report.applied
    # the quiet flat rows froze first, part of the noisier ones later (a move out of a moved
    # solver), the textured rows never
    assert len(report.moves) == 2, report.moves
    assert (report.frozen_at[:FLAT_ROWS // 2] == report.moves[0]["iteration"]).all()
    assert (report.frozen_at[FLAT_ROWS // 2:FLAT_ROWS] == report.moves[1]["iteration"]).any()
    assert (report.frozen_at[FLAT_ROWS:] == 0).all()
    assert report.frozen_lenses == np.count_nonzero(report.frozen_at)
    assert report.lens_iterations_skipped == np.sum(K - report.frozen_at[report.frozen_at > 0])
    for move in report.moves:  # the moved solvers' sizes come from the fixed ladder
        assert move["solver_lenses"][0] // BLOCK[0] in ladder_rows(-(-S // BLOCK[0]), SETTINGS.shrink_at)

    steps, plain_history = plain_trajectory(runtime, b, x0, params, K, weights)
    filled = [lens_fill_np(x, weights, PITCH) if dark_corner else x for x in steps]  # as at the end of a solve
    got = lens_values(result.x.get())
    expected = np.empty_like(got)
    for s in range(S):
        for t in range(T):
            expected[s, t] = lens_values(filled[report.frozen_at[s, t] or K])[s, t]
    assert np.abs(got - expected).max() <= 1e-6
    # and the test can fail: the frozen lenses moved on in the plain run
    frozen = report.frozen_at > 0
    assert np.abs(lens_values(filled[K])[frozen] - got[frozen]).max() > 100 * 1e-6

    # the history is the whole problem's: the global rule stopped it, the records before the
    # first move are the plain ones, and after it the frozen lenses' constant sums are added
    assert all(np.isfinite([r.objective, r.primal_residual, r.dual_residual, r.rms_change]).all()
               for r in result.history)
    assert result.history[-1].rms_change <= params.change_tol < result.history[-2].rms_change
    def lens_change2(k):  # squared change of each lens in iteration k
        return np.sum((lens_values(steps[k]) - lens_values(steps[k - 1])).astype(np.float64) ** 2, axis=-1)

    for k, record in enumerate(result.history, start=1):  # over all samples, a frozen lens with its last change
        at = np.where((report.frozen_at > 0) & (report.frozen_at < k), report.frozen_at, k)
        change2 = sum(lens_change2(j)[at == j].sum() for j in np.unique(at))
        assert record.rms_change == pytest.approx(np.sqrt(change2 / x0.size), rel=1e-4, abs=1e-9)
    first_move = report.moves[0]["iteration"]
    for mine, plain in zip(result.history[:first_move], plain_history):
        assert mine.objective == pytest.approx(plain.objective, rel=1e-6)
        assert mine.rms_change == pytest.approx(plain.rms_change, rel=1e-5)
    # the objective depends on x alone: the last record's is that of the whole final x
    whole, frozen_share = objective_np(result.x.get(), b, params, weights, report.frozen_at > 0)
    assert result.history[-1].objective == pytest.approx(whole, rel=1e-5)
    assert frozen_share > 1e-3 * whole  # so leaving the frozen lenses out would fail


def test_freezing_matches_the_float64_reference(runtime, rng):
    # The reference (float64, CG run to convergence) on the whole image, stopped at each
    # iteration where lenses froze, gives those lenses; stopped at the end, all the others.
    b, x0 = half_flat_mosaic(rng)
    params = params_for()
    result, report = run_frozen(runtime, b, x0, params)
    got = lens_values(result.x.get())
    converged = AdmmParams(lam=params.lam, rho=params.rho, cg_steps=400, cg_tol=1e-13)
    stops = sorted(set(report.frozen_at[report.frozen_at > 0].tolist()) | {result.iterations})
    assert len(stops) >= 2
    for k in stops:
        expected = admm_reference(b, "GRBG", PITCH, "uv", AdmmParams(**{**converged.__dict__, "max_iter": k}), x0)
        lenses = (report.frozen_at == k) if k != result.iterations else (report.frozen_at == 0)
        want = lens_values(expected.x)[lenses]
        relative = np.linalg.norm(got[lenses] - want) / np.linalg.norm(want)
        assert relative <= 1e-5, (k, relative)


def test_demosaic_lightfield_freeze_option(rng):
    from lfcl.methods import demosaic_lightfield
    from lfcl.noise import NoiseEstimate

    b, _ = half_flat_mosaic(rng)
    noise = NoiseEstimate(0.0, 0.01**2, 0.01, "test")
    # every lens solved: leaving the flat half out (skip_flat, the default) would leave nothing to freeze
    plain = demosaic_lightfield(b, "GRBG", PITCH, "admm-uv", noise=noise, freeze=False, skip_flat=False)
    frozen = demosaic_lightfield(b, "GRBG", PITCH, "admm-uv", noise=noise, freeze=0.3, skip_flat=False)
    assert "freeze" not in plain.parameters
    record = frozen.parameters["freeze"]
    json.dumps(record)  # goes into the outputs' metadata
    assert record["applied"] and record["fraction"] == 0.3 and record["lenses"] == S * T
    assert record["frozen_lenses"] > 0 and 0 < record["skipped_share"] < 1
    assert np.abs(frozen.planes - plain.planes).max() < 0.05
    # a fixed iteration count has no change rule to freeze against: it runs plain and says why
    fixed = demosaic_lightfield(b, "GRBG", PITCH, "admm-uv-xc", noise=noise, iterations=3, freeze=True)
    assert not fixed.parameters["freeze"]["applied"] and "stop rule" in fixed.parameters["freeze"]["why"]
    with pytest.raises(ValueError, match="couples no two lenses"):
        demosaic_lightfield(b, "GRBG", PITCH, "admm-uvst", noise=noise, freeze=True)
    with pytest.raises(ValueError, match="fraction of the stop tolerance"):
        demosaic_lightfield(b, "GRBG", PITCH, "admm-uv", noise=noise, freeze=1.5)
