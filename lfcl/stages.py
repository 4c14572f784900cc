"""`lfcl process` as small stage objects that compose into a :class:`Pipeline` (docs/stages.md).

Contract (each stage is a callable; a wrong input is a one-line ``ValueError`` naming the stage
and the problem, before any work):

==================  ====================================  =============================================
stage               takes                                 returns
==================  ====================================  =============================================
``Decode``          a path (str / PathLike)               :class:`lfcl.raw.Mosaic`
``Grid``            a ``Mosaic``                          :class:`Gridded` (data, pitch, origin,
                                                          lens_response, metadata; + mosaic, lenses)
``Demosaic``        a ``Gridded``                         :class:`Demosaiced` (result, lightfield
                                                          ``[S, T, U, V, 3]``, metadata, mosaic)
``Outputs``         a ``Demosaiced`` and an output folder :class:`Written` (paths, plan, metadata)
==================  ====================================  =============================================

The stages call the same functions as ``lfcl process`` (read_mosaic, aligned_geometry,
calibrate_white / load_calibration, demosaic_lightfield, plan_outputs / write_outputs), with the
same arguments, so a :class:`Pipeline` and ``lfcl process`` with the same settings write the same
``lightfield.npy``.
"""

from __future__ import annotations

import os
import time
from pathlib import Path
from typing import NamedTuple

import numpy as np

from .raw import Mosaic

DEFAULT_PITCH = 9
DEFAULT_OUTPUTS = ("center", "mean", "lightfield")
DEFAULT_REFOCUS = "-1:1:0.25"


class Gridded(NamedTuple):
    """The lens grid stage's result: the cropped normalised mosaic and where its lenses are."""

    data: np.ndarray  # [H, W] float32: whole lenses only, normalised like Mosaic.data
    pitch: int  # pixels per lens (square, aligned)
    origin: tuple  # sensor (row, col) of the first whole lens's top-left pixel
    lens_response: np.ndarray | None  # [P, P] vignetting from a white image / calibration, or None
    metadata: dict  # "geometry" (+ "calibration", "flat_field")
    mosaic: Mosaic  # the decoded raw (pattern, noise profile, colour)
    lenses: tuple  # S, T


class Demosaiced(NamedTuple):
    """The demosaic stage's result."""

    result: object  # lfcl.methods.DemosaicResult
    lightfield: np.ndarray  # [S, T, U, V, 3] float32
    metadata: dict  # what every output file records (method, parameters, geometry, input, ...)
    mosaic: Mosaic


class Written(NamedTuple):
    """The output stage's result."""

    paths: list  # the files written, in order
    plan: object  # lfcl.outputs.OutputPlan
    seconds: dict  # kind -> write seconds


def _need(value, kind, stage: str, what: str):
    if not isinstance(value, kind):
        raise ValueError(f"{stage} takes {what}, got {type(value).__name__}")  # noqa: TRY004 (the stage contract: ValueError)


class Decode:
    """path -> :class:`lfcl.raw.Mosaic` (DNG, camera raw, or EXR/TIFF/PNG mosaic with ``pattern``)."""

    name = "decode"

    def __init__(self, pattern: str | None = None):
        if pattern is not None and not isinstance(pattern, str):
            raise ValueError(f"Decode: pattern must be a string like 'GRBG', got {pattern!r}")
        self.pattern = pattern

    def options(self) -> dict:
        return {"pattern": self.pattern}

    def __call__(self, path) -> Mosaic:
        if not isinstance(path, (str, os.PathLike)):
            raise ValueError(f"Decode takes a path, got {type(path).__name__}")  # noqa: TRY004 (the stage contract: ValueError)
        if not Path(path).is_file():
            raise ValueError(f"Decode: raw {str(path)!r} does not exist or is not a file")
        from .raw import read_mosaic

        return read_mosaic(path, self.pattern)


