"""The numpy reference ADMM: the paper's updates written plainly, in float64.

It is the yardstick for the OpenCL solver (lfcl/solvers/admm.py): same
parameters, same warm-started Jacobi-preconditioned CG, same stopping rule, and
the tests require both to agree on small light fields. It is slow on purpose:
no fused kernels, every operator applied as written.

    min_x 1/2 ||A x - b||^2 + lam ||D x||_1,   split as  D x = z  (paper, 3.4)

    x <- (A^T A + rho D^T D)^{-1} (A^T b + rho D^T (z - u))
    z <- S_{lam/rho}(D x + u)
    u <- u + D x - z
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ..ops.cfa import cfa_adjoint_np, cfa_sample_np
from ..ops.crosschannel import COLOUR_GRAM, stacked_prior_np
from ..ops.gradient import gradient_adjoint_np, gradient_np, linked_count_np
from ..ops.lensfill import lens_fill_np
from .params import AdmmParams, AdmmResult, IterationRecord, extrapolate, stop_reason


def neighbour_count(planes_shape, pitch, dims) -> np.ndarray:
    """diag(D^T D): per sample, how many neighbours it has along the chosen dims."""
    C, H, W = planes_shape
    U, V = pitch
    shape5 = (C, H // U, U, W // V, V)
    count = np.zeros(shape5)
    for d in dims:
        axis = {"s": 1, "u": 2, "t": 3, "v": 4}[d]
        n = shape5[axis]
        along = np.full(n, 2.0)
        along[0] -= 1
        along[-1] -= 1
        if n == 1:
            along[:] = 0
        view = [1] * 5
        view[axis] = n
        count = count + along.reshape(view)
    return count.reshape(planes_shape)


def conjugate_gradient(apply, rhs, x, precondition, max_steps, tol):
    """Preconditioned CG from the warm start ``x``; returns (x, steps taken)."""
    r = rhs - apply(x)
    z = precondition(r)
    p = z.copy()
    rz = float(np.vdot(r, z))
    rhs_norm = math.sqrt(float(np.vdot(rhs, rhs)))
    steps = 0
    for steps in range(max_steps):
        if math.sqrt(float(np.vdot(r, r))) <= tol * rhs_norm or rz == 0:
            return x, steps
        q = apply(p)
        alpha = rz / float(np.vdot(p, q))
        x = x + alpha * p
        r = r - alpha * q
        z = precondition(r)
        rz_next = float(np.vdot(r, z))
        p = z + (rz_next / rz) * p
        rz = rz_next
    return x, max_steps


def admm_reference(b, pattern, pitch, dims, params: AdmmParams, x0, origin=(0, 0), lens_weights=None) -> AdmmResult:
    """Solve the paper's problem for mosaic ``b`` [H, W] from the start ``x0`` [3, H, W].

    ``lens_weights`` [U, V] weight the data term, 1/2 ||W^(1/2) (A x - b)||^2, with the
    same weights under every lens (None: the paper's unweighted term).
    ``params.lam_xc > 0`` adds the cross-channel prior lam_xc ||D C x||_1: K = [D; D C].
    A pixel of weight 0 is left out of the prior too: K = M D (M D C), M dropping the
    differences that touch it (docs/admm.md); its CG row is 0, so it keeps x0 until the
    end, and then gets the harmonic extension of its lens (lfcl/ops/lensfill.py).
    """
    b = np.asarray(b, dtype=np.float64)
    U, V = pitch
    lens_w = np.ones((U, V)) if lens_weights is None else np.asarray(lens_weights, dtype=np.float64)
    w = np.tile(lens_w, (b.shape[0] // U, b.shape[1] // V))  # per sensor pixel
    x0 = np.asarray(x0, dtype=np.float64)
    mask = lens_w if (lens_w <= 0).any() else None
    prior, prior_adjoint, prior_weights = (lambda v: gradient_np(v, pitch, dims, mask),
                                           lambda z: gradient_adjoint_np(z, pitch, dims, mask), 1.0)
    links = linked_count_np(x0.shape, pitch, dims, mask)  # diag(K^T K)
    if params.cross_channel:  # per-entry weights lam, lam_xc carry both thresholds
        prior, prior_adjoint, split = stacked_prior_np(x0.shape, pitch, dims, mask)
        prior_weights = np.where(np.arange(split + split * 2 // 3) < split, params.lam, params.lam_xc)
        params = dataclasses.replace(params, lam=1.0)
        links = links * (1 + np.diag(COLOUR_GRAM))[:, None, None]
    diagonal = cfa_adjoint_np(w, pattern, origin) + params.rho * links
    result = admm_operators(
        b, x0, params, w,
        forward=lambda v: cfa_sample_np(v, pattern, origin),
        adjoint=lambda r: cfa_adjoint_np(r, pattern, origin),
        prior=prior, prior_adjoint=prior_adjoint, diagonal=diagonal, prior_weights=prior_weights,
    )
    if mask is not None:
        result.x = lens_fill_np(result.x, mask, pitch)
    return result


def admm_operators(b, x0, params: AdmmParams, data_weights, *, forward, adjoint, prior, prior_adjoint,
                   diagonal=None, prior_weights=1.0, proximal: float = 0.0, precondition=None) -> AdmmResult:
    """Scaled-form ADMM for ``min_x 1/2 ||W^(1/2) (A x - b)||^2 + lam sum(w_K |K x|)`` in float64.

    The generic core of the reference solvers: ``forward``/``adjoint`` are A and A^T,
    ``prior``/``prior_adjoint`` are K and K^T (D, or D stacked with other linear
    terms), ``data_weights`` W (broadcast against b), ``prior_weights`` w_K (broadcast
    against K x; each entry's shrinkage threshold is w_K * lam / rho), ``diagonal``
    the diagonal of A^T W A + rho K^T K (the Jacobi preconditioner; entries <= 0 are
    left unpreconditioned as 0). The x-update is warm-started Jacobi-PCG. ``proximal`` > 0 adds
    ``proximal/2 ||x - x_k||^2`` to the x-update (proximal ADMM; the same fixed point), and to its diagonal.
    ``precondition(r)``, if given, replaces the Jacobi preconditioner (it must include ``proximal`` itself; no
    ``diagonal`` then). ``params.extrapolation`` = beta: from the second x-update on, CG starts from
    ``x_k + beta (x_k - x_{k-1})`` (the proximal term's anchor stays x_k), unless the last iteration changed x more
    than the one before (lfcl.solvers.params.extrapolate).
    """
    b = np.asarray(b, dtype=np.float64)
    x = np.array(x0, dtype=np.float64)
    rho = params.rho
    thresholds = params.kappa * np.asarray(prior_weights, dtype=np.float64)

    def normal(v):
        return adjoint(data_weights * forward(v)) + rho * prior_adjoint(prior(v)) + proximal * v

    if precondition is None:
        diagonal = np.asarray(diagonal, dtype=np.float64) + proximal
        inverse_diagonal = np.divide(1.0, diagonal, out=np.zeros_like(diagonal), where=diagonal > 0)

        def precondition(r):
            return inverse_diagonal * r

    Atb = adjoint(data_weights * b)
    z = prior(x)
    u = np.zeros_like(z)
    history = []
    x_older = None
    while True:
        step = params.extrapolation if x_older is not None and extrapolate(history) else 0.0
        warm = x + step * (x - x_older) if step else x
        x_next, steps = conjugate_gradient(
            normal, Atb + rho * prior_adjoint(z - u) + proximal * x, warm, precondition, params.cg_steps,
            params.cg_tol
        )
        dx = prior(x_next)
        v = dx + u
        z_next = np.sign(v) * np.maximum(np.abs(v) - thresholds, 0.0)
        u = v - z_next
        record = IterationRecord(
            iteration=len(history) + 1,
            objective=0.5 * float(np.sum(data_weights * (forward(x_next) - b) ** 2))
            + params.lam * float(np.sum(np.asarray(prior_weights) * np.abs(dx))),
            primal_residual=float(np.linalg.norm(dx - z_next)),
            dual_residual=rho * float(np.linalg.norm(prior_adjoint(z_next - z))),
            rms_change=float(np.sqrt(np.mean((x_next - x) ** 2))),
            cg_steps=steps,
        )
        history.append(record)
        primal_scale = max(float(np.linalg.norm(dx)), float(np.linalg.norm(z_next)))
        dual_scale = rho * float(np.linalg.norm(prior_adjoint(u)))
        x_older, x, z = x, x_next, z_next
        reason = stop_reason(params, record, primal_scale, dual_scale, z.size, x.size)
        if reason:
            return AdmmResult(x=x, history=history, stop_reason=reason)


def admm_resampled_reference(b, weights, matrix, shape, dims, params: AdmmParams, x0) -> AdmmResult:
    """The float64 twin of lfcl/solvers/resampled.py: ``A`` a sparse matrix.

    ``matrix`` maps the regular planes ``[3, S*U, T*V]`` (``shape = (S, T, U, V)``)
    flattened onto the measured pixels (lfcl/grid/resampling.py ``forward_matrix``);
    ``b`` and ``weights`` are per measured pixel; ``x0`` the start planes.
    """
    import scipy.sparse

    A = scipy.sparse.csr_matrix(matrix, dtype=np.float64)
    S, T, U, V = shape
    planes_shape = (3, S * U, T * V)
    w = np.asarray(weights, dtype=np.float64)
    diagonal = (np.asarray(A.multiply(A).T @ w).reshape(planes_shape)
                + params.rho * neighbour_count(planes_shape, (U, V), dims))
    return admm_operators(
        b, x0, params, w,
        forward=lambda v: A @ v.ravel(),
        adjoint=lambda r: (A.T @ r).reshape(planes_shape),
        prior=lambda v: gradient_np(v, (U, V), dims),
        prior_adjoint=lambda z: gradient_adjoint_np(z, (U, V), dims),
        diagonal=diagonal,
    )
