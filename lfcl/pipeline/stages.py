"""`lfcl process` as small stage objects that compose into a :class:`Pipeline` (docs/stages.md).

Contract (each stage is a callable; a wrong input is a one-line ``ValueError`` naming the stage
and the problem, before any work):

==================  ====================================  =============================================
stage               takes                                 returns
==================  ====================================  =============================================
``Decode``          a path (str / PathLike)               :class:`lfcl.io.raw.Mosaic`
``Grid``            a ``Mosaic``                          :class:`Gridded` (data, pitch, origin,
                                                          lens_response, metadata; + mosaic, lenses,
                                                          seconds, sampling)
``Demosaic``        a ``Gridded``                         :class:`Demosaiced` (result, lightfield
                                                          ``[S, T, U, V, 3]``, metadata, mosaic)
``Outputs``         a ``Demosaiced`` and an output folder :class:`Written` (paths, plan, seconds)
==================  ====================================  =============================================

These objects are the one implementation: ``lfcl process`` and ``lfcl batch`` build a
:class:`Pipeline` of them (lfcl/cli/commands/process.py) and run it, so a Pipeline and the
commands with the same settings write the same files. Each stage's options are its schema in
lfcl/pipeline/parameters.py (checked there; ``options()`` records them in ``summary.json``).
"""

from __future__ import annotations

import dataclasses
import os
import time
from pathlib import Path
from typing import NamedTuple

import numpy as np

from ..demosaic.auto_report import skipped_by_auto
from ..io.raw import Mosaic
from .parameters import (
    DEFAULT_OUTPUTS,  # noqa: F401 (part of this module's names)
    DEFAULT_PITCH,
    DEFAULT_REFOCUS,  # noqa: F401
    DecodeParameters,
    DemosaicParameters,
    GridParameters,
    OutputParameters,
)


class Gridded(NamedTuple):
    """The Grid stage's result: the sensor samples and where the lenses are on them.

    * ``data``: ``[H, W]`` float32 sensor samples the Demosaic stage reads, normalised like
      ``Mosaic.data``. For the ``aligned-square`` grid: the mosaic cropped to whole lenses,
      ``H = S * pitch``, ``W = T * pitch``; for ``resampled``: the whole sensor.
    * ``pitch``: samples per lens along u and along v of the light field (int; U = V = pitch;
      for ``resampled`` the views per lens, ``round(pitch)`` of the calibration).
    * ``origin``: sensor (row, col) of ``data[0, 0]``; the Bayer phase of ``data`` follows from it.
    * ``lens_response``: ``[pitch, pitch]`` vignetting from a white image or calibration
      weights (lfcl/grid/vignetting.py), or None (always None for ``resampled``: its sampling model
      holds the per-pixel response).
    * ``metadata``: JSON-friendly, recorded in every output file (so nothing run-dependent
      such as timings): ``geometry`` always (the grid's ``geometry(how)`` record, lfcl/grid/model.py), with
      ``grid`` (the grid kind, one of lfcl.grid.model.GRID_KINDS), ``pitch`` [U, V], ``lenses`` [S, T],
      ``from`` (where the grid came from) and ``first_lens_pixel`` (aligned) or ``packing``, ``features``,
      ``lens_origin`` (resampled); ``calibration`` and ``flat_field`` when they apply.
    * ``mosaic``: the decoded raw (pattern, noise profile, colour metadata).
    * ``lenses``: (S, T) of the light field.
    * ``seconds``: parts of this stage worth timing apart (``calibrate`` with a white image).
    * ``sampling``: for ``resampled``, the :class:`lfcl.grid.resampling.SamplingModel` (where every
      regular sample lies on the sensor); None for ``aligned-square``.

    :attr:`grid` is the lens grid as a typed value (lfcl.grid.model.AlignedGrid or ResampledGrid), which the
    Demosaic stage hands to lfcl.demosaic.driver.demosaic_grid; it refuses a kind it does not know.
    """

    data: np.ndarray
    pitch: int
    origin: tuple
    lens_response: np.ndarray | None
    metadata: dict
    mosaic: Mosaic
    lenses: tuple
    seconds: dict = {}  # noqa: RUF012 (a NamedTuple default; never mutated)
    sampling: object = None  # lfcl.grid.resampling.SamplingModel for the "resampled" kind

    @property
    def grid(self):
        """The typed lens grid (lfcl.grid.model.lens_grid): its kind from ``metadata["geometry"]``, the rest from
        these fields; a one-line ValueError for a kind it does not know."""
        from ..grid.model import lens_grid

        return lens_grid(self.metadata.get("geometry", {}), pitch=self.pitch, origin=self.origin,
                         lenses=self.lenses, lens_response=self.lens_response, sampling=self.sampling)


