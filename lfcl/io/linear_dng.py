"""LinearRaw DNG: a demosaiced image handed back to a raw editor (darktable, RawTherapee, ...), docs/darktable.md.

A LinearRaw DNG holds demosaiced, still scene-linear *camera* RGB together with the
camera's colour matrix and as-shot white balance, so the editor goes on with white
balance, colour, tone and lens corrections as for any raw (as DxO PureRAW and Adobe's
Enhance hand their results back). lfcl writes one per image output with ``--format dng``
(lfcl.outputs.files).

The layout is the one that rawpy (LibRaw), darktable-cli 4.2 and rawtherapee-cli 5.9
all render (tests/test_linear_dng.py; tiles, deflate and float samples each broke at
least one of them): one IFD, NewSubfileType 0, uncompressed strips, 3 samples of 16
bits, and

=====  ======================  ==================================================================
tag    name                    value
=====  ======================  ==================================================================
262    PhotometricInterp.      34892 (LinearRaw)
270    ImageDescription        ``{"lfcl": {...}}``: method, parameters and output, as in the EXRs
271    Make, 272 Model         the input raw's (TIFF-based raws and DNGs), else "lfcl" and the
                               camera name LibRaw knows
274    Orientation             the input's, else 1
50706  DNGVersion              1.4.0.0; 50707 DNGBackwardVersion 1.3.0.0
50708  UniqueCameraModel       the input's, else "Make Model"
50714  BlackLevel              0, 0, 0: the black is subtracted before (darktable ignores
                               BlackLevel on LinearRaw); BlackLevelRepeatDim 1, 1
50717  WhiteLevel              65535 per sample: code = round(65535 x value), value in the
                               normalised raw's units (1 = the raw's white), clipped to [0, 1]
50721  ColorMatrix1            XYZ -> camera: see :class:`DngCamera`
50778  CalibrationIlluminant1  its illuminant (21 = D65 where lfcl supplies the matrix)
50728  AsShotNeutral           camera RGB of the scene's white (1 / the as-shot multipliers)
=====  ======================  ==================================================================

From an input DNG the colour tags are carried as they are: ColorMatrix1/2,
CalibrationIlluminant1/2, CameraCalibration1/2, AnalogBalance, ForwardMatrix1/2,
AsShotNeutral, AsShotWhiteXY and BaselineExposure. From another camera raw, LibRaw's
``cam_xyz`` (a D65 matrix, dcraw's and Adobe's convention) is ColorMatrix1 with
illuminant D65. Without any matrix (an EXR/TIFF mosaic), camera RGB is declared to be
linear sRGB (ColorMatrix1 = XYZ -> sRGB, the simulator's convention) and the file says so.
"""

from __future__ import annotations

import dataclasses
from fractions import Fraction
from pathlib import Path

import numpy as np

#: The code of the normalised raw's white (value 1).
WHITE_LEVEL = 65535
D65 = 21  # EXIF LightSource / DNG CalibrationIlluminant
XYZ_D65 = (0.95047, 1.0, 1.08883)
# XYZ (D65) -> linear sRGB, IEC 61966-2-1 (the matrix colour-science's sRGB colourspace uses).
XYZ_TO_SRGB = (
    (3.2406, -1.5372, -0.4986),
    (-0.9689, 1.8758, 0.0415),
    (0.0557, -0.2040, 1.0570),
)

# tifffile tag types
BYTE, ASCII, SHORT, LONG, RATIONAL, SRATIONAL = 1, 2, 3, 4, 5, 10

