"""The demosaic/denoise methods and their defaults, and the solver of aligned grids.

The entry point for every grid is lfcl.demosaic.driver.demosaic_grid: it checks the input, resolves
``auto`` and runs :func:`solve_aligned` (an aligned square grid of integer pitch, sliced exactly) or
lfcl.demosaic.resampled.solve_resampled, then the safety net where it applies.

``malvar``     2D Malvar-He-Cutler on the whole lenslet mosaic (the paper's baseline).
``admm-uv``    ADMM-TV with the prior over (u, v): within each microlens.
``admm-st``    ADMM-TV over (s, t): across microlenses, within each view.
``admm-uvst``  ADMM-TV over all four dims.
``linear4d``   a learned 4D linear filter per CFA phase and (u, v), coefficients by noise level
               (docs/linear4d.md); no iterations, no Malvar start.
``admm-uv-xc``, ``admm-uvst-xc``  ADMM with TV plus the cross-channel prior
               ``lam_xc ||D (x_R - x_G)||_1 + lam_xc ||D (x_B - x_G)||_1`` over (u, v),
               resp. (u, v, s, t) (docs/admm.md, "The cross-channel prior").
``admm-epi``   ADMM with differences along each sample's epipolar line, the disparity estimated from
               the raw (lfcl.depth), and a (u, v) fall-back where its confidence is low; its lam, stop
               and start (guarded below about 5e-3 sigma, else Malvar) follow the noise
               (lfcl/solvers/epi.py EPI_SCHEDULE; docs/admm.md, "admm-epi").

Every ADMM method starts from the Malvar result. Its defaults follow the noise
level ``sigma`` (rms noise per raw pixel, normalised units) estimated from the raw
(lfcl/noise/model.py): ``lam = lam_per_sigma * sigma`` and, for the early-stopped
methods, stop when ``rms(x_k - x_{k-1}) <= change_per_sigma * sigma``. The
numbers come from the sweep documented in docs/admm.md. The cross-channel weight
follows sigma the same way, ``lam_xc = xc_per_sigma * sigma`` (with an explicit
lam it keeps its default ratio to lam). ``strength`` multiplies lam (and lam_xc)
for scenes that want more or less smoothing.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import time

import numpy as np

from ..device import get_runtime, memory_text
from ..grid.vignetting import flat_field
from ..layout import LightFieldShape
from ..noise.model import NoiseEstimate, estimate_noise
from ..ops.lenscopy import LensCopy
from ..ops.malvar import Malvar, malvar_planes
from ..ops.reduce import Reductions
from ..solvers.admm import AdmmSolver, solver_bytes, solver_largest_buffer
from ..solvers.params import AdmmParams, BandedResult
from .flat_lenses import FLAT_P, SKIPPABLE, fill_flat, flat_lenses_on_device, pack_lenses
from .names import METHODS, STARTS  # noqa: F401  (STARTS: re-exported for lfcl.pipeline.stages and lfcl.bench)


@dataclasses.dataclass(frozen=True)
class AdmmDefaults:
    """How an ADMM method's parameters follow the noise level."""

    dims: str
    lam_per_sigma: float
    change_per_sigma: float  # 0: no early stop on the change of x
    max_iter: int
    rho: float = 0.3
    cg_steps: int = 4
    xc_per_sigma: float = 0.0  # cross-channel prior weight / sigma; 0: no cross-channel prior
    fb_per_sigma: float = 0.0  # admm-epi's fall-back weight lam_fb / sigma (dims "epi": lfcl/solvers/epi.py)


