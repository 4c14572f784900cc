"""ADMM-TV demosaicing/denoising of a lenslet mosaic on an OpenCL device.

Solves the paper's problem (section 3.4) over the sensor-shaped planes of
docs/layout.md::

    min_x 1/2 ||A x - b||^2 + lam ||D x||_1

with A the CFA sampling, D forward differences over the chosen dims of
(u, v, s, t), per channel (anisotropic TV). Scaled-form ADMM with z = D x:

    x <- (A^T A + rho D^T D)^{-1} (A^T b + rho D^T (z - u))   Jacobi-PCG, warm-started,
                                                               or exact per lens for (u, v)
    z <- S_{lam/rho}(D x + u)                                  soft-thresholding
    u <- u + D x - z                                           scaled dual update

The start x0 is normally the Malvar demosaic, z0 = D x0 and u0 = 0. It stops
on the primal/dual residuals (Boyd et al.), on the rms change of x, or after
max_iter; the history of objective and residuals is returned. The numpy twin is
lfcl/solvers/reference.py; both take the same AdmmParams.

Example::

    >>> import numpy as np
    >>> from lfcl.device import get_runtime
    >>> from lfcl.solvers.admm import AdmmSolver
    >>> from lfcl.solvers.params import AdmmParams
    >>> rt = get_runtime()
    >>> solver = AdmmSolver(rt, (18, 18), "GRBG", (9, 9), "uv")
    >>> b = rt.to_device(np.full((18, 18), 0.5, np.float32))
    >>> x0 = rt.to_device(np.full((3, 18, 18), 0.5, np.float32))
    >>> result = solver.solve(b, x0, AdmmParams(lam=0.01, max_iter=3))
    >>> result.iterations, result.x.shape
    (3, (3, 18, 18))
"""

from __future__ import annotations

import functools
import math

import numpy as np

from ..device import grid_defines
from ..layout import channel_map, dims_mask, ordered_dims, packed_pattern
from ..ops import check_device_array
from ..ops.cfa import CfaSampling
from ..ops.gradient import Gradient, gradient_gram_np
from ..ops.linalg import VectorOps
from ..ops.reduce import Reductions
from ..ops.shrink import Shrinkage
from .params import AdmmParams, AdmmResult, IterationRecord, stop_reason


@functools.lru_cache(maxsize=8)
def _lens_laplacian(pitch) -> np.ndarray:
    """D_uv^T D_uv of one lens as a UV x UV matrix, column by column from unit vectors."""
    U, V = pitch
    eye = np.eye(U * V)
    return np.stack([gradient_gram_np(eye[j].reshape(1, U, V), (U, V), "uv").ravel() for j in range(U * V)], axis=1)


@functools.lru_cache(maxsize=16)
def lens_block_inverses(pattern: str, origin, pitch, rho: float, lens_weights: tuple | None = None) -> np.ndarray:
    """(A^T W A + rho D_uv^T D_uv)^-1 restricted to one lens: [4 parities, 3 colours, UV, UV].

    ``lens_weights``: the data-term weight of each of the lens's UV pixels (row-major
    tuple, hashable for the cache); None for all ones.

    Parity 2*ps + pt: the Bayer parity (row, col) of the lens's first sensor pixel. A
    block is symmetric positive definite when the lens has a pixel of that colour; a
    colour no pixel of the lens measures (a 1-pixel lens) gets the pseudo-inverse.
    Cached: every solver of the same camera and rho shares them (read-only).
    """
    U, V = pitch
    laplacian = _lens_laplacian((U, V))
    weights = np.ones(U * V) if lens_weights is None else np.asarray(lens_weights, dtype=np.float64)
    blocks = np.empty((4, 3, U * V, U * V), np.float32)
    for ps in range(2):
        for pt in range(2):
            colours = channel_map((U, V), pattern, (origin[0] + ps, origin[1] + pt)).ravel()
            for c in range(3):
                measured = (colours == c) * weights
                normal = np.diag(measured) + rho * laplacian
                try:
                    inverse = np.linalg.inv(normal) if measured.any() else np.linalg.pinv(normal)
                except np.linalg.LinAlgError:
                    inverse = np.linalg.pinv(normal, hermitian=True)
                blocks[2 * ps + pt, c] = inverse
    blocks.setflags(write=False)
    return blocks


def solver_bytes(sensor_shape, dims, exact: bool) -> int:
    """Device memory an AdmmSolver.solve needs, with its Malvar start and mosaic (bytes)."""
    H, W = (int(n) for n in sensor_shape)
    planes = 3 * H * W
    k = len(ordered_dims(dims))
    floats = (5 if exact else 9) * planes + 4 * k * planes + 2 * H * W  # planes, CG, z/u/Dx/dz, b and A x
    return 4 * floats