class Grid:
    """Mosaic -> :class:`Gridded`: an aligned square lens grid from ``pitch`` (at pixel 0, 0),
    a ``calibration`` file (``lfcl calibrate``) or a ``white`` image (calibrated first).
    Give at most one; none means ``pitch=9``."""

    name = "grid"

    def __init__(self, pitch: int | None = None, calibration=None, white=None, pattern: str | None = None):
        given = [n for n, v in (("pitch", pitch), ("calibration", calibration), ("white", white)) if v is not None]
        if len(given) > 1:
            raise ValueError(f"Grid: give the lens grid once, not {' and '.join(given)} together")
        if pitch is not None and (isinstance(pitch, bool) or not isinstance(pitch, (int, np.integer)) or pitch < 2):
            raise ValueError(f"Grid: pitch must be an integer >= 2, got {pitch!r}")
        for name, value in (("calibration", calibration), ("white", white)):
            if value is not None and not Path(value).is_file():
                raise ValueError(f"Grid: {name} {str(value)!r} does not exist")
        self.pitch, self.calibration, self.white, self.pattern = pitch, calibration, white, pattern

    def options(self) -> dict:
        return {"pitch": self.pitch, "calibration": None if self.calibration is None else str(self.calibration),
                "white": None if self.white is None else str(self.white)}

    def __call__(self, mosaic: Mosaic) -> Gridded:
        _need(mosaic, Mosaic, "Grid", "a Mosaic (from Decode)")
        from .commands.process import _calibration_metadata, aligned_geometry
        from .layout import LightFieldShape

        meta: dict = {}
        lens_response = None
        if self.calibration is not None or self.white is not None:
            from .calib import calibrate_white, load_calibration

            if self.calibration is not None:
                cal = load_calibration(self.calibration, mosaic.shape, mosaic.pattern)
                how, what, src = "--calibration", f"calibration {self.calibration}", self.calibration
            else:
                cal = calibrate_white(self.white, self.pattern)
                cal.check(mosaic.shape, mosaic.pattern, what=Path(mosaic.source).name or "the raw")
                how, what, src = "--white", f"white image {self.white}", self.white
            geo = aligned_geometry(cal, what)
            meta["calibration"] = _calibration_metadata(cal, how, src, geo)
            P, (r0, c0), (S, T) = geo["pitch"], geo["first"], geo["lenses"]
            if cal.weight is not None:
                from .flatfield import lens_response_from_calibration

                lens_response = lens_response_from_calibration(cal, (P, P))
                meta["flat_field"] = {
                    "lens_response": np.round(lens_response, 4).tolist(),
                    "left_out_below": 0.2, "data_term_weight": "response^2 (docs: lfcl/flatfield.py)"}
        else:
            P, (r0, c0) = self.pitch or DEFAULT_PITCH, (0, 0)
            how = "--pitch" if self.pitch is not None else "default pitch"
            full = LightFieldShape.from_sensor(mosaic.shape, (P, P))
            S, T = full.S, full.T
        H, W = LightFieldShape(S, T, P, P).sensor_shape
        meta["geometry"] = {"grid": "aligned-square", "pitch": [P, P], "lenses": [S, T],
                            "first_lens_pixel": [r0, c0], "from": how}
        return Gridded(mosaic.data[r0:r0 + H, c0:c0 + W], int(P), (r0, c0), lens_response, meta, mosaic, (S, T))


class Demosaic:
    """Gridded -> :class:`Demosaiced` with ``lfcl.methods.demosaic_lightfield``.

    ``lam``/``iterations`` ``None``: follow the noise level (docs/admm.md); ``strength``
    multiplies the default lambda. ``device``: an OpenCL device spec or None (default)."""

    name = "demosaic"

    def __init__(self, method: str = "admm-uv", lam: float | None = None, iterations: int | None = None,
                 strength: float = 1.0, device=None, callback=None):
        from .methods import parse_method

        try:
            self.method = parse_method(method)
        except ValueError as e:
            raise ValueError(f"Demosaic: {e}") from None
        if lam is not None and (isinstance(lam, bool) or not isinstance(lam, (int, float)) or not lam >= 0):
            raise ValueError(f"Demosaic: lam must be a number >= 0 or None, got {lam!r}")
        if iterations is not None and (isinstance(iterations, bool) or not isinstance(iterations, (int, np.integer))
                                       or iterations < 1):
            raise ValueError(f"Demosaic: iterations must be an integer >= 1 or None, got {iterations!r}")
        if isinstance(strength, bool) or not isinstance(strength, (int, float)) or not strength > 0:
            raise ValueError(f"Demosaic: strength must be a number > 0, got {strength!r}")
        self.lam, self.iterations, self.strength = lam, iterations, float(strength)
        self.device, self.callback = device, callback

    def options(self) -> dict:
        return {"method": self.method, "lambda": self.lam, "iterations": self.iterations, "strength": self.strength}

    def __call__(self, gridded: Gridded) -> Demosaiced:
        _need(gridded, Gridded, "Demosaic", "a Gridded (from Grid)")
        from . import __version__
        from .layout import LightFieldShape, planes_to_exchange
        from .methods import demosaic_lightfield
        from .noise import from_noise_profile

        mosaic, P = gridded.mosaic, gridded.pitch
        noise = None
        if mosaic.noise_profile is not None and self.method != "malvar":
            noise = from_noise_profile(mosaic.noise_profile, gridded.data)
        result = demosaic_lightfield(gridded.data, mosaic.pattern, (P, P), self.method, origin=gridded.origin,
                                     lam=self.lam, iterations=self.iterations, strength=self.strength, noise=noise,
                                     device=self.device, callback=self.callback,
                                     lens_response=gridded.lens_response)
        S, T = gridded.lenses
        lightfield = planes_to_exchange(result.planes, LightFieldShape(S, T, P, P))
        meta = {
            "method": self.method, "parameters": result.parameters, "source": mosaic.source,
            "pattern": mosaic.pattern, "geometry": gridded.metadata["geometry"],
            "iterations": result.iterations, "stop_reason": result.stop_reason,
            "noise_sigma": None if result.noise is None else result.noise.sigma,
            "input": mosaic.metadata(), "generator": f"lfcl {__version__} stages",
            **{k: v for k, v in gridded.metadata.items() if k != "geometry"},
        }
        return Demosaiced(result, lightfield, meta, mosaic)


