"""The primal-dual solver of admm-epi's problem (lfcl/solvers/epi_pd.py): the device against its float64 twin,
the step sizes against the convergence condition, and the twin against ADMM's converged answer."""

from __future__ import annotations

import numpy as np
import pytest
from test_epi import assert_matches_the_reference, maps, plane_scene_mosaic

from lfcl.ops.cfa import cfa_sample_np
from lfcl.ops.epi import epi_gradient_np, epi_matrix_np
from lfcl.solvers.epi import EpiPrior, admm_epi_reference, epi_cross_gradient_np
from lfcl.solvers.epi_pd import CROSS_COLUMNS, EpiPdSolver, _sigmas, epi_pd_reference
from lfcl.solvers.params import AdmmParams


@pytest.mark.parametrize("pattern", ["GRBG", "BGGR"])
@pytest.mark.parametrize("lam_xc, lam_fb", [(0.0, 0.0), (0.015, 0.0), (0.0, 0.02), (0.015, 0.02)])
def test_device_matches_the_float64_twin(runtime, rng, pattern, lam_xc, lam_fb):
    S, T, U, V = 5, 4, 9, 9
    b, x0, _ = plane_scene_mosaic(rng, S, T, U, V, pattern=pattern)
    disparity, confidence = maps(rng, S, T, spread=1.0)
    prior = EpiPrior(disparity, confidence if lam_fb else None, lam_fb=lam_fb)
    params = AdmmParams(lam=0.01, lam_xc=lam_xc, rho=0.3, max_iter=9)
    weights = np.ones((U, V))
    weights[0, 0] = 0.0  # a dark corner out of the data term
    weights[4, 4] = 0.5
    expected = epi_pd_reference(b, pattern, (U, V), params, x0, prior, lens_weights=weights)
    solver = EpiPdSolver(runtime, b.shape, pattern, (U, V))
    got = solver.solve(runtime.to_device(b), runtime.to_device(x0), params, prior, lens_weights=weights)
    assert len(solver._blocks) == 1 + (lam_fb > 0) and solver._blocks[0]["cross"] == (lam_xc > 0)
    assert_matches_the_reference(got, expected, iterations=9)


def test_change_rule_stops_device_and_twin_at_the_same_iteration(runtime, rng):
    S, T, U, V = 6, 5, 9, 9
    b, x0, _ = plane_scene_mosaic(rng, S, T, U, V, noise=0.02)
    disparity, _ = maps(rng, S, T, spread=0.8)
    params = AdmmParams(lam=0.01, lam_xc=0.01, rho=0.3, max_iter=200, change_tol=2e-4)
    expected = epi_pd_reference(b, "GRBG", (U, V), params, x0, EpiPrior(disparity))
    got = EpiPdSolver(runtime, b.shape, "GRBG", (U, V)).solve(runtime.to_device(b), runtime.to_device(x0), params,
                                                              EpiPrior(disparity))
    assert 3 < got.iterations == expected.iterations < 200
    assert got.stop_reason.startswith("rms change")


