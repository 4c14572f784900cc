"""The solver of resampled lens grids (rotated, non-integer pitch, hexagonal): a regular light field from the raw.

lfcl.demosaic.driver.demosaic_grid runs :func:`solve_resampled` for a :class:`lfcl.grid.model.ResampledGrid`
(an aligned square grid of integer pitch is sliced exactly instead, lfcl/demosaic/methods.py); docs/geometry.md.

``malvar``     2D Malvar-He-Cutler on the flat-fielded sensor, then the resampling
               map ``M`` onto the regular light field (lfcl/grid/resampling.py).
``admm-uv``    ADMM-TV with the resampling inside the forward operator: ``A`` maps the
``admm-st``    regular light field onto the measured sensor pixels, so the solver
``admm-uvst``  fits real sensor samples, never interpolated colours
               (lfcl/solvers/resampled.py). Starts from the malvar result.
``auto``       resolved by the driver (lfcl.demosaic.driver.resolve_auto): Malvar, since every prior
               here lost to it on most training captures (lfcl.demosaic.auto.on_resampled_grid).

Defaults follow lfcl.demosaic.methods.ADMM_DEFAULTS (lambda per sigma, the stopping rule)
with the corrections of :data:`GRID_TUNING`, measured on resampled grids
(docs/geometry.md); the x-update is always CG here, :data:`GRID_CG_STEPS` steps.

Example::

    >>> import numpy as np
    >>> from lfcl.demosaic.driver import demosaic_grid
    >>> from lfcl.grid.model import ResampledGrid
    >>> from lfcl.sim.geometry import GridGeometry
    >>> geometry = GridGeometry((60, 60), "hex", 9.4, 0.7, (0.2, 0.1))
    >>> mosaic = (0.3 * geometry.white_expected("GRBG", 1.0)).astype(np.float32)
    >>> result = demosaic_grid(mosaic, "GRBG", ResampledGrid.of(geometry, "GRBG"), "malvar")
    >>> result.lightfield.shape[2:]
    (9, 9, 3)
"""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np

from ..grid.resampling import SamplingModel
from ..noise.model import NoiseEstimate
from .methods import ADMM_DEFAULTS, DemosaicResult, admm_params

# CG steps per ADMM iteration (the aligned admm-uv solves its x-update exactly; here
# A^T W A differs from lens to lens, so CG it is). See docs/geometry.md for the measurement.
GRID_CG_STEPS = 4


@dataclasses.dataclass(frozen=True)
class GridTuning:
    """How a method's defaults on a resampled grid differ from lfcl.demosaic.methods.ADMM_DEFAULTS."""

    strength: float = 1.0  # multiplies lam_per_sigma
    change_factor: float = 1.0  # multiplies change_per_sigma (the early stop)
    interpolation_weight: float = 0.0  # lfcl.grid.resampling.SamplingModel.data


# From the sweep in docs/geometry.md (charts and deadleaves, square and hex grids at pitch 9.4 and
# 0.7 degrees, 0.5-12 lux; tuned on seed 1, checked on seed 0): the aligned admm-uv rule loses up to
# 0.7 dB on the centre view against malvar, because the bilinear A is inverted (the data fit
# sharpens what the resampling blurs) and pixels between samples are the worst modelled. Twice
# lambda, down-weighting those pixels and stopping once the change falls below 0.8 sigma (after
# 3 iterations in every case measured) gains on every setting measured. admm-st/uvst (measured at
# 1 lux only): the down-weighting halves their loss on the centre view; they still lose to malvar there.
GRID_TUNING = {
    "admm-uv": GridTuning(strength=2.0, change_factor=8.0, interpolation_weight=3.0),
    "admm-st": GridTuning(interpolation_weight=3.0),
    "admm-uvst": GridTuning(interpolation_weight=3.0),
}


def resample_start(runtime, sampling: SamplingModel, mosaic: np.ndarray):
    """The malvar result on the device: Malvar of the flat-fielded sensor, resampled (planes [3, S*U, T*V])."""
    from ..ops.malvar import Malvar
    from ..ops.resample import SparseOperator

    H, W = sampling.sensor_shape
    sensor = Malvar(runtime, (H, W), sampling.pattern).forward(runtime.to_device(sampling.flat_field(mosaic)))
    resample = SparseOperator(runtime, sampling.resample_matrix(), planes=3, in_shape=(3, H, W),
                              out_shape=sampling.planes_shape)
    return resample.forward(sensor)