class Outputs:
    """(Demosaiced, out_dir) -> :class:`Written`: ``lfcl.outputs.plan_outputs`` then ``write_outputs``
    (all files or none). ``refocus``: slopes spec, used when ``refocus`` is among ``outputs``."""

    name = "outputs"

    def __init__(self, outputs=DEFAULT_OUTPUTS, refocus: str = DEFAULT_REFOCUS, fmt: str = "exr",
                 previews: bool = True, metadata: dict | None = None):
        from .outputs import parse_format, parse_outputs
        from .refocus import parse_slopes

        try:
            self.outputs = parse_outputs(outputs if isinstance(outputs, str) else ",".join(outputs))
            self.fmt = parse_format(fmt)
            self.slopes = parse_slopes(refocus) if "refocus" in self.outputs else []
        except (ValueError, TypeError) as e:
            raise ValueError(f"Outputs: {e}") from None
        if not isinstance(previews, bool):
            raise ValueError(f"Outputs: previews must be true or false, got {previews!r}")  # noqa: TRY004 (the stage contract: ValueError)
        self.refocus, self.previews, self.metadata = refocus, previews, dict(metadata or {})

    def options(self) -> dict:
        return {"outputs": list(self.outputs), "refocus": self.refocus, "format": self.fmt, "previews": self.previews}

    def __call__(self, demosaiced: Demosaiced, out_dir) -> Written:
        _need(demosaiced, Demosaiced, "Outputs", "a Demosaiced (from Demosaic)")
        if not isinstance(out_dir, (str, os.PathLike)):
            raise ValueError(f"Outputs needs an output folder path, got {type(out_dir).__name__}")  # noqa: TRY004 (the stage contract: ValueError)
        from .outputs import plan_outputs, write_outputs

        colour = None
        if self.previews:
            from .colour import ColourPipeline

            colour = ColourPipeline.from_mosaic(demosaiced.mosaic)
        plan = plan_outputs(demosaiced.lightfield, self.outputs, slopes=self.slopes, fmt=self.fmt,
                            previews=self.previews, metadata={**demosaiced.metadata, **self.metadata}, colour=colour)
        seconds: dict = {}
        paths = write_outputs(out_dir, plan.files, seconds)
        return Written(paths, plan, seconds)


class Pipeline:
    """Decode -> Grid -> Demosaic -> Outputs (in that order; Outputs optional).

    ``run(path, out_dir)`` runs the stages, writes ``summary.json`` beside the outputs and
    returns the summary: the Demosaic metadata plus ``options`` (every stage's options, and
    ``recipe`` when built from one), ``seconds`` (per stage), ``outputs``, ``skipped``.
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

    def run(self, path, out_dir=None) -> dict:
        seconds: dict = {}
        value = path
        for stage in self.stages:
            start = time.perf_counter()
            value = stage(value, out_dir) if isinstance(stage, Outputs) else stage(value)
            seconds[stage.name] = time.perf_counter() - start
            if isinstance(value, Demosaiced):
                demosaiced = value
        options = self.options()
        summary = {**demosaiced.metadata, "source": str(path), "lenses": list(demosaiced.lightfield.shape[:2]),
                   "options": options, "seconds": seconds}
        if self.recipe is not None:
            summary["recipe"] = {k: self.recipe[k] for k in ("name", "path") if k in self.recipe}
        if isinstance(value, Written):
            from .imageio import write_json

            plan = value.plan
            summary.update({"format": plan.image_format, "previews": plan.previews, "colour": plan.colour,
                            "outputs": [f.name for f in plan.files], "refocus": plan.refocus,
                            "skipped": plan.skipped, "output_seconds": {"compute": plan.seconds,
                                                                        "write": value.seconds}})
            write_json(Path(out_dir) / "summary.json", summary)
        self.lightfield = demosaiced.lightfield
        return summary
