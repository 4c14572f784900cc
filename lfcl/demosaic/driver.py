"""The one entry point of demosaicing: :func:`demosaic_grid` on either kind of lens grid (lfcl/grid/model.py).

1. check the input: the method and start against the grid (one-line ValueErrors), the mosaic against the grid;
2. resolve ``auto`` once, up front (:func:`resolve_auto`: the rule's pick for the raw's noise level, made
   runnable on this grid; its record goes into ``parameters["auto"]``);
3. run the solver of the grid: lfcl.demosaic.methods.solve_aligned (an aligned square grid, sliced exactly)
   or lfcl.demosaic.resampled.solve_resampled (any other calibrated grid, through its sampling model);
4. the safety net where the grid has one (aligned: lfcl/demosaic/safety_net.py), for every method but Malvar.

It returns one :class:`lfcl.demosaic.methods.DemosaicResult` (``planes``, ``lightfield``, ``parameters``, ...).

Example::

    >>> import numpy as np
    >>> from lfcl.grid.model import AlignedGrid
    >>> mosaic = np.random.default_rng(0).random((36, 45), dtype=np.float32)
    >>> result = demosaic_grid(mosaic, "GRBG", AlignedGrid(9), "malvar")
    >>> result.lightfield.shape
    (4, 5, 9, 9, 3)
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..grid.model import AlignedGrid, ResampledGrid
from ..layout import LightFieldShape
from ..noise.model import NoiseEstimate
from .methods import DemosaicResult, change_for_tolerance_db, solve_aligned, with_safety_net
from .names import SKIPPABLE


@dataclasses.dataclass(frozen=True)
class AutoResolution:
    """What ``auto`` runs on a raw (:func:`resolve_auto`)."""

    method: str
    strength: float  # multiplies the caller's strength
    start: str | None  # the ADMM start the rule names (None: the method's own; a start the caller gives wins)
    noise: NoiseEstimate  # the raw's noise model the choice was made at (the solver uses it too)
    record: dict  # parameters["auto"]: lfcl.demosaic.auto.AutoChoice.as_dict() (+ "replaced" when it fell back)


def resolve_auto(mosaic: np.ndarray, pattern: str, grid, *, noise: NoiseEstimate | None = None,
                 view: str = "both", costly: bool = True, device=None) -> AutoResolution:
    """``auto`` on ``mosaic`` (normalised, not flat-fielded) of ``grid``: lfcl.demosaic.auto.choose once, at the
    sigma the grid's lambda uses, judged on ``view`` (lfcl.demosaic.auto.VIEWS), then made runnable here;
    ``costly`` False: from the rule fitted without the costly methods (``--auto-cheap``).

    Aligned grids: sigma of ``noise`` (None: estimated from the raw), and the raw's cross-lens ratio
    (lfcl/demosaic/lens_ratio.py) is recorded. Resampled grids run Malvar (lfcl.demosaic.auto.on_resampled_grid),
    with no noise estimate. linear4d on a pitch it has no coefficients for is replaced as
    lfcl.demosaic.auto.for_pitch says; the replaced pick goes into the record's ``replaced``. A frame narrower
    than lfcl.demosaic.auto.min_lenses on a side runs Malvar (lfcl.demosaic.auto.small_frame), before any noise
    estimate.
    """
    from . import auto

    if isinstance(grid, AlignedGrid):
        lenses, pitch = (mosaic.shape[0] // grid.pitch[0], mosaic.shape[1] // grid.pitch[1]), grid.pitch
    else:
        lenses, pitch = grid.sampling.lenses, grid.sampling.views
    small = auto.small_frame(lenses, pitch)
    if small is not None:  # before the noise estimate, which a frame of a few lenses may not allow
        return AutoResolution(small.method, 1.0, None, noise, {**small.as_dict(), "view": view, "costly": costly})
    if not isinstance(grid, AlignedGrid):
        malvar = auto.on_resampled_grid(grid.words)
        return AutoResolution(malvar.method, 1.0, None, noise, {**malvar.as_dict(), "view": view, "costly": costly})
    from ..noise.model import estimate_noise
    from .lens_ratio import cross_lens_ratio

    noise = noise if noise is not None else estimate_noise(mosaic, pattern, grid.pitch, grid.origin, device=device)
    lens_ratio = cross_lens_ratio(mosaic, grid.pitch, noise, grid.lens_response)  # content like the training's?
    choice = auto.choose(noise.sigma, lens_ratio=lens_ratio, view=view, costly=costly)
    ran, replaced = auto.for_pitch(choice, grid.pitch)
    return AutoResolution(ran.method, ran.strength, ran.start, noise,
                          {**ran.as_dict(), **({"replaced": replaced} if replaced else {})})


def _checked_mosaic(mosaic, pattern: str | None, grid) -> np.ndarray:
    """``mosaic`` as contiguous float32 [H, W] that fits ``grid`` (whole lenses of an aligned grid, the sensor of
    a resampled one), or a one-line ValueError."""
    grid.check_complete()
    mosaic = np.ascontiguousarray(mosaic, dtype=np.float32)
    if mosaic.ndim != 2:
        raise ValueError(f"mosaic must be 2D [H, W], got shape {mosaic.shape}")
    H, W = mosaic.shape
    if isinstance(grid, AlignedGrid):
        if pattern is None:
            raise ValueError("an aligned lens grid needs the raw's Bayer pattern (pattern='GRBG', ...)")
        U, V = grid.pitch
        if H < U or W < V:
            raise ValueError(f"mosaic {H}x{W} is smaller than one {U}x{V} lens")
        if H % U or W % V:
            raise ValueError(f"mosaic {H}x{W} is not a whole number of {U}x{V} lenses")
        if grid.lenses is not None and grid.lenses != (H // U, W // V):
            raise ValueError(f"mosaic {H}x{W} holds {H // U}x{W // V} lenses of {U}x{V}, but the lens grid has "
                             f"{grid.lenses[0]}x{grid.lenses[1]}")
    else:
        from ..layout import parse_pattern

        if pattern is not None and parse_pattern(pattern) != grid.sampling.pattern:
            raise ValueError(f"the raw is {parse_pattern(pattern)} but the sampling model is for "
                             f"{grid.sampling.pattern}")
        if grid.sampling.sensor_shape != (H, W):
            h, w = grid.sampling.sensor_shape
            raise ValueError(f"the lens grid is for a {h}x{w} sensor but the raw is {H}x{W}")
    if not np.all(np.isfinite(mosaic)):
        raise ValueError("mosaic holds NaN or Inf values")
    return mosaic


def demosaic_grid(mosaic: np.ndarray, pattern: str | None, grid, method: str, *, lam=None, iterations=None,
                  rho=None, strength: float = 1.0, noise: NoiseEstimate | None = None, device=None, callback=None,
                  max_memory: int | None = None, tolerance_db: float | None = None, start: str | None = None,
                  skip_flat: bool | float | None = None, auto_view: str = "both", auto_costly: bool = True,
                  safety_net: bool = True, cg_steps: int | None = None, interpolation_weight: float | None = None,
                  disparity=None) -> DemosaicResult:
    """Demosaic (and denoise) a normalised lenslet raw ``mosaic`` [H, W] on ``grid`` (module docstring).

    ``grid``: a :class:`lfcl.grid.model.AlignedGrid` (``mosaic`` holds whole lenses of its pitch, cut at its
    ``origin``; its ``lens_response`` flat-fields the mosaic and weights the data term) or a
    :class:`lfcl.grid.model.ResampledGrid` (``mosaic`` is the whole sensor of its sampling model, not
    flat-fielded). ``pattern``: the raw's Bayer pattern (resampled: None takes the sampling model's).
    ``method``: one of ``grid.methods`` (lfcl/demosaic/methods.py says what each does); ``auto`` is resolved
    once by :func:`resolve_auto` and runs its pick at ``strength`` times the picked strength, from the start
    it names unless ``start`` is given, judged on ``auto_view``; ``auto_costly`` False: from the rule fitted
    without the costly methods (admm-epi; lfcl.demosaic.auto.COSTLY_METHODS).

    ``lam``, ``iterations``, ``rho``, ``strength``, ``noise``, ``tolerance_db``, ``max_memory``, ``callback``,
    ``device``: as lfcl.demosaic.methods.solve_aligned and lfcl.demosaic.resampled.solve_resampled take them
    (the lambda of a resampled grid follows ``noise.sigma_at`` the measured pixels' level). ``start`` (one of
    ``grid.starts``) and ``skip_flat``: aligned grids (solve_aligned). ``safety_net`` (on by default): each lens's
    colour means are soft-thresholded towards Malvar's at the noise of a lens mean (lfcl/demosaic/safety_net.py),
    recorded in ``parameters["safety_net"]``; on grids with ``grid.safety_net`` only (aligned), for every method
    but Malvar. ``cg_steps``, ``interpolation_weight``: resampled grids (solve_resampled). ``disparity``: aligned grids,
    an ``lfcl.depth.DisparityMap`` already estimated from this mosaic (the depth output's), which admm-epi takes
    instead of estimating its own (solve_aligned).

    Returns a :class:`lfcl.demosaic.methods.DemosaicResult`: ``planes`` [3, S*U, T*V], ``lightfield``
    [S, T, U, V, 3] float32, ``parameters`` (with ``auto``: ``parameters["auto"]``), ``sampling`` (resampled).
    """
    if not isinstance(grid, (AlignedGrid, ResampledGrid)):
        raise ValueError(f"grid must be an AlignedGrid or a ResampledGrid (lfcl.grid.model), got "
                         f"{type(grid).__name__}")
    grid.check_method(method)
    grid.check_options(start, skip_flat)
    aligned = isinstance(grid, AlignedGrid)
    if aligned and (cg_steps is not None or interpolation_weight is not None):
        raise ValueError("cg_steps and interpolation_weight are for resampled lens grids (the aligned admm-uv "
                         "solves its x-update exactly)")
    if disparity is not None and not aligned:
        raise ValueError("a disparity map is for aligned square lens grids (the depth output needs one)")
    if tolerance_db is not None:
        change_for_tolerance_db(tolerance_db)  # a bad tolerance: one line now, before any work
    mosaic = _checked_mosaic(mosaic, pattern, grid)
    auto = None
    flat_ignored = None  # auto's pick does not skip flat lenses: the asked --skip-flat is recorded as not applied
    if method == "auto":
        auto = resolve_auto(mosaic, pattern, grid, noise=noise, view=auto_view, costly=auto_costly, device=device)
        method, strength, noise = auto.method, strength * auto.strength, auto.noise
        start = start if start is not None else auto.start
        if skip_flat and method not in SKIPPABLE:
            flat_ignored = {"flat_lenses": 0, "ignored": True,
                            "why": f"not applied: auto picked {method}, which solves every lens (flat lenses are "
                                   f"skipped by {', '.join(SKIPPABLE)})"}
        skip_flat = skip_flat if method in SKIPPABLE else None
    if aligned:
        result = solve_aligned(mosaic, pattern, grid.pitch, method, origin=grid.origin, lam=lam,
                               iterations=iterations, rho=rho, strength=strength, noise=noise, device=device,
                               callback=callback, max_memory=max_memory, lens_response=grid.lens_response,
                               tolerance_db=tolerance_db, start=start, skip_flat=skip_flat, disparity=disparity)
        result.shape = LightFieldShape(mosaic.shape[0] // grid.pitch[0], mosaic.shape[1] // grid.pitch[1],
                                       *grid.pitch)
    else:
        from .resampled import solve_resampled

        result = solve_resampled(mosaic, grid.sampling, method, lam=lam, iterations=iterations, rho=rho,
                                 strength=strength, cg_steps=cg_steps, interpolation_weight=interpolation_weight,
                                 noise=noise, device=device, callback=callback, max_memory=max_memory,
                                 tolerance_db=tolerance_db)
    if safety_net and grid.safety_net and method != "malvar":
        result = with_safety_net(result, mosaic, pattern, grid.pitch, grid.origin, grid.lens_response, device)
    if auto is not None:
        result.parameters = {**result.parameters, "auto": auto.record}
    if flat_ignored is not None:
        result.parameters = {**result.parameters, "flat_lenses": flat_ignored}
    result.device = device
    return result
