"""Warm-started Jacobi-preconditioned conjugate gradients on device arrays (the ADMM x-update).

Shared by the aligned solver (lfcl/solvers/admm.py) and the resampled one
(lfcl/solvers/resampled.py); the float64 twin is lfcl/solvers/reference.py
``conjugate_gradient``.
"""

from __future__ import annotations


def preconditioned_cg(vec, red, apply, precondition, x, rhs, buffers, max_steps: int, tol: float,
                      residual_ready: bool = False, fused=None) -> int:
    """Solve ``apply(x) = rhs`` in place from the warm start ``x``; returns the steps taken.

    ``apply(src, out)`` and ``precondition(src, out)`` write into ``out``; ``vec`` and
    ``red`` are the VectorOps and Reductions of the runtime; ``buffers`` four arrays
    shaped like ``x`` (r, P r, p, q). Stops when ``||r|| <= tol ||rhs||`` or after
    ``max_steps``. One host round trip per reduction point: (r.Pr, |r|^2) together.
    With ``residual_ready`` the caller has put ``rhs - M x`` in r (a caller that carries it
    saves the product M x); afterwards r holds the final residual (CG's recurrence).

    ``fused``, if given, does a step's work in fewer passes over the vectors: ``fused.apply_dot(p, q)``
    writes ``q = M p`` and returns ``<p, q>``; ``fused.update(alpha, x, p, r, q, pz)`` does ``x += alpha p``,
    ``r -= alpha q``, ``pz = P r`` and returns ``(<r, pz>, |r|^2)`` (lfcl/solvers/epi.py EpiAdmmSolver).
    """
    r, pz, p, q = buffers
    if not residual_ready:
        apply(x, q)
        vec.axpby(1.0, rhs, -1.0, q, r)  # r = rhs - M x
    precondition(r, pz)
    vec.copy(pz, p)
    rz, r2, rhs2 = red.many(("dot", r, pz), ("norm2", r), ("norm2", rhs))
    threshold2 = tol * tol * rhs2
    for step in range(max_steps):
        if r2 <= threshold2 or rz == 0:
            return step
        if fused is not None:
            alpha = rz / fused.apply_dot(p, q)
            rz_next, r2 = fused.update(alpha, x, p, r, q, pz)
        else:
            apply(p, q)
            alpha = rz / red.dot(p, q)
            vec.axpby(1.0, x, alpha, p, x)
            vec.axpby(1.0, r, -alpha, q, r)
            precondition(r, pz)
            rz_next, r2 = red.many(("dot", r, pz), ("norm2", r))
        vec.axpby(1.0, pz, rz_next / rz, p, p)
        rz = rz_next
    return max_steps