class Demosaiced(NamedTuple):
    """The demosaic stage's result."""

    result: object  # lfcl.demosaic.methods.DemosaicResult
    lightfield: np.ndarray  # [S, T, U, V, 3] float32
    metadata: dict  # what every output file records (method, parameters, geometry, input, ...)
    mosaic: Mosaic
    device: object = None  # the device spec the stage ran on (None: the default); the depth output runs there too


class Written(NamedTuple):
    """The output stage's result."""

    paths: list  # the files written, in order
    plan: object  # lfcl.outputs.files.OutputPlan
    seconds: dict  # kind -> write seconds


def grid_words(geometry: dict) -> str:
    """``hexagonal``, ``rotated, non-integer-pitch square`` or ``aligned square``: the grid of a ``geometry`` record
    (a summary's, or ``grid``, ``packing``, ``features``) in words (lfcl.grid.model: the grid's ``words``)."""
    from ..grid.model import lens_grid

    return lens_grid(geometry).words


def check_method_for_grid(method: str, kind: str, what: str = "") -> None:
    """A one-line ``ValueError`` when ``method`` does not run on a grid of ``kind`` (``what``: the grid, for the
    message), naming the methods that do (lfcl.grid.model: the grid's ``check_method``)."""
    from ..grid.model import lens_grid

    lens_grid({"grid": kind}).check_method(method, what or "a resampled lens grid")


def _need(value, kind, stage: str, what: str):
    if not isinstance(value, kind):
        raise ValueError(f"{stage} takes {what}, got {type(value).__name__}")


def _parameters(stage: str, schema: type, **values):
    """``schema(**values)`` (lfcl/pipeline/parameters.py: the stage's options, checked); its one-line
    ``ValueError`` names the stage."""
    try:
        return schema(**values)
    except ValueError as e:
        raise ValueError(f"{stage}: {e}") from None


def _take(stage, parameters) -> None:
    """The stage keeps its checked options (``stage.parameters``) and each as an attribute (``stage.method``)."""
    stage.parameters = parameters
    for name in parameters.__dataclass_fields__:
        setattr(stage, name, getattr(parameters, name))


class Decode:
    """path -> :class:`lfcl.io.raw.Mosaic` (DNG, camera raw, or EXR/TIFF/PNG mosaic with ``pattern``)."""

    name = "decode"

    def __init__(self, pattern: str | None = DecodeParameters.pattern):
        _take(self, _parameters("Decode", DecodeParameters, pattern=pattern))

    def options(self) -> dict:
        return self.parameters.options()

    def __call__(self, path) -> Mosaic:
        if not isinstance(path, (str, os.PathLike)):
            raise ValueError(f"Decode takes a path, got {type(path).__name__}")
        from ..io.raw import read_mosaic

        try:
            return read_mosaic(path, self.pattern)
        except FileNotFoundError as e:  # read_mosaic's own message names the file
            raise ValueError(str(e)) from None