# From the sweep in docs/admm.md (python research/sweep.py): the rule with the best
# worst-case centre-view gain over Malvar across charts/deadleaves at 1-50 lux, among
# rules that never lose more than 0.3 dB on the mean image.
ADMM_DEFAULTS = {
    "admm-uv": AdmmDefaults(dims="uv", lam_per_sigma=0.1, change_per_sigma=0.1, max_iter=60),
    "admm-st": AdmmDefaults(dims="st", lam_per_sigma=0.01, change_per_sigma=0.0, max_iter=5),
    "admm-uvst": AdmmDefaults(dims="uvst", lam_per_sigma=0.01, change_per_sigma=0.0, max_iter=10),
    # uv-xc: python research/fit_uv_xc.py (docs/admm.md, "The cross-channel prior"; the training captures with
    # the lens-scale gratings among them, as `lfcl process` runs it, the safety net on): never below Malvar on any of
    # them at 0.5-50 lux, the best worst centre-view gain (+0.40 dB; 0.15 / 0.03 before, from sweep_xc.py on charts
    # and deadleaves only, fell to -0.32 on a grating). uvst-xc (research/sweep_xc.py), like uvst, stays close to
    # Malvar because (s, t) smoothing costs deadleaves' mean image.
    "admm-uv-xc": AdmmDefaults(dims="uv", lam_per_sigma=0.12, change_per_sigma=0.1, max_iter=45, xc_per_sigma=0.09),
    "admm-uvst-xc": AdmmDefaults(dims="uvst", lam_per_sigma=0.03, change_per_sigma=0.05, max_iter=60,
                                 xc_per_sigma=0.01),
    # The prior along the epipolar lines (dims "epi", lfcl/solvers/epi.py), from research/fit_epi.py
    # (docs/admm.md, "admm-epi"; training seeds 1, 2 of charts, deadleaves, finetexture, 48x48 lenses).
    # lam, lam_fb, the stop, the start and the x-update (CG steps, warm start) follow the noise by
    # lfcl/solvers/epi.py EPI_SCHEDULE (its rows at 2-12 lux are these lam and stop); this entry gives rho, and the
    # CG steps and the tolerance_db path where no noise level chooses them.
    "admm-epi": AdmmDefaults(dims="epi", lam_per_sigma=0.2, change_per_sigma=0.05, max_iter=40, rho=1.0, cg_steps=5,
                             fb_per_sigma=0.0),
}


def parse_method(method: str) -> str:
    if method not in METHODS:
        raise ValueError(f"unknown method {method!r}: expected one of {', '.join(METHODS)}")
    return method


def change_for_tolerance_db(tolerance_db: float) -> float:
    """The rms change per iteration, in units of sigma, that moves PSNR by at most ``tolerance_db``.

    If x_k has rms error e against the truth, then ||x_k+1 - t|| lies within e +- c
    for an rms change c, so PSNR moves by at most -20 log10(1 - c/e) dB; where
    e >= sigma, c <= (1 - 10^(-T/20)) sigma bounds the move by T dB. On the
    built-in scenes e >= sigma from about 8 lux (charts) and 2 lux (deadleaves) up;
    darker, the absolute errors are smaller and the bound is a guide (docs/auto.md).
    """
    if not (isinstance(tolerance_db, (int, float)) and math.isfinite(tolerance_db) and tolerance_db > 0):
        raise ValueError(f"tolerance must be a number of dB > 0, got {tolerance_db!r}")
    return 1.0 - 10.0 ** (-float(tolerance_db) / 20.0)


def tolerance_db_for_change(change_per_sigma: float) -> float:
    """The inverse of :func:`change_for_tolerance_db` (inf for a change of sigma or more)."""
    return -20.0 * math.log10(1.0 - change_per_sigma) if change_per_sigma < 1 else math.inf


def admm_params(method: str, sigma: float, *, lam=None, iterations=None, rho=None, strength=1.0,
                tolerance_db=None) -> AdmmParams:
    """The parameters ``method`` uses at noise level ``sigma`` (explicit values win).

    ``tolerance_db``: stop once an iteration can move PSNR by less than this
    (:func:`change_for_tolerance_db`) instead of the method's default rule; with
    ``iterations`` as well, that many iterations at most.
    """
    d = ADMM_DEFAULTS[parse_method(method)]
    if not (strength > 0):
        raise ValueError(f"strength must be > 0, got {strength!r}")
    sigma = max(float(sigma), 1e-6)
    # the cross-channel weight keeps its default ratio to an explicit lam
    lam_xc = (float(lam) * d.xc_per_sigma / d.lam_per_sigma if lam is not None and d.lam_per_sigma > 0
              else strength * d.xc_per_sigma * sigma)
    if tolerance_db is not None:
        return AdmmParams(
            lam=float(lam) if lam is not None else strength * d.lam_per_sigma * sigma,
            rho=float(rho) if rho is not None else d.rho,
            max_iter=int(iterations) if iterations is not None else max(d.max_iter, 60),
            cg_steps=d.cg_steps,
            change_tol=change_for_tolerance_db(tolerance_db) * sigma,
            lam_xc=lam_xc,
        )
    return AdmmParams(
        lam=float(lam) if lam is not None else strength * d.lam_per_sigma * sigma,
        rho=float(rho) if rho is not None else d.rho,
        max_iter=int(iterations) if iterations is not None else d.max_iter,
        cg_steps=d.cg_steps,
        # an explicit iteration count means "run that many"
        change_tol=d.change_per_sigma * sigma if iterations is None else 0.0,
        lam_xc=lam_xc,
    )