@pytest.mark.parametrize("cross, fallback", [(False, False), (True, False), (True, True)])
def test_step_sizes_meet_the_convergence_condition(rng, cross, fallback):
    """||Sigma^(1/2) K T^(1/2)|| <= 1 (Pock & Chambolle 2011) with the solver's sigma and tau, for any rho, on the
    stacked K = [D; D C; D_fb] as a dense matrix; the row bound is nearly reached (the steps are not timid)."""
    S, T, U, V = 3, 3, 3, 3
    disparity, confidence = maps(rng, S, T, spread=2.0)
    disparity[1, 1] = 0.5  # the fraction where the Catmull-Rom taps' absolute weights sum to the most
    w = confidence if fallback else None
    D = epi_matrix_np(disparity, (U, V), w).toarray()
    n = D.shape[1]
    eye = np.eye(3)
    C = np.array([[1.0, -1.0, 0.0], [0.0, -1.0, 1.0]])
    for rho in (0.05, 1.0, 7.0):
        sigma, sigma_x, sigma_fb = _sigmas(rho, w)
        rows = [np.kron(eye, D)]
        sig = [np.full(3 * D.shape[0], sigma)]
        if cross:
            rows.append(np.kron(C, D))
            sig.append(np.full(2 * D.shape[0], sigma_x))
        if fallback:
            F = epi_matrix_np(np.zeros_like(disparity), (U, V), 1 - confidence).toarray()
            rows.append(np.kron(eye, F))
            sig.append(np.full(3 * F.shape[0], sigma_fb))
        K = np.vstack(rows)
        tau = 1.0 / (rho * np.abs(K).sum(axis=0))
        assert np.all(np.isfinite(tau))
        scaled = np.sqrt(np.concatenate(sig))[:, None] * K * np.sqrt(tau)[None, :]
        assert np.linalg.norm(scaled, 2) <= 1.0 + 1e-9
        # tau as the solver builds it: the column sums of |D| times (1 + the column sums of |C|) per colour
        columns = np.abs(D).sum(axis=0)
        by_colour = np.concatenate([columns * (1.0 + (CROSS_COLUMNS[c] if cross else 0.0)) for c in range(3)])
        if fallback:
            by_colour = by_colour + np.tile(np.abs(F).sum(axis=0), 3)
        np.testing.assert_allclose(1.0 / (rho * by_colour), tau, rtol=1e-12)
    assert n == S * U * T * V


def test_twin_reaches_the_minimum_admm_reaches(rng):
    """Both methods solve one problem: run long, their objectives agree (to the few 1e-6 neither has converged
    further) and perturbations only raise the primal-dual answer's."""
    S, T, U, V = 3, 3, 3, 3
    b, x0, _ = plane_scene_mosaic(rng, S, T, U, V, noise=0.05)
    disparity, confidence = maps(rng, S, T, spread=0.8)
    lam, lam_xc, lam_fb = 0.02, 0.01, 0.01
    prior = EpiPrior(disparity, confidence, lam_fb=lam_fb)

    def objective(x):
        return (0.5 * np.sum((cfa_sample_np(x, "GRBG") - b) ** 2)
                + lam * np.abs(epi_gradient_np(x, disparity, (U, V), confidence)).sum()
                + lam_xc * np.abs(epi_cross_gradient_np(x, disparity, (U, V), confidence)).sum()
                + lam_fb * np.abs(epi_gradient_np(x, np.zeros_like(disparity), (U, V), 1 - confidence)).sum())

    pd = epi_pd_reference(b, "GRBG", (U, V), AdmmParams(lam=lam, lam_xc=lam_xc, rho=1.0, max_iter=6000), x0, prior)
    admm = admm_epi_reference(b, "GRBG", (U, V), AdmmParams(lam=lam, lam_xc=lam_xc, rho=1.0, max_iter=600,
                                                            cg_steps=40, cg_tol=1e-13), x0, prior)
    best = objective(admm.x)
    assert objective(pd.x) == pytest.approx(best, rel=2e-5)
    for _ in range(30):
        assert objective(pd.x + 1e-3 * rng.standard_normal(pd.x.shape)) >= objective(pd.x) - 1e-9


def test_bad_parameters_are_refused(runtime):
    solver = EpiPdSolver(runtime, (18, 18), "GRBG", (9, 9))
    b, x0 = runtime.zeros((18, 18)), runtime.zeros((3, 18, 18))
    prior = EpiPrior(np.zeros((2, 2), np.float32))
    with pytest.raises(ValueError, match="lam must be > 0"):
        solver.solve(b, x0, AdmmParams(lam=0.0, rho=1.0), prior)
    with pytest.raises(ValueError, match="whole number"):
        EpiPdSolver(runtime, (18, 17), "GRBG", (9, 9))