class Grid:
    """Mosaic -> :class:`Gridded`: an aligned square lens grid from ``pitch`` (at pixel 0, 0),
    a ``calibration`` file (``lfcl calibrate``) or a ``white`` image (calibrated first).
    Give at most one; none means ``pitch=9``.

    A calibration of an aligned square grid of integer pitch (lfcl.grid.aligned.fit_grid)
    gives the ``aligned-square`` kind, sliced exactly; any other calibrated grid (rotated,
    non-integer pitch, offset by a fraction of a pixel, hexagonal) the ``resampled`` kind
    with its sampling model (lfcl.grid.resampling.sampling_model, docs/geometry.md)."""

    name = "grid"

    def __init__(self, pitch: int | None = GridParameters.pitch, calibration=GridParameters.calibration,
                 white=GridParameters.white, pattern: str | None = DecodeParameters.pattern):
        _take(self, _parameters("Grid", GridParameters, pitch=pitch, calibration=calibration, white=white))
        self.pattern = _parameters("Grid", DecodeParameters, pattern=pattern).pattern  # the white image's

    def options(self) -> dict:
        return self.parameters.options()

    def __call__(self, mosaic: Mosaic) -> Gridded:
        _need(mosaic, Mosaic, "Grid", "a Mosaic (from Decode)")
        from ..grid.model import AlignedGrid
        from ..layout import LightFieldShape

        meta: dict = {}
        seconds: dict = {}
        lens_response = None
        if self.calibration is not None or self.white is not None:
            from ..grid import calibrate_white, load_calibration
            from ..grid.aligned import ALIGNED, calibration_metadata, fit_grid

            if self.calibration is not None:
                cal = load_calibration(self.calibration, mosaic.shape, mosaic.pattern)
                how, what, src = "--calibration", f"calibration {self.calibration}", self.calibration
            else:
                start = time.perf_counter()
                cal = calibrate_white(self.white, self.pattern)
                cal.check(mosaic.shape, mosaic.pattern, what=Path(mosaic.source).name or "the raw")
                seconds["calibrate"] = time.perf_counter() - start
                how, what, src = "--white", f"white image {self.white}", self.white
            geo = fit_grid(cal, what)
            meta["calibration"] = calibration_metadata(cal, how, src, geo)
            if geo["kind"] != ALIGNED:
                return _resampled(mosaic, cal, geo, how, meta, seconds)
            P, (r0, c0), (S, T) = geo["pitch"], geo["first"], geo["lenses"]
            if cal.weight is not None:  # the white image's vignetting: flat-field, weight the data term
                from ..grid.vignetting import lens_response_from_calibration

                lens_response = lens_response_from_calibration(cal, (P, P))
                meta["flat_field"] = {
                    "lens_response": np.round(lens_response, 4).tolist(),
                    "left_out_below": 0.2, "data_term_weight": "response^2 (docs: lfcl/grid/vignetting.py)"}
        else:
            P, (r0, c0) = self.pitch or DEFAULT_PITCH, (0, 0)
            how = "--pitch" if self.pitch is not None else "default pitch"
            full = LightFieldShape.from_sensor(mosaic.shape, (P, P))
            S, T = full.S, full.T
        H, W = LightFieldShape(S, T, P, P).sensor_shape
        meta["geometry"] = AlignedGrid(P, (r0, c0), (S, T)).geometry(how)
        return Gridded(mosaic.data[r0:r0 + H, c0:c0 + W], int(P), (r0, c0), lens_response, meta, mosaic, (S, T),
                       seconds)


def _resampled(mosaic: Mosaic, cal, geo: dict, how: str, meta: dict, seconds: dict) -> Gridded:
    """The ``resampled`` kind of a calibrated grid: the whole sensor and its sampling model."""
    from ..grid.model import ResampledGrid
    from ..grid.resampling import sampling_model

    sampling = sampling_model(cal, mosaic.pattern)
    U, (S, T) = sampling.views[0], sampling.lenses
    meta["geometry"] = ResampledGrid(sampling, cal.grid.packing, geo["features"]).geometry(how)
    if cal.weight is not None:
        meta["flat_field"] = {"response": "the calibration's weight model, micro-image cores scaled to median 1",
                              "left_out_below": sampling.threshold,
                              "data_term_weight": "response^2 (docs/geometry.md)"}
    return Gridded(mosaic.data, int(U), (0, 0), None, meta, mosaic, (S, T), seconds, sampling)