@dataclasses.dataclass
class DemosaicResult:
    """What lfcl.demosaic.driver.demosaic_grid returns on either kind of grid.

    ``planes`` [3, S*U, T*V] float32 (docs/layout.md) of a light field of ``shape``; :attr:`lightfield` is
    the same in the exchange layout. ``sampling``: the resampled grid's SamplingModel (None: aligned).
    """

    planes: np.ndarray  # [3, H, W] float32, docs/layout.md
    method: str
    parameters: dict
    iterations: int
    seconds: float
    stop_reason: str
    history: list
    noise: NoiseEstimate | None
    shape: LightFieldShape | None = None
    sampling: object = None  # lfcl.grid.resampling.SamplingModel of a resampled grid
    device: object = None  # the device it ran on (lfcl.device.get_runtime's spec), which also lays out the light field
    part_seconds: dict = dataclasses.field(default_factory=dict)  # parts of ``seconds`` timed apart (admm-epi: disparity)

    @functools.cached_property
    def lightfield(self) -> np.ndarray:
        """``[S, T, U, V, 3]`` float32: the planes in the exchange layout (made on first use, on the device:
        lfcl.ops.exchange; its numpy twin lfcl.layout.planes_to_exchange took 4x longer at 500x500 lenses)."""
        from ..device import get_runtime
        from ..ops.exchange import exchange_from_host_planes

        return exchange_from_host_planes(get_runtime(self.device), self.planes, self.shape)


def _check_finite(planes: np.ndarray, what: str, mosaic: np.ndarray):
    """A finite input can still overflow float32 (values near 3e38): say so, never return Inf."""
    if not np.all(np.isfinite(planes)):
        raise ValueError(f"{what} overflowed float32: the mosaic's values reach {float(np.abs(mosaic).max()):.3g}; "
                         "a normalised raw should lie near [0, 1]")


