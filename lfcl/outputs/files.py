"""The output stage: images, previews and the light field from a demosaiced light field (docs/outputs.md).

:func:`plan_outputs` computes everything that was asked for, in memory, and
nothing else; :func:`write_outputs` then writes the files, each atomically,
and removes the ones it already wrote if any write fails, so a run leaves either
all its outputs or none.

Output kinds (``--outputs``):

===============  ===========================================  ================================
kind             content                                      files
===============  ===========================================  ================================
``center``       centre view ``L[:, :, U//2, V//2]``          ``center.exr``
``mean``         mean over all views                          ``mean.exr``
``views``        every view, tiled U x V (paper's Fig. 4b)    ``views.exr``
``views-each``   every view, one file each                    ``view_UU_VV.exr``
``refocus``      shift-and-add focal stack (lfcl.outputs.refocus)     ``refocus_+0.25.exr`` per slope
``lightfield``   the light field ``[S, T, U, V, 3]``          ``lightfield.npy``
``depth``        disparity per lens, from the raw (depth.md)  ``depth*.exr``, ``depth.png``
===============  ===========================================  ================================

Images are EXR (float32, scene-linear camera RGB, unclipped) or, with
``fmt="tiff"``, 16-bit TIFF (linear camera RGB clipped to [0, 1]) or, with ``fmt="dng"``,
LinearRaw DNG for raw editors (16 bits, clipped to [0, 1], with the raw's colour matrix and
white balance: lfcl.io.linear_dng, docs/darktable.md); with previews,
each image also gets an 8-bit sRGB PNG of the same name (lfcl.outputs.previews).
"""

from __future__ import annotations

import contextlib
import dataclasses
import errno
import os
import shutil
import time
from pathlib import Path

import numpy as np

from ..evaluation.metrics import centre_view, mean_image
from ..layout import tiled_views
from .previews import ColourPipeline
from .refocus import refocus, slope_label

KINDS = ("center", "mean", "views", "views-each", "refocus", "lightfield", "depth")
FORMATS = {"exr": ".exr", "tiff": ".tif", "dng": ".dng"}
ENCODINGS = {
    "exr": "scene-linear camera RGB (the normalised raw's units), float32, not clipped",
    "tiff": "linear camera RGB (the normalised raw's units), clipped to [0, 1], 16 bits",
    "dng": "LinearRaw DNG: linear camera RGB (the normalised raw's units) x 65535, clipped to [0, 65535], "
           "16 bits, black 0, white 65535; the raw's colour matrix and as-shot neutral (see dng)",
    "png": "sRGB preview, 8 bits (see colour)",
}


def parse_outputs(text: str) -> list[str]:
    """``center,mean,...`` -> the kinds in the order given (repeats dropped); one-line ``ValueError`` otherwise."""
    names = [n.strip().lower() for n in str(text).split(",") if n.strip()]
    unknown = [n for n in names if n not in KINDS]
    if unknown or not names:
        raise ValueError(f"unknown outputs {', '.join(unknown) or '(none)'}: choose from {', '.join(KINDS)}")
    return list(dict.fromkeys(names))


def parse_format(text: str) -> str:
    fmt = str(text).strip().lower()
    fmt = {"tif": "tiff", "openexr": "exr"}.get(fmt, fmt)
    if fmt not in FORMATS:
        raise ValueError(f"unknown --format {text!r}: choose exr, tiff or dng")
    return fmt


def view_name(u: int, v: int, U: int, V: int) -> str:
    """``view_UU_VV`` with u, v zero-padded to the width of the larger index (at least 2 digits)."""
    width = max(2, len(str(max(U, V) - 1)))
    return f"view_{u:0{width}d}_{v:0{width}d}"


@dataclasses.dataclass
class PlannedFile:
    """One file to write: its name in the output folder, what it holds and how to write it."""

    name: str
    kind: str  # an output kind
    writer: str  # "image", "preview", "dng", "npy" or "json"
    data: object
    metadata: dict | None = None
    writer_args: dict | None = None  # more keyword arguments of the writer (the DNG's camera)


@dataclasses.dataclass
class OutputPlan:
    files: list[PlannedFile]
    seconds: dict  # kind -> compute seconds
    refocus: list[dict]
    skipped: list[dict]
    colour: dict | None
    image_format: str
    previews: bool

    def counts(self) -> dict:
        out: dict = {}
        for f in self.files:
            out[f.kind] = out.get(f.kind, 0) + 1
        return out


