"""ADMM with the prior along the epipolar lines (``admm-epi``) on an OpenCL device, and its float64 twin.

    min_x 1/2 ||W^(1/2) (A x - b)||^2 + lam ||D_epi(d, w) x||_1 + lam_fb ||D_epi(0, 1 - w) x||_1
          + lam_xc ||D_epi(d, w) C x||_1 + lam_xc ||D_epi(0, m) C x||_1

``A`` the CFA sampling (the data term stays exact: A on the true sensor samples), ``D_epi(d, w)``
the confidence-weighted differences along each sample's epipolar line (lfcl/ops/epi.py), and the
fall-back term ``D_epi(0, 1 - w) = (1 - w) D_uv``: (u, v) differences where the disparity is not
trusted (occlusions, textureless or non-Lambertian lenses), 0 where the confidence is 1. The optional
cross-channel term (``params.lam_xc > 0``) takes the same EPI differences of the colour differences
``C x = (x_R - x_G, x_B - x_G)`` (lfcl/ops/crosschannel.py): colour fringes along the epipolar lines. In the
lenses whose epipolar lines carry one CFA colour (``m`` = 1; an odd pitch at an odd whole disparity, where no sample
along a line measures its two other colours) the cross term also takes the colour differences across the lines,
within each micro-image (``D_epi(0, m) = m D_uv``, :class:`InLensCrossGradient`; docs/admm.md, "One-colour lines").

Scaled-form ADMM over the stacked blocks ``K = [K_epi; K_xc; K_lens; K_fb]``, each with its own threshold:

    x <- (A^T W A + rho K^T K)^{-1} (A^T W b + rho K^T (z - u))   block-Jacobi PCG, warm-started
    z <- S_{lam_b / rho}(K_b x + u_b)                              per block
    u <- u + K x - z

``A^T W A + rho K^T K`` couples neighbouring lenses, so the x-update is the shared preconditioned CG
(lfcl/solvers/cg.py), preconditioned by each pixel's 3x3 colour block of the normal operator (the colour
differences of the cross block couple a pixel's colours; ``diag(K^T K)`` from the operator's gather,
EpiGradient.diagonal; lfcl/kernels/epi.cl ``block_jacobi``, twin :func:`epi_block_jacobi_np`). Everything runs on
the device; the host sees only the reductions (CG's scalars and one wait per iteration for the history). The
history records and the stop rule are those of lfcl/solvers/admm.py (AdmmParams, IterationRecord, stop_reason):
lam is ``params.lam``, lam_fb comes with the disparity in :class:`EpiPrior`.

This is a solver beside :class:`lfcl.solvers.admm.AdmmSolver` rather than a mode of it because that
solver's kernels fuse D over the (u, v, s, t) stencils into the normal operator, the right-hand side
and the z/u step (and the exact per-lens x-update); the EPI prior is a gather with per-sample taps.
The pieces are shared: CG, reductions, vector ops, params, records, the stop rule and the reference's
generic ADMM core (:func:`lfcl.solvers.reference.admm_operators`).
"""

from __future__ import annotations

import dataclasses
import itertools
import math

import numpy as np
import scipy.sparse

from ..device import grid_defines
from ..layout import packed_pattern
from ..ops import check_device_array, lens_weights_or_ones
from ..ops.cfa import cfa_adjoint_np, cfa_sample_np
from ..ops.crosschannel import COLOUR_GRAM, ColourDifferences, colour_differences_adjoint_np, colour_differences_np
from ..ops.epi import EpiGradient, check_maps, epi_adjoint_np, epi_diagonal_np, epi_gradient_np, epi_matrix_np
from ..ops.linalg import VectorOps, elementwise_size
from ..ops.reduce import Reductions
from .admm import weight_runs_np
from .cg import preconditioned_cg
from .params import AdmmParams, AdmmResult, BandedResult, IterationRecord, extrapolate, stop_reason
from .reference import admm_operators


@dataclasses.dataclass(frozen=True)
class EpiPrior:
    """The prior's lens maps and the fall-back weight.

    disparity:  [S, T] lenses per view step (lfcl/ops/epi.py for the sign).
    confidence: [S, T] in [0, 1], weighting the EPI differences (None: 1 everywhere).
    lam_fb:     weight of the fall-back term lam_fb ||(1 - w) D_uv x||_1 (0: none; it also
                vanishes where the confidence is 1).
    one_colour: [S, T] bool, the lenses whose epipolar lines carry one colour (:func:`one_colour_prior_lenses`),
                where the cross-channel term also takes the (u, v) colour differences (None: none).
    """

    disparity: np.ndarray
    confidence: np.ndarray | None = None
    lam_fb: float = 0.0
    one_colour: np.ndarray | None = None

    def __post_init__(self):
        if not (isinstance(self.lam_fb, (int, float)) and math.isfinite(self.lam_fb) and self.lam_fb >= 0):
            raise ValueError(f"lam_fb must be a finite number >= 0, got {self.lam_fb!r}")

    def maps(self, lenses) -> tuple[np.ndarray, np.ndarray]:
        return check_maps(self.disparity, self.confidence, lenses)

    def has_fallback(self, lenses) -> bool:
        return self.lam_fb > 0 and bool(np.any(self.maps(lenses)[1] < 1))

    def one_colour_weights(self, lenses) -> np.ndarray | None:
        """The in-lens cross block's lens weights m [S, T] float32 (None: no lens has one-colour lines)."""
        if self.one_colour is None:
            return None
        m = np.asarray(self.one_colour)
        if m.shape != tuple(lenses):
            raise ValueError(f"one_colour must be a map of {lenses[0]}x{lenses[1]} lenses, got shape {m.shape}")
        return m.astype(np.float32) if np.any(m) else None

    def rows(self, h0: int, h1: int) -> EpiPrior:
        """The prior of lens rows [h0, h1) (a band of :func:`_solve_bands`)."""
        def cut(a):
            return None if a is None else np.asarray(a)[h0:h1]
        return dataclasses.replace(self, disparity=self.disparity[h0:h1], confidence=cut(self.confidence),
                                   one_colour=cut(self.one_colour))


#: Lenses whose disparity lies within this many lenses per view step of a one-colour disparity (an odd whole one at
#: an odd pitch: lfcl.demosaic.guarded_start.one_colour_lenses) get admm-epi's in-lens cross block. Near such a
#: disparity the lines' interpolation mixes in the other colours only weakly. The training captures pointed at 0.15;
#: held out, the Lytro frame (all of it at d = 0.84-0.88) then lost up to 4 dB of mean image, so 0.1, checked on
#: captures used for nothing before (docs/admm.md, "One-colour lines").
ONE_COLOUR_PRIOR_WITHIN = 0.1


#: In those lenses the prior also keeps each colour smooth across the micro-image: the fall-back term, with the lines'
#: weight w lowered to 1 - ONE_COLOUR_FALLBACK_SHARE there (1 elsewhere, so no other lens gets it) and, where no
#: fall-back runs otherwise, lam_fb = ONE_COLOUR_FB_PER_LAM * lam. The in-lens cross block alone makes the two
#: colours a line does not measure the measured one plus colour differences constant across the micro-image: right
#: on grey content, wrong where the hue changes at the lens scale (a coloured grating of 5.8 lenses at d = 1.03 fell
#: 4.9 dB below Malvar's centre view at 12 lux). As in a Bayer demosaic, each colour smooth lets the colour differences
#: follow the content. Fitted on training captures (the gratings family's seeds 1-2, grey gratings at noise seed 1,
#: charts, deadleaves, finetexture, periodic): the best worst case (docs/admm.md, "Each colour's own share where the
#: hue changes").
ONE_COLOUR_FALLBACK_SHARE = 0.2
ONE_COLOUR_FB_PER_LAM = 2.5


