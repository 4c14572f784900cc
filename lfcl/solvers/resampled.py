"""ADMM-TV on the regular light field of any lens grid, with the resampling inside the forward operator.

The problem of lfcl/solvers/admm.py (paper, section 3.4), but ``A`` now maps the
regular light field ``x`` (planes ``[3, S*U, T*V]``, lfcl/grid/resampling.py) onto
the *measured sensor pixels* of a rotated, non-integer-pitch or hexagonal grid:
``A = CFA-pick(R x)`` with ``R`` bilinear within each lens, a sparse matrix::

    min_x 1/2 ||W^(1/2) (A x - b)||^2 + lam ||D x||_1

``b`` the flat-fielded raw at the measured pixels, ``W`` their white response
squared, ``D`` forward differences over the chosen dims of (u, v, s, t) on the
regular grid (lfcl/ops/gradient.py, unchanged). Scaled-form ADMM with ``z = D x``:

    x <- (A^T W A + rho D^T D)^{-1} (A^T W b + rho D^T (z - u))   Jacobi-PCG, warm-started
    z <- S_{lam/rho}(D x + u)
    u <- u + D x - z

``A`` and ``A^T`` are CSR gathers (lfcl/ops/resample.py). Unlike the aligned
grid, ``A^T W A`` differs from lens to lens, so the x-update is always CG (no
exact per-lens solve). Same parameters, history and stopping rule as the aligned
solver; the float64 twin is :func:`lfcl.solvers.reference.admm_resampled_reference`.

Example::

    >>> import numpy as np, scipy.sparse
    >>> from lfcl.device import get_runtime
    >>> from lfcl.solvers.params import AdmmParams
    >>> rt = get_runtime()
    >>> A = scipy.sparse.eye(10, 3 * 2 * 2 * 2 * 2, format="csr")  # 10 pixels, 2x2 lenses of 2x2 views
    >>> solver = ResampledAdmmSolver(rt, A, (2, 2, 2, 2), "uv")
    >>> b = rt.to_device(np.full(10, 0.5, np.float32))
    >>> w = rt.to_device(np.ones(10, np.float32))
    >>> x0 = rt.to_device(np.full((3, 4, 4), 0.5, np.float32))
    >>> solver.solve(b, w, x0, AdmmParams(lam=0.01, max_iter=2)).iterations
    2
"""

from __future__ import annotations

import hashlib
import math

import numpy as np
import scipy.sparse

from ..layout import LightFieldShape, ordered_dims
from ..ops import check_device_array
from ..ops.gradient import Gradient
from ..ops.linalg import VectorOps
from ..ops.reduce import Reductions
from ..ops.resample import SparseOperator, multiply
from ..ops.shrink import Shrinkage
from .cg import preconditioned_cg
from .params import AdmmParams, AdmmResult, IterationRecord, stop_reason
from .reference import neighbour_count


def normal_diagonal(matrix, weights, planes_shape, pitch, dims, rho: float) -> np.ndarray:
    """diag(A^T W A + rho D^T D) in float64, shaped like the planes: the Jacobi preconditioner."""
    A = scipy.sparse.csr_matrix(matrix)
    data_part = np.asarray(A.multiply(A).T @ np.asarray(weights, np.float64)).ravel()
    return data_part.reshape(planes_shape) + rho * neighbour_count(planes_shape, pitch, dims)


def resampled_solver_bytes(n_pixels: int, nnz: int, shape, dims) -> int:
    """Device memory a :class:`ResampledAdmmSolver` needs with its start, bytes (A and A^T included)."""
    S, T, U, V = shape
    planes = 3 * S * T * U * V
    k = len(ordered_dims(dims))
    floats = 11 * planes + 5 * k * planes + 5 * n_pixels  # x, x0, prev, rhs, AtWb, diag, tmp, CG r/Pr/p/q
    return 4 * floats + 2 * (8 * nnz + 4 * (n_pixels + planes))  # + two CSR copies