def lens_row_bands(lens_rows: int, per_row: tuple[int, int], limits: tuple[int, int]) -> list[tuple[int, int]]:
    """Split ``lens_rows`` into bands [s0, s1) that fit the device.

    per_row: (solver bytes, largest-buffer bytes) of one lens row; limits: (memory
    budget, largest allocation) of the device.
    """
    per_band = max(1, min(limit // max(need, 1) for need, limit in zip(per_row, limits)))
    return [(s0, min(s0 + per_band, lens_rows)) for s0 in range(0, lens_rows, per_band)]


def flat_threshold_for(method: str, skip_flat) -> float | None:
    """The p threshold ``demosaic_grid(skip_flat=...)`` tests lenses with (None: no test).

    None or False: off (the default: on fine texture off the focal plane the chi-square test took
    grain for noise and cost up to 5 dB, docs/auto.md); True: FLAT_P; a number in (0, 1): that
    threshold, for the methods whose prior couples no two lenses.
    """
    if skip_flat is None or skip_flat is False:  # off by default: it took fine texture for noise (docs/auto.md)
        return None
    if method not in SKIPPABLE:
        raise ValueError(f"skipping flat lenses needs a prior that couples no two lenses ({', '.join(SKIPPABLE)}), "
                         f"not {method}")
    if skip_flat is True:
        return FLAT_P
    if not isinstance(skip_flat, (int, float)) or not 0 < skip_flat < 1:
        raise ValueError(f"skip_flat must be True, False or a p threshold in (0, 1), got {skip_flat!r}")
    return float(skip_flat)


def _noise_model_or_why(noise, raw_mosaic, pattern, pitch, origin, asked, device=None) -> tuple:
    """(the noise model the flat-lens test and the safety net use, None) or (None, why there is none).

    Without a usable model the test cannot run; if it was not ``asked`` for (the default) the
    lenses are all solved and the outputs say why, if it was, that is an error.
    """
    why = None
    if noise is None:
        try:
            noise = estimate_noise(raw_mosaic, pattern, pitch, origin, device=device)
        except ValueError as e:
            why = f"not tested: no noise model ({e})"
    if why is None and not all(math.isfinite(v) and 0 <= v < 1e30 for v in (noise.gain, noise.floor)):
        why = f"not tested: the noise model (gain {noise.gain:.3g}, floor {noise.floor:.3g}) is out of range"
    if why is not None and asked is not None:
        raise ValueError(f"skipping flat lenses: {why.removeprefix('not tested: ')}")
    return (None, why) if why is not None else (noise, None)


def with_safety_net(result: DemosaicResult, mosaic, pattern, pitch, origin, lens_response, device) -> DemosaicResult:
    """``result`` after the safety net (lfcl/demosaic/safety_net.py), on the mosaic the method saw."""
    from .safety_net import apply_safety_net, net_k

    k = net_k(result.method)  # inf: no soft threshold, only the flat lenses' fill
    began = time.perf_counter()
    mosaic = np.ascontiguousarray(mosaic, dtype=np.float32)
    noise, why = _noise_model_or_why(result.noise, mosaic, pattern, pitch, origin, asked=None, device=device)
    if noise is None:  # a raw too small to estimate the noise from: the outputs say the net did not act
        report = {"lenses": 0, "lenses_from_malvar": 0, "why": why.replace("not tested", "not applied")}
        return dataclasses.replace(result, parameters={**result.parameters, "safety_net": report})
    lens_weights = None
    if lens_response is not None:
        mosaic, lens_weights = flat_field(mosaic, lens_response)
    planes, report = apply_safety_net(get_runtime(device), result.planes, mosaic, pattern, pitch, origin, noise, k,
                                      lens_weights)
    _check_finite(planes, "the safety net", mosaic)
    return dataclasses.replace(result, planes=planes, parameters={**result.parameters, "safety_net": report},
                               seconds=result.seconds + time.perf_counter() - began, noise=noise)


def solve_aligned(mosaic: np.ndarray, pattern: str, pitch, method: str, *, origin=(0, 0),
                  lam=None, iterations=None, rho=None, strength=1.0, noise: NoiseEstimate | None = None,
                  device=None, callback=None, max_memory: int | None = None,
                  lens_response=None, tolerance_db: float | None = None,
                  start: str | None = None, skip_flat: bool | float | None = None, disparity=None) -> DemosaicResult:
    """Demosaic (and denoise) a normalised lenslet mosaic [H, W] of an aligned grid into [3, H, W] planes.

    Called by lfcl.demosaic.driver.demosaic_grid, which has checked the input (H and W whole
    multiples of the pitch, finite values, a known method and start) and resolved ``auto``; the
    safety net is the driver's too. ``noise`` defaults to an estimate from the mosaic (used by
    the ADMM methods only). ``max_memory`` (bytes, default: 80 % of the device's global memory)
    bounds the solver's device buffers: a larger admm-uv problem runs in bands of lens rows, which
    is exact because the (u, v) prior couples no two lenses (each band stops on its own rule);
    the other priors couple neighbouring lenses and say so instead.
    ``lens_response`` [U, V] (the white image's vignetting, lfcl/grid/vignetting.py):
    flat-field the mosaic, and for the ADMM methods weight the data term by the
    response squared, leaving the dark corners out.
    ``tolerance_db``: stop when an iteration can move PSNR by less than this many dB
    (:func:`admm_params`); default: the method's own rule.
    ``start`` (ADMM methods): the first estimate, ``"malvar"`` (the paper's, and the
    default), ``"linear4d"`` (the learned 4D filter, which also reads the neighbouring
    lenses: measured in docs/auto.md, it gains on textured and multi-plane scenes and
    loses on large flat in-focus patches), ``"lens-malvar"`` (Malvar bounded to each
    lens, so that no filter mixes two micro-images; docs/auto.md) or ``"guarded"`` (linear4d, with
    Malvar in the lenses where the two disagree far more than in the rest of the frame: high-contrast
    edges and clipped highlights, where linear4d breaks; with admm-epi also where the epipolar lines carry
    one colour, so that the missing colours are the start's, and where the disparity sits at an end of the search
    range without confidence; lfcl/demosaic/guarded_start.py, recorded in
    ``parameters["start_guard"]``).
    ``skip_flat`` (admm-uv, admm-uv-xc): lenses that are flat within the noise (a chi-square
    test, lfcl/demosaic/flat_lenses.py) get their colour means and the solve runs on the others only,
    packed into a smaller mosaic; None or False: off (the default: the test took fine texture
    for noise, docs/auto.md), True: on at p threshold FLAT_P, a number: that p threshold.
    Recorded in ``parameters["flat_lenses"]``; ``callback``'s x is then the packed mosaic's.
    ``disparity``: an ``lfcl.depth.DisparityMap`` already estimated from this mosaic (the depth output's); admm-epi
    takes it instead of estimating its own (lfcl/solvers/epi.py demosaic_epi), the other methods ignore it.
    """
    mosaic = np.ascontiguousarray(mosaic, dtype=np.float32)
    U, V = pitch
    flat_threshold = flat_threshold_for(method, skip_flat)
    raw_mosaic, lens_weights = mosaic, None
    if lens_response is not None:
        mosaic, lens_weights = flat_field(mosaic, lens_response)
    runtime = get_runtime(device)
    began = time.perf_counter()
    if method == "linear4d":  # learned 4D linear filter, coefficients picked by the noise (docs/linear4d.md)
        from ..ops.linear4d import linear4d

        noise = noise if noise is not None else estimate_noise(raw_mosaic, pattern, pitch, origin, device=device)
        planes = linear4d(runtime, mosaic, pattern, pitch, origin, noise)
        _check_finite(planes, "linear4d", mosaic)
        return DemosaicResult(planes, method, {}, 0, time.perf_counter() - began, "direct", [], noise)
    if method == "malvar":
        planes = malvar_planes(runtime, mosaic, pattern, origin)
        _check_finite(planes, "malvar", mosaic)
        return DemosaicResult(planes, method, {}, 0, time.perf_counter() - began, "direct", [], None)
    b = runtime.to_device(mosaic)
    epi_start_replaced = None
    # admm-epi's start follows the noise (lfcl/solvers/epi.py EPI_SCHEDULE), unless lam and iterations are given
    # and there is no noise model: then nothing is estimated and it starts from Malvar
    if method == "admm-epi" and start is None and (noise is not None or lam is None or iterations is None):
        from ..solvers.epi import epi_start

        noise = noise if noise is not None else estimate_noise(raw_mosaic, pattern, pitch, origin, device=device)
        start, epi_start_replaced = epi_start(noise.sigma, pitch)
    start = start or "malvar"
    guard = None
    depth, depth_seconds = disparity, None  # admm-epi's: the one given, else estimated for the start or the solve
    if method == "admm-epi" and depth is not None:
        from ..solvers.epi import check_depth

        check_depth(depth, mosaic.shape, pitch)
    if start in ("linear4d", "guarded"):
        from ..ops.linear4d import linear4d_operator

        noise = noise if noise is not None else estimate_noise(raw_mosaic, pattern, pitch, origin, device=device)
        x0 = linear4d_operator(runtime, mosaic, pattern, pitch, origin, noise).forward(b)
        if start == "guarded":  # Malvar in the lenses where linear4d breaks (lfcl/demosaic/guarded_start.py)
            from .guarded_start import guarded_start

            if method == "admm-epi" and depth is None:  # and where the lines admm-epi follows cannot mend it
                from ..solvers.epi import epi_disparity

                depth, depth_seconds = epi_disparity(raw_mosaic, pattern, pitch, origin, noise, device)
            flat = None
            if method == "admm-epi":  # lenses flat within the noise have no lines to get wrong
                flat = flat_lenses_on_device(runtime, b, mosaic, pattern, pitch, noise, origin=origin,
                                             lens_weights=lens_weights).flat
            malvar = Malvar(runtime, mosaic.shape, pattern, origin).forward(b)
            colour = 0.0
            if method == "admm-epi":  # its schedule's colour differences (lfcl/solvers/epi.py EpiSetting)
                from ..solvers.epi import epi_setting

                colour = epi_setting(max(float(noise.sigma), 1e-6)).malvar_colour
            x0, guard = guarded_start(runtime, x0, malvar, b, pitch, noise, depth=depth, flat=flat,
                                      malvar_colour=colour)
            del malvar
    else:  # lens-malvar: Malvar bounded to each lens, so that no filter reads a neighbouring micro-image
        x0 = Malvar(runtime, mosaic.shape, pattern, origin, lens=pitch if start == "lens-malvar" else None).forward(b)
    if not math.isfinite(Reductions(runtime).abs_sum(x0)):  # on the device: no 3-plane copy to the host
        _check_finite(np.array([np.inf]), f"the {start} start", mosaic)
    defaults = ADMM_DEFAULTS[method]
    needs_sigma = lam is None or tolerance_db is not None or (iterations is None and defaults.change_per_sigma > 0) \
        or (defaults.dims == "epi" and iterations is None)  # its stop follows the noise (lfcl/solvers/epi.py)
    if noise is None and needs_sigma:
        noise = estimate_noise(raw_mosaic, pattern, pitch, origin, device=device)  # the raw's, as lambda expects
    sigma = noise.sigma if noise is not None else 0.0  # unused when lam and iterations are given
    params = admm_params(method, sigma, lam=lam, iterations=iterations, rho=rho, strength=strength,
                         tolerance_db=tolerance_db)
    dims = ADMM_DEFAULTS[method].dims
    found, packing, real, full_shape = None, None, None, (3, *mosaic.shape)
    flat_noise, flat_why = None, "not tested (skip_flat off)"
    if flat_threshold is not None:
        flat_noise, flat_why = _noise_model_or_why(noise, raw_mosaic, pattern, pitch, origin, asked=skip_flat,
                                                   device=device)
        noise = noise if noise is not None else flat_noise
    if flat_noise is not None:  # flat lenses get their colour means and leave the solve (lfcl/demosaic/flat_lenses.py)
        found = flat_lenses_on_device(runtime, b, mosaic, pattern, pitch, flat_noise, origin=origin,
                                      lens_weights=lens_weights, threshold=flat_threshold)
        packing = pack_lenses(~found.flat) if found.flat.any() else None
        if packing is not None and packing.grid[0] == packing.full[0] and not found.flat.all():
            packing = None  # too few to shrink the solver: packing, filling and a new size would only cost
        if packing is not None:  # the lenses still to solve, side by side, on the device
            real = packing.real
            copy = LensCopy(runtime, pitch)
            table = copy.upload(packing.pairs())
            packed_shape = (packing.grid[0] * U, packing.grid[1] * V)
            b = copy(b, runtime.empty(packed_shape), table)
            x0 = copy(x0, runtime.empty((3, *packed_shape)), table)
    H, W = b.shape
    if dims == "epi":  # the prior along the epipolar lines, with the disparity from the raw (lfcl/solvers/epi.py)
        from ..solvers.epi import demosaic_epi, epi_params

        if tolerance_db is None and noise is not None:  # lam, lam_fb and the stop follow the noise (EPI_SCHEDULE)
            params, lam_fb = epi_params(params, sigma, lam=lam, iterations=iterations, strength=strength)
        else:
            lam_fb = params.lam * defaults.fb_per_sigma / defaults.lam_per_sigma
        planes, extra, run, depth_seconds = demosaic_epi(runtime, raw_mosaic, b, x0, pattern, pitch, origin, params,
                                                         lam_fb, noise, device, lens_weights, callback, max_memory,
                                                         depth=depth, depth_seconds=depth_seconds)
        parameters = {**dataclasses.asdict(params), "start": start, **extra}
        if epi_start_replaced is not None:
            parameters["start_replaced"] = epi_start_replaced
        if guard is not None:
            parameters["start_guard"] = guard
        return DemosaicResult(planes, method, parameters, run.iterations, time.perf_counter() - began,
                              run.stop_reason, run.history_rows(), noise,
                              part_seconds={} if disparity is not None else {"disparity": depth_seconds})
    budget = int(max_memory) if max_memory is not None else int(0.8 * runtime.device.global_mem_size)
    needed = solver_bytes((H, W), dims, exact=dims == "uv", cross_channel=params.cross_channel)
    largest = solver_largest_buffer((H, W), dims)
    fits = needed <= budget and largest <= runtime.device.max_mem_alloc_size

    def samples_in(rows: slice) -> int | None:
        """The samples the stop rule's rms change is over, for these sensor rows (None: all of x).

        Packed: the solved lenses' samples, not the padding's. The flat lenses are final and are
        not counted either: counted with change 0 they stopped the busy lenses early, at up to
        0.4 dB below the plain solve (docs/auto.md).
        """
        return None if real is None else int(real[rows.start // U:rows.stop // U].sum()) * 3 * U * V

    def solve(solver, b, x0, samples):
        return solver.solve(b, x0, params, callback=callback, lens_weights=lens_weights, samples=samples)

    planes_packed = packing is not None  # planes on the host that hold the packed lenses only
    if real is not None and not real.any():  # every lens is flat: nothing to solve
        planes, runs, band_rows = np.zeros((3, H, W), np.float32), [], []
    elif fits:
        result = solve(AdmmSolver(runtime, (H, W), pattern, pitch, dims, origin), b, x0, samples_in(slice(0, H)))
        x, runs, band_rows = result.x, [dataclasses.replace(result, x=None)], [H]
        if packing is not None:  # the solved lenses back to their places and the flat ones' means, on the device
            del b, x0, result  # the solver's buffers go; x and the full planes fit where the full start was
            x = copy(x, runtime.empty(full_shape), copy.upload(packing.unpack_pairs()))
            copy.fill(x, *found.flat_means())
            planes_packed = False
        planes = x.get()
    elif dims == "uv":
        per_row = (solver_bytes((U, W), dims, exact=True, cross_channel=params.cross_channel),
                   solver_largest_buffer((U, W), dims))
        bands = lens_row_bands(H // U, per_row, (budget, runtime.device.max_mem_alloc_size))
        x0_host = x0.get()
        del b, x0
        if packing is not None:
            mosaic = packing.pack(mosaic, pitch)
        planes, runs = np.zeros_like(x0_host), []
        band_rows, solver, solver_key = [], None, None
        for s0, s1 in bands:
            rows = slice(s0 * U, s1 * U)
            if samples_in(rows) == 0:  # padding rows of a packed mosaic
                continue
            key = (rows.stop - rows.start, (origin[0] + rows.start) % 2)
            if key != solver_key:  # one solver alive at a time: the budget is for one band's buffers
                solver = None
                solver, solver_key = AdmmSolver(runtime, (key[0], W), pattern, pitch, dims,
                                                (origin[0] + rows.start, origin[1])), key
            result = solve(solver, runtime.to_device(mosaic[rows]), runtime.to_device(x0_host[:, rows]),
                           samples_in(rows))
            planes[:, rows] = result.x.get()
            runs.append(dataclasses.replace(result, x=None))  # the band's planes are on the host now
            band_rows.append(rows.stop - rows.start)
    else:
        raise ValueError(
            f"{method} on a {H}x{W} sensor needs about {memory_text(needed)} of device memory "
            f"(largest buffer {memory_text(largest)}) but {runtime.name} allows {memory_text(budget)} "
            f"(max allocation {memory_text(runtime.device.max_mem_alloc_size)}); its prior couples "
            "neighbouring lenses, so it does not run in bands: use admm-uv, a crop, or a larger device"
        )
    if planes_packed:  # the solved lenses back to their places, the flat ones to their means
        planes = fill_flat(packing.unpack(planes, np.empty(full_shape, np.float32), pitch), found, pitch)
    if not np.all(np.isfinite(planes)):
        raise FloatingPointError(f"{method} produced NaN/Inf values; try a smaller lambda or rho")
    banded = BandedResult(runs, band_rows)
    reason = "every lens is flat: no iterations" if not runs else banded.stop_reason
    parameters = dataclasses.asdict(params)
    parameters["start"] = start
    if guard is not None:
        parameters["start_guard"] = guard
    if found is not None:
        parameters["flat_lenses"] = found.as_dict(packing.grid[0] if packing is not None else None)
    elif dims == "uv":
        parameters["flat_lenses"] = {"flat_lenses": 0, "why": flat_why}
    if len(runs) > 1:  # as admm-epi records its own: each band stops on its own rule
        parameters["bands"] = {"rows": list(band_rows), "iterations": [run.iterations for run in runs],
                               "rows_are": "mosaic rows each band solved (of the packed mosaic with --skip-flat)"}
    return DemosaicResult(planes, method, parameters, banded.iterations, time.perf_counter() - began, reason,
                          banded.history_rows(), noise)
