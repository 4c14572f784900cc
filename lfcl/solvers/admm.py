"""ADMM-TV demosaicing/denoising of a lenslet mosaic on an OpenCL device.

Solves the paper's problem (section 3.4) over the sensor-shaped planes of
docs/layout.md::

    min_x 1/2 ||A x - b||^2 + lam ||D x||_1 (+ lam_xc ||D C x||_1)

with A the CFA sampling, D forward differences over the chosen dims of
(u, v, s, t), per channel (anisotropic TV), and optionally the cross-channel
prior on the colour differences C x = (x_R - x_G, x_B - x_G) (docs/admm.md).
Scaled-form ADMM with z = K x, K = D or [D; D C]:

    x <- (A^T A + rho K^T K)^{-1} (A^T b + rho K^T (z - u))   Jacobi-PCG, warm-started,
                                                               or exact per lens for (u, v)
    z <- S_{lam/rho}(K x + u)   (lam_xc/rho on the D C block)  soft-thresholding
    u <- u + K x - z                                           scaled dual update

With lens weights that leave dark pixels out of the data term, the prior leaves
them out too: K = M [D; D C], M dropping every difference that touches such a
pixel; they keep their start value during the iterations and get the harmonic
extension of their lens's lit pixels at the end (lfcl/ops/lensfill.py).

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
import pyopencl as cl
import scipy.ndimage

from ..device import grid_defines
from ..layout import channel_map, dims_mask, ordered_dims, packed_pattern
from ..ops import check_device_array, lens_weights_or_ones
from ..ops.cfa import CfaSampling
from ..ops.crosschannel import COLOUR_GRAM, CrossGradient
from ..ops.gradient import Gradient, gradient_gram_np
from ..ops.lensfill import LensFill
from ..ops.linalg import VectorOps
from ..ops.reduce import Reductions
from ..ops.shrink import Shrinkage
from .cg import preconditioned_cg
from .params import AdmmParams, AdmmResult, IterationRecord, stop_reason


@functools.lru_cache(maxsize=8)
def _lens_laplacian(pitch, active: tuple | None = None) -> np.ndarray:
    """D_uv^T D_uv of one lens as a UV x UV matrix, column by column from unit vectors.

    ``active`` (UV booleans): D_uv^T M D_uv, the differences between active pixels only.
    """
    U, V = pitch
    eye = np.eye(U * V)
    mask = None if active is None else np.reshape(active, (U, V)).astype(np.float64)
    return np.stack([gradient_gram_np(eye[j].reshape(1, U, V), (U, V), "uv", mask).ravel() for j in range(U * V)],
                    axis=1)


def lens_components_measure_every_colour(pattern: str, origin, pitch, lens_weights) -> bool:
    """Whether the lens x-update is regular: every part of a lens that the prior connects
    has a weighted sample of each colour, whatever the lens's Bayer parity.

    The (u, v) prior connects the pixels of weight > 0 that touch (4-neighbours); pixels of
    weight 0 are out of the solve. If some part lacks a colour, that colour's constant on it
    is free: the exact solve would zero it, while CG keeps the warm start's, so CG is used then.
    """
    U, V = pitch
    active = np.asarray(lens_weights, dtype=np.float64).reshape(U, V) > 0
    labels, parts = scipy.ndimage.label(active)
    for ps in range(2):
        for pt in range(2):
            colours = channel_map((U, V), pattern, (origin[0] + ps, origin[1] + pt))
            for part in range(1, parts + 1):
                inside = (labels == part) & active
                if any(not np.any((colours == c) & inside) for c in range(3)):
                    return False
    return True


def _inverse_on(normal: np.ndarray, rows: np.ndarray, regular: bool) -> np.ndarray:
    """The inverse of a symmetric block restricted to ``rows`` (zero elsewhere), or its
    pseudo-inverse when it is singular."""
    sub = normal[np.ix_(rows, rows)]
    try:
        inverse = np.linalg.inv(sub) if regular else np.linalg.pinv(sub, hermitian=True)
    except np.linalg.LinAlgError:
        inverse = np.linalg.pinv(sub, hermitian=True)
    full = np.zeros_like(normal)
    full[np.ix_(rows, rows)] = inverse
    return full


@functools.lru_cache(maxsize=16)
def lens_block_inverses(pattern: str, origin, pitch, rho: float, lens_weights: tuple | None = None,
                        cross_channel: bool = False) -> np.ndarray:
    """(A^T W A + rho K_uv^T K_uv)^-1 restricted to one lens, rows per output colour.

    K = D_uv: [4 parities, 3 colours, UV, UV], one independent block per colour.
    K = [D_uv; D_uv C] (``cross_channel``): K^T K = (I + C^T C) (x) D_uv^T D_uv couples the
    colours, so the lens's 3UV x 3UV inverse is split into its rows of each output
    colour: [4, 3, UV, 3UV], columns ordered (colour, u, v).

    ``lens_weights``: the data-term weight of each of the lens's UV pixels (row-major
    tuple, hashable for the cache); None for all ones. The prior keeps only differences
    between pixels of weight > 0 (K = M D_uv); pixels of weight 0 then have zero rows, are
    left out of the inverse (their rows and columns are 0) and the kernel leaves them unchanged.

    Parity 2*ps + pt: the Bayer parity (row, col) of the lens's first sensor pixel. A
    block is symmetric positive definite when the lens has a pixel of each colour it
    couples; a colour no pixel of the lens measures (a 1-pixel lens) gets the
    pseudo-inverse. Cached: every solver of the same camera and rho shares them (read-only).
    """
    U, V = pitch
    UV = U * V
    weights = np.ones(UV) if lens_weights is None else np.asarray(lens_weights, dtype=np.float64)
    active = weights > 0
    laplacian = _lens_laplacian((U, V), None if active.all() else tuple(active))
    blocks = np.empty((4, 3, UV, 3 * UV if cross_channel else UV), np.float32)
    coupling = np.eye(3) + COLOUR_GRAM
    for ps in range(2):
        for pt in range(2):
            colours = channel_map((U, V), pattern, (origin[0] + ps, origin[1] + pt)).ravel()
            measured = [(colours == c) * weights for c in range(3)]
            if cross_channel:
                normal = np.diag(np.concatenate(measured)) + rho * np.kron(coupling, laplacian)
                inverse = _inverse_on(normal, np.tile(active, 3), all(m.any() for m in measured))
                blocks[2 * ps + pt] = inverse.reshape(3, UV, 3 * UV)
                continue
            for c in range(3):
                normal = np.diag(measured[c]) + rho * laplacian
                blocks[2 * ps + pt, c] = _inverse_on(normal, active, measured[c].any())
    blocks.setflags(write=False)
    return blocks


def weight_runs_np(lens_weights: np.ndarray) -> np.ndarray:
    """The lens weights [U, V] as the admm kernels read them (admm.cl row_weights): for every
    lens row u and column phase p, the weights of the 16 columns from p on,
    ``runs[u, p, k] = w[u, (p + k) % V]``, float32 [U * V * 16]."""
    weights = np.asarray(lens_weights, dtype=np.float32)
    V = weights.shape[1]
    columns = (np.arange(V)[:, None] + np.arange(16)[None, :]) % V
    return np.ascontiguousarray(weights[:, columns].reshape(-1))


def solver_bytes(sensor_shape, dims, exact: bool, cross_channel: bool = False) -> int:
    """Device memory an AdmmSolver.solve needs, with its Malvar start and mosaic (bytes)."""
    H, W = (int(n) for n in sensor_shape)
    planes = 3 * H * W
    k = len(ordered_dims(dims))
    # planes: the start, x, rhs, tmp (+ the previous x and 4 CG vectors for the CG x-update); z/u/dz; b and the sums
    floats = (4 if exact else 9) * planes + 3 * k * planes + 2 * H * W
    if cross_channel:
        floats += 4 * k * 2 * H * W  # z/u/Dx/dz of the cross-channel block
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
        self.DC = CrossGradient(runtime, self.planes_shape, pitch, self.dims)
        self.fill = LensFill(runtime, self.planes_shape, pitch)
        self.vectors = VectorOps(runtime)
        self.reduce = Reductions(runtime)
        self.shrink = Shrinkage(runtime)
        self.pattern, self.origin = pattern, origin
        self._inverse = None  # per-lens inverse blocks, built for one rho and weights on first use
        self._unit_weights = tuple([1.0] * (self.U * self.V))
        self._weights_key = self._unit_weights
        self._weights = runtime.to_device(np.ones(self.U * self.V, np.float32))
        self._weight_runs = runtime.to_device(weight_runs_np(np.ones((self.U, self.V), np.float32)))
        self._normal_args = (np.int32(self.height), np.int32(self.width), packed_pattern(pattern, origin))
        self._grid_defines = grid_defines(pitch, dims_mask(self.dims))
        self._cross_channel = False  # K = [D; D C]: set per solve from params.lam_xc
        self._prior_mask = False  # K = M [D; D C]: some lens weight is 0 (set_lens_weights)
        self._exact = False  # the x-update: exact per lens, or CG (set by prepare())
        self._row_runs = ((self.width + 15) // 16, self.height, 3)  # stencils: 16 columns a work-item
        self._rhs, self._tmp = (runtime.empty(self.planes_shape) for _ in range(2))
        self._x_prev = None  # the CG x-update's previous x (the lens solve sums its own change)
        self._cg_buffers = None  # r, P r, p, q: only the CG x-update needs them
        # D x is computed where it is used (zu_step)
        self._z, self._u, self._dz = (runtime.empty(self.D.gradient_shape) for _ in range(3))
        self._cross_buffers = None  # zc, uc, D C x, dzc: only the cross-channel prior needs them
        # the history's per-row sums (admm.cl zu_step, dual_and_misfit) and per-work-item
        # squared updates of lens_solve, fetched in one copy per iteration
        self._rows = 3 * self.height
        self._lens_grid = (2 * -(-(self.width // self.V) // 4), self.height // self.U, 3)
        # lens_solve holds 2 (U V) floats per work-item in private arrays (22 KB at pitch 37). PoCL on a CPU runs a
        # work-group's work-items on one thread's stack and, left to choose, made groups large enough to overflow it
        # (a segmentation fault at pitch 13 from 64x64 lenses on); one work-item a group, as linear4d's kernel. Other
        # devices choose their own.
        self._lens_group = (1, 1, 1) if runtime.device.type & cl.device_type.CPU else None
        self._sums_host = np.empty(5 * self._rows + int(np.prod(self._lens_grid)), np.float32)
        self._sums = runtime.zeros(self._sums_host.shape)

    @property
    def _defines(self) -> tuple:
        """Build-time constants of the admm program: pitch, dims and the prior's blocks."""
        return (*self._grid_defines, ("CROSS_CHANNEL", int(self._cross_channel)),
                ("PRIOR_MASK", int(self._prior_mask)))

    @property
    def _links(self):
        """The table of kept differences the admm kernels read under PRIOR_MASK (else unused)."""
        return self.D.links.buffer(self._weights)

    def set_cross_channel(self, enabled: bool):
        """Stack the cross-channel block D C under D in K (solve() sets it from params.lam_xc)."""
        self._cross_channel = bool(enabled)
        if enabled and self._cross_buffers is None:
            self._cross_buffers = [self.runtime.empty(self.DC.gradient_shape) for _ in range(4)]

    # --- the x-update: (A^T W A + rho K^T K) x = rhs by Jacobi-preconditioned CG ---

    # --- the fused steps, public so that benchmarks time exactly what the solver runs ---

    def normal(self, x, out, rho):
        """out = (A^T W A + rho K^T K) x (K = M [D; D C] as set for the current solve)."""
        return self._launch("normal_apply", x, out, rho)

    def precondition(self, r, out, rho):
        """out = r / diag(A^T W A + rho K^T K) (Jacobi)."""
        return self._launch("jacobi_apply", r, out, rho)

    def right_hand_side(self, b, z, u, out, rho, residual_of=None):
        """out = A^T W b + rho K^T (z - u), or with ``residual_of`` (an x) that minus M x.

        With the cross-channel block, z and u are the pairs (z of D, z of D C), (u of D, u of D C).
        """
        x, flag = (residual_of, np.int32(1)) if residual_of is not None else (b, np.int32(0))
        if self._cross_channel:
            (z, zc), (u, uc) = z, u
            self.runtime.launch(
                "admm", "build_rhs_xc", self._row_runs, b.data, z.data, u.data, zc.data, uc.data, out.data,
                *self._normal_args, np.float32(rho), self._weight_runs.data, self._links.data, x.data, flag,
                defines=self._defines,
            )
            return out
        self.runtime.launch(
            "admm", "build_rhs", self._row_runs, b.data, z.data, u.data, out.data,
            *self._normal_args, np.float32(rho), self._weight_runs.data, self._links.data, x.data, flag,
            defines=self._defines,
        )
        return out

    def _launch(self, kernel, src, out, rho):
        self.runtime.launch(
            "admm", kernel, self._row_runs, src.data, out.data,
            *self._normal_args, np.float32(rho), self._weight_runs.data, self._links.data, defines=self._defines,
        )
        return out

    def zu_step(self, x, kappa):
        """z <- S_kappa(M D x + u), u <- M D x + u - z, dz <- z_new - z_old, with D x on the fly
        (admm.cl zu_step); leaves the row sums of the primal residual^2, TV and ||M D x||^2."""
        self.runtime.launch(
            "admm", "zu_step", (self.height, 3), x.data, self._z.data, self._u.data, self._dz.data,
            np.float32(kappa), np.int32(self.height), np.int32(self.width), self._links.data, self._sums.data,
            defines=self._defines,
        )

    def dual_and_misfit(self, x, b, accumulate: bool = False):
        """tmp (+)= D^T M dz, with the row sums of ||tmp||^2 and of the misfit ||W^(1/2) (A x - b)||^2
        (admm.cl dual_and_misfit)."""
        self.runtime.launch(
            "admm", "dual_and_misfit", (self.height, 3), self._dz.data, self._tmp.data, np.int32(bool(accumulate)),
            x.data, b.data, *self._normal_args, self._weight_runs.data, self._links.data, self._sums.data,
            defines=self._defines,
        )

    def _fetch_sums(self, with_change: bool) -> list[float]:
        """The history's sums from the device partials, each added in float64:
        (primal^2, TV, ||M D x||^2, dual^2 / rho^2, misfit^2[, change^2]); waits for the queue."""
        cl.enqueue_copy(self.runtime.queue, self._sums_host, self._sums.data, is_blocking=False)
        self.runtime.queue.finish()
        rows, host = self._rows, self._sums_host
        sums = [float(np.sum(host[k * rows:(k + 1) * rows], dtype=np.float64)) for k in range(5)]
        if with_change:
            sums.append(float(np.sum(host[5 * rows:], dtype=np.float64)))
        return sums

    def _every_lens_sees_every_colour(self) -> bool:
        """lens_components_measure_every_colour for this solver's weights."""
        return lens_components_measure_every_colour(self.pattern, self.origin, (self.U, self.V), self._weights_key)

    def _uses_lens_solve(self, params: AdmmParams) -> bool:
        if params.x_update == "lens":
            if self.dims != ("u", "v"):
                raise ValueError(f"x_update 'lens' needs a prior over (u, v) only, not {''.join(self.dims)}")
            if not self._every_lens_sees_every_colour():
                raise ValueError("x_update 'lens' needs every lens (every connected part of it, with dark "
                                 "pixels left out of the prior) to measure every colour: with this pitch or "
                                 "these lens weights some has none of one colour (use 'cg' or 'auto')")
            return True
        return params.x_update == "auto" and self.dims == ("u", "v") and self._every_lens_sees_every_colour()

    def lens_solve(self, rhs, x, rho, accumulate: bool = False):
        """x = (A^T W A + rho K_uv^T K_uv)^-1 rhs, exactly, lens by lens (x += ... with ``accumulate``)."""
        key = (rho, self._weights_key, self._cross_channel)
        if self._inverse is None or self._inverse[0] != key:
            weights = None if self._weights_key == self._unit_weights else self._weights_key
            blocks = lens_block_inverses(self.pattern, tuple(o % 2 for o in self.origin), (self.U, self.V),
                                         float(rho), weights, self._cross_channel)
            # the kernel reads block columns as float16 runs: transpose, pad i to 16
            UV = self.U * self.V
            padded = np.zeros((4, 3, blocks.shape[-1], -(-UV // 16) * 16), np.float32)
            padded[..., :UV] = blocks.transpose(0, 1, 3, 2)
            self._inverse = (key, self.runtime.to_device(padded))
        self.runtime.launch(
            "admm", "lens_solve", self._lens_grid,
            rhs.data, x.data, self._inverse[1].data, np.int32(self.height), np.int32(self.width),
            self._weight_runs.data, np.int32(bool(accumulate)), self._sums.data, np.int32(5 * self._rows),
            local_size=self._lens_group, defines=self._defines,
        )

    def _conjugate_gradient(self, x, rhs, rho, max_steps, tol) -> int:
        """Warm-started PCG on x in place; returns the steps taken."""
        if self._cg_buffers is None:
            self._cg_buffers = [self.runtime.empty(self.planes_shape) for _ in range(4)]
        return preconditioned_cg(self.vectors, self.reduce, lambda src, out: self.normal(src, out, rho),
                                 lambda src, out: self.precondition(src, out, rho), x, rhs, self._cg_buffers,
                                 max_steps, tol)

    def set_lens_weights(self, lens_weights=None):
        """Data-term weights of the U x V pixels of every lens (None: all ones).

        For an aligned grid the white image's response repeats from lens to lens;
        a weight of 0 leaves that pixel out of the data term and out of the prior
        (a dark, vignetted corner; issue #6, docs/admm.md).
        """
        weights = lens_weights_or_ones(lens_weights, (self.U, self.V))
        key = tuple(float(w) for w in weights.ravel())
        if key != self._weights_key:  # a blocking upload: only when the weights change
            self._weights_key = key
            self._weights.set(weights.ravel())
            self._weight_runs.set(weight_runs_np(weights))
            self._prior_mask = min(key) <= 0  # the mask only matters with dark pixels
            mask = np.asarray(key).reshape(self.U, self.V) if self._prior_mask else None
            self.D.set_lens_weights(mask)
            self.DC.set_lens_weights(mask)

    def prepare(self, params: AdmmParams, lens_weights=None) -> bool:
        """Set the lens weights (and with them the prior's mask) and the prior's blocks for ``params``
        (before :meth:`start` or :meth:`iterate`); returns whether the x-update is the exact lens solve."""
        if params.extrapolation:
            raise ValueError("the extrapolated warm start (extrapolation > 0) is admm-epi's (lfcl/solvers/epi.py)")
        self.set_lens_weights(lens_weights)
        self.set_cross_channel(params.cross_channel)
        self._exact = self._uses_lens_solve(params)
        return self._exact

    @property
    def exact_update(self) -> bool:
        """Whether the x-update of the prepared solve is the exact lens solve (else CG)."""
        return self._exact

    def start(self, x):
        """The ADMM start from ``x``: z = K x, u = 0 (in the solver's buffers)."""
        self.D.forward(x, out=self._z)
        self.vectors.zero(self._u)
        if self._cross_channel:
            zc, uc, _, _ = self._cross_buffers
            self.DC.forward(x, out=zc)
            self.vectors.zero(uc)

    def finish(self, x):
        """After the last iteration: dark pixels (neither data nor prior) get the harmonic extension."""
        if self._prior_mask:
            self.fill(x, np.asarray(self._weights_key).reshape(self.U, self.V), self._weights)

    def solve(self, b, x0, params: AdmmParams, callback=None, lens_weights=None, samples: int | None = None
              ) -> AdmmResult:
        """Run ADMM on mosaic ``b`` [H, W] from ``x0`` [3, H, W] (both float32 device arrays).

        ``x0`` is not modified; the result's ``x`` is a new device array.
        ``callback(record, x)`` is called after every iteration (progress bars,
        parameter sweeps); ``x`` is the current device array, not to be modified.
        ``lens_weights`` [U, V]: see :meth:`set_lens_weights`.
        ``samples``: the samples the rms change is taken over (default all of x; a packed
        mosaic's zero padding lenses, lfcl/demosaic/flat_lenses.py, are left out of it).
        """
        self.set_lens_weights(lens_weights)
        check_device_array(b, (self.height, self.width), "b")
        check_device_array(x0, self.planes_shape, "x0")
        self.prepare(params, lens_weights)
        x = x0.copy()
        self.start(x)
        history: list[IterationRecord] = []
        reason = self.iterate(b, x, params, history, callback=callback, samples=samples)
        self.finish(x)
        return AdmmResult(x=x, history=history, stop_reason=reason)

    def iterate(self, b, x, params: AdmmParams, history: list, *, callback=None, samples: int | None = None) -> str:
        """ADMM iterations on ``x`` in place, from the duals held now (:meth:`start`), appending to
        ``history``, until the stop rule holds (returns its reason). :meth:`prepare` first.
        ``samples``: the samples the rms change is over (default: all of x).
        """
        rho, lam = params.rho, params.lam
        vec, red, D, DC = self.vectors, self.reduce, self.D, self.DC
        cross, exact = self._cross_channel, self._exact
        samples = samples if samples is not None else x.size
        n_z = self._z.size
        if cross:
            zc, uc, dxc, dzc = self._cross_buffers
            n_z += zc.size
        while True:
            if not exact:  # the lens solve sums its own updates
                if self._x_prev is None:
                    self._x_prev = self.runtime.empty(self.planes_shape)
                vec.copy(x, self._x_prev)
            z_blocks, u_blocks = ((self._z, zc), (self._u, uc)) if cross else (self._z, self._u)
            # the exact solve adds M^-1 (rhs - M x): float32 round-off then scales with the update
            self.right_hand_side(b, z_blocks, u_blocks, self._rhs, rho, residual_of=x if exact else None)
            if exact:
                self.lens_solve(self._rhs, x, rho, accumulate=True)
                steps = 0
            else:
                steps = self._conjugate_gradient(x, self._rhs, rho, params.cg_steps, params.cg_tol)
            self.zu_step(x, params.kappa)  # D x, z, u, dz and their sums in one pass
            if cross:
                DC.forward(x, out=dxc)
                self.shrink.zu_update(dxc, zc, uc, dzc, params.kappa_xc)
                DC.adjoint(dzc, out=self._tmp)  # (D C)^T (z - z_prev), D^T's share added next
            self.dual_and_misfit(x, b, accumulate=cross)  # K^T (z - z_prev) and A x - b, summed
            # the whole history in one round trip to the host: the kernels' partials, and the
            # reductions of the cross-channel block and of the CG x-update's change
            requests = [] if exact else [("diff_norm2", x, self._x_prev)]
            if cross:
                requests += [("diff_norm2", dxc, zc), ("abs_sum", dxc)]
            enqueued = [red.enqueue(i, *request) for i, request in enumerate(requests)]
            primal2, tv, kx2, dual2, misfit2, *change = self._fetch_sums(with_change=exact)
            extra = red.collect(enqueued)
            change2 = change[0] if exact else extra.pop(0)
            cross_sums = extra
            prior = lam * tv
            if cross:
                primal2 += cross_sums[0]
                prior += params.lam_xc * cross_sums[1]
            record = IterationRecord(
                iteration=len(history) + 1,
                objective=0.5 * misfit2 + prior,
                primal_residual=math.sqrt(primal2),
                dual_residual=rho * math.sqrt(dual2),
                rms_change=math.sqrt(change2 / samples),
                cg_steps=steps,
            )
            history.append(record)
            if callback is not None:
                callback(record, x)
            primal_scale = dual_scale = 0.0
            if params.abs_tol > 0 or params.rel_tol > 0:
                z2 = red.norm2(self._z)
                D.adjoint(self._u, out=self._tmp)
                if cross:
                    kx2, z2 = kx2 + red.norm2(dxc), z2 + red.norm2(zc)
                    DC.adjoint(uc, out=self._tmp, accumulate=True)
                primal_scale = math.sqrt(max(kx2, z2))
                dual_scale = rho * math.sqrt(red.norm2(self._tmp))
            reason = stop_reason(params, record, primal_scale, dual_scale, n_z, samples)
            if reason:
                return reason