class Demosaic:
    """Gridded -> :class:`Demosaiced` with ``lfcl.demosaic.driver.demosaic_grid`` on ``Gridded.grid`` (the methods
    of ``resampled``: auto, malvar, admm-uv, admm-st, admm-uvst).

    ``lam``/``iterations`` ``None``: follow the noise level (docs/admm.md); ``strength``
    multiplies the default lambda. ``tolerance_db``: stop the ADMM iterations once one can
    move PSNR by less than this (docs/auto.md); None: the method's own rule.
    ``max_memory``: device bytes the solver may use (None: 80 % of the device's; a larger
    admm-uv problem on an aligned grid runs in bands of lens rows).
    ``method``: ``METHOD[:START]`` (lfcl.demosaic.names.parse_method_spec), the method and, for the ADMM methods,
    their first estimate (``lfcl.demosaic.names.STARTS``; aligned grids only), as ``admm-uv-xc:guarded``; no
    START: the method's (Malvar; ``auto``: the one its rule names). The stage keeps them apart as ``method`` and
    ``start`` (None: the method's); ``summary.json`` records the name as ``method`` and the start as
    ``parameters.start``.
    ``skip_flat``: leave lenses that are flat within the noise out of the solve and give them their
    colour means (lfcl/demosaic/flat_lenses.py; admm-uv, admm-uv-xc, aligned grids); None or False: off (the
    default), True or a p threshold in (0, 1): on.
    ``safety_net``: keep every lens's colour means within the noise of Malvar's (lfcl/demosaic/safety_net.py;
    aligned grids; on by default).
    ``auto_view``: with ``auto``, the view its rule was judged on (lfcl.demosaic.auto.VIEWS; ``lfcl process``
    passes lfcl.demosaic.auto.view_for_outputs of its outputs).
    ``auto_costly``: with ``auto``, whether its rule may pick a costly method (admm-epi; on by default); False
    (``--auto-cheap``): the rule fitted without them, the methods of about admm-uv's time.
    ``device``: an OpenCL device spec or None (``LFCL_DEVICE``, else the first GPU, else the first device).
    ``callback(record, x)``: called after every ADMM iteration (progress bars)."""

    name = "demosaic"

    def __init__(self, method: str = DemosaicParameters.method, lam: float | None = DemosaicParameters.lam,
                 iterations: int | None = DemosaicParameters.iterations,
                 strength: float = DemosaicParameters.strength, device=None, callback=None,
                 max_memory: int | None = DemosaicParameters.max_memory,
                 tolerance_db: float | None = DemosaicParameters.tolerance_db,
                 skip_flat: bool | float | None = DemosaicParameters.skip_flat,
                 auto_view: str = DemosaicParameters.auto_view, auto_costly: bool = DemosaicParameters.auto_costly,
                 safety_net: bool = DemosaicParameters.safety_net):
        _take(self, _parameters("Demosaic", DemosaicParameters, method=method, lam=lam, iterations=iterations,
                                strength=strength, max_memory=max_memory, tolerance_db=tolerance_db,
                                skip_flat=skip_flat, auto_view=auto_view, auto_costly=auto_costly,
                                safety_net=safety_net))
        self.method, self.start = self.parameters.method_and_start  # METHOD[:START], apart
        if callback is not None and not callable(callback):
            raise ValueError(f"Demosaic: callback must be callable(record, x), got {type(callback).__name__}")
        self.device, self.callback = device, callback  # where it runs and who watches: not parameters

    def options(self) -> dict:
        return self.parameters.options()

    def __call__(self, gridded: Gridded, disparity=None) -> Demosaiced:
        """``disparity``: an ``lfcl.depth.DisparityMap`` already estimated from this raw (the depth output's,
        :func:`depth_of`); admm-epi takes it instead of estimating its own."""
        _need(gridded, Gridded, "Demosaic", "a Gridded (from Grid)")
        if disparity is not None:
            from ..depth import DisparityMap

            _need(disparity, DisparityMap, "Demosaic", "an lfcl.depth.DisparityMap as its disparity (depth_of)")
        try:
            grid = gridded.grid
            grid.check_complete()
            grid.check_method(self.method)
            grid.check_options(self.start, self.skip_flat)
        except ValueError as e:
            raise ValueError(f"Demosaic: {e}") from None
        from .. import __version__
        from ..demosaic.driver import demosaic_grid
        from ..noise.model import from_noise_profile

        mosaic = gridded.mosaic
        noise = None
        if mosaic.noise_profile is not None and self.method != "malvar":
            noise = from_noise_profile(mosaic.noise_profile, gridded.data)
        result = demosaic_grid(gridded.data, mosaic.pattern, grid, self.method, lam=self.lam,
                               iterations=self.iterations, strength=self.strength, noise=noise, device=self.device,
                               callback=self.callback, max_memory=self.max_memory, tolerance_db=self.tolerance_db,
                               start=self.start, skip_flat=self.skip_flat, auto_view=self.auto_view,
                               auto_costly=self.auto_costly, safety_net=self.safety_net, disparity=disparity)
        from ..device import device_metadata

        extra = {"sampling": result.sampling.as_meta()} if result.sampling is not None else {}
        meta = {
            "device": device_metadata(self.device),  # where it ran: the default is the first GPU, else the first device
            "method": self.method, "parameters": result.parameters, "source": mosaic.source,
            "pattern": mosaic.pattern, "geometry": gridded.metadata["geometry"],
            "iterations": result.iterations, "stop_reason": result.stop_reason,
            "noise_sigma": None if result.noise is None else result.noise.sigma,
            "noise": None if result.noise is None else dataclasses.asdict(result.noise),
            "input": mosaic.metadata(), "generator": f"lfcl {__version__} stages",
            **{k: v for k, v in gridded.metadata.items() if k != "geometry"}, **extra,
        }
        return Demosaiced(result, result.lightfield, meta, mosaic, self.device)