def epi_prior(depth, pitch, lam: float, lam_fb: float, cross_channel: bool) -> EpiPrior:
    """admm-epi's prior from the disparity map ``depth`` (an ``lfcl.depth.DisparityMap``): the lines weighted by the
    confidence where a fall-back runs (``lam_fb`` > 0; without one every ray keeps its full weight, since a
    low-confidence lens would otherwise be left with almost no prior), and with the cross-channel block
    (``cross_channel``) the in-lens block and its own fall-back share in the lenses of :func:`one_colour_prior_lenses`
    (:data:`ONE_COLOUR_FALLBACK_SHARE`, :data:`ONE_COLOUR_FB_PER_LAM` times ``lam``)."""
    confidence = np.asarray(depth.confidence, np.float32) if lam_fb > 0 else None
    one_colour = one_colour_prior_lenses(depth, pitch) if cross_channel else None
    if one_colour is not None and one_colour.any() and ONE_COLOUR_FALLBACK_SHARE > 0:
        lines = np.where(one_colour, np.float32(1.0 - ONE_COLOUR_FALLBACK_SHARE), np.float32(1.0))
        confidence = lines if confidence is None else confidence * lines
        lam_fb = lam_fb if lam_fb > 0 else ONE_COLOUR_FB_PER_LAM * float(lam)
    return EpiPrior(depth.disparity, confidence, lam_fb=float(lam_fb), one_colour=one_colour)


def one_colour_prior_lenses(depth, pitch, within: float | None = None) -> np.ndarray:
    """The lenses [S, T] (bool) that get the in-lens cross block: one-colour lines (``within``, None:
    :data:`ONE_COLOUR_PRIOR_WITHIN`) whose disparity is known, as the start guard counts them
    (lfcl.demosaic.guarded_start.known_one_colour_lenses). ``depth``: an ``lfcl.depth.DisparityMap``."""
    from ..demosaic.guarded_start import known_one_colour_lenses

    return known_one_colour_lenses(depth, pitch, ONE_COLOUR_PRIOR_WITHIN if within is None else float(within))


#: The disparity's candidate spacing where no noise level chooses it (the parabola through the best candidate and its
#: neighbours refines between candidates; lfcl.depth.estimate_disparity's own default is 0.05).
DEPTH_STEP = 0.1


@dataclasses.dataclass(frozen=True)
class EpiSetting:
    """admm-epi's parameters at one noise level (a row of :data:`EPI_SCHEDULE`)."""

    sigma: float  # the training captures' noise level (rms per raw pixel, normalised units)
    lam_per_sigma: float  # lam = lam_per_sigma * sigma
    fb_per_lam: float  # lam_fb = fb_per_lam * lam
    change_per_sigma: float  # stop once rms(x_k - x_{k-1}) <= change_per_sigma * sigma (0: never)
    iterations: int  # at most
    start: str  # the first estimate (lfcl.demosaic.methods.solve_aligned's ``start``)
    xc_per_lam: float = 0.0  # lam_xc = xc_per_lam * lam: the cross-channel block along the epipolar lines (0: none)
    depth_step: float = DEPTH_STEP  # the disparity's candidate spacing (lenses per view step; epi_depth_options)
    cg_steps: int = 5  # CG steps per x-update
    extrapolation: float = 0.0  # CG's warm start x_k + extrapolation (x_k - x_{k-1}) (AdmmParams.extrapolation)
    malvar_colour: float = 0.0  # the guarded start's colour differences moved this share towards Malvar's (guarded_start)


#: admm-epi's defaults by noise level, fitted by research/fit_epi.py on training seeds with the noise model
#: `lfcl process` reads (the DNG's noise profile; docs/admm.md, "admm-epi"). Between rows :func:`epi_setting`
#: interpolates lam_per_sigma, fb_per_lam, xc_per_lam, change_per_sigma and the iterations in log sigma and takes
#: the start and the disparity's step of the nearer row; outside, the end row's. The cross-channel block along the
#: lines (xc_per_lam) won at every level; the fall-back (fb_per_lam > 0, with the rays weighted by the disparity's
#: confidence) lost at every level to the EPI prior on every ray (research/fit_epi_fit_48.json: depth "trusted"
#: against "shipped"); with it the guarded start won at 12-50 lux too (research/fit_epi_starts_48.json).
#: From the 2-lux row up the x-update takes 3 CG steps from the extrapolated warm start x_k + 0.8 (x_k - x_{k-1})
#: instead of 5 from x_k: about a quarter fewer gathers for +0.05..+0.10 dB of centre view on the training captures
#: (research/epi_extrapolation.py; docs/admm.md, "The extrapolated warm start"); the 0.5-lux row keeps 5 from x_k,
#: where the extrapolation needed more iterations and cost the mean image up to 0.4 dB. It restarts after an
#: iteration that changed x more than the one before (lfcl/solvers/params.py extrapolate).
#: From the 12-lux row up the guarded start's colour differences move part of the way to Malvar's (``malvar_colour``:
#: 0.75 at 12 lux, all of it at 50; docs/admm.md, "The start's colour differences"): lens-scale gratings off the focal
#: plane fell up to 8.2 dB below Malvar from linear4d's; the rows below keep linear4d's, which the training captures
#: preferred there.
EPI_SCHEDULE = (  # the median sigma of the training captures at 0.5, 2, 12 and 50 lux
    EpiSetting(sigma=1.03e-3, lam_per_sigma=0.2, fb_per_lam=0.0, change_per_sigma=0.02, iterations=20, start="guarded",
               xc_per_lam=1.0, depth_step=0.2),
    EpiSetting(sigma=1.92e-3, lam_per_sigma=0.2, fb_per_lam=0.0, change_per_sigma=0.05, iterations=40, start="guarded",
               xc_per_lam=1.0, depth_step=0.2, cg_steps=3, extrapolation=0.8),
    EpiSetting(sigma=4.6e-3, lam_per_sigma=0.2, fb_per_lam=0.0, change_per_sigma=0.05, iterations=40, start="guarded",
               xc_per_lam=1.0, depth_step=0.2, cg_steps=3, extrapolation=0.8, malvar_colour=0.75),
    EpiSetting(sigma=9.24e-3, lam_per_sigma=0.4, fb_per_lam=0.0, change_per_sigma=0.05, iterations=20, start="guarded",
               xc_per_lam=1.0, depth_step=0.1, cg_steps=3, extrapolation=0.8, malvar_colour=1.0),
)

#: lfcl.depth.estimate_disparity's options for admm-epi (its own defaults otherwise, the half apertures among them):
#: without the half apertures a smooth plane in front of a grating (research/training_scenes.py seed 1000) took
#: the foreground's disparity on a band of background lenses and admm-epi fell 0.84 dB below Malvar at 50 lux;
#: with them it gains +2.35 dB there, +0.14 / +0.22 dB on average on the training captures and -0.01 / +0.03 on
#: held-out ones (docs/admm.md, "admm-epi").
#: The candidates' spacing follows the noise (EpiSetting.depth_step, :func:`epi_depth_options`): 0.1 lens instead of
#: 0.05 at every level (the centre view moved by -0.003 dB on average on the training captures, -0.03..+0.04, for
#: half the disparity's time), and 0.2 at 0.5-12 lux (the training captures' centre view -0.005 dB on average at
#: 0.5-2 lux, -0.08..+0.15, the mean image +0.06; but charts lost 0.25 dB at 50 lux, so that row keeps 0.1):
#: research/epi_depth_step.py, docs/admm.md. The depth output keeps estimate_disparity's own step.
EPI_DEPTH_OPTIONS: dict = {}


def epi_depth_options(sigma: float | None) -> dict:
    """lfcl.depth.estimate_disparity's options for admm-epi at noise level ``sigma`` (None: no noise level, the
    step :data:`DEPTH_STEP`); an explicit step in :data:`EPI_DEPTH_OPTIONS` wins."""
    step = epi_setting(max(float(sigma), 1e-6)).depth_step if sigma is not None else DEPTH_STEP
    return {"step": step, **EPI_DEPTH_OPTIONS}