def solve_resampled(mosaic: np.ndarray, sampling: SamplingModel, method: str, *, lam=None, iterations=None,
                    rho=None, strength: float = 1.0, cg_steps: int | None = None,
                    interpolation_weight: float | None = None, noise: NoiseEstimate | None = None, device=None,
                    callback=None, max_memory: int | None = None, tolerance_db: float | None = None
                    ) -> DemosaicResult:
    """Demosaic (and denoise) a normalised lenslet raw ``mosaic`` [H, W] of the lens grid of ``sampling``.

    Called by lfcl.demosaic.driver.demosaic_grid, which has checked the input (the whole sensor,
    ``sampling.sensor_shape``, finite; a method of :data:`lfcl.demosaic.names.RESAMPLED_METHODS`) and resolved
    ``auto``. ``mosaic`` is ``(raw - black) / (white - black)``, not flat-fielded (this function divides by
    the white response).

    ``noise``: the raw's noise model (e.g. ``lfcl.noise.model.from_noise_profile``);
    lambda uses its sigma *at the mean level of the measured pixels*
    (``noise.sigma_at``), whatever level it was made for. None: estimated from the
    raw (lfcl/noise/resampled.py). ``lam``, ``iterations``, ``rho``, ``strength`` as on aligned grids
    (``strength`` multiplies the grid default of :data:`GRID_TUNING`); ``cg_steps`` (default
    :data:`GRID_CG_STEPS`); ``interpolation_weight`` (:meth:`lfcl.grid.resampling.SamplingModel.data`; default
    from :data:`GRID_TUNING`).
    ``callback(record, x)`` after every ADMM iteration. ``max_memory`` bytes
    (default 80 % of the device's): a larger problem is a ``ValueError`` (no bands yet).
    ``tolerance_db``: stop once an iteration can move PSNR by less than this many dB
    (lfcl.demosaic.methods.admm_params, docs/auto.md) instead of the grid's stopping rule (the
    :data:`GRID_TUNING` change factor then does not apply); ignored by malvar.

    Returns a :class:`lfcl.demosaic.methods.DemosaicResult`: ``planes`` [3, S*U, T*V] (``lightfield``
    [S, T, U, V, 3] float32) and ``sampling`` (its ``as_meta()`` for metadata).
    """
    from ..device import get_runtime
    from ..ops.reduce import Reductions

    runtime = get_runtime(device)
    start = time.perf_counter()
    x0 = resample_start(runtime, sampling, mosaic)
    shape = sampling.shape
    if method == "malvar":
        planes = _finite(x0.get(), "malvar", mosaic)
        return DemosaicResult(planes, method, {}, 0, time.perf_counter() - start, "direct", [], None, shape, sampling)
    if not math.isfinite(Reductions(runtime).abs_sum(x0)):
        _finite(np.array([np.inf]), "the Malvar start", mosaic)
    pixels, level = measured(sampling, mosaic)
    defaults = ADMM_DEFAULTS[method]
    if noise is None and (lam is None or tolerance_db is not None
                          or (iterations is None and defaults.change_per_sigma > 0)):
        from ..noise.resampled import estimate_grid_noise

        noise = estimate_grid_noise(mosaic, sampling)
    sigma = noise.sigma_at(level) if noise is not None else 0.0
    tuning = GRID_TUNING.get(method, GridTuning())
    params = admm_params(method, sigma, lam=lam, iterations=iterations, rho=rho, strength=strength * tuning.strength,
                         tolerance_db=tolerance_db)
    # the grid's later stop (change_factor) tunes the default rule; a tolerance in dB is the user's own
    change_factor = tuning.change_factor if tolerance_db is None else 1.0
    params = dataclasses.replace(params, change_tol=params.change_tol * change_factor,
                                 cg_steps=int(cg_steps if cg_steps is not None else GRID_CG_STEPS), x_update="cg")
    if interpolation_weight is None:
        interpolation_weight = tuning.interpolation_weight
    matrix = sampling.forward_matrix(pixels)
    b, weights = sampling.data(mosaic, pixels, interpolation_weight)
    _check_memory(runtime, max_memory, pixels.size, matrix.nnz, shape, defaults.dims, method)
    from ..solvers.resampled import ResampledAdmmSolver

    solver = ResampledAdmmSolver(runtime, matrix, (shape.S, shape.T, shape.U, shape.V), defaults.dims)
    result = solver.solve(runtime.to_device(b), runtime.to_device(weights), x0, params, callback=callback)
    planes = result.x.get()
    if not np.all(np.isfinite(planes)):
        raise FloatingPointError(f"{method} produced NaN/Inf values; try a smaller lambda or rho")
    history = [dict(dataclasses.asdict(r), band=0) for r in result.history]
    parameters = {**dataclasses.asdict(params), "sigma": sigma, "interpolation_weight": interpolation_weight,
                  "start": "malvar"}  # the resampled path starts from Malvar (2D), then resampled
    return DemosaicResult(planes, method, parameters, result.iterations, time.perf_counter() - start,
                          result.stop_reason, history, noise, shape, sampling)


def measured(sampling: SamplingModel, mosaic: np.ndarray):
    """The data term's pixels and their mean raw level (the level sigma is taken at)."""
    pixels = sampling.measured_pixels()
    if pixels.size == 0:
        raise ValueError("no sensor pixel is bright enough in the white image to measure the light field")
    return pixels, float(np.mean(mosaic.ravel()[pixels], dtype=np.float64))


def _finite(planes: np.ndarray, what: str, mosaic: np.ndarray) -> np.ndarray:
    if not np.all(np.isfinite(planes)):
        raise ValueError(f"{what} overflowed float32: the mosaic's values reach {float(np.abs(mosaic).max()):.3g}; "
                         "a normalised raw should lie near [0, 1]")
    return planes


def _check_memory(runtime, max_memory, n_pixels, nnz, shape, dims, method):
    from ..device import memory_text
    from ..solvers.resampled import resampled_solver_bytes

    budget = int(max_memory) if max_memory is not None else int(0.8 * runtime.device.global_mem_size)
    needed = resampled_solver_bytes(n_pixels, nnz, (shape.S, shape.T, shape.U, shape.V), dims)
    largest = 4 * len(dims) * 3 * shape.S * shape.T * shape.U * shape.V
    if needed > budget or largest > runtime.device.max_mem_alloc_size:
        raise ValueError(f"{method} on this {shape.S}x{shape.T}-lens grid needs about {memory_text(needed)} of "
                         f"device memory (largest buffer {memory_text(largest)}) but {runtime.name} allows "
                         f"{memory_text(budget)}: resampled grids do not run in bands yet; use a crop or a "
                         "larger device")