def depth_of(mosaic: Mosaic, geometry: dict, device=None):
    """The depth output's disparity map of a decoded raw on the Grid stage's ``geometry``, and its seconds:
    ``(lfcl.depth.DisparityMap, seconds)``. From the raw itself, not from the demosaiced light field (docs/depth.md),
    on ``device`` (the demosaic's: ``--device cpu`` must keep every kernel off a GPU whose compiler fails). A grid
    other than an aligned square one is a ``ValueError``."""
    from ..depth.output import depth_from_mosaic

    start = time.perf_counter()
    depth = depth_from_mosaic(mosaic, geometry, device=device)
    return depth, time.perf_counter() - start


class Outputs:
    """(Demosaiced, out_dir) -> :class:`Written`: ``lfcl.outputs.files.plan_outputs`` then ``write_outputs``
    (all files or none). ``refocus``: slopes spec, used when ``refocus`` is among ``outputs``.
    ``metadata``: extra keys every output file records (they win over the Demosaic stage's)."""

    name = "outputs"

    def __init__(self, outputs=OutputParameters.outputs, refocus: str = OutputParameters.refocus,
                 fmt: str = OutputParameters.fmt, previews: bool = OutputParameters.previews,
                 metadata: dict | None = None):
        from ..outputs.refocus import parse_slopes

        _take(self, _parameters("Outputs", OutputParameters, outputs=outputs, refocus=refocus, fmt=fmt,
                                previews=previews))
        self.outputs = list(self.outputs)
        self.slopes = parse_slopes(self.refocus) if "refocus" in self.outputs else []
        if metadata is not None and not isinstance(metadata, dict):
            raise ValueError(f"Outputs: metadata must be a dict, got {type(metadata).__name__}")
        if metadata:
            from ..io.images import to_json

            try:
                to_json(metadata)  # every file's header holds it as JSON: refused now, not at the first write
            except (TypeError, ValueError) as error:
                raise ValueError(f"Outputs: metadata must be plain JSON data ({error})") from None
        self.metadata = dict(metadata or {})

    def options(self) -> dict:
        return self.parameters.options()

    def check_grid(self, gridded: Gridded) -> None:
        """What these outputs cannot be for this lens grid, refused before the demosaic: DNGs of a view narrower
        than raw editors read (lfcl.io.linear_dng.MIN_DNG_SIDE lenses)."""
        from ..io.linear_dng import MIN_DNG_SIDE

        if self.fmt != "dng":
            return
        S, T = gridded.metadata["geometry"]["lenses"]
        if min(S, T) < MIN_DNG_SIDE:
            raise ValueError(f"--format dng: the views of {S}x{T} lenses would be DNGs that raw editors cannot open "
                             f"(LibRaw reads {MIN_DNG_SIDE} pixels a side at least): use --format exr or tiff")

    def file_metadata(self, demosaiced: Demosaiced) -> dict:
        """What every output file records: the Demosaic stage's metadata and this stage's ``metadata``."""
        return {**demosaiced.metadata, **self.metadata}

    def plan(self, demosaiced: Demosaiced, depth=None):
        """Compute every output asked for, in memory: an ``lfcl.outputs.files.OutputPlan`` (nothing written).

        ``plan.seconds["previews-setup"]`` includes building the colour pipeline. ``depth``: the depth output's
        disparity map and its seconds, ``(DisparityMap, seconds)``, when already estimated (:func:`depth_of`;
        None: estimated here, on the demosaic's device).
        """
        _need(demosaiced, Demosaiced, "Outputs", "a Demosaiced (from Demosaic)")
        from ..outputs.files import plan_outputs

        start = time.perf_counter()
        colour = None
        if self.previews:
            from ..outputs.previews import ColourPipeline

            colour = ColourPipeline.from_mosaic(demosaiced.mosaic)
        colour_seconds = time.perf_counter() - start
        camera = None
        if self.fmt == "dng":  # the raw's names, colour matrix and white balance go into every DNG
            from ..io.linear_dng import DngCamera

            camera = DngCamera.from_mosaic(demosaiced.mosaic)
        depth, depth_seconds = depth if depth is not None else (None, 0.0)
        if "depth" in self.outputs and depth is None:
            depth, depth_seconds = depth_of(demosaiced.mosaic, demosaiced.metadata["geometry"], demosaiced.device)
        plan = plan_outputs(demosaiced.lightfield, self.outputs, slopes=self.slopes, fmt=self.fmt,
                            previews=self.previews, metadata=self.file_metadata(demosaiced), colour=colour,
                            camera=camera, depth=depth)
        if depth is not None:
            plan.seconds["depth"] = plan.seconds.get("depth", 0.0) + depth_seconds
        if "previews-setup" in plan.seconds:
            plan.seconds["previews-setup"] += colour_seconds
        return plan

    def write(self, plan, out_dir, extra=(), seconds: dict | None = None, inputs=()) -> list:
        """Write ``plan``'s files and then ``extra`` (``lfcl.outputs.files.PlannedFile``) into ``out_dir``: all or none.

        ``seconds`` (kind -> write seconds) is filled in as the files are written; a file that would replace one of
        ``inputs`` (paths) is refused before any is written.
        """
        if not isinstance(out_dir, (str, os.PathLike)):
            raise ValueError(f"Outputs needs an output folder path, got {type(out_dir).__name__}")
        from ..outputs.files import write_outputs

        return write_outputs(out_dir, [*plan.files, *extra], seconds, inputs)

    def __call__(self, demosaiced: Demosaiced, out_dir) -> Written:
        _need(demosaiced, Demosaiced, "Outputs", "a Demosaiced (from Demosaic)")
        if not isinstance(out_dir, (str, os.PathLike)):
            raise ValueError(f"Outputs needs an output folder path, got {type(out_dir).__name__}")
        plan = self.plan(demosaiced)
        seconds: dict = {}
        paths = self.write(plan, out_dir, seconds=seconds)
        return Written(paths, plan, seconds)