def solver_largest_buffer(sensor_shape, dims) -> int:
    """The solver's largest single buffer (one gradient: k colour-plane sets), bytes."""
    H, W = (int(n) for n in sensor_shape)
    return 4 * len(ordered_dims(dims)) * 3 * H * W


class AdmmSolver:
    """ADMM-TV for one sensor size, Bayer phase, lens pitch and set of dims.

    Build it once and call :meth:`solve` for each capture: the kernels and the
    work buffers are allocated here and reused.
    """

    def __init__(self, runtime, sensor_shape, pattern: str, pitch, dims, origin=(0, 0)):
        self.runtime = runtime
        self.height, self.width = (int(n) for n in sensor_shape)
        self.U, self.V = (int(p) for p in pitch)
        self.dims = ordered_dims(dims)
        self.planes_shape = (3, self.height, self.width)
        self.A = CfaSampling(runtime, sensor_shape, pattern, origin)
        self.D = Gradient(runtime, self.planes_shape, pitch, self.dims)
        self.vectors = VectorOps(runtime)
        self.reduce = Reductions(runtime)
        self.shrink = Shrinkage(runtime)
        self.pattern, self.origin = pattern, origin
        self._inverse = None  # per-lens inverse blocks, built for one rho and weights on first use
        self._unit_weights = tuple([1.0] * (self.U * self.V))
        self._weights_key = self._unit_weights
        self._weights = runtime.to_device(np.ones(self.U * self.V, np.float32))
        self._normal_args = (np.int32(self.height), np.int32(self.width), packed_pattern(pattern, origin))
        self._defines = grid_defines(pitch, dims_mask(self.dims))
        self._row_runs = ((self.width + 15) // 16, self.height, 3)  # stencils: 16 columns a work-item
        planes = [runtime.empty(self.planes_shape) for _ in range(3)]
        self._x_prev, self._rhs, self._tmp = planes
        self._cg_buffers = None  # r, P r, p, q: only the CG x-update needs them
        grads = [runtime.empty(self.D.gradient_shape) for _ in range(4)]
        self._z, self._u, self._dx, self._dz = grads
        self._mosaic = runtime.empty((self.height, self.width))

    # --- the x-update: (A^T A + rho D^T D) x = rhs by Jacobi-preconditioned CG ---

    # --- the fused steps, public so that benchmarks time exactly what the solver runs ---

    def normal(self, x, out, rho):
        """out = (A^T A + rho D^T D) x."""
        return self._launch("normal_apply", x, out, rho)

    def precondition(self, r, out, rho):
        """out = r / diag(A^T A + rho D^T D) (Jacobi)."""
        return self._launch("jacobi_apply", r, out, rho)

    def right_hand_side(self, b, z, u, out, rho):
        """out = A^T b + rho D^T (z - u)."""
        self.runtime.launch(
            "admm", "build_rhs", self._row_runs, b.data, z.data, u.data, out.data,
            *self._normal_args, np.float32(rho), self._weights.data, defines=self._defines,
        )
        return out

    def _launch(self, kernel, src, out, rho):
        self.runtime.launch(
            "admm", kernel, self._row_runs, src.data, out.data,
            *self._normal_args, np.float32(rho), self._weights.data, defines=self._defines,
        )
        return out

    def _every_lens_sees_every_colour(self) -> bool:
        """Whether every lens has a weighted sample of each colour, whatever its Bayer parity.

        If not, that colour's block is singular (its constant part is free) and the
        exact solve would zero it, while CG keeps the warm start's: CG is used then.
        """
        weights = np.asarray(self._weights_key).reshape(self.U, self.V) > 0
        for ps in range(2):
            for pt in range(2):
                colours = channel_map((self.U, self.V), self.pattern, (self.origin[0] + ps, self.origin[1] + pt))
                if any(not np.any((colours == c) & weights) for c in range(3)):
                    return False
        return True

    def _uses_lens_solve(self, params: AdmmParams) -> bool:
        if params.x_update == "lens":
            if self.dims != ("u", "v"):
                raise ValueError(f"x_update 'lens' needs a prior over (u, v) only, not {''.join(self.dims)}")
            if not self._every_lens_sees_every_colour():
                raise ValueError("x_update 'lens' needs every lens to measure every colour: with this pitch "
                                 "or these lens weights some lens has none of one colour (use 'cg' or 'auto')")
            return True
        return params.x_update == "auto" and self.dims == ("u", "v") and self._every_lens_sees_every_colour()

    def lens_solve(self, rhs, x, rho):
        """x = (A^T A + rho D_uv^T D_uv)^-1 rhs, exactly, lens by lens."""
        key = (rho, self._weights_key)
        if self._inverse is None or self._inverse[0] != key:
            weights = None if self._weights_key == self._unit_weights else self._weights_key
            blocks = lens_block_inverses(self.pattern, tuple(o % 2 for o in self.origin), (self.U, self.V),
                                         float(rho), weights)
            # the kernel reads block columns as float16 runs: transpose, pad i to 16
            UV = self.U * self.V
            padded = np.zeros((4, 3, UV, -(-UV // 16) * 16), np.float32)
            padded[..., :UV] = blocks.transpose(0, 1, 3, 2)
            self._inverse = (key, self.runtime.to_device(padded))
        self.runtime.launch(
            "admm", "lens_solve", (2 * -(-(self.width // self.V) // 4), self.height // self.U, 3),
            rhs.data, x.data, self._inverse[1].data, np.int32(self.height), np.int32(self.width),
            defines=self._defines,
        )

    def _conjugate_gradient(self, x, rhs, rho, max_steps, tol) -> int:
        """Warm-started PCG on x in place; returns the steps taken."""
        vec, red = self.vectors, self.reduce
        if self._cg_buffers is None:
            self._cg_buffers = [self.runtime.empty(self.planes_shape) for _ in range(4)]
        r, pz, p, q = self._cg_buffers
        self.normal(x, q, rho)
        vec.axpby(1.0, rhs, -1.0, q, r)  # r = rhs - M x
        self.precondition(r, pz, rho)
        vec.copy(pz, p)
        # one host round trip per reduction point: (r.Pr, |r|^2) together, |rhs|^2 with them
        rz, r2, rhs2 = red.many(("dot", r, pz), ("norm2", r), ("norm2", rhs))
        threshold2 = tol * tol * rhs2
        for step in range(max_steps):
            if r2 <= threshold2 or rz == 0:
                return step
            self.normal(p, q, rho)
            alpha = rz / red.dot(p, q)
            vec.axpby(1.0, x, alpha, p, x)
            vec.axpby(1.0, r, -alpha, q, r)
            self.precondition(r, pz, rho)
            rz_next, r2 = red.many(("dot", r, pz), ("norm2", r))
            vec.axpby(1.0, pz, rz_next / rz, p, p)
            rz = rz_next
        return max_steps

    def set_lens_weights(self, lens_weights=None):
        """Data-term weights of the U x V pixels of every lens (None: all ones).

        For an aligned grid the white image's response repeats from lens to lens;
        a weight of 0 leaves that pixel out of the data term (a dark, vignetted corner).
        """
        if lens_weights is None:
            weights = np.ones((self.U, self.V), np.float32)
        else:
            weights = np.asarray(lens_weights, dtype=np.float32)
            if weights.shape != (self.U, self.V) or not np.all(np.isfinite(weights)) or np.any(weights < 0):
                raise ValueError(f"lens weights must be a finite, non-negative {self.U}x{self.V} array, "
                                 f"got shape {weights.shape}")
        key = tuple(float(w) for w in weights.ravel())
        if key != self._weights_key:  # a blocking upload: only when the weights change
            self._weights_key = key
            self._weights.set(weights.ravel())

    def solve(self, b, x0, params: AdmmParams, callback=None, lens_weights=None) -> AdmmResult:
        """Run ADMM on mosaic ``b`` [H, W] from ``x0`` [3, H, W] (both float32 device arrays).

        ``x0`` is not modified; the result's ``x`` is a new device array.
        ``callback(record, x)`` is called after every iteration (progress bars,
        parameter sweeps); ``x`` is the current device array, not to be modified.
        ``lens_weights`` [U, V]: see :meth:`set_lens_weights`.
        """
        self.set_lens_weights(lens_weights)
        check_device_array(b, (self.height, self.width), "b")
        check_device_array(x0, self.planes_shape, "x0")
        rho, lam = params.rho, params.lam
        vec, red, D = self.vectors, self.reduce, self.D
        x = x0.copy()
        exact = self._uses_lens_solve(params)
        D.forward(x, out=self._z)
        self._u.fill(0)
        n_x, n_z = x.size, self._z.size
        history: list[IterationRecord] = []
        while True:
            vec.copy(x, self._x_prev)
            self.right_hand_side(b, self._z, self._u, self._rhs, rho)
            if exact:
                self.lens_solve(self._rhs, x, rho)
                steps = 0
            else:
                steps = self._conjugate_gradient(x, self._rhs, rho, params.cg_steps, params.cg_tol)
            D.forward(x, out=self._dx)
            self.shrink.zu_update(self._dx, self._z, self._u, self._dz, params.kappa)
            D.adjoint(self._dz, out=self._tmp)
            self.runtime.launch(  # W^(1/2) (A x - b)
                "admm", "weighted_residual", self._row_runs[:2], x.data, b.data, self._mosaic.data,
                *self._normal_args, self._weights.data, defines=self._defines,
            )
            # the whole history in one round trip to the host
            primal2, dual2, misfit2, tv, change2 = red.many(
                ("diff_norm2", self._dx, self._z), ("norm2", self._tmp), ("norm2", self._mosaic),
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
