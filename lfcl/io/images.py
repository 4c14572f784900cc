"""Image files in and out, through OpenImageIO; every write is atomic.

Writers go to a temporary file in the destination folder and rename it into
place, so a failed or interrupted run never leaves a half-written output.
"""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
from pathlib import Path

import numpy as np
import OpenImageIO as oiio


class ImageReadError(ValueError):
    """A file that OpenImageIO cannot read as an image."""


@contextlib.contextmanager
def atomic_path(path, suffix: str | None = None):
    """Yield a temporary path beside ``path``; rename it onto ``path`` on success.

    On failure the temporary file is removed, and so are the folders made for it.
    """
    path = Path(path)
    made = [folder for folder in (path.parent, *path.parent.parents) if not folder.exists()]
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=suffix or path.suffix, dir=path.parent)
    except BaseException:
        _remove_empty(made)
        raise
    os.close(fd)
    try:
        yield Path(tmp)
        # mkstemp makes the file private (0600); give it the permissions a plain open() would
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        _remove_empty(made)
        raise


def _remove_empty(folders) -> None:
    """Remove ``folders`` (deepest first) that are still empty; leave the others."""
    for folder in folders:
        with contextlib.suppress(OSError):
            folder.rmdir()


def one_line_error(text, limit: int = 400) -> str:
    """OpenImageIO's error text as one line: its lines (often repeated) once each, joined, shortened."""
    parts: list[str] = []
    for line in str(text or "").splitlines():
        line = " ".join(line.split())
        if line and line not in parts:
            parts.append(line)
    joined = "; ".join(parts)
    return joined if len(joined) <= limit else joined[: limit - 3].rstrip() + "..."


def _check_name(path: Path) -> None:
    """OpenImageIO takes UTF-8 file names only: ``ValueError`` for another (a Linux name can be any bytes)."""
    try:
        str(path).encode("utf-8")
    except UnicodeEncodeError:
        raise ValueError(f"cannot use {str(path)!r}: its name is not valid UTF-8 (choose another)") from None


def read_image(path) -> np.ndarray:
    """Any image OpenImageIO reads, as float32 ``(H, W, C)``; ``ImageReadError`` (one line) if it cannot."""
    # image libraries (libpng) print on fd 2 before OpenImageIO reports the error
    from .raw import _captured_stderr

    _check_name(Path(path))
    with _captured_stderr():
        buf = oiio.ImageBuf(str(path))
        if buf.has_error:
            raise ImageReadError(f"cannot read image {path}: {one_line_error(buf.geterror()) or 'unknown format'}")
        pixels = buf.get_pixels(oiio.FLOAT)
        if buf.has_error or pixels is None:
            raise ImageReadError(f"cannot read image {path}: {one_line_error(buf.geterror()) or 'read failed'}")
    pixels = np.asarray(pixels, dtype=np.float32)
    if pixels.ndim == 2:
        pixels = pixels[:, :, None]
    return pixels


_FORMATS = {".exr": oiio.FLOAT, ".tif": oiio.UINT16, ".tiff": oiio.UINT16, ".png": oiio.UINT8}


def write_image(path, image: np.ndarray, metadata: dict | None = None, *, pixel_format=None) -> Path:
    """Write ``(H, W[, C])`` float data atomically.

    EXR keeps float32 values as they are (scene-linear, unclipped); TIFF is
    16-bit and PNG 8-bit, both clipped to [0, 1] by OpenImageIO's conversion.
    ``metadata`` goes into the file's header as ``lfcl:<key>`` attributes
    (non-string values as JSON) and, whole, as JSON in ImageDescription (the one
    field TIFF keeps).
    """
    path = Path(path)
    _check_name(path)
    fmt = pixel_format if pixel_format is not None else _FORMATS.get(path.suffix.lower())
    if fmt is None:
        raise ValueError(f"unsupported output extension {path.suffix!r}: use .exr, .tif, .tiff or .png")
    image = np.asarray(image, dtype=np.float32)
    if image.ndim == 2:
        image = image[:, :, None]
    if image.ndim != 3:
        raise ValueError(f"an image must have shape (H, W) or (H, W, C), got {image.shape}")
    if not np.all(np.isfinite(image)):
        raise ValueError(f"refusing to write {path.name}: the image holds NaN or Inf values")
    height, width, channels = image.shape
    spec = oiio.ImageSpec(width, height, channels, fmt)
    # no write date (OpenImageIO stamps EXR capDate / TIFF DateTime otherwise): same inputs, same bytes
    spec.attribute("DateTime", "")
    if path.suffix.lower() == ".exr":
        spec.attribute("compression", "zip")
    for key, value in (metadata or {}).items():
        spec.attribute(f"lfcl:{key}", value if isinstance(value, str) else to_json(value))
    if metadata:
        # TIFF keeps no custom attributes; ImageDescription survives in every format.
        spec.attribute("ImageDescription", to_json({"lfcl": metadata}))
    with atomic_path(path) as tmp:
        out = oiio.ImageOutput.create(str(tmp))
        if out is None or not out.open(str(tmp), spec):
            raise OSError(f"cannot write {path}: {oiio.geterror().strip()}")
        ok = out.write_image(np.ascontiguousarray(image))
        out.close()
        if not ok:
            raise OSError(f"cannot write {path}: {out.geterror().strip()}")
    return path


def to_json(data, **options) -> str:
    """``data`` as strict JSON: NaN and Infinity, which Python's json writes but JSON has not, are refused (a number
    a stage recorded that way is a defect to mend where it is made, not text that other readers choke on)."""
    try:
        return json.dumps(data, allow_nan=False, **options)
    except ValueError as error:
        raise ValueError(f"metadata with a NaN or Infinity cannot be written as JSON ({error})") from None


def write_json(path, data) -> Path:
    """Write ``data`` as indented JSON (:func:`to_json`), atomically."""
    text = to_json(data, indent=2, sort_keys=False) + "\n"
    with atomic_path(path) as tmp:
        tmp.write_text(text)
    return Path(path)


def write_npy(path, array: np.ndarray) -> Path:
    """Write a ``.npy`` atomically."""
    with atomic_path(path, suffix=".npy") as tmp:
        np.save(tmp, array)
    return Path(path)