def epi_setting(sigma: float, schedule=None) -> EpiSetting:
    """admm-epi's parameters at noise level ``sigma`` (``schedule``'s rows; None: :data:`EPI_SCHEDULE`)."""
    if not (isinstance(sigma, (int, float)) and math.isfinite(sigma) and sigma > 0):
        raise ValueError(f"sigma must be a finite number > 0, got {sigma!r}")
    rows = sorted(EPI_SCHEDULE if schedule is None else schedule, key=lambda r: r.sigma)
    if not rows:
        raise ValueError("the schedule is empty")
    if sigma <= rows[0].sigma:
        return dataclasses.replace(rows[0], sigma=float(sigma))
    if sigma >= rows[-1].sigma:
        return dataclasses.replace(rows[-1], sigma=float(sigma))
    hi = next(i for i, r in enumerate(rows) if r.sigma >= sigma)
    a, b = rows[hi - 1], rows[hi]
    t = (math.log(sigma) - math.log(a.sigma)) / (math.log(b.sigma) - math.log(a.sigma))
    return EpiSetting(sigma=float(sigma), lam_per_sigma=(1 - t) * a.lam_per_sigma + t * b.lam_per_sigma,
                      fb_per_lam=(1 - t) * a.fb_per_lam + t * b.fb_per_lam,
                      change_per_sigma=(1 - t) * a.change_per_sigma + t * b.change_per_sigma,
                      iterations=round((1 - t) * a.iterations + t * b.iterations),
                      start=a.start if t < 0.5 else b.start, xc_per_lam=(1 - t) * a.xc_per_lam + t * b.xc_per_lam,
                      depth_step=a.depth_step if t < 0.5 else b.depth_step,
                      cg_steps=a.cg_steps if t < 0.5 else b.cg_steps,
                      extrapolation=a.extrapolation if t < 0.5 else b.extrapolation,
                      malvar_colour=a.malvar_colour if t < 0.5 else b.malvar_colour)


def epi_start(sigma: float, pitch) -> tuple[str, str | None]:
    """The schedule's start at ``sigma`` for lenses of ``pitch``, and why it was replaced (None: it was not).

    linear4d (and so the guarded start) has coefficients for one pitch only; elsewhere the start is Malvar's,
    and the reason goes into the parameters (lfcl.demosaic.methods), as auto does (lfcl.demosaic.auto.for_pitch)."""
    start = epi_setting(max(float(sigma), 1e-6)).start
    if start not in ("linear4d", "guarded"):
        return start, None
    from ..ops.linear4d import load_model

    fitted, pitch = tuple(load_model().pitch), tuple(int(p) for p in pitch)
    if pitch == fitted:
        return start, None
    return "malvar", (f"the schedule's {start} start needs linear4d, which has coefficients for "
                      f"{fitted[0]}x{fitted[1]} lenses only, not {pitch[0]}x{pitch[1]}: Malvar's instead")


def epi_params(params: AdmmParams, sigma: float, *, lam=None, iterations=None, strength: float = 1.0
               ) -> tuple[AdmmParams, float]:
    """``params`` (lfcl.demosaic.methods.admm_params's for admm-epi) with lam and the stop (change rule and most
    iterations) of :func:`epi_setting` at ``sigma`` where they were not given explicitly, lam_xc = xc_per_lam lam
    (the cross-channel block), the x-update's CG steps and warm-start extrapolation, and lam_fb.
    An explicit ``iterations`` runs that many (no change rule), as for the other methods."""
    sigma = max(float(sigma), 1e-6)
    setting = epi_setting(sigma)
    if lam is None:
        params = dataclasses.replace(params, lam=strength * setting.lam_per_sigma * sigma)
    if iterations is None:
        params = dataclasses.replace(params, max_iter=setting.iterations, change_tol=setting.change_per_sigma * sigma)
    params = dataclasses.replace(params, lam_xc=setting.xc_per_lam * params.lam, cg_steps=setting.cg_steps,
                                 extrapolation=setting.extrapolation)
    return params, setting.fb_per_lam * params.lam


def _check_params(params: AdmmParams):
    if params.x_update == "lens":
        raise ValueError("x_update 'lens' needs the (u, v) prior; the EPI prior couples lenses (use 'cg' or 'auto')")


