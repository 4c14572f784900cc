"""admm-epi's problem by a primal-dual method on an OpenCL device, and its float64 twin.

    min_x 1/2 ||W^(1/2) (A x - b)||^2 + lam ||D_epi(d, w) x||_1 + lam_xc ||D_epi(d, w) C x||_1
          + lam_fb ||D_epi(0, 1 - w) x||_1

(the problem of lfcl/solvers/epi.py). The method of Chambolle & Pock (2011), with the diagonal step sizes of
Pock & Chambolle (2011, "Diagonal preconditioning for first order primal-dual algorithms"), over the stacked
blocks ``K = [K_epi; K_xc; K_fb]``:

    y_b <- clip(y_b + sigma_b K_b x_bar, -lam_b, lam_b)             per block (the prox of lam_b ||.||_1's conjugate)
    x'  <- prox_{tau f}(x - tau K^T y)                               per sample: the data term f is separable
    x_bar <- 2 x' - x

``tau_j = 1 / (rho sum_i |K_ij|)`` per sample and colour (the column sums of |K|: EpiGradient.column_abs_sums,
times the column sums of |C|, (1, 2, 1), with the cross block) and ``sigma_b = rho / r_b``, ``r_b`` a bound on
the row sums of |K_b| (a difference has weight w <= 1 on its sample and on Catmull-Rom taps whose absolute
weights sum to at most 1.25: r = 2.25 w_max; the cross block's rows twice that, the colour differences have
two entries). With these steps ``||Sigma^(1/2) K T^(1/2)|| <= 1`` for every rho > 0 (Pock & Chambolle's lemma
with alpha = 1: sigma at or below the inverse row sums), so the iteration converges; rho trades the primal step
against the dual one. It is linearized ADMM with the penalty ``rho / r_b`` per block (y = penalty times the
scaled dual u, Chambolle & Pock 2011, section 4.3): no inner solve, one ``K`` and one ``K^T`` an iteration
against the CG steps of lfcl/solvers/epi.py's exact x-update.

The records: ``rms_change`` = rms(x' - x) (the shared stop rule, lfcl/solvers/params.py), ``primal_residual``
= ||(y' - y) / sigma|| (linearized ADMM's K x - z), ``dual_residual`` = ||(x' - x) / tau||, ``objective`` =
1/2 ||A x' - b||_W^2 + sum_b lam_b ||K_b x_bar||_1 (the prior at the point K was applied to).
"""

from __future__ import annotations

import math

import numpy as np

from ..device import grid_defines
from ..layout import packed_pattern
from ..ops import check_device_array, lens_weights_or_ones
from ..ops.cfa import cfa_adjoint_np
from ..ops.epi import EpiGradient, epi_matrix_np
from ..ops.linalg import VectorOps
from ..ops.reduce import Reductions
from .admm import weight_runs_np
from .params import AdmmParams, AdmmResult, IterationRecord, stop_reason

#: A bound on the row sums of |D_epi(d, w)| for w <= 1: the sample's own -w and the Catmull-Rom taps of its
#: neighbour, whose absolute weights sum to at most 1.25 (at the fraction 0.5).
EPI_ROW_BOUND = 2.25
#: The column sums of |C| (R - G, B - G) per colour: the cross block's share of a sample's column sum.
CROSS_COLUMNS = (1.0, 2.0, 1.0)


def _check(params: AdmmParams):
    """AdmmParams checks itself (finite, rho > 0); the prior needs lam > 0."""
    if not params.lam > 0:
        raise ValueError(f"lam must be > 0, got {params.lam!r}")


def _sigmas(rho: float, confidence) -> tuple[float, float, float]:
    """sigma of the EPI, cross and fall-back blocks: rho over a bound on their row sums of |K_b|."""
    w_max = 1.0 if confidence is None else float(np.max(confidence, initial=0.0))
    fb_max = 0.0 if confidence is None else float(np.max(1.0 - confidence, initial=0.0))
    epi = rho / (EPI_ROW_BOUND * max(w_max, 1e-12))
    return epi, epi / 2.0, rho / (2.0 * max(fb_max, 1e-12))  # d = 0: the taps are one lens, |row| = 2 (1 - w)


