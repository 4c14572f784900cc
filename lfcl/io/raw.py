"""Read a Bayer mosaic from a camera raw, a DNG or an image file.

:func:`read_mosaic` returns a :class:`Mosaic`: the visible sensor area as
float32 ``[H, W]``, normalised per pixel as ``(raw - black[c]) / (white - black[c])``
with ``c`` the pixel's CFA colour (values are not clipped), the Bayer phase of its
first pixel, and the camera metadata that later stages need.

Two routes:

* Camera raws and DNGs go through rawpy (LibRaw). Only Bayer sensors with an
  R, G, B, G colour description are accepted; X-Trans, Leaf, monochrome, CMYG and
  stacked / linear data (Foveon, linear DNG, film scanners) are refused.
* Image files (EXR, TIFF, PNG, ...) go through OpenImageIO and must be a mosaic:
  one channel, or 3/4 channels that repeat the mosaic in R, G and B, or that hold
  it in the first channel with the others all zero (the layout of
  colour-demosaicing's Lighthouse ``*_CFA_*.exr`` files). Their pattern has to be
  given. Integer files are normalised by their type's maximum (OpenImageIO does
  that when it reads them as float); float files are taken as they are, and must be
  normalised already (values above ``FLOAT_MOSAIC_MAX`` are refused). A file
  must hold the format its extension names (a DNG renamed .exr is refused, not
  read as a TIFF without its black level).

Every failure a user can cause (missing, unsupported, corrupt or truncated file,
non-Bayer sensor, wrong pattern, image too large) is a ``ValueError`` (or
``FileNotFoundError``) with a one-line message. The size a header declares is
checked against ``max_pixels`` before any pixel is allocated, and an image file
is read in bands, so the one full-size array is the float32 result; metadata a
damaged file holds that cannot be used (non-finite colour matrices, white
balance or noise profile) is dropped, as if absent.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import os
import sys
import tempfile
from pathlib import Path

import numpy as np

from ..layout import parse_pattern

#: Refuse images whose declared size exceeds this many pixels (float32: 1 GiB per plane).
MAX_PIXELS = 2**28

#: Extensions read through OpenImageIO; everything else goes to LibRaw.
IMAGE_EXTENSIONS = frozenset({".exr", ".tif", ".tiff", ".png", ".pgm", ".ppm", ".pnm", ".pfm", ".hdr"})

#: The OpenImageIO format each image extension must hold (OpenImageIO itself would read a
#: file with any reader that takes it: a DNG named .exr would be read as a TIFF, without
#: its black level).
IMAGE_FORMATS = {".exr": "openexr", ".tif": "tiff", ".tiff": "tiff", ".png": "png", ".pgm": "pnm",
                 ".ppm": "pnm", ".pnm": "pnm", ".pfm": "pnm", ".hdr": "hdr"}

_RAW_INDEX_NAMES = ("R", "G", "B", "G2")


@dataclasses.dataclass
class Mosaic:
    """A Bayer mosaic and what is known about the camera that took it.

    ``data``: float32 ``[H, W]``, ``(raw - black[c]) / (white - black[c])`` per
    pixel (not clipped: noise below black is negative, saturated pixels may
    exceed 1). ``pattern``: the Bayer phase at ``data[0, 0]`` (layout.py's
    convention), with ``origin`` = (0, 0).

    ``black``: black levels indexed by LibRaw colour index (R, G, B, G2), in raw
    code values; ``white``: the saturation level in raw code values. For image
    files both are in the normalised units of ``data``: black 0, white 1.

    ``as_shot_wb``: camera (as shot) white-balance multipliers (R, G, B) with
    G = 1, or None when the file has none. ``xyz_to_camera``: LibRaw's ``cam_xyz``
    (rawpy's ``rgb_xyz_matrix``, first 3 rows: camera RGB from CIE XYZ, the
    Adobe/DNG ColorMatrix convention), or None; ``camera_to_xyz`` is its inverse.
    ``color_matrix``: rawpy's ``color_matrix`` (3x4, read from the file for some
    cameras), or None when it is all zeros. ``noise_profile``: the DNG
    NoiseProfile tag (51041) as a flat tuple of (scale, offset) pairs, in the
    normalised units of ``data``, or None.

    ``bits``: bits per stored sample where known (for raws: the bit length of the
    white level). ``raw_max``: the largest sample of the visible area before
    normalisation, in the file's units. ``camera``: make and model where the
    file says (TIFF-based raws), else None.
    """

    data: np.ndarray
    pattern: str
    origin: tuple[int, int] = (0, 0)
    black: list[float] = dataclasses.field(default_factory=lambda: [0.0, 0.0, 0.0, 0.0])
    white: float = 1.0
    as_shot_wb: tuple[float, float, float] | None = None
    xyz_to_camera: np.ndarray | None = None
    color_matrix: np.ndarray | None = None
    noise_profile: tuple[float, ...] | None = None
    source: str = ""
    bits: int | None = None
    raw_max: float | None = None
    camera: str | None = None
    kind: str = "image"  # "raw" (LibRaw) or "image" (OpenImageIO)

    @property
    def shape(self) -> tuple[int, int]:
        return tuple(self.data.shape)

    @property
    def camera_to_xyz(self) -> np.ndarray | None:
        """CIE XYZ from camera RGB: the inverse of ``xyz_to_camera`` (None if absent or singular)."""
        if self.xyz_to_camera is None:
            return None
        try:
            return np.linalg.inv(np.asarray(self.xyz_to_camera, dtype=np.float64)).astype(np.float32)
        except np.linalg.LinAlgError:
            return None

    def metadata(self) -> dict:
        """What an output file should record about this input (JSON-friendly)."""
        meta = {
            "source": self.source,
            "pattern": self.pattern,
            "origin": list(self.origin),
            "black": [float(b) for b in self.black],
            "white": float(self.white),
            "input_kind": self.kind,
        }
        if self.as_shot_wb is not None:
            meta["as_shot_wb"] = [float(v) for v in self.as_shot_wb]
        if self.camera:
            meta["camera"] = self.camera
        if self.noise_profile is not None:
            meta["noise_profile"] = [float(v) for v in self.noise_profile]
        if self.bits is not None:
            meta["bits"] = int(self.bits)
        return meta


def read_mosaic(path, pattern: str | None = None, *, max_pixels: int = MAX_PIXELS) -> Mosaic:
    """Read the Bayer mosaic of ``path`` (see the module docstring).

    ``pattern`` is required for image files; for raws it is read from the file,
    and a given ``pattern`` must agree with it (``ValueError`` otherwise).
    """
    if pattern is not None:
        pattern = parse_pattern(pattern)
    path = Path(path)
    try:
        exists = path.exists()
    except PermissionError:  # a folder on the way is closed to us
        raise ValueError(f"cannot read {str(path)!r}: permission denied") from None
    if not exists:
        raise FileNotFoundError(f"input file {str(path)!r} does not exist")
    if not path.is_file():
        raise ValueError(f"input {str(path)!r} is not a file")
    if not os.access(path, os.R_OK):
        raise ValueError(f"cannot read {str(path)!r}: permission denied")
    try:
        str(path).encode("utf-8")
    except UnicodeEncodeError:  # LibRaw and OpenImageIO take UTF-8 names only
        raise ValueError(f"cannot read {str(path)!r}: its name is not valid UTF-8 (rename the file)") from None
    try:
        if path.suffix.lower() in IMAGE_EXTENSIONS:
            return _read_image_mosaic(path, pattern, max_pixels)
        return _read_raw_mosaic(path, pattern, max_pixels)
    except ValueError as exc:  # one line, even for a file name with a line break in it
        text = str(exc)
        if "\n" in text or "\r" in text:
            raise ValueError(_one_line(text)) from None
        raise


# --------------------------------------------------------------------------- images


def _read_image_mosaic(path: Path, pattern: str | None, max_pixels: int) -> Mosaic:
    import OpenImageIO as oiio

    if pattern is None:
        raise ValueError(
            f"{path.name} is an image file, which does not say its Bayer pattern: give one "
            "(--pattern RGGB, GRBG, GBRG or BGGR)"
        )
    # libpng and friends print their complaints on fd 2 before OpenImageIO reports them
    # (which it does, in the error we raise): keep them off the user's terminal.
    with _captured_stderr():
        data, fmt, declared_bits = _read_image_plane(path, max_pixels)
    if not np.all(np.isfinite(data)):
        raise ValueError(f"{path.name} holds NaN or infinite values; a mosaic must be finite")

    type_max = {
        oiio.UINT8: 255, oiio.UINT16: 65535, oiio.UINT32: 2**32 - 1,
        oiio.INT8: 127, oiio.INT16: 32767, oiio.INT32: 2**31 - 1,
    }.get(fmt.basetype)
    if type_max is not None:
        bits = declared_bits or 8 * fmt.size()
        raw_max = float(np.round(float(data.max()) * type_max))
    else:
        bits = None
        raw_max = float(data.max())
        if raw_max > FLOAT_MOSAIC_MAX:  # in camera units: the saturation tests, depth and noise model would all be off
            raise ValueError(f"{path.name} holds float values up to {raw_max:.6g}: a float mosaic must be normalised "
                             "(black 0, white 1): subtract the black level and divide by white - black")
    return Mosaic(
        data=data, pattern=pattern, origin=(0, 0),
        black=[0.0, 0.0, 0.0, 0.0], white=1.0, source=str(path), bits=bits, raw_max=raw_max, kind="image",
    )


#: The largest value a float image mosaic may hold: it is taken as normalised (black 0, white 1; values are not
#: clipped, so noise and interpolation overshoot above 1 stay), and one in camera units (e.g. 64..4095) is refused.
FLOAT_MOSAIC_MAX = 2.0

#: Samples per band when an image mosaic is read (bounded temporary memory: the result is
#: the only full-size array, whatever the file's channel count).
_BAND_SAMPLES = 1 << 22


def _read_image_plane(path: Path, max_pixels: int):
    """The mosaic plane (float32 ``[H, W]``) of an image file, its pixel format and declared bits.

    The header is checked first (size against ``max_pixels``, channel count), so a
    file that declares a huge or non-mosaic image is refused before anything is
    allocated; the pixels are then read in bands of rows, the first channel kept
    and the others only compared with it (the layouts of the module docstring).
    """
    import OpenImageIO as oiio

    from .images import one_line_error

    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise ValueError(f"cannot read image {path}: {one_line_error(oiio.geterror()) or 'unknown format'}")
    try:
        expected, actual = IMAGE_FORMATS.get(path.suffix.lower()), inp.format_name()
        if expected is not None and actual != expected:
            raise ValueError(
                f"{path.name} holds a {actual} image, not the {expected} its extension says: give it its real extension "
                "(a DNG or camera raw must keep its raw extension to be read with its black and white levels)"
            )
        spec = inp.spec()
        width, height, channels = int(spec.width), int(spec.height), int(spec.nchannels)
        if width < 1 or height < 1 or int(spec.depth) > 1:
            raise ValueError(f"{path.name} declares a {width}x{height}x{spec.depth} image, not a 2-D mosaic")
        if width * height > max_pixels:
            raise ValueError(
                f"{path.name} is {width}x{height} = {width * height} pixels, more than the limit of {max_pixels}"
            )
        if spec.deep:
            raise ValueError(f"{path.name} is a deep image (several samples per pixel), not a Bayer mosaic")
        if channels not in (1, 3, 4):
            raise ValueError(_layout_error(path, height, width, channels))
        fmt = spec.format
        declared_bits = spec.get_int_attribute("oiio:BitsPerSample", 0)
        used = min(channels, 3)  # a fourth channel (alpha) is not looked at
        data = np.empty((height, width), np.float32)
        repeated = zeroed = used > 1
        rows_per_band = max(1, _BAND_SAMPLES // (width * used))
        tile = int(spec.tile_height) if int(spec.tile_width) > 0 else 0
        if tile > 0:
            rows_per_band = max(1, rows_per_band // tile) * tile
        for y in range(0, height, rows_per_band):
            rows = min(rows_per_band, height - y)
            if tile > 0:
                band = inp.read_tiles(0, 0, spec.x, spec.x + width, spec.y + y, spec.y + y + rows,
                                      spec.z, spec.z + 1, 0, used, oiio.FLOAT)
            else:
                band = inp.read_scanlines(0, 0, spec.y + y, spec.y + y + rows, spec.z, 0, used, oiio.FLOAT)
            if band is None or inp.has_error:
                raise ValueError(f"cannot read image {path}: {one_line_error(inp.geterror()) or 'read failed'}")
            band = np.asarray(band, dtype=np.float32)
            if band.size != rows * width * used:
                raise ValueError(f"cannot read image {path}: got {band.size} samples for rows {y}..{y + rows - 1}, "
                                 f"expected {rows * width * used}")
            band = band.reshape(rows, width, used)
            plane = band[:, :, 0]
            data[y:y + rows] = plane
            if used > 1:
                repeated = repeated and np.array_equal(band[:, :, 1], plane) and np.array_equal(band[:, :, 2], plane)
                zeroed = zeroed and not np.any(band[:, :, 1:])
                if not (repeated or zeroed):
                    raise ValueError(_layout_error(path, height, width, channels))
    finally:
        inp.close()
    return data, fmt, declared_bits


def _layout_error(path: Path, height: int, width: int, channels: int) -> str:
    return (
        f"{path.name} has shape {height}x{width}x{channels}: a mosaic must have one "
        "channel, or 3/4 channels with the mosaic repeated in the first three (or only in the first, "
        "the others zero); this looks like an RGB image, not a Bayer mosaic"
    )


# --------------------------------------------------------------------------- raws


def _read_raw_mosaic(path: Path, pattern: str | None, max_pixels: int) -> Mosaic:
    import rawpy

    error = None
    raw = None
    with _captured_stderr() as messages:
        try:
            raw = rawpy.imread(str(path))
        except rawpy.LibRawError as exc:
            error = exc
        except OSError as exc:
            error = exc
    if error is not None:
        raise ValueError(f"cannot read {path}: {_libraw_cause(error, messages, path)}") from None

    with raw:
        sizes = raw.sizes
        declared = int(sizes.raw_height) * int(sizes.raw_width)
        if declared > max_pixels:
            raise ValueError(
                f"{path.name} declares a {sizes.raw_width}x{sizes.raw_height} sensor = {declared} pixels, "
                f"more than the limit of {max_pixels}"
            )
        with _captured_stderr() as messages:
            try:
                visible = raw.raw_image_visible
                raw_type = raw.raw_type
            except (rawpy.LibRawError, RuntimeError) as exc:  # RuntimeError: rawpy's 'unsupported raw data'
                error = exc
        if error is not None:
            raise ValueError(f"cannot decode {path}: {_libraw_cause(error, messages, path)}") from None
        if raw_type != rawpy.RawType.Flat or visible.ndim != 2:
            per_pixel = visible.shape[2] if visible.ndim == 3 else "several"
            raise ValueError(
                f"{path.name} is not a Bayer sensor (LibRaw gives {per_pixel} colour samples per pixel: an "
                "RGB/linear image such as a film scanner file, a linear DNG or a stacked/Foveon sensor)"
            )
        if visible.size == 0:
            raise ValueError(f"{path.name} has an empty visible area")

        cells = _bayer_cells(raw, path)
        desc = raw.color_desc.decode("ascii", "replace")
        file_pattern = parse_pattern("".join(desc[int(i)] for i in cells.ravel()))
        if pattern is not None and pattern != file_pattern:
            raise ValueError(
                f"--pattern {pattern} disagrees with {path.name}, whose visible area starts with "
                f"{file_pattern} (leave the pattern out to use the file's)"
            )

        black = [float(b) for b in raw.black_level_per_channel]
        white = float(raw.white_level)
        tags = _tiff_tags(path)
        black = _fix_dng_black_phase(black, cells, sizes, tags)

        raw_values = np.array(visible, dtype=np.float32)  # copy: the view dies with `raw`
        cam_mul = [float(v) for v in raw.camera_whitebalance]
        xyz_to_camera = np.array(raw.rgb_xyz_matrix, dtype=np.float32)[:3]
        color_matrix = np.array(raw.color_matrix, dtype=np.float32)

    black_cells = np.array([black[int(i)] for i in cells.ravel()], dtype=np.float64).reshape(2, 2)
    if white <= float(black_cells.max()):
        raise ValueError(f"{path.name}: white level {white:g} is not above the black levels {black}")
    raw_max = float(raw_values.max())
    data = raw_values  # normalised in place, one CFA phase at a time (no per-pixel black map)
    for y in range(2):
        for x in range(2):
            phase = data[y::2, x::2]
            phase -= np.float32(black_cells[y, x])
            phase *= np.float32(1.0 / (white - black_cells[y, x]))

    as_shot = None
    r, g, b = cam_mul[0], cam_mul[1], cam_mul[2]
    if all(math.isfinite(v) and v > 0 for v in (r, g, b)):
        as_shot = (r / g, 1.0, b / g)
        if not all(math.isfinite(v) and v > 0 for v in as_shot):
            as_shot = None
    # A damaged file can hold NaN/Inf colour matrices: metadata we cannot use is metadata we do not have.
    xyz_to_camera = xyz_to_camera if np.any(xyz_to_camera) and np.all(np.isfinite(xyz_to_camera)) else None
    color_matrix = color_matrix if np.any(color_matrix) and np.all(np.isfinite(color_matrix)) else None

    return Mosaic(
        data=np.ascontiguousarray(data, dtype=np.float32),
        pattern=file_pattern,
        origin=(0, 0),
        black=black,
        white=white,
        as_shot_wb=as_shot,
        xyz_to_camera=xyz_to_camera,
        color_matrix=color_matrix,
        noise_profile=tags.get("noise_profile"),
        source=str(path),
        bits=int(white).bit_length() if white >= 1 else None,
        raw_max=raw_max,
        camera=tags.get("camera"),
        kind="raw",
    )


def _bayer_cells(raw, path: Path) -> np.ndarray:
    """LibRaw colour indices (0 R, 1 G, 2 B, 3 G2) of the visible area's 2x2 top-left cell.

    Where the pattern starts: LibRaw's ``COLOR(row, col)`` is relative to the
    *visible* area (LibRaw issue #172), while rawpy's ``raw_color(row, col)``
    takes *full-raw* coordinates and calls ``COLOR(row - top_margin, col -
    left_margin)``, so rawpy's ``raw_pattern`` (built from ``raw_color(y, x)``,
    y, x < 2) is nominally the phase at full-raw (0, 0). The two agree because
    LibRaw >= 0.20 makes top/left margins even for Bayer sensors (an odd DNG
    ActiveArea is rounded up and the visible area loses a row/column; checked
    with rawpy 0.28 / LibRaw 0.22 on DNGs written with odd ActiveArea). To be
    right whatever the margins, we ask for ``COLOR(y, x)`` itself:
    ``raw_color(top_margin + y, left_margin + x)``. This was also checked
    against LibRaw's own half-size decode of colorchart.dng (margins 26/152),
    the Canon CRWs (6/12) and the Kodak/QuickTake files.
    """
    desc = raw.color_desc.decode("ascii", "replace")
    try:
        repeat = raw.raw_pattern
    except NotImplementedError as exc:  # a LibRaw `filters` value rawpy does not know
        raise ValueError(f"{path.name} is not a Bayer sensor (unknown colour filter layout: {exc})") from None
    n = 0 if repeat is None else repeat.shape[0]
    if n != 2:
        what = {
            0: "no colour filter array",
            1: "monochrome sensor, no colour filter array",
            6: "Fuji X-Trans 6x6 colour filter array",
            16: "Leaf Catchlight 16x16 colour filter array",
        }.get(n, f"colour filter array repeating every {n}x{n} pixels, not 2x2")
        raise ValueError(f"{path.name} is not a Bayer sensor ({what})")
    sizes = raw.sizes
    top, left = int(sizes.top_margin), int(sizes.left_margin)
    # LibRaw's Bayer `filters` word describes 8 rows x 2 columns: check 8x8 is 2x2-periodic.
    block = np.array([[raw.raw_color(top + y, left + x) for x in range(8)] for y in range(8)])
    cells = block[:2, :2]
    if not np.array_equal(block, np.tile(cells, (4, 4))):
        raise ValueError(f"{path.name} is not a Bayer sensor (its colour filter array does not repeat every 2x2 pixels)")
    letters = "".join(desc[int(i)] if 0 <= int(i) < len(desc) else "?" for i in cells.ravel())
    if sorted(letters) != ["B", "G", "G", "R"]:
        raise ValueError(
            f"{path.name} is not a Bayer sensor (colour filters {letters!r} from LibRaw's colour description "
            f"{desc!r}; only R, G, G, B is supported)"
        )
    return cells.astype(np.int64)


def _fix_dng_black_phase(black: list[float], cells: np.ndarray, sizes, tags: dict) -> list[float]:
    """Undo LibRaw's black-level phase slip on DNGs with an odd ActiveArea origin.

    A DNG's per-position BlackLevel pattern (BlackLevelRepeatDim 2x2) starts at
    the ActiveArea's top-left, like its CFAPattern. When LibRaw rounds an odd
    ActiveArea top/left up to an even margin it shifts the CFA phase but folds the
    black pattern into per-colour levels as if it started at the new margin
    (observed with LibRaw 0.22 on synthetic DNGs). Shift it back by the rounding.
    """
    active = tags.get("active_area")
    repeat = tags.get("black_repeat")
    if active is None or repeat is None or tuple(repeat) != (2, 2) or len(set(black)) == 1:
        return black
    dy = (int(sizes.top_margin) - int(active[0])) % 2
    dx = (int(sizes.left_margin) - int(active[1])) % 2
    if (dy, dx) == (0, 0):
        return black
    libraw_cells = np.array([black[int(i)] for i in cells.ravel()]).reshape(2, 2)
    fixed = list(black)
    for y in range(2):
        for x in range(2):
            fixed[int(cells[y, x])] = float(libraw_cells[(y + dy) % 2, (x + dx) % 2])
    return fixed


#: IFDs (and SubIFDs of each) that :func:`_tiff_tags` looks at.
_MAX_TIFF_PAGES = 16


def _tiff_tags(path: Path) -> dict:
    """Camera name, and for DNGs ActiveArea / BlackLevelRepeatDim / NoiseProfile, via tifffile.

    Best effort: anything tifffile cannot read (non-TIFF raws such as CRW, KDC,
    QTK; damaged files) gives an empty dict.
    """
    import itertools
    import logging
    import warnings

    out: dict = {}
    logger = logging.getLogger("tifffile")
    level = logger.level
    logger.setLevel(logging.CRITICAL)  # its warnings about odd tags are not ours to print
    try:
        import tifffile

        with warnings.catch_warnings(), tifffile.TiffFile(str(path)) as tif:
            warnings.simplefilter("ignore")
            # a damaged or hostile file can chain any number of IFDs: a DNG's raw is in the first few
            pages = list(itertools.islice(tif.pages, _MAX_TIFF_PAGES))
            for page in list(pages):
                sub = getattr(page, "pages", None)
                if page.subifds and sub is not None:
                    pages.extend(itertools.islice(sub, _MAX_TIFF_PAGES))

            def tag(page, code):
                t = page.tags.get(code)
                return None if t is None else t.value

            first = pages[0]
            make, model = tag(first, 271), tag(first, 272)
            unique = tag(first, 50708)
            make = str(make or "").strip()
            model = str(model or "").strip()
            name = model if make and model.lower().startswith(make.lower()) else f"{make} {model}".strip()
            if not name and unique:
                name = str(unique).strip()
            name = "".join(c if c.isprintable() else " " for c in _one_line(name))[:200].strip()
            if name:
                out["camera"] = name
            cfa = [p for p in pages if getattr(p, "photometric", None) == 32803 and not (int(p.subfiletype) & 1)]
            raw_page = cfa[0] if cfa else None
            for source in ([raw_page] if raw_page is not None else []) + [first]:
                if "active_area" not in out and tag(source, 50829) is not None:
                    out["active_area"] = tuple(int(v) for v in tag(source, 50829))
                if "black_repeat" not in out and tag(source, 50713) is not None:
                    out["black_repeat"] = tuple(int(v) for v in tag(source, 50713))
                if "noise_profile" not in out and tag(source, 51041) is not None:
                    value = tag(source, 51041)
                    value = value if isinstance(value, (tuple, list)) else (value,)
                    out["noise_profile"] = tuple(float(v) for v in value)
            if raw_page is None:  # only trust DNG-specific placement for CFA files
                out.pop("active_area", None)
                out.pop("black_repeat", None)
            # keep only well-formed values (a damaged file can hold anything)
            if len(out.get("active_area", (0,) * 4)) != 4:
                out.pop("active_area")
            if len(out.get("black_repeat", (0,) * 2)) != 2:
                out.pop("black_repeat")
            profile = out.get("noise_profile")
            if profile is not None and (len(profile) < 2 or len(profile) % 2
                                        or not all(math.isfinite(v) for v in profile)):
                out.pop("noise_profile")
    except Exception:
        return {k: v for k, v in out.items() if k == "camera"}
    finally:
        logger.setLevel(level)
    return out


# --------------------------------------------------------------------------- errors


def _one_line(text: str) -> str:
    return " ".join(str(text).split())


def _libraw_cause(error: BaseException, messages: list[str], path: Path) -> str:
    """One line: LibRaw's error string plus what it printed on stderr."""
    first = error.args[0] if error.args else None
    if isinstance(first, tuple) and len(first) == 2:  # rawpy's OSError((errno, strerror))
        cause = str(first[1])
    elif isinstance(first, bytes):
        cause = first.decode("utf-8", "replace")
    else:
        cause = str(error)
    if "Unsupported file format" in cause:
        cause += " (LibRaw cannot decode this file)"
    elif type(error).__name__ == "LibRawIOError" and _readable(path):  # LibRaw's word for data it cannot parse
        cause += " (the file itself reads fine: not a camera raw LibRaw can decode, or a damaged one)"
    extra = []
    for line in messages:
        line = line.strip()
        prefix = f"{path}: "
        line = line.removeprefix(prefix)
        if line and line not in extra:
            extra.append(line)
    if extra:
        cause += f" ({'; '.join(extra)})"
    return _one_line(f"{type(error).__name__}: {cause}")


def _readable(path: Path) -> bool:
    try:
        with open(path, "rb") as f:
            f.read(1)
        return True
    except OSError:
        return False


@contextlib.contextmanager
def _captured_stderr():
    """Collect what C code (LibRaw) prints on file descriptor 2 while the block runs.

    LibRaw reports e.g. "Unexpected end of file" on stderr before rawpy raises;
    catching it keeps our error to one line and puts the cause in it. The list
    is filled when the block exits. While it runs, anything else written to fd 2
    in this process is caught too; callers report it only with an error.
    """
    lines: list[str] = []
    try:
        sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, ValueError, AttributeError):
        yield lines
        return
    tmp = tempfile.TemporaryFile()  # noqa: SIM115 (closed in the finally below, after fd 2 is restored)
    try:
        os.dup2(tmp.fileno(), 2)
        try:
            yield lines
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            tmp.seek(0)
            lines.extend(tmp.read().decode("utf-8", "replace").splitlines())
    finally:
        tmp.close()