class ResampledAdmmSolver:
    """ADMM-TV for one forward matrix ``A`` (``[n_pixels, 3 S U T V]``), light-field shape and dims.

    ``shape``: ``(S, T, U, V)`` of the regular light field. Build once per
    calibration and call :meth:`solve` for each capture.
    """

    def __init__(self, runtime, matrix, shape, dims):
        self.runtime = runtime
        self.shape = LightFieldShape(*(int(n) for n in shape))
        self.planes_shape = self.shape.planes_shape
        self.pitch = (self.shape.U, self.shape.V)
        self.dims = ordered_dims(dims)
        matrix = scipy.sparse.csr_matrix(matrix)
        if matrix.shape[1] != int(np.prod(self.planes_shape)):
            raise ValueError(f"the forward matrix has {matrix.shape[1]} columns, the light field "
                             f"{self.planes_shape} needs {int(np.prod(self.planes_shape))}")
        self.n_pixels = int(matrix.shape[0])
        self.matrix = matrix
        self.A = SparseOperator(runtime, matrix, in_shape=self.planes_shape, out_shape=(self.n_pixels,))
        self.D = Gradient(runtime, self.planes_shape, self.pitch, self.dims)
        self.vectors = VectorOps(runtime)
        self.reduce = Reductions(runtime)
        self.shrink = Shrinkage(runtime)
        planes = [runtime.empty(self.planes_shape) for _ in range(8)]
        self._x_prev, self._rhs, self._tmp, self._atwb, self._inverse_diagonal = planes[:5]
        self._cg = planes[5:] + [runtime.empty(self.planes_shape)]  # r, P r, p, q
        grads = [runtime.empty(self.D.gradient_shape) for _ in range(4)]
        self._z, self._u, self._dx, self._dz = grads
        self._pixels = [runtime.empty((self.n_pixels,)) for _ in range(2)]  # W A p, the weighted residual
        self._weights = self._sqrt_weights = None
        self._diagonal_key = None

    # --- operators -------------------------------------------------------------------
    def normal(self, x, out, rho):
        """out = (A^T W A + rho D^T D) x."""
        self.A.forward_scaled(x, self._weights, out=self._pixels[0])
        self.D.gram(x, out=out)
        return self.A.adjoint_add(self._pixels[0], out, rho, out=out)

    def _set_data(self, b, weights, rho):
        """Weights, sqrt(weights), A^T W b and the Jacobi preconditioner for this data and rho."""
        check_device_array(b, (self.n_pixels,), "b")
        check_device_array(weights, (self.n_pixels,), "weights")
        host_weights = weights.get()
        if not np.all(np.isfinite(host_weights)) or host_weights.min(initial=0) < 0:
            raise ValueError("the data-term weights must be finite and non-negative")
        self._weights = weights
        self._sqrt_weights = self.runtime.to_device(np.sqrt(host_weights))
        self.A.adjoint(multiply(self.runtime, b, weights, out=self._pixels[1]), out=self._atwb)  # A^T W b
        key = (rho, hashlib.blake2b(host_weights).digest())
        if key != self._diagonal_key:
            diagonal = normal_diagonal(self.matrix, host_weights, self.planes_shape, self.pitch, self.dims, rho)
            inverse = np.divide(1.0, diagonal, out=np.zeros_like(diagonal), where=diagonal > 0)
            self._inverse_diagonal.set(inverse.astype(np.float32))
            self._diagonal_key = key

    def _precondition(self, r, out):
        multiply(self.runtime, r, self._inverse_diagonal, out=out)

    def _conjugate_gradient(self, x, rhs, rho, max_steps, tol) -> int:
        """Warm-started Jacobi-PCG on x in place (lfcl/solvers/cg.py); returns the steps taken."""
        return preconditioned_cg(self.vectors, self.reduce, lambda src, out: self.normal(src, out, rho),
                                 self._precondition, x, rhs, self._cg, max_steps, tol)

    def solve(self, b, weights, x0, params: AdmmParams, callback=None) -> AdmmResult:
        """ADMM from ``x0`` [3, S*U, T*V] for the measurements ``b`` and ``weights`` [n_pixels] (device arrays).

        ``x0`` is not modified. ``callback(record, x)`` after every iteration.
        ``params.x_update`` "lens" is refused (no exact per-lens solve here).
        """
        if params.x_update == "lens":
            raise ValueError("x_update 'lens' needs an aligned grid: a resampled grid uses CG")
        if getattr(params, "cross_channel", False):
            raise ValueError("the cross-channel prior (lam_xc > 0) is not implemented for resampled grids")
        if params.extrapolation:
            raise ValueError("the extrapolated warm start (extrapolation > 0) is admm-epi's (lfcl/solvers/epi.py)")
        check_device_array(x0, self.planes_shape, "x0")
        rho, lam = params.rho, params.lam
        self._set_data(b, weights, rho)
        vec, red, D = self.vectors, self.reduce, self.D
        x = x0.copy()
        D.forward(x, out=self._z)
        self.vectors.zero(self._u)
        n_x, n_z = x.size, self._z.size
        history: list[IterationRecord] = []
        while True:
            vec.copy(x, self._x_prev)
            vec.axpby(1.0, self._z, -1.0, self._u, self._dz)  # z - u
            D.adjoint(self._dz, out=self._tmp)
            vec.axpby(1.0, self._atwb, rho, self._tmp, self._rhs)
            steps = self._conjugate_gradient(x, self._rhs, rho, params.cg_steps, params.cg_tol)
            D.forward(x, out=self._dx)
            self.shrink.zu_update(self._dx, self._z, self._u, self._dz, params.kappa)
            D.adjoint(self._dz, out=self._tmp)
            self.A.residual(x, b, self._sqrt_weights, out=self._pixels[1])
            primal2, dual2, misfit2, tv, change2 = red.many(
                ("diff_norm2", self._dx, self._z), ("norm2", self._tmp), ("norm2", self._pixels[1]),
                ("abs_sum", self._dx), ("diff_norm2", x, self._x_prev),
            )
            record = IterationRecord(
                iteration=len(history) + 1,
                objective=0.5 * misfit2 + lam * tv,
                primal_residual=math.sqrt(primal2),
                dual_residual=rho * math.sqrt(dual2),
                rms_change=math.sqrt(change2 / n_x),
                cg_steps=steps,
            )
            history.append(record)
            if callback is not None:
                callback(record, x)
            primal_scale = dual_scale = 0.0
            if params.abs_tol > 0 or params.rel_tol > 0:
                primal_scale = math.sqrt(max(red.norm2(self._dx), red.norm2(self._z)))
                D.adjoint(self._u, out=self._tmp)
                dual_scale = rho * math.sqrt(red.norm2(self._tmp))
            reason = stop_reason(params, record, primal_scale, dual_scale, n_z, n_x)
            if reason:
                return AdmmResult(x=x, history=history, stop_reason=reason)