def epi_solver_bytes(sensor_shape, fallback: bool, cross_channel: bool = False, extrapolation: bool = False,
                     one_colour: bool = False) -> int:
    """Device memory an EpiAdmmSolver.solve needs, with its start and mosaic (bytes)."""
    H, W = (int(n) for n in sensor_shape)
    planes = 3 * H * W
    blocks = 2 if fallback else 1
    # planes: the start, x, previous x, rhs, K^T z, 4 CG vectors; K x scratch (2 planes); z, u per block (2 x 2
    # planes); per block the rays (d, w per sample); the mosaic and diag(K^T K); the fused CG step's 3 partial sums
    # per run of 16 columns (CgSteps)
    floats = 9 * planes + 2 * planes + blocks * (4 * planes + 2 * H * W) + 2 * H * W + 3 * H * -(-W // 16)
    if cross_channel:  # z, u and the K x scratch ([2, 2, H, W] each) and diag(D^T D) [H, W]
        floats += 3 * 4 * H * W + H * W
    if extrapolation:  # N x_k - N x_{k-1}
        floats += planes
    if cross_channel and one_colour:  # the in-lens cross block: z, u [2, 2, H, W], C x [2, H, W], its rays (d, w)
        floats += 2 * 4 * H * W + 2 * H * W + 2 * H * W
    return 4 * floats


def epi_extrapolate_np(x, x_prev, r, dnx, beta: float):
    """The twin of lfcl/kernels/epi.cl ``epi_extrapolate`` (float32, the kernel's order of operations): CG's warm
    start ``x + beta (x - x_prev)`` and its residual ``r - beta dnx`` (``dnx`` = N x - N x_prev), the anchor
    ``x_prev = x`` and ``dnx = beta dnx + r``. Returns the new (x, x_prev, r, dnx)."""
    x, x_prev, r, dnx = (np.asarray(v, np.float32) for v in (x, x_prev, r, dnx))
    beta = np.float32(beta)
    rn = r - beta * dnx
    return x + beta * (x - x_prev), x.copy(), rn, beta * dnx + rn


def epi_cross_gradient_np(x, disparity, pitch, confidence=None, matrix=None) -> np.ndarray:
    """D_epi C x, the cross-channel block: ``[3, H, W]`` -> ``[2 (u/v block), 2 (R - G, B - G), H, W]``."""
    return epi_gradient_np(colour_differences_np(np.asarray(x)), disparity, pitch, confidence, matrix)


def epi_cross_adjoint_np(z, disparity, pitch, confidence=None, matrix=None) -> np.ndarray:
    """C^T D_epi^T z: ``[2, 2, H, W]`` -> ``[3, H, W]``."""
    return colour_differences_adjoint_np(epi_adjoint_np(z, disparity, pitch, confidence, matrix))


class EpiCrossGradient:
    """The cross-channel block ``D_epi(d, w) C`` on the device, ``[3, H, W]`` -> ``[2, 2, H, W]``, computed as
    ``C D_epi``: the EPI differences have the same taps and weights in every colour, so the differences of the
    colour differences are the colour differences of the differences. It shares ``epi`` (the 3-colour
    :class:`~lfcl.ops.epi.EpiGradient` of the EPI block, its maps and its gathers): next to that block the
    solver gets ``D_epi C x`` from ``D_epi x`` by :meth:`of_gradient` and folds the adjoint into the EPI
    block's with :meth:`fold` (one gather and one scatter for both blocks instead of two of each). Twins:
    :func:`epi_cross_gradient_np`, :func:`epi_cross_adjoint_np` (``D_epi C`` and ``C^T D_epi^T`` as written).
    """

    def __init__(self, runtime, epi):
        if epi.channels != 3:
            raise ValueError(f"the cross block needs the 3-colour EPI operator, got {epi.channels} channels")
        self.epi = epi
        self.planes_shape = epi.planes_shape
        self.colour = ColourDifferences(runtime, epi.planes_shape, batch=2)  # the u and v halves
        self.gradient_shape = self.colour.out_shape
        self._runtime, self._gradient = runtime, None  # D_epi x, C^T z of forward / adjoint (made on first use)

    def _buffer(self):
        if self._gradient is None:
            self._gradient = self._runtime.empty(self.epi.gradient_shape)
        return self._gradient

    def of_gradient(self, gradient, out=None):
        """C applied to each half of an EPI gradient ``D_epi x`` [2, 3, H, W]: ``D_epi C x`` [2, 2, H, W]."""
        return self.colour.forward(gradient, out)

    def fold(self, z, gradient):
        """``gradient += C^T z``: afterwards ``D_epi^T gradient`` is the sum of both blocks' adjoints."""
        return self.colour.adjoint(z, gradient, accumulate=True)

    def forward(self, x, out=None):
        """D_epi C x."""
        return self.of_gradient(self.epi.forward(x, self._buffer()), out)

    def adjoint(self, z, out=None, accumulate: bool = False):
        """C^T D_epi^T z; with ``accumulate`` added into ``out``."""
        return self.epi.adjoint(self.colour.adjoint(z, self._buffer()), out, accumulate)


class InLensCrossGradient:
    """The in-lens cross block ``D_epi(0, m) C = m D_uv C`` on the device, ``[3, H, W]`` -> ``[2, 2, H, W]``: the
    (u, v) differences of the colour differences, weighted per lens by ``m`` (1 where the epipolar lines carry one
    colour, :class:`EpiPrior` ``one_colour``). There the lines measure one colour each, so the other two are tied to
    the neighbouring lines' only across them. Computed as ``D_epi(0, m)`` (a 2-channel
    :class:`~lfcl.ops.epi.EpiGradient`, whose taps at d = 0 stay in the lens) of ``C x``. Twins:
    :func:`epi_cross_gradient_np`, :func:`epi_cross_adjoint_np` with disparity 0 and confidence m."""

    def __init__(self, runtime, planes_shape, pitch):
        _, H, W = planes_shape
        self.planes_shape = tuple(planes_shape)
        self.colour = ColourDifferences(runtime, self.planes_shape)
        self.epi = EpiGradient(runtime, (2, H, W), pitch)
        self.gradient_shape = self.epi.gradient_shape
        self._differences = runtime.empty((2, H, W))  # C x, C^T's input

    def set_weights(self, weights: np.ndarray):
        """The lens weights m [S, T]."""
        self.epi.set_maps(np.zeros_like(weights, dtype=np.float32), weights)

    def diagonal(self, out, accumulate: bool = False):
        """diag(D^T D) [H, W] of the (u, v) differences (times C^T C in the preconditioner's colour block)."""
        return self.epi.diagonal(out, accumulate)

    def forward(self, x, out=None):
        """m D_uv C x."""
        return self.epi.forward(self.colour.forward(x, self._differences), out)

    def adjoint(self, z, out=None, accumulate: bool = False):
        """C^T D_uv^T m z; with ``accumulate`` added into ``out``."""
        return self.colour.adjoint(self.epi.adjoint(z, self._differences), out, accumulate)


#: Every this many iterations EpiAdmmSolver.iterate recomputes the vectors it carries (EpiAdmmSolver.refresh). The
#: carry's float32 round-off grows with the iterations: on a 12x12-lens plane (5 CG steps, carried throughout)
#: 6e-6 of |rhs| after 6 iterations, 1.6e-4 after 50 and 1.3e-3 after 200, by then as large as the residual itself.
EPI_REFRESH = 10

#: The proximal term of the x-update, ``delta/2 ||x - x_k||^2`` with ``delta = EPI_PROXIMAL * rho`` (proximal ADMM:
#: it vanishes at the fixed point, so the problem solved is the same). Without it a sample that measured no colour of a
#: channel and that the prior reaches only through a tiny interpolation weight w (the last view of a lens, u = U - 1
#: and v = V - 1, has no difference of its own; its neighbours' lines may barely touch it where the disparity jumps
#: between lenses) has an x-update that scales the misfit of its one term by 1 / w: at 2 lux on the 500x500-lens
#: charts, such samples reached 5.8 where the scene's brightest is 0.043 (docs/admm.md, "The proximal term").
EPI_PROXIMAL = 0.01


class CgSteps:
    """A CG step of :class:`EpiAdmmSolver`'s x-update in two passes over the vectors (lfcl/solvers/cg.py ``fused``):
    the normal operator's last kernel also sums ``<p, q>`` per work-item, and one kernel (``epi_cg_update``) updates
    x and r, preconditions r and sums ``<r, P r>`` and ``|r|^2``; the host adds the partials, compensated
    (Reductions.sum). The unfused step makes five more passes (a dot, two axpby, the Jacobi step, a dot with a
    norm): 672-681 -> 650-657 ms an iteration at 256x256 lenses (2-core PoCL, alternating runs)."""

    def __init__(self, solver: EpiAdmmSolver, rho: float):
        self.solver, self.rho = solver, rho

    def apply_dot(self, p, q) -> float:
        self.solver.normal(p, q, self.rho)
        return self.solver.reduce.sum(self.solver._cg_partials[0])

    def update(self, alpha, x, p, r, q, pz) -> tuple[float, float]:
        solver = self.solver
        rz_part, r2_part = solver._cg_partials[1], solver._cg_partials[2]
        solver._pixelwise("epi_cg_update", x.data, p.data, r.data, q.data, pz.data, np.float32(alpha),
                          *solver._jacobi_args(self.rho), rz_part.data, r2_part.data)
        return tuple(solver.reduce.many(("sum", rz_part), ("sum", r2_part)))


class EpiAdmmSolver:
    """ADMM with the EPI prior for one sensor size, Bayer phase and lens pitch (build once, solve many)."""

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
        self.cross: EpiCrossGradient | None = None  # D_epi C, built by the first prepare with lam_xc > 0
        self.lens_cross: InLensCrossGradient | None = None  # m D_uv C, built by the first prepare that has m
        self.vectors = VectorOps(runtime)
        self.reduce = Reductions(runtime)
        self._rhs, self._x_prev = runtime.empty(self.planes_shape), runtime.empty(self.planes_shape)
        self._kz = runtime.empty(self.planes_shape)  # K^T z, carried (iterate)
        self._cg = [runtime.empty(self.planes_shape) for _ in range(4)]
        # K_b x, z - u, dz of the EPI and fall-back blocks (one after the other); the cross block has its own
        self._scratch = runtime.empty(self.epi.gradient_shape)
        self._kdiag = runtime.empty((self.height, self.width))
        self._xdiag = self._cross_scratch = None  # diag(D_epi^T D_epi) and the scratch of the cross block, with it
        self._dnx = None  # N x_k - N x_{k-1}, for the extrapolated warm start (made by the first solve that uses it)
        self._state: dict = {}  # (z, u) per block operator, of its gradient shape
        n = self._scratch.size
        self._chunks = -(-n // 16)  # the z/u step runs this many chunks for every block (past its end: sums of 0)
        self._primal_part, self._l1_part = runtime.empty(self._chunks), runtime.empty(self._chunks)
        self._misfit_rows = runtime.empty(self.height)
        # the fused CG step's partial sums, one per work-item of the pixelwise kernels (CgSteps)
        runs = (self.width + 15) // 16
        self._cg_partials = [runtime.empty(runs * self.height) for _ in range(3)]
        self._weight_runs = runtime.to_device(weight_runs_np(np.ones((self.U, self.V), np.float32)))
        self._runs = ((self.width + 15) // 16, self.height)  # the pixelwise kernels: 16 columns a work-item
        self.blocks: list[tuple] = []  # (operator, lam) per prior block
        self._states: list = []  # (z, u) of each of self.blocks
        self._scratches: list = []  # the scratch of each of self.blocks

    def set_lens_weights(self, lens_weights=None):
        """Data-term weights [U, V] of every lens (None: ones); see AdmmSolver.set_lens_weights."""
        weights = lens_weights_or_ones(lens_weights, (self.U, self.V))
        self._weight_runs.set(weight_runs_np(weights))

    def prepare(self, params: AdmmParams, prior: EpiPrior, lens_weights=None):
        """Upload the maps and weights, build diag(K^T K) and the blocks (op, lam) for ``params``.

        The blocks run in the order EPI, cross-channel (lam_xc > 0), in-lens cross (lam_xc > 0 and lenses of
        one-colour lines, :class:`InLensCrossGradient`), fall-back (where the confidence is below 1): the cross
        block's ``K x`` comes from the EPI block's and its adjoint folds into the EPI block's gather
        (:class:`EpiCrossGradient`), so those two share one ``D_epi`` and one ``D_epi^T``."""
        _check_params(params)
        self.set_lens_weights(lens_weights)
        disparity, confidence = prior.maps(self.lenses)
        self.epi.set_maps(disparity, confidence)
        self.blocks = [(self.epi, params.lam)]
        self.epi.diagonal(self._kdiag)
        if params.cross_channel:  # the same lines and weights as the EPI block, on the colour differences
            if self.cross is None:
                self.cross = EpiCrossGradient(self.runtime, self.epi)
                self._xdiag = self.runtime.empty((self.height, self.width))
                self._cross_scratch = self.runtime.empty(self.cross.gradient_shape)
            self.vectors.copy(self._kdiag, self._xdiag)  # diag(D_epi^T D_epi); times C^T C in block_jacobi
            self.blocks.append((self.cross, params.lam_xc))
            one_colour = prior.one_colour_weights(self.lenses)
            if one_colour is not None:
                if self.lens_cross is None:
                    self.lens_cross = InLensCrossGradient(self.runtime, self.planes_shape, (self.U, self.V))
                self.lens_cross.set_weights(one_colour)
                self.lens_cross.diagonal(self._xdiag, accumulate=True)
                self.blocks.append((self.lens_cross, params.lam_xc))
        if prior.has_fallback(self.lenses):
            self.fallback.set_maps(np.zeros_like(disparity), 1 - confidence)
            self.fallback.diagonal(self._kdiag, accumulate=True)
            self.blocks.append((self.fallback, prior.lam_fb))
        for op, _ in self.blocks:
            if op not in self._state:
                self._state[op] = (self.runtime.empty(op.gradient_shape), self.runtime.empty(op.gradient_shape))
        self._states = [self._state[op] for op, _ in self.blocks]
        # the in-lens cross block's K x shares the cross block's scratch: each block's is used up before the next's
        self._scratches = [self._cross_scratch if op in (self.cross, self.lens_cross) else self._scratch
                           for op, _ in self.blocks]

    @property
    def _has_cross(self) -> bool:
        return any(op is self.cross for op, _ in self.blocks)

    def _accumulate(self, i: int) -> bool:
        """Whether block ``i``'s adjoint adds to the output: every one after the first that writes (with the cross
        block, the EPI block's adjoint is written at the cross block's turn)."""
        return i > (1 if self._has_cross else 0)

    def _forward(self, op, x, out):
        """K_b x into ``out``; the cross block's from the EPI block's ``K x``, which must be in the scratch."""
        if op is self.cross:
            return self.cross.of_gradient(self._scratch, out)
        return op.forward(x, out)

    def _adjoint(self, op, gradient, out, accumulate):
        """out (+)= K_b^T gradient, the EPI block's once the cross block (next) has folded its own into it."""
        if op is self.epi and self._has_cross:
            return None  # the cross block's turn does both
        if op is self.cross:
            self.cross.fold(gradient, self._scratch)
            op, gradient = self.epi, self._scratch
        return op.adjoint(gradient, out, accumulate)

    def _pixelwise(self, kernel, *args):
        self.runtime.launch("epi", kernel, self._runs, *args, defines=self._defines)

    def normal(self, src, out, rho):
        """out = (A^T W A + rho K^T K) src; the EPI and cross blocks' share as D^T (I + C^T C) D src (one gather
        each way: EpiGradient.forward's colour mix). Enqueues the partial sums of <src, out> (CgSteps)."""
        written = False
        for op, _ in self.blocks:
            if op is self.cross:
                continue  # in the EPI block's mixed gradient
            if op is self.lens_cross:
                op.adjoint(op.forward(src, self._cross_scratch), out, accumulate=written)
            else:
                mixed = op is self.epi and self._has_cross
                op.adjoint(op.forward(src, self._scratch, mixed=mixed), out, accumulate=written)
            written = True
        self._pixelwise("epi_normal_finish", out.data, src.data, self._weight_runs.data, np.float32(rho),
                        np.float32(EPI_PROXIMAL * rho), np.int32(self.height), np.int32(self.width), self._pattern,
                        self._cg_partials[0].data)
        return out

    def _jacobi_args(self, rho):
        cross = self._has_cross
        return (self._kdiag.data, (self._xdiag if cross else self._kdiag).data, np.int32(cross),
                self._weight_runs.data, np.float32(rho), np.float32(EPI_PROXIMAL * rho), np.int32(self.height),
                np.int32(self.width), self._pattern)

    def precondition(self, r, out, rho):
        """out = the inverse of each pixel's colour block of ``A^T W A + rho K^T K + delta`` applied to r (block
        Jacobi, lfcl/kernels/epi.cl ``block_jacobi``)."""
        self._pixelwise("epi_jacobi", r.data, out.data, *self._jacobi_args(rho))
        return out

    def _each_block(self, x, step, out):
        """Per block: K_b x into its scratch, ``step(i, scratch)``, then ``out`` (+)= K_b^T scratch (the blocks'
        adjoints summed, the cross block's folded into the EPI block's: :meth:`_adjoint`)."""
        for i, ((op, _), scratch) in enumerate(zip(self.blocks, self._scratches)):
            if op is not self.cross:  # the cross block's K x is made from the EPI block's, before its step
                self._forward(op, x, scratch)
            if op is self.epi and self._has_cross:
                self._forward(self.cross, x, self._cross_scratch)
            step(i, scratch)
            self._adjoint(op, scratch, out, accumulate=self._accumulate(i))

    def start(self, x, b, rho):
        """z = K x, u = 0, and the vectors :meth:`iterate` carries (:meth:`refresh`)."""
        for (op, _), (z, u), scratch in zip(self.blocks, self._states, self._scratches):
            self.vectors.copy(self._forward(op, x, scratch), z)
            self.vectors.zero(u)
        self.refresh(b, x, rho)

    def _adjoint_of(self, fill, out):
        """out = sum_b K_b^T v_b, ``fill(z, u, scratch)`` writing each block's v_b into its scratch."""
        for i, ((op, _), (z, u), scratch) in enumerate(zip(self.blocks, self._states, self._scratches)):
            fill(z, u, scratch)
            self._adjoint(op, scratch, out, accumulate=self._accumulate(i))

    def refresh(self, b, x, rho):
        """The vectors :meth:`iterate` carries, from their definitions: ``kz = K^T z``, the right-hand side
        ``A^T W b + rho K^T (z - u) + delta x`` and CG's residual ``rhs - N x`` (4 gathers; delta the proximal term,
        :data:`EPI_PROXIMAL`, and x the next x-update's warm start)."""
        self._adjoint_of(lambda z, u, scratch: self.vectors.copy(z, scratch), self._kz)
        self._adjoint_of(lambda z, u, scratch: self.vectors.axpby(1.0, z, -1.0, u, scratch), self._rhs)
        self._pixelwise("epi_rhs_finish", self._rhs.data, b.data, x.data, self._weight_runs.data, np.float32(rho),
                        np.float32(EPI_PROXIMAL * rho), np.int32(self.height), np.int32(self.width), self._pattern)
        residual, product = self._cg[0], self._cg[3]
        self.normal(x, product, rho)
        self.vectors.axpby(1.0, self._rhs, -1.0, product, residual)

    def solve(self, b, x0, params: AdmmParams, prior: EpiPrior, callback=None, lens_weights=None) -> AdmmResult:
        """Run ADMM on mosaic ``b`` [H, W] from ``x0`` [3, H, W] (float32 device arrays; x0 is not modified).

        ``callback(record, x)`` after every iteration; ``lens_weights`` [U, V] weight the data term.
        """
        check_device_array(b, (self.height, self.width), "b")
        check_device_array(x0, self.planes_shape, "x0")
        self.prepare(params, prior, lens_weights)
        x = x0.copy()
        self.start(x, b, params.rho)
        history: list[IterationRecord] = []
        reason = self.iterate(b, x, params, history, callback=callback)
        return AdmmResult(x=x, history=history, stop_reason=reason)

    def iterate(self, b, x, params: AdmmParams, history: list, callback=None) -> str:
        """ADMM iterations from :meth:`start` until a stop rule fires; returns its reason.

        The right-hand side ``A^T W b + rho K^T (z - u) + delta x_prev`` and CG's first residual ``rhs - N x``
        (``N = A^T W A + rho K^T K + delta``, delta the proximal term :data:`EPI_PROXIMAL` and x_prev the x-update's
        warm start) are carried from one iteration to the next instead of recomputed, so an iteration runs K once
        (the z/u step) and K^T once (``K^T (z' - z)``, which the dual residual needs anyway) besides its CG steps:
        with ``kz = K^T z``, ``u' = u + K x - z'`` and CG's final residual ``r = rhs - N x``,
        ``rho K^T K x = rhs - r - A^T W A x - delta x`` gives
        ``rhs' = r + A^T W A x + rho (kz + 2 K^T (z' - z)) + delta (2 x - x_prev)`` and ``r' = rhs' - rhs + r``
        (epi_carry_rhs).
        Every :data:`EPI_REFRESH` iterations they are recomputed instead (:meth:`refresh`): the carry's float32
        round-off grows with the iterations.
        With ``params.extrapolation`` = beta > 0, CG starts from ``x_k + beta (x_k - x_{k-1})`` instead of x_k (the
        proximal term keeps x_k as its anchor, so the problem solved is the same), and its first residual is the
        carried one less ``beta (N x_k - N x_{k-1})``, which the previous x-update's CG gives without a product (its
        residual's change: ``epi_extrapolate``): fewer CG steps reach what more reached from x_k (docs/admm.md,
        "The extrapolated warm start"). After an iteration that changed x more than the one before, the next
        starts from x_k (a restart, lfcl/solvers/params.py ``extrapolate``).
        """
        rho, vec, red = params.rho, self.vectors, self.reduce
        n_z = sum(z.size for z, _ in self._states)
        size = elementwise_size(self._scratch.size)  # every block's step over all the chunks (see __init__)
        residual, dual = self._cg[0], self._cg[1]  # CG's P r buffer is free until the next x-update
        beta = float(params.extrapolation)
        if beta > 0 and self._dnx is None:
            self._dnx = self.runtime.empty(self.planes_shape)
        planes_size = elementwise_size(x.size)
        while True:
            if beta > 0 and history:  # CG from x_k + beta (x_k - x_{k-1}), its residual by N x_k - N x_{k-1}
                step = beta if extrapolate(history) else 0.0  # 0: from x_k, the change of N x still tracked
                self.runtime.launch("epi", "epi_extrapolate", planes_size, x.data, self._x_prev.data, residual.data,
                                    self._dnx.data, np.float32(step), np.uint64(x.size),
                                    np.uint64(-(-x.size // 16)), defines=self._defines)
            else:
                vec.copy(x, self._x_prev)
                if beta > 0:
                    vec.copy(residual, self._dnx)
            steps = preconditioned_cg(vec, red, lambda src, out: self.normal(src, out, rho),
                                      lambda src, out: self.precondition(src, out, rho), x, self._rhs, self._cg,
                                      params.cg_steps, params.cg_tol, residual_ready=True, fused=CgSteps(self, rho))
            if beta > 0:  # dnx = r at CG's start - r at its end (+ beta dnx before) = N x_{k+1} - N x_k
                vec.axpby(1.0, self._dnx, -1.0, residual, self._dnx)
            red.enqueue(0, "diff_norm2", x, self._x_prev)

            def z_u_step(i, scratch):  # z, u, and scratch <- z' - z, with the sums of the residuals
                (_, lam), (z, u) = self.blocks[i], self._states[i]
                self.runtime.launch("epi", "epi_zu", size, scratch.data, z.data, u.data, self._primal_part.data,
                                    self._l1_part.data, np.float32(lam / rho), np.uint64(scratch.size),
                                    np.uint64(self._chunks), defines=self._defines)
                red.enqueue(2 * i + 1, "sum", self._primal_part)
                red.enqueue(2 * i + 2, "sum", self._l1_part)

            self._each_block(x, z_u_step, dual)  # dual = K^T (z' - z)
            slot = 2 * len(self.blocks)
            red.enqueue(slot + 1, "norm2", dual)
            if (len(history) + 1) % EPI_REFRESH:
                self._pixelwise("epi_carry_rhs", self._rhs.data, residual.data, self._kz.data, dual.data, x.data,
                                self._x_prev.data, self._weight_runs.data, np.float32(rho),
                                np.float32(EPI_PROXIMAL * rho), np.int32(self.height), np.int32(self.width),
                                self._pattern)
            else:
                self.refresh(b, x, rho)
            self.runtime.launch("epi", "epi_misfit_rows", (self.height,), x.data, b.data, self._weight_runs.data,
                                self._misfit_rows.data, np.int32(self.height), np.int32(self.width), self._pattern,
                                defines=self._defines)
            red.enqueue(slot + 2, "sum", self._misfit_rows)
            self.runtime.queue.finish()
            sums = red.collect([True] * (slot + 3))
            change2, dual2, misfit2 = sums[0], sums[slot + 1], sums[slot + 2]
            primal2 = sum(sums[1:slot + 1:2])
            prior = sum(lam * l1 for (_, lam), l1 in zip(self.blocks, sums[2:slot + 1:2]))
            record = IterationRecord(
                iteration=len(history) + 1,
                objective=0.5 * misfit2 + prior,
                primal_residual=math.sqrt(primal2),
                dual_residual=rho * math.sqrt(dual2),
                rms_change=math.sqrt(change2 / x.size),
                cg_steps=steps,
            )
            history.append(record)
            if callback is not None:
                callback(record, x)
            primal_scale = dual_scale = 0.0
            if params.abs_tol > 0 or params.rel_tol > 0:
                kx2 = z2 = 0.0
                for i, ((op, _), (z, u), scratch) in enumerate(zip(self.blocks, self._states, self._scratches)):
                    kx2 += red.norm2(op.forward(x, scratch))
                    z2 += red.norm2(z)
                    op.adjoint(u, dual, accumulate=i > 0)
                primal_scale = math.sqrt(max(kx2, z2))
                dual_scale = rho * math.sqrt(red.norm2(dual))
            reason = stop_reason(params, record, primal_scale, dual_scale, n_z, x.size)
            if reason:
                return reason


def admm_epi_reference(b, pattern, pitch, params: AdmmParams, x0, prior: EpiPrior, origin=(0, 0),
                       lens_weights=None) -> AdmmResult:
    """The float64 twin of :class:`EpiAdmmSolver`: the same problem and updates through
    :func:`lfcl.solvers.reference.admm_operators`, with K the stacked sparse matrices."""
    _check_params(params)
    prior_spec = prior
    b = np.asarray(b, dtype=np.float64)
    U, V = pitch
    H, W = b.shape
    lenses = (H // U, W // V)
    disparity, confidence = prior.maps(lenses)
    lens_w = np.ones((U, V)) if lens_weights is None else np.asarray(lens_weights, dtype=np.float64)
    w = np.tile(lens_w, lenses)
    M = epi_matrix_np(disparity, pitch, confidence)
    blocks = [M]
    lams = [params.lam]
    if prior.has_fallback(lenses):
        blocks.append(epi_matrix_np(np.zeros_like(disparity), pitch, 1 - confidence))
        lams.append(prior.lam_fb)
    K = scipy.sparse.vstack(blocks).tocsr()
    KT = K.T.tocsr()
    kdiag = np.asarray(K.multiply(K).sum(axis=0)).reshape(H, W)
    # per-entry weights carry every threshold (lam_b / rho with params.lam = 1), as the cross-channel reference does
    prior_weights = np.concatenate([np.full(m.shape[0], lam) for m, lam in zip(blocks, lams)])[None, :]

    def main_prior(v):  # [3, rows of K]
        return (K @ v.reshape(3, H * W).T).T

    def main_adjoint(z):
        return (KT @ z.T).T.reshape(3, H, W)

    prior, prior_adjoint = main_prior, main_adjoint
    data = cfa_adjoint_np(w, pattern, origin)  # [3, H, W]: the data weight on each pixel's measured colour
    cross = np.zeros((H, W))
    if params.cross_channel:  # K_xc = D_epi(d, w) C on the colour differences: K x flat, [K_main x; K_xc x]
        cross = epi_diagonal_np(disparity, pitch, matrix=M)  # its per-pixel colour block: this times C^T C
        split = 3 * K.shape[0]

        def stacked_prior(v):
            return np.concatenate([main_prior(v).ravel(), epi_cross_gradient_np(v, disparity, pitch, matrix=M).ravel()])

        def stacked_adjoint(z):
            return (main_adjoint(z[:split].reshape(3, -1))
                    + epi_cross_adjoint_np(z[split:].reshape(2, 2, H, W), disparity, pitch, matrix=M))

        prior, prior_adjoint = stacked_prior, stacked_adjoint
        prior_weights = np.concatenate([np.tile(prior_weights[0], 3), np.full(4 * H * W, params.lam_xc)])
        one_colour = prior_spec.one_colour_weights(lenses)
        if one_colour is not None:  # the in-lens cross block D_epi(0, m) C after the cross block
            zero = np.zeros_like(disparity)
            L = epi_matrix_np(zero, pitch, one_colour)
            cross = cross + epi_diagonal_np(zero, pitch, matrix=L)
            split2 = split + 4 * H * W

            def lens_prior(v, outer=prior):
                return np.concatenate([outer(v), epi_cross_gradient_np(v, zero, pitch, matrix=L).ravel()])

            def lens_adjoint(z, outer=prior_adjoint):
                return outer(z[:split2]) + epi_cross_adjoint_np(z[split2:].reshape(2, 2, H, W), zero, pitch, matrix=L)

            prior, prior_adjoint = lens_prior, lens_adjoint
            prior_weights = np.concatenate([prior_weights, np.full(4 * H * W, params.lam_xc)])
    blocks = epi_colour_blocks_np(data, kdiag, cross, params.rho, EPI_PROXIMAL * params.rho)
    return admm_operators(
        b, x0, dataclasses.replace(params, lam=1.0), w,
        forward=lambda v: cfa_sample_np(v, pattern, origin),
        adjoint=lambda r: cfa_adjoint_np(r, pattern, origin),
        prior=prior,
        prior_adjoint=prior_adjoint,
        prior_weights=prior_weights,
        proximal=EPI_PROXIMAL * params.rho,
        precondition=lambda r: epi_block_jacobi_np(blocks, r),
    )


def epi_colour_blocks_np(data, kdiag, cross, rho, delta) -> np.ndarray:
    """admm-epi's preconditioner blocks: per pixel the 3x3 colour block of ``A^T W A + rho K^T K + delta``,
    ``diag(data) + (rho kdiag + delta) I + rho cross C^T C`` as [H, W, 3, 3] float64: ``data`` [3, H, W] the data
    weight on each pixel's measured colour, ``kdiag`` [H, W] diag(D^T D) of the EPI block, ``cross`` [H, W] that of the
    cross-channel block (zeros without it: the blocks are then diagonal, Jacobi)."""
    blocks = (rho * np.asarray(kdiag, np.float64) + delta)[..., None, None] * np.eye(3)
    blocks = blocks + rho * np.asarray(cross, np.float64)[..., None, None] * COLOUR_GRAM
    return blocks + np.moveaxis(np.asarray(data, np.float64), 0, -1)[..., None] * np.eye(3)


def epi_block_jacobi_np(blocks, r) -> np.ndarray:
    """The twin of lfcl/kernels/epi.cl ``block_jacobi``: each pixel's colour block (:func:`epi_colour_blocks_np`)
    solved for r [3, H, W]; a block that is not positive definite gives 0."""
    rhs = np.moveaxis(np.asarray(r, np.float64), 0, -1)[..., None]
    definite = np.linalg.det(blocks) > 0
    safe = np.where(definite[..., None, None], blocks, np.eye(3))
    return np.moveaxis(np.where(definite[..., None], np.linalg.solve(safe, rhs)[..., 0], 0.0), -1, 0)


def epi_disparity(raw_mosaic, pattern, pitch, origin, noise, device=None, depth_options: dict | None = None):
    """admm-epi's disparity of the raw (lfcl.depth.estimate_disparity with :func:`epi_depth_options`, or
    ``depth_options``) and the seconds it took."""
    import time

    from ..depth import estimate_disparity

    began = time.perf_counter()
    depth = estimate_disparity(raw_mosaic, pattern, pitch, origin=origin, noise=noise, device=device,
                               **(epi_depth_options(None if noise is None else noise.sigma)
                                  if depth_options is None else depth_options))
    return depth, time.perf_counter() - began


def check_depth(depth, sensor_shape, pitch):
    """A ValueError unless the disparity map ``depth`` has one value per lens of a ``sensor_shape`` raw."""
    lenses = (int(sensor_shape[0]) // int(pitch[0]), int(sensor_shape[1]) // int(pitch[1]))
    if tuple(depth.disparity.shape) != lenses:
        raise ValueError(f"the disparity map given has {depth.disparity.shape[0]}x{depth.disparity.shape[1]} "
                         f"lenses, this raw {lenses[0]}x{lenses[1]}")


def demosaic_epi(runtime, raw_mosaic, b, x0, pattern, pitch, origin, params: AdmmParams, lam_fb: float, noise,
                 device=None, lens_weights=None, callback=None, max_memory: int | None = None,
                 depth_options: dict | None = None, depth=None, depth_seconds: float | None = None
                 ) -> tuple[np.ndarray, dict, AdmmResult, float]:
    """``admm-epi`` of lfcl.demosaic.methods.solve_aligned: estimate the disparity from the raw
    (:func:`epi_disparity`), then solve from the start ``x0`` (device arrays ``b``, ``x0``).
    ``depth``: a disparity map already estimated from this raw (an ``lfcl.depth.DisparityMap`` of its lenses): with
    ``depth_seconds``, :func:`epi_disparity`'s, made for the start (lfcl/demosaic/guarded_start.py) and taking that
    long; without, the depth output's, whose finer candidates change the solve by hundredths of a dB (docs/admm.md),
    and its seconds are 0 here.

    A sensor whose solver does not fit ``max_memory`` (default :func:`epi_default_budget`) is solved in bands of
    lens rows, each with the halo of lens rows its prior reaches (:func:`epi_halo`), each stopped by its own
    rule; only the band's own rows are kept (docs/admm.md, "admm-epi in bands").

    Returns the planes [3, H, W] on the host, the parameters to record (the disparity's
    statistics, lam_fb, the bands), the solver's runs (:class:`BandedResult`, their x dropped) and the seconds the
    disparity took (apart from the parameters, so that the same raw and options record the same parameters).
    """
    H, W = b.shape
    shared = depth is not None and depth_seconds is None
    if depth is not None:
        check_depth(depth, (H, W), pitch)
    else:
        depth, depth_seconds = epi_disparity(raw_mosaic, pattern, pitch, origin, noise, device, depth_options)
    depth_seconds = 0.0 if shared else depth_seconds
    prior = epi_prior(depth, pitch, params.lam, lam_fb, params.cross_channel)
    one_colour = prior.one_colour
    U = int(pitch[0])
    S = H // U
    budget = int(max_memory) if max_memory is not None else epi_default_budget(runtime.device)
    fallback = prior.has_fallback((S, W // int(pitch[1])))
    halo = epi_halo(depth.disparity, pitch)
    bands = epi_bands(S, halo, epi_lens_rows_that_fit((U, W), fallback, budget, runtime.device.max_mem_alloc_size,
                                                      cross_channel=params.cross_channel,
                                                      extrapolation=params.extrapolation > 0,
                                                      one_colour=one_colour is not None and bool(one_colour.any())))
    dark = lens_weights is not None and np.any(np.asarray(lens_weights) == 0)
    if len(bands) == 1:
        solver = EpiAdmmSolver(runtime, (H, W), pattern, pitch, origin)
        run = solver.solve(b, x0, params, prior, callback=callback, lens_weights=lens_weights)
        planes = (_fill_dark(runtime, run.x, lens_weights, pitch) if dark else run.x).get()  # filled on the device
        result = BandedResult([dataclasses.replace(run, x=None)], [S])
    else:
        planes, result = _solve_bands(runtime, b.get(), x0.get(), pattern, pitch, origin, params, prior, bands,
                                      callback, lens_weights)
        if dark:  # the bands' planes are on the host already: up once, filled, down
            planes = _fill_dark(runtime, runtime.to_device(planes), lens_weights, pitch).get()
    if not np.all(np.isfinite(planes)):
        raise FloatingPointError("admm-epi produced NaN/Inf values; try a smaller lambda or rho")
    d, w = depth.disparity, depth.confidence
    parameters = {
        "lam_fb": float(prior.lam_fb),
        "fallback_block": fallback,
        "one_colour_fallback_share": ONE_COLOUR_FALLBACK_SHARE,
        # lenses whose lines carry one colour: the cross term there also across the lines (InLensCrossGradient)
        "one_colour_cross_lenses": 0 if one_colour is None else int(one_colour.sum()),
        "one_colour_cross_within": ONE_COLOUR_PRIOR_WITHIN,
        "disparity": {
            "units": "lenses per view step", "min": float(d.min()), "max": float(d.max()),
            "mean": float(d.mean()), "median": float(np.median(d)), "std": float(d.std()),
            "confidence_mean": float(w.mean()), "confident_share": float(np.mean(w >= 0.5)),
            "search_range": [-depth.dmax, depth.dmax], "step": depth.step,
            "options": dict(depth.options),  # every option of the estimate, its defaults included
            "lookup": "d and confidence read at the lens the ray sees in the centre view",
            "source": "given (the depth output's estimate)" if shared else "estimated for admm-epi",
        },
    }
    if len(bands) > 1:
        parameters["bands"] = {"lens_rows": [s1 - s0 for s0, s1, _, _ in bands], "halo_lens_rows": halo,
                               "iterations": [run.iterations for run in result.runs]}  # each band stops on its own
    return planes, parameters, result, depth_seconds


def _fill_dark(runtime, x, lens_weights, pitch):
    """The dark lens pixels of a white image (data weight 0) get the harmonic extension of their lens's lit ones, as
    the (u, v) solvers' give them (lfcl/ops/lensfill.py): their samples are not the flat-fielded scene (the flat field
    leaves them raw), so what the start and the prior made of them is not either (docs/admm.md, "A white image's
    dark pixels")."""
    from ..ops.lensfill import LensFill

    weights = np.asarray(lens_weights, np.float32).reshape(int(pitch[0]), int(pitch[1]))
    return LensFill(runtime, x.shape, pitch)(x, weights, runtime.to_device(weights.ravel()))  # x [3, H, W], in place


#: admm-epi's default solver memory on a CPU device, whose "device memory" is the host's: at the paper's
#: 500x500 lenses (2-core PoCL) the whole-frame solve peaked at 5.7 GB of RSS in 127 s, three bands with
#: their halo at 3.3 GB in 133 s (docs/admm.md, "admm-epi in bands"), as darktable tiles on a CPU
#: within a host memory limit.
EPI_CPU_BUDGET = 2 * 2**30


def epi_default_budget(device) -> int:
    """The solver memory admm-epi takes when none is given: 80 % of the device's, at most
    :data:`EPI_CPU_BUDGET` on a CPU device."""
    import pyopencl as cl

    budget = int(0.8 * device.global_mem_size)
    return min(budget, EPI_CPU_BUDGET) if device.type & cl.device_type.CPU else budget


def epi_halo(disparity, pitch) -> int:
    """Lens rows of halo a band needs so that its own rows see what the whole sensor's would: a ray's
    disparity is read up to ``|d| (U - 1) / 2`` lenses away (the lens it sees in the centre view), its
    difference reaches ``|d|`` lenses on, and the cubic interpolation 2 more."""
    dmax = float(np.max(np.abs(disparity))) if np.size(disparity) else 0.0
    return math.ceil(dmax * (int(pitch[0]) - 1) / 2) + math.ceil(dmax) + 2


def epi_lens_rows_that_fit(lens_row_shape, fallback: bool, budget: int, largest_buffer: int,
                           cross_channel: bool = False, extrapolation: bool = False, one_colour: bool = False) -> int:
    """The most lens rows whose EpiAdmmSolver fits ``budget`` bytes, with every buffer under ``largest_buffer``."""
    U, W = lens_row_shape
    per_row = epi_solver_bytes((U, W), fallback, cross_channel, extrapolation, one_colour)
    return max(0, min(budget // per_row, largest_buffer // (4 * 6 * U * W)))


def epi_bands(lens_rows: int, halo: int, rows_that_fit: int) -> list[tuple[int, int, int, int]]:
    """Bands ``(s0, s1, h0, h1)`` of lens rows: band ``[s0, s1)`` is solved over ``[h0, h1)``, its halo on both
    sides (clipped at the frame), each band solve at most ``rows_that_fit`` lens rows. One band when all fit."""
    if rows_that_fit >= lens_rows:
        return [(0, lens_rows, 0, lens_rows)]
    inner = rows_that_fit - 2 * halo
    if inner < 1:
        raise ValueError(f"admm-epi solves bands of lens rows with {halo} lens rows of halo on each side (its prior "
                         f"couples lenses that far apart at this disparity), but the device memory holds "
                         f"{rows_that_fit} lens rows: give it more (--max-memory) or use admm-uv")
    count = -(-lens_rows // inner)
    edges = [round(i * lens_rows / count) for i in range(count + 1)]
    return [(s0, s1, max(0, s0 - halo), min(lens_rows, s1 + halo)) for s0, s1 in itertools.pairwise(edges)]


def _solve_bands(runtime, b_host, x0_host, pattern, pitch, origin, params, prior: EpiPrior, bands, callback,
                 lens_weights) -> tuple[np.ndarray, BandedResult]:
    """Solve each band with its halo on its own (its own stop), keep its rows: planes [3, H, W] on the host."""
    U = int(pitch[0])
    planes = np.empty_like(x0_host)
    runs, solver = [], None
    for s0, s1, h0, h1 in bands:
        rows = slice(h0 * U, h1 * U)
        band_origin = (origin[0] + h0 * U, origin[1])
        # a solver serves the next band of its size and Bayer phase (an odd pitch flips the phase every lens row)
        if solver is None or solver.height != (h1 - h0) * U or (solver.origin[0] - band_origin[0]) % 2:
            solver = None  # the previous band's buffers go before the next band's come
            solver = EpiAdmmSolver(runtime, ((h1 - h0) * U, b_host.shape[1]), pattern, pitch, band_origin)
        band_prior = prior.rows(h0, h1)
        run = solver.solve(runtime.to_device(b_host[rows]), runtime.to_device(x0_host[:, rows]), params, band_prior,
                           callback=callback, lens_weights=lens_weights)
        planes[:, s0 * U:s1 * U] = run.x.get()[:, (s0 - h0) * U:(s1 - h0) * U]
        runs.append(dataclasses.replace(run, x=None))
    return planes, BandedResult(runs, [s1 - s0 for s0, s1, _, _ in bands])