def plan_outputs(lightfield: np.ndarray, kinds, *, slopes=(), fmt: str = "exr", previews: bool = True,
                 metadata: dict | None = None, colour: ColourPipeline | None = None, camera=None,
                 depth=None) -> OutputPlan:
    """Compute every output of ``kinds`` (and only those) from ``lightfield`` ``[S, T, U, V, 3]``.

    ``slopes``: the refocus slopes (used with ``refocus``). ``metadata``: what every
    file records (method, parameters, ...). ``colour``: the camera -> sRGB pipeline
    for the previews (default: camera RGB taken as linear sRGB, neutral balance). ``camera``:
    with ``fmt="dng"``, the DNGs' names and colour tags (an :class:`lfcl.io.linear_dng.DngCamera`;
    default: camera RGB declared linear sRGB, neutral balance). ``depth``: with ``depth``, the
    :class:`lfcl.depth.DisparityMap` (lfcl.depth.output writes it; always EXR + PNG).
    """
    kinds = parse_outputs(",".join(kinds)) if not isinstance(kinds, str) else parse_outputs(kinds)
    fmt = parse_format(fmt)
    ext = FORMATS[fmt]
    lightfield = np.asarray(lightfield)
    if lightfield.ndim != 5 or lightfield.shape[-1] != 3:
        raise ValueError(f"a light field must have shape [S, T, U, V, 3], got {lightfield.shape}")
    S, T, U, V, _ = lightfield.shape
    base = dict(metadata or {})
    images = [k for k in kinds if k not in ("lightfield", "depth")]
    skipped = [{"output": k, "reason": "not asked for (--outputs)"} for k in KINDS if k not in kinds]
    if "refocus" in kinds and not slopes:
        raise ValueError("the refocus output needs slopes (--refocus start:stop:step or a comma list)")
    files: list[PlannedFile] = []
    seconds: dict = {}

    scale = None
    colour_meta = None
    if previews and images:
        start = time.perf_counter()
        colour = colour or ColourPipeline.from_camera()
        scale = colour.exposure(lightfield)
        colour_meta = colour.metadata(scale)
        seconds["previews-setup"] = time.perf_counter() - start
    elif not previews:
        skipped.append({"output": "previews", "reason": "--no-previews"})
    else:
        skipped.append({"output": "previews", "reason": "no image outputs asked for"})

    def add(kind: str, stem: str, image: np.ndarray, extra: dict):
        meta = {**base, "output": kind, **extra, "encoding": ENCODINGS[fmt]}
        if colour_meta is not None:
            meta["preview_colour"] = colour_meta
        if fmt == "dng":
            files.append(PlannedFile(stem + ext, kind, "dng", np.ascontiguousarray(image, np.float32), meta,
                                     {"camera": camera}))
        else:
            files.append(PlannedFile(stem + ext, kind, "image", np.ascontiguousarray(image, np.float32), meta))
        if scale is not None:
            pmeta = {**base, "output": kind, **extra, "encoding": ENCODINGS["png"], "colour": colour_meta}
            files.append(PlannedFile(stem + ".png", kind, "preview", colour.preview(image, scale), pmeta))

    refocus_list: list[dict] = []
    for kind in kinds:
        start = time.perf_counter()
        if kind == "center":
            add(kind, "center", centre_view(lightfield), {"view": [U // 2, V // 2]})
        elif kind == "mean":
            add(kind, "mean", mean_image(lightfield), {})
        elif kind == "views":
            add(kind, "views", tiled_views(lightfield),
                {"tiling": f"{U}x{V} grid of {S}x{T} views: view (u, v) at rows u*S.., cols v*T.. (Fig. 4b)"})
        elif kind == "views-each":
            for u in range(U):
                for v in range(V):
                    add(kind, view_name(u, v, U, V), lightfield[:, :, u, v], {"view": [u, v]})
        elif kind == "refocus":
            for slope in slopes:
                stem = f"refocus_{slope_label(slope)}"
                add(kind, stem, refocus(lightfield, slope),
                    {"slope": float(slope), "refocus": "image(s,t) = mean_uv L(s + a(u-u0), t + a(v-v0), u, v), "
                                                      "bilinear, taps outside left out"})
                entry = {"slope": float(slope), "file": stem + ext}
                if scale is not None:
                    entry["preview"] = stem + ".png"
                refocus_list.append(entry)
        elif kind == "depth":  # lfcl.depth.DisparityMap from the raw (Outputs.plan); always EXR + PNG
            if depth is None:
                raise ValueError("the depth output needs the disparity map (lfcl.depth.estimate_disparity)")
            from ..depth.output import depth_files

            files.extend(PlannedFile(name, kind, "image", image, meta)
                         for name, image, meta in depth_files(depth, base))
        elif kind == "lightfield":
            files.append(PlannedFile("lightfield.npy", kind, "npy", np.ascontiguousarray(lightfield, np.float32)))
        seconds[kind] = time.perf_counter() - start
    names = [f.name for f in files]
    if len(set(names)) != len(names):  # cannot happen with the names above; a guard for later kinds
        raise ValueError("two outputs would share a file name")
    return OutputPlan(files, seconds, refocus_list, skipped, colour_meta, fmt, bool(previews and images))


def _write_one(out_dir: Path, f: PlannedFile) -> Path:
    try:
        return _write_file(out_dir, f)
    except OSError as e:  # numpy says "N requested and M written" of a full disk: name the file and the space
        from ..device import memory_text

        try:
            free = shutil.disk_usage(out_dir).free
        except OSError:
            raise e from None
        if e.errno == errno.ENOSPC or free < 64 * 2**20:
            full = OSError(f"cannot write {out_dir / f.name}: the disk is full ({memory_text(free)} free; "
                           f"{e.strerror or e})")
            full.errno = errno.ENOSPC
            raise full from None
        raise


def _write_file(out_dir: Path, f: PlannedFile) -> Path:
    from ..io.images import write_image, write_json, write_npy

    path = out_dir / f.name
    if f.writer in ("image", "preview"):
        return write_image(path, f.data, f.metadata)
    if f.writer == "dng":
        from ..io.linear_dng import write_linear_dng

        return write_linear_dng(path, f.data, metadata=f.metadata, **(f.writer_args or {}))
    if f.writer == "npy":
        return write_npy(path, f.data)
    if f.writer == "json":  # data may be a callable: a summary that reports the writes before it
        return write_json(path, f.data() if callable(f.data) else f.data)
    raise ValueError(f"unknown writer {f.writer!r}")


def write_outputs(out_dir, files, seconds: dict | None = None, inputs=()) -> list[Path]:
    """Write ``files`` (each atomically) into ``out_dir`` in order; all or nothing.

    If any write fails (or is interrupted), the files this call already wrote are
    removed, and ``out_dir`` too when this call created it and it is empty, then
    the error propagates. ``seconds`` (kind -> seconds) is updated as each file is
    written, so a last ``json`` file with a callable can report the writes before it.
    ``inputs``: the run's input files (the raw, a calibration, a white image); a file
    that would replace one of them, or a name held by something other than a file (a
    folder), is refused before anything is written, so no earlier file is replaced.
    Returns the paths written.
    """
    out_dir = Path(out_dir)
    for f in files:
        target = out_dir / f.name
        if target.exists() and not target.is_file():
            raise ValueError(f"cannot write {target}: something other than a file (a folder?) has that name")
        for source in inputs:
            if target.exists() and Path(source).exists() and os.path.samefile(target, source):
                raise ValueError(f"the output {target} is the input {source}: writing it would replace the input; "
                                 "choose another output folder")
    created = []
    for parent in (out_dir, *out_dir.parents):
        if parent.exists():
            break
        created.append(parent)
    written: list[Path] = []
    seconds = {} if seconds is None else seconds
    # What the folder held before: on failure, whatever this call added goes, wherever an interrupt (Ctrl-C)
    # landed, between a temporary file's making and its rename or between a rename and its bookkeeping
    before = set(os.listdir(out_dir)) if out_dir.is_dir() else set()
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
        for f in files:
            start = time.perf_counter()
            written.append(_write_one(out_dir, f))
            seconds[f.kind] = seconds.get(f.kind, 0.0) + time.perf_counter() - start
    except BaseException:
        _remove_added(out_dir, files, before)
        for folder in created:  # innermost first
            with contextlib.suppress(OSError):
                folder.rmdir()
        raise
    return written


def _remove_added(out_dir: Path, files, before: set) -> None:
    """Remove from ``out_dir`` the planned files and their temporary files (``.STEM.*``, lfcl.io.images.atomic_path)
    that were not there in ``before``; a file that was there and is now replaced stays replaced (docs/outputs.md)."""
    names = {f.name for f in files}
    stems = tuple(f".{Path(name).stem}." for name in names)
    with contextlib.suppress(OSError):
        for name in set(os.listdir(out_dir)) - before:
            if name in names or name.startswith(stems):
                with contextlib.suppress(OSError):
                    (out_dir / name).unlink()
