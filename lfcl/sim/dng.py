"""Write a CFA mosaic as a minimal, valid DNG 1.4 with tifffile.

One uncompressed IFD (NewSubfileType 0) holding the uint16 mosaic, with:

=====  ======================  ==============================================
tag    name                    value
=====  ======================  ==============================================
262    PhotometricInterp.      32803 (CFA)
33421  CFARepeatPatternDim     2, 2
33422  CFAPattern              the Bayer pattern, 0 = R, 1 = G, 2 = B
50706  DNGVersion              1.4.0.0
50707  DNGBackwardVersion      1.3.0.0 (NoiseProfile is a DNG 1.3 tag)
50708  UniqueCameraModel       "lfcl simulated lenslet camera"
50710  CFAPlaneColor           0, 1, 2
50711  CFALayout               1 (rectangular)
50713  BlackLevelRepeatDim     1, 1
50714  BlackLevel              black level, DN
50717  WhiteLevel              2**bits - 1
50721  ColorMatrix1            XYZ -> linear sRGB (IEC 61966-2-1), the camera's primaries
50728  AsShotNeutral           1, 1, 1 (D65 white is neutral for sRGB primaries)
50778  CalibrationIlluminant1  21 (D65)
51041  NoiseProfile            (S, O) for R, G, B: variance = S * x + O, x in [0, 1]
=====  ======================  ==============================================

plus Make "lfcl", Model "simulated lenslet camera", Orientation 1 and Software.
LibRaw (rawpy) reads it back bit-exactly with the right ``raw_pattern``,
``black_level_per_channel`` and ``white_level``; its ``color_matrix`` comes out
as the identity (camera = sRGB).
"""

from __future__ import annotations

import numpy as np
import tifffile

from ..io.linear_dng import (
    MIN_DNG_SIDE,  # LibRaw, hence `lfcl process`, reads no narrower raw
    XYZ_TO_SRGB,  # XYZ (D65) -> linear sRGB: the simulated camera's primaries
)
from ..io.linear_dng import rationals as _rationals  # the TIFF rationals, shared with the LinearRaw writer
from ..layout import CHANNEL_INDEX, parse_pattern

CAMERA_MODEL = "lfcl simulated lenslet camera"


def dng_tags(pattern: str, black_level: int, white_level: int, noise_profile=None,
             as_shot_neutral=(1.0, 1.0, 1.0)) -> list[tuple]:
    """tifffile ``extratags`` for a Bayer DNG."""
    pattern = parse_pattern(pattern)
    tags = [
        (271, 2, 0, "lfcl", True),
        (272, 2, 0, "simulated lenslet camera", True),
        (274, 3, 1, 1, True),
        (33421, 3, 2, (2, 2), True),
        (33422, 1, 4, tuple(CHANNEL_INDEX[c] for c in pattern), True),
        (50706, 1, 4, (1, 4, 0, 0), True),
        (50707, 1, 4, (1, 3, 0, 0), True),
        (50708, 2, 0, CAMERA_MODEL, True),
        (50710, 1, 3, (0, 1, 2), True),
        (50711, 3, 1, 1, True),
        (50713, 3, 2, (1, 1), True),
        (50714, 4, 1, int(black_level), True),
        (50717, 4, 1, int(white_level), True),
        (50721, 10, 9, _rationals(np.ravel(XYZ_TO_SRGB), signed=True), True),
        (50728, 5, 3, _rationals(as_shot_neutral, signed=False), True),
        (50778, 3, 1, 21, True),
    ]
    if noise_profile is not None:
        values = []
        for s, o in noise_profile:
            values += [float(s), float(o)]
        tags.append((51041, 12, len(values), tuple(values), True))
    return tags




def write_dng(path, mosaic: np.ndarray, pattern: str, black_level: int, white_level: int,
              noise_profile=None) -> None:
    """Write ``mosaic`` (uint16 ``[H, W]``, at least :data:`MIN_DNG_SIDE` pixels a side) to ``path`` (not atomic:
    write into a temporary folder)."""
    mosaic = np.asarray(mosaic)
    if mosaic.ndim != 2 or mosaic.dtype != np.uint16:
        raise ValueError(f"a DNG mosaic must be uint16 [H, W], got {mosaic.dtype} {mosaic.shape}")
    if min(mosaic.shape) < MIN_DNG_SIDE:
        raise ValueError(f"a {mosaic.shape[0]}x{mosaic.shape[1]}-pixel raw would be a DNG that LibRaw (and so lfcl "
                         f"process) cannot read: it needs {MIN_DNG_SIDE} pixels a side (at pitch 9, 3 lenses)")
    if noise_profile is not None and np.ndim(noise_profile) == 1:
        noise_profile = [tuple(noise_profile)] * 3
    tifffile.imwrite(
        str(path), mosaic, photometric=32803, metadata=None, software="lfcl simulate",
        subfiletype=0, extratags=dng_tags(pattern, black_level, white_level, noise_profile),
    )


def read_noise_profile(path) -> list[tuple[float, float]]:
    """The ``(S, O)`` pairs of a DNG's NoiseProfile tag (empty if absent)."""
    with tifffile.TiffFile(str(path)) as tif:
        tag = tif.pages[0].tags.get(51041)
        if tag is None:
            return []
        values = list(tag.value)
    return [(values[i], values[i + 1]) for i in range(0, len(values), 2)]