def epi_pd_solver_bytes(sensor_shape, fallback: bool, cross_channel: bool = False) -> int:
    """Device memory an EpiPdSolver.solve needs, with its start and mosaic (bytes)."""
    H, W = (int(n) for n in sensor_shape)
    planes = 3 * H * W
    # planes: the start, x, x_bar, K^T y; per block K x_bar, y and s (2 planes each) and the rays (d, w); the
    # mosaic, the column sums; the cross block's y ([2, 2, H, W])
    blocks = 2 if fallback else 1
    floats = 4 * planes + blocks * (3 * 2 * planes + 3 * H * W) + H * W
    if cross_channel:
        floats += 4 * H * W
    return 4 * floats


class EpiPdSolver:
    """The primal-dual method for admm-epi's problem, one sensor size, Bayer phase and lens pitch (module
    docstring; build once, solve many). ``solve`` has :class:`lfcl.solvers.epi.EpiAdmmSolver`'s signature;
    ``params.rho`` balances the primal and dual steps, ``params.cg_steps`` is not used."""

    def __init__(self, runtime, sensor_shape, pattern: str, pitch, origin=(0, 0)):
        self.runtime = runtime
        self.height, self.width = (int(n) for n in sensor_shape)
        self.U, self.V = (int(p) for p in pitch)
        if self.height % self.U or self.width % self.V:
            raise ValueError(f"sensor {self.height}x{self.width} is not a whole number of {self.U}x{self.V} lenses")
        self.lenses = (self.height // self.U, self.width // self.V)
        self.planes_shape = (3, self.height, self.width)
        self.pattern, self.origin = pattern, origin
        self._pattern = packed_pattern(pattern, origin)
        self._defines = grid_defines((self.U, self.V), 3)
        self.epi = EpiGradient(runtime, self.planes_shape, (self.U, self.V))
        self.fallback = EpiGradient(runtime, self.planes_shape, (self.U, self.V))  # d = 0, weights 1 - w
        self.vectors, self.reduce = VectorOps(runtime), Reductions(runtime)
        self._xbar, self._v = runtime.empty(self.planes_shape), runtime.empty(self.planes_shape)
        self._a_epi, self._a_fb = runtime.empty((self.height, self.width)), None
        self._runs = ((self.width + 15) // 16, self.height)
        self._sums = [runtime.empty(self._runs[0] * self.height) for _ in range(3)]  # change, scaled, misfit
        plane = self.height * self.width
        self._chunks = -(-plane // 16)
        self._weight_runs = runtime.to_device(weight_runs_np(np.ones((self.U, self.V), np.float32)))
        self._blocks: list[dict] = []

    def _block(self, op, cross: bool):
        """The buffers of one block's dual step (and of the cross block's with ``cross``)."""
        rt = self.runtime
        return {"op": op, "g": rt.empty(op.gradient_shape), "y": rt.empty(op.gradient_shape),
                "s": rt.empty(op.gradient_shape), "yx": rt.empty((2, 2, self.height, self.width)) if cross else None,
                "moved": rt.empty(2 * self._chunks), "l1": rt.empty(2 * self._chunks)}

    def prepare(self, params: AdmmParams, prior, lens_weights=None):
        """Upload the maps and the data weights; the column sums of |K| (the primal steps) and the blocks."""
        _check(params)
        self._weight_runs.set(weight_runs_np(lens_weights_or_ones(lens_weights, (self.U, self.V))))
        disparity, confidence = prior.maps(self.lenses)
        self.epi.set_maps(disparity, confidence)
        self.epi.column_abs_sums(self._a_epi)
        cross = params.cross_channel
        sigma, sigma_x, sigma_fb = _sigmas(params.rho, None if prior.confidence is None else confidence)
        self._blocks = [dict(self._block(self.epi, cross), lam=params.lam, sigma=sigma, lam_x=params.lam_xc,
                             sigma_x=sigma_x, cross=cross)]
        self._fallback = prior.has_fallback(self.lenses)
        if self._fallback:
            self.fallback.set_maps(np.zeros_like(disparity), 1 - confidence)
            if self._a_fb is None:
                self._a_fb = self.runtime.empty((self.height, self.width))
            self.fallback.column_abs_sums(self._a_fb)
            self._blocks.append(dict(self._block(self.fallback, False), lam=prior.lam_fb, sigma=sigma_fb, lam_x=0.0,
                                     sigma_x=1.0, cross=False))
        for block in self._blocks:
            self.vectors.zero(block["y"])
            if block["yx"] is not None:
                self.vectors.zero(block["yx"])

    def solve(self, b, x0, params: AdmmParams, prior, callback=None, lens_weights=None) -> AdmmResult:
        """Iterate on mosaic ``b`` [H, W] from ``x0`` [3, H, W] (float32 device arrays; x0 is not modified), the
        duals from 0, until the stop rule of ``params`` (lfcl/solvers/params.py) fires; ``callback(record, x)``
        after every iteration."""
        check_device_array(b, (self.height, self.width), "b")
        check_device_array(x0, self.planes_shape, "x0")
        self.prepare(params, prior, lens_weights)
        x = x0.copy()
        self.vectors.copy(x, self._xbar)
        plane = self.height * self.width
        history: list[IterationRecord] = []
        n_z = sum(2 * (3 + (2 if blk["cross"] else 0)) * plane for blk in self._blocks)
        while True:
            for i, blk in enumerate(self._blocks):
                blk["op"].forward(self._xbar, blk["g"])
                self.runtime.launch(
                    "epi", "epi_pd_dual", (2 * self._chunks,), blk["g"].data, blk["y"].data,
                    (blk["yx"] if blk["cross"] else blk["y"]).data, blk["s"].data, blk["moved"].data, blk["l1"].data,
                    np.float32(blk["sigma"]), np.float32(blk["lam"]), np.float32(blk["sigma_x"]),
                    np.float32(blk["lam_x"]), np.int32(blk["cross"]), np.uint64(plane), np.uint64(self._chunks),
                    defines=self._defines)
                blk["op"].adjoint(blk["s"], self._v, accumulate=i > 0)
            self.runtime.launch(
                "epi", "epi_pd_primal", self._runs, x.data, self._xbar.data, self._v.data, b.data, self._a_epi.data,
                (self._a_fb if self._fallback else self._a_epi).data, np.int32(self._fallback),
                np.int32(self._blocks[0]["cross"]), self._weight_runs.data, np.float32(params.rho),
                *(s.data for s in self._sums), np.int32(self.height), np.int32(self.width), self._pattern,
                defines=self._defines)
            requests = [("sum", s) for s in self._sums]
            for blk in self._blocks:
                requests += [("sum", blk["moved"]), ("sum", blk["l1"])]
            sums = self.reduce.many(*requests)
            change2, scaled2, misfit2 = sums[:3]
            record = IterationRecord(
                iteration=len(history) + 1,
                objective=0.5 * misfit2 + sum(sums[4::2]),
                primal_residual=math.sqrt(sum(sums[3::2])),
                dual_residual=math.sqrt(scaled2),
                rms_change=math.sqrt(change2 / x.size),
                cg_steps=0,
            )
            history.append(record)
            if callback is not None:
                callback(record, x)
            reason = stop_reason(params, record, 0.0, 0.0, n_z, x.size)
            if reason:
                return AdmmResult(x=x, history=history, stop_reason=reason)


def epi_pd_reference(b, pattern, pitch, params: AdmmParams, x0, prior, origin=(0, 0),
                     lens_weights=None) -> AdmmResult:
    """The float64 twin of :class:`EpiPdSolver`: the same iteration with the stacked sparse matrices."""
    _check(params)
    b = np.asarray(b, dtype=np.float64)
    U, V = pitch
    H, W = b.shape
    lenses = (H // U, W // V)
    disparity, confidence = prior.maps(lenses)
    lens_w = np.ones((U, V)) if lens_weights is None else np.asarray(lens_weights, dtype=np.float64)
    weights = cfa_adjoint_np(np.tile(lens_w, lenses), pattern, origin)  # [3, H, W]: w where measured, else 0
    target = cfa_adjoint_np(b, pattern, origin)
    C = np.array([[1.0, -1.0, 0.0], [0.0, -1.0, 1.0]])
    sigma, sigma_x, sigma_fb = _sigmas(params.rho, None if prior.confidence is None else confidence)
    blocks = [(epi_matrix_np(disparity, pitch, confidence), params.lam, sigma, params.cross_channel)]
    if prior.has_fallback(lenses):
        blocks.append((epi_matrix_np(np.zeros_like(disparity), pitch, 1 - confidence), prior.lam_fb, sigma_fb, False))
    cross_columns = np.asarray(CROSS_COLUMNS)[:, None] if params.cross_channel else np.zeros((3, 1))
    reach = sum(np.asarray(abs(M).sum(axis=0)).reshape(1, -1) * (1.0 + (cross_columns if i == 0 else 0.0))
                for i, (M, _, _, _) in enumerate(blocks)).reshape(3, H, W) * params.rho  # 1 / tau
    x = np.asarray(x0, dtype=np.float64).copy()
    xbar = x.copy()
    duals = [(np.zeros((3, M.shape[0])), np.zeros((2, M.shape[0])) if cross else None) for M, _, _, cross in blocks]
    n_z = sum(M.shape[0] * (3 + (2 if cross else 0)) for M, _, _, cross in blocks)
    history: list[IterationRecord] = []
    while True:
        v = np.zeros((3, H * W))
        moved2 = prior_l1 = 0.0
        for (M, lam, sig, cross), (y, yx) in zip(blocks, duals):
            g = (M @ xbar.reshape(3, -1).T).T  # [3, rows]
            y_new = np.clip(y + sig * g, -lam, lam)
            moved2 += float(np.sum(((y_new - y) / sig) ** 2))
            prior_l1 += lam * float(np.abs(g).sum())
            y[...] = y_new
            s = y.copy()
            if cross:
                gx = C @ g
                yx_new = np.clip(yx + sigma_x * gx, -params.lam_xc, params.lam_xc)
                moved2 += float(np.sum(((yx_new - yx) / sigma_x) ** 2))
                prior_l1 += params.lam_xc * float(np.abs(gx).sum())
                yx[...] = yx_new
                s += C.T @ yx
            v += (M.T @ s.T).T
        v = v.reshape(3, H, W)
        with np.errstate(divide="ignore", invalid="ignore"):
            q = x - v / reach
            solved = np.where(reach > 0, (reach * q + weights * target) / (reach + weights),
                              np.where(weights > 0, target, x))
        dx = solved - x
        xbar = 2.0 * solved - x
        x = solved
        misfit2 = float(np.sum(weights * (x - target) ** 2))
        record = IterationRecord(
            iteration=len(history) + 1,
            objective=0.5 * misfit2 + prior_l1,
            primal_residual=math.sqrt(moved2),
            dual_residual=math.sqrt(float(np.sum((dx * reach) ** 2))),
            rms_change=math.sqrt(float(np.sum(dx * dx)) / x.size),
            cg_steps=0,
        )
        history.append(record)
        reason = stop_reason(params, record, 0.0, 0.0, n_z, x.size)
        if reason:
            return AdmmResult(x=x, history=history, stop_reason=reason)