#: DNG colour tags carried from an input DNG: code -> (name, type, values per colour plane count rule).
COLOUR_TAGS = {
    50721: ("ColorMatrix1", SRATIONAL, 9),
    50722: ("ColorMatrix2", SRATIONAL, 9),
    50723: ("CameraCalibration1", SRATIONAL, 9),
    50724: ("CameraCalibration2", SRATIONAL, 9),
    50727: ("AnalogBalance", RATIONAL, 3),
    50728: ("AsShotNeutral", RATIONAL, 3),
    50729: ("AsShotWhiteXY", RATIONAL, 2),
    50730: ("BaselineExposure", SRATIONAL, 1),
    50778: ("CalibrationIlluminant1", SHORT, 1),
    50779: ("CalibrationIlluminant2", SHORT, 1),
    50964: ("ForwardMatrix1", SRATIONAL, 9),
    50965: ("ForwardMatrix2", SRATIONAL, 9),
}


def rationals(values, signed: bool, denominator: int = 10000) -> tuple:
    """TIFF (S)RATIONAL values: numerator, denominator pairs of ``values`` (shared with lfcl.sim.dng)."""
    out = []
    limit = 2**31 - 1 if signed else 2**32 - 1
    for v in values:
        f = Fraction(float(v)).limit_denominator(denominator)
        num, den = f.numerator, f.denominator
        if not signed and num < 0:
            raise ValueError("unsigned rational must be >= 0")
        if abs(num) > limit:
            raise ValueError(f"{float(v)!r} does not fit a TIFF rational")
        out += [num, den]
    return tuple(out)


def _floats(tag_value, tag_type: int) -> tuple[float, ...]:
    """A tag's value as floats (tifffile gives rationals as flat numerator, denominator pairs)."""
    values = tag_value if isinstance(tag_value, (tuple, list)) else (tag_value,)
    if tag_type in (RATIONAL, SRATIONAL):
        if len(values) % 2:
            raise ValueError("odd rational")
        # x/0 (real DNGs hold a BaselineExposure of 0/0): NaN, so that tag alone is left out, not every tag
        return tuple(values[i] / values[i + 1] if values[i + 1] else float("nan") for i in range(0, len(values), 2))
    return tuple(float(v) for v in values)