def _skipped_flat(record) -> list:
    from ..demosaic.flat_lenses import skipped_flat_lenses  # scipy: not at import (lfcl --help)

    return skipped_flat_lenses(record)


def _skipped(plan, outputs: list) -> list:
    """What was not computed and why (``refocus`` is also asked for by ``--refocus``)."""
    if "refocus" in outputs:
        return list(plan.skipped)
    return [s if s["output"] != "refocus" else {"output": "refocus", "reason": "not asked for (--outputs, --refocus)"}
            for s in plan.skipped]


def _output_seconds(plan, compute: float, write: dict, files: int) -> dict:
    """Per output kind: compute and write seconds and the number of files; ``total`` last."""
    out = {kind: {"compute": plan.seconds.get(kind, 0.0), "write": write.get(kind, 0.0), "files": n}
           for kind, n in plan.counts().items()}
    if "previews-setup" in plan.seconds:
        out["previews-setup"] = {"compute": plan.seconds["previews-setup"], "write": 0.0, "files": 0}
    out["total"] = {"compute": compute, "write": sum(v for k, v in write.items() if k != "summary"), "files": files}
    return out


class Pipeline:
    """Decode -> Grid -> Demosaic -> Outputs (in that order; Outputs optional).

    ``run(path, out_dir)`` runs the stages and returns the summary (docs/outputs.md,
    "summary.json"): the metadata every output records (method, parameters, geometry,
    input, ...), ``lenses``, ``options`` (every stage's options, defaults included),
    ``seconds`` (per stage: ``decode``, ``grid``, ``demosaic``, ``outputs``, and
    ``calibrate`` when the grid came from a white image; ``grid`` is then the rest of that
    stage; likewise ``disparity`` apart from ``demosaic`` for admm-epi, unless it took the depth output's, which is
    estimated once, before the demosaic, and counts in ``outputs``), and with an Outputs stage ``format``,
    ``previews``, ``colour``, ``outputs``,
    ``refocus``, ``skipped`` (with ``auto``: also the candidates it skipped, lfcl/demosaic/auto_report.py),
    ``output_seconds``. With an Outputs stage the summary is also
    written as ``summary.json``, last, with the other files: all of them or none.
    ``finish(summary) -> summary`` (optional) edits the summary before it is written and
    returned. After a run, ``pipeline.lightfield`` holds the light field.
    """

    ORDER = (Decode, Grid, Demosaic, Outputs)

    def __init__(self, stages, recipe: dict | None = None):
        stages = list(stages)
        kinds = [type(s) for s in stages]
        if kinds not in (list(self.ORDER), list(self.ORDER[:3])):
            raise ValueError("Pipeline takes the stages Decode, Grid, Demosaic[, Outputs] in that order, got "
                             + (", ".join(type(s).__name__ for s in stages) or "none"))
        self.stages, self.recipe = stages, recipe

    def options(self) -> dict:
        out: dict = {}
        for s in self.stages:
            out.update(s.options())
        return out

    def run(self, path, out_dir=None, finish=None) -> dict:
        decode, grid, demosaic = self.stages[:3]
        outputs = self.stages[3] if len(self.stages) == 4 else None
        if outputs is not None and not isinstance(out_dir, (str, os.PathLike)):
            raise ValueError(f"Outputs needs an output folder path, got {type(out_dir).__name__}")
        seconds: dict = {}

        def timed(stage, value):
            start = time.perf_counter()
            value = stage(value)
            seconds[stage.name] = time.perf_counter() - start
            return value

        mosaic = timed(decode, path)
        gridded = timed(grid, mosaic)
        if outputs is not None:
            outputs.check_grid(gridded)
        if "calibrate" in gridded.seconds:  # report the white image's calibration apart
            seconds["calibrate"] = gridded.seconds["calibrate"]
            seconds["grid"] = max(0.0, seconds["grid"] - seconds["calibrate"])
        depth = None
        if outputs is not None and "depth" in outputs.outputs:
            # before the demosaic: a grid it cannot run on is refused before the long part, and admm-epi takes this
            # estimate instead of one of its own (one disparity per run; its seconds count in the outputs')
            depth = depth_of(mosaic, gridded.metadata["geometry"], demosaic.device)
        start = time.perf_counter()
        demosaiced = demosaic(gridded, disparity=None if depth is None else depth[0])
        seconds[demosaic.name] = time.perf_counter() - start
        for part, spent in demosaiced.result.part_seconds.items():  # e.g. admm-epi's disparity, reported apart
            seconds[part] = spent
            seconds["demosaic"] = max(0.0, seconds["demosaic"] - spent)
        self.lightfield = demosaiced.lightfield
        metadata = demosaiced.metadata if outputs is None else outputs.file_metadata(demosaiced)
        summary = {**metadata, "lenses": list(demosaiced.lightfield.shape[:2]), "options": self.options()}
        if self.recipe is not None and "recipe" not in summary:
            summary["recipe"] = {k: self.recipe[k] for k in ("name", "path") if k in self.recipe}
        summary["seconds"] = seconds

        def done() -> dict:  # a fresh copy each time: ``finish`` may edit it
            out = {**summary, "seconds": dict(seconds)}
            if finish is None:
                return out
            out = finish(out)
            if not isinstance(out, dict):  # it becomes summary.json
                raise ValueError(f"Pipeline.run: finish must return the summary (a dict), returned {type(out).__name__}")
            return out

        if outputs is None:
            return done()

        from ..outputs.files import PlannedFile

        start = time.perf_counter()
        plan = outputs.plan(demosaiced, depth=depth)
        compute = time.perf_counter() - start + (depth[1] if depth is not None else 0.0)
        summary.update({"format": plan.image_format, "previews": plan.previews, "colour": plan.colour,
                        "outputs": [f.name for f in plan.files], "refocus": plan.refocus,
                        "skipped": _skipped(plan, outputs.outputs)
                        + skipped_by_auto(demosaiced.metadata["parameters"].get("auto"))
                        + _skipped_flat(demosaiced.metadata["parameters"].get("flat_lenses"))})
        write: dict = {}

        def final() -> dict:  # called when summary.json is written (last), and after
            seconds["outputs"] = compute + sum(v for k, v in write.items() if k != "summary")
            summary["output_seconds"] = _output_seconds(plan, compute, write, len(plan.files))
            return done()

        inputs = [p for p in (path, grid.calibration, grid.white) if isinstance(p, (str, os.PathLike))]
        outputs.write(plan, out_dir, [PlannedFile("summary.json", "summary", "json", final)], write, inputs)
        write.pop("summary", None)
        return final()