@dataclasses.dataclass(frozen=True)
class DngCamera:
    """What a LinearRaw DNG says about the camera: names, orientation and the colour tags.

    ``colour``: DNG colour tag code -> float values (at least ColorMatrix1 (50721),
    CalibrationIlluminant1 (50778) and AsShotNeutral (50728)). ``source``: where the
    colour tags come from, in words (recorded in the file's description).
    """

    make: str
    model: str
    unique_model: str
    colour: dict
    source: str
    orientation: int = 1

    def __post_init__(self):
        for code in (50721, 50778, 50728):
            if code not in self.colour:
                raise ValueError(f"a LinearRaw DNG needs {COLOUR_TAGS[code][0]}")
        for code, values in self.colour.items():
            if code not in COLOUR_TAGS:
                raise ValueError(f"tag {code} is not a DNG colour tag lfcl carries")
            if not all(np.isfinite(v) for v in values):
                raise ValueError(f"{COLOUR_TAGS[code][0]} is not finite: {values}")
        if not all(v > 0 for v in self.colour[50728]):
            raise ValueError(f"AsShotNeutral must be positive, got {self.colour[50728]}")

    # --- constructors -------------------------------------------------------------------
    @classmethod
    def from_matrix(cls, xyz_to_camera=None, as_shot_wb=None, make: str = "lfcl", model: str = "",
                    orientation: int = 1, source: str | None = None) -> DngCamera:
        """From an XYZ -> camera matrix (D65) and as-shot multipliers (R, G, B; G = 1); see the module docstring.

        Without a matrix, camera RGB is declared linear sRGB; without multipliers, the
        neutral is the camera's response to D65 (the matrix's) normalised to G = 1.
        """
        matrix = None if xyz_to_camera is None else np.asarray(xyz_to_camera, np.float64)[:3, :3]
        if matrix is not None and (not np.all(np.isfinite(matrix)) or abs(np.linalg.det(matrix)) < 1e-12):
            matrix = None
        words = source or ("the raw's XYZ -> camera matrix (LibRaw cam_xyz), illuminant D65"
                           if matrix is not None else "none in the raw: camera RGB declared linear sRGB")
        if matrix is None:
            matrix = np.asarray(XYZ_TO_SRGB, np.float64)
        if as_shot_wb is not None and all(np.isfinite(g) and g > 0 for g in as_shot_wb):
            gains = np.asarray(as_shot_wb, np.float64)[:3]
            neutral = gains[1] / gains
        else:
            response = matrix @ np.asarray(XYZ_D65)
            neutral = response / response[1] if np.all(response > 0) else np.ones(3)
            words += "; no as-shot white balance: neutral = the camera's D65 response"
        model = model or "unknown camera"
        return cls(make=make, model=model, unique_model=f"{make} {model}".strip(),
                   colour={50721: tuple(matrix.ravel()), 50778: (D65,), 50728: tuple(neutral)},
                   source=words, orientation=int(orientation))

    @classmethod
    def from_mosaic(cls, mosaic) -> DngCamera:
        """From an :class:`lfcl.io.raw.Mosaic`: an input DNG's own tags, else the matrix and white balance LibRaw read."""
        tags = _input_tags(mosaic.source) if getattr(mosaic, "kind", "") == "raw" else {}
        make = tags.get(271) or "lfcl"
        model = tags.get(272) or (mosaic.camera or "")
        matrix = mosaic.xyz_to_camera
        source = None
        if matrix is None and mosaic.color_matrix is not None:  # only rgb_cam: XYZ -> camera through sRGB
            rgb_cam = np.asarray(mosaic.color_matrix, np.float64)[:3, :3]
            if np.all(np.isfinite(rgb_cam)) and abs(np.linalg.det(rgb_cam)) > 1e-12:
                matrix = np.linalg.inv(rgb_cam) @ np.asarray(XYZ_TO_SRGB)
                source = "inv(the raw's camera -> sRGB matrix, LibRaw rgb_cam) @ XYZ -> sRGB, illuminant D65"
        camera = cls.from_matrix(matrix, mosaic.as_shot_wb, make=make, model=model,
                                 orientation=tags.get(274, 1), source=source)
        colour = tags.get("colour")
        if colour:  # the input DNG's own colour tags win: they are what its editor would use
            camera = dataclasses.replace(camera, colour=colour, source="the input DNG's colour tags, as they were")
        if tags.get(50708):
            camera = dataclasses.replace(camera, unique_model=tags[50708])
        return camera

    # --- the file -----------------------------------------------------------------------
    def tags(self) -> list[tuple]:
        """tifffile ``extratags`` for these names and colour tags (not the pixel layout's)."""
        out = [
            (271, ASCII, 0, _ascii(self.make), True),
            (272, ASCII, 0, _ascii(self.model), True),
            (274, SHORT, 1, int(self.orientation), True),
            (50706, BYTE, 4, (1, 4, 0, 0), True),
            (50707, BYTE, 4, (1, 3, 0, 0), True),
            (50708, ASCII, 0, _ascii(self.unique_model), True),
        ]
        for code in sorted(self.colour):
            _, kind, _ = COLOUR_TAGS[code]
            values = self.colour[code]
            if kind == SHORT:
                out.append((code, SHORT, len(values), tuple(int(v) for v in values), True))
            else:
                out.append((code, kind, len(values), rationals(values, signed=kind == SRATIONAL,
                                                               denominator=1_000_000), True))
        return out

    def metadata(self) -> dict:
        return {"make": self.make, "model": self.model, "unique_camera_model": self.unique_model,
                "colour_tags": self.source,
                **{COLOUR_TAGS[c][0]: [round(float(v), 6) for v in vals] for c, vals in sorted(self.colour.items())}}


def _ascii(text: str) -> str:
    text = "".join(c if 32 <= ord(c) < 127 else " " for c in str(text)).strip()
    return text or "unknown"


def _input_tags(path) -> dict:
    """Make (271), Model (272), Orientation (274), UniqueCameraModel (50708) and, for a DNG of three colour
    planes, its colour tags (``"colour"``), from the first IFD of a TIFF-based raw; {} for other files."""
    import logging
    import warnings

    import tifffile

    out: dict = {}
    logger = logging.getLogger("tifffile")
    level = logger.level
    logger.setLevel(logging.CRITICAL)
    try:
        with warnings.catch_warnings(), tifffile.TiffFile(str(path)) as tif:
            warnings.simplefilter("ignore")
            tags = tif.pages[0].tags
            for code in (271, 272, 50708):
                if code in tags and isinstance(tags[code].value, str) and tags[code].value.strip():
                    out[code] = _ascii(tags[code].value)
            if 274 in tags and int(tags[274].value) in range(1, 9):
                out[274] = int(tags[274].value)
            if 50706 in tags and 50721 in tags:  # a DNG with a colour matrix
                colour = {}
                for code, (_, kind, count) in COLOUR_TAGS.items():
                    if code in tags:
                        values = _floats(tags[code].value, kind)
                        if len(values) == count and all(np.isfinite(v) for v in values):
                            colour[code] = values
                if 50721 in colour and 50728 in colour and all(v > 0 for v in colour[50728]):
                    colour.setdefault(50778, (D65,))
                    out["colour"] = colour
    except Exception:  # not a TIFF (or a damaged one): the names LibRaw gave and its matrix instead
        return {}
    finally:
        logger.setLevel(level)
    return out


def dng_codes(image: np.ndarray) -> np.ndarray:
    """uint16 codes of ``image`` (normalised raw units): ``round(65535 x value)``, clipped to [0, 65535]."""
    image = np.asarray(image, np.float32)
    return np.clip(np.rint(image.astype(np.float64) * WHITE_LEVEL), 0, WHITE_LEVEL).astype(np.uint16)


#: LibRaw (rawpy) opens no raw narrower than this many pixels on a side ("Unsupported file format or not RAW file":
#: 21x21-pixel DNGs failed, 22x22 opened, LibRaw 0.22).
MIN_DNG_SIDE = 22


def write_linear_dng(path, image: np.ndarray, camera: DngCamera | None = None, metadata: dict | None = None) -> Path:
    """Write ``image`` ``(H, W, 3)`` (camera RGB, the normalised raw's units) as a LinearRaw DNG, atomically.

    ``camera``: names and colour tags (default: camera RGB declared linear sRGB, neutral
    white balance). ``metadata``: recorded as ``{"lfcl": metadata}`` JSON in ImageDescription,
    with the camera's description under ``dng``.
    """
    import tifffile

    from .. import __version__
    from .images import atomic_path, to_json

    image = np.asarray(image)
    if image.ndim != 3 or image.shape[2] != 3 or min(image.shape[:2]) < 1:
        raise ValueError(f"a LinearRaw DNG holds an (H, W, 3) image, got shape {image.shape}")
    if min(image.shape[:2]) < MIN_DNG_SIDE:
        raise ValueError(f"{Path(path).name}: a {image.shape[0]}x{image.shape[1]} DNG would not open in raw editors (LibRaw "
                         f"reads {MIN_DNG_SIDE} pixels a side at least): use --format exr or tiff")
    camera = camera or DngCamera.from_matrix(None, (1.0, 1.0, 1.0))
    path = Path(path)
    meta = {**(metadata or {}), "dng": camera.metadata()}
    description = to_json({"lfcl": meta})  # ASCII (json escapes the rest), as TIFF wants
    layout = [
        (50713, SHORT, 2, (1, 1), True),  # BlackLevelRepeatDim
        (50714, LONG, 3, (0, 0, 0), True),  # BlackLevel: subtracted already
        (50717, LONG, 3, (WHITE_LEVEL,) * 3, True),  # WhiteLevel
    ]
    with atomic_path(path) as tmp:
        tifffile.imwrite(str(tmp), dng_codes(image), photometric=34892, planarconfig="contig", compression=None,
                         subfiletype=0, metadata=None, description=description, software=f"lfcl {__version__}",
                         extratags=camera.tags() + layout)
    return path
