"""User images as linear RGB, and as plane textures (``--texture IMAGE``).

:func:`read_linear` reads anything OpenImageIO reads. Integer (8/16-bit) files
are taken as sRGB-encoded and decoded to linear with colour-science's
``cctf_decoding(..., function="sRGB")`` (through a lookup table of every code
value, so it is exact and fast); float files (EXR, float TIFF) are taken as
linear already. Camera raws that OpenImageIO cannot open (CRW, NEF, most DNGs)
are developed by LibRaw (rawpy) to linear sRGB with the camera's white balance
and no brightening, so a photograph's own scene statistics can texture a plane. Grey images are replicated to RGB, alpha is dropped, negative
values are clipped to 0.

:class:`ImageTexture` maps an image onto a plane: the image is scaled to
*cover* the plane's box (aspect kept, centred, the overflow cropped),
pre-filtered to at most ``PIXELS_PER_LENS`` image pixels per lens (area
average, so it does not alias) and sampled bilinearly; outside the image the
edge pixels continue.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import OpenImageIO as oiio

PIXELS_PER_LENS = 4
#: Image files OpenImageIO opens first; any other file is tried as a camera raw first (a TIFF-based
#: raw such as a Kodak KDC opens in OpenImageIO as its embedded thumbnail).
IMAGE_SUFFIXES = frozenset((".png", ".jpg", ".jpeg", ".tif", ".tiff", ".exr", ".hdr", ".bmp", ".ppm", ".pgm",
                            ".pnm", ".pfm", ".webp", ".gif", ".tga", ".dpx", ".jp2", ".psd", ".sgi", ".fits"))


def _decode_lut(bits: int) -> np.ndarray:
    import colour

    codes = np.arange(2**bits, dtype=np.float64) / (2**bits - 1)
    return np.asarray(colour.cctf_decoding(codes, function="sRGB"), dtype=np.float32)


def srgb_decode(values: np.ndarray) -> np.ndarray:
    """uint8 / uint16 sRGB code values -> linear float32 in [0, 1]."""
    values = np.asarray(values)
    if values.dtype == np.uint8:
        return _decode_lut(8)[values]
    if values.dtype == np.uint16:
        return _decode_lut(16)[values]
    raise ValueError(f"sRGB decoding needs uint8 or uint16 code values, got {values.dtype}")


def _to_rgb(pixels: np.ndarray, path) -> np.ndarray:
    if pixels.ndim == 2:
        pixels = pixels[:, :, None]
    channels = pixels.shape[2]
    if channels in (1, 2):
        pixels = np.repeat(pixels[:, :, :1], 3, axis=2)
    elif channels >= 3:
        pixels = pixels[:, :, :3]
    else:
        raise ValueError(f"image {path} has no channels")
    return pixels


def read_linear(path) -> np.ndarray:
    """An image file as linear float32 RGB ``(H, W, 3)``; ``ValueError`` if it cannot be read."""
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"cannot read image {path}: no such file")
    tried_raw = path.suffix.lower() not in IMAGE_SUFFIXES
    if tried_raw:  # a camera raw: OpenImageIO may read only its thumbnail
        developed = _develop_raw(path)
        if developed is not None:
            return _finite_rgb(developed, path)
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        reason = oiio.geterror().strip() or "unknown format"
        developed = None if tried_raw else _develop_raw(path)
        if developed is None:
            raise ValueError(f"cannot read image {path}: {reason} (nor is it a camera raw LibRaw reads)")
        return _finite_rgb(developed, path)
    try:
        spec = inp.spec()
        base = spec.format.basetype
        if base in (oiio.UINT8, oiio.UINT16):
            fmt = oiio.UINT8 if base == oiio.UINT8 else oiio.UINT16
            pixels = inp.read_image(0, 0, 0, spec.nchannels, fmt)
            if pixels is None:
                raise ValueError(f"cannot read image {path}: {inp.geterror().strip()}")
            pixels = srgb_decode(_to_rgb(np.asarray(pixels), path))
        else:
            pixels = inp.read_image(0, 0, 0, spec.nchannels, oiio.FLOAT)
            if pixels is None:
                raise ValueError(f"cannot read image {path}: {inp.geterror().strip()}")
            pixels = _to_rgb(np.asarray(pixels, dtype=np.float32), path)
    finally:
        inp.close()
    return _finite_rgb(pixels, path)


def _finite_rgb(pixels: np.ndarray, path) -> np.ndarray:
    if pixels.size == 0:
        raise ValueError(f"image {path} is empty")
    if not np.all(np.isfinite(pixels)):
        raise ValueError(f"image {path} holds NaN or Inf values")
    return np.ascontiguousarray(np.clip(pixels, 0.0, None), dtype=np.float32)


def _develop_raw(path: Path) -> np.ndarray | None:
    """A camera raw developed by LibRaw to linear sRGB in [0, 1] (camera white balance, no
    brightening, 16 bits); None if LibRaw does not read the file, ``ValueError`` if its header
    declares more than lfcl.io.raw.MAX_PIXELS pixels."""
    import rawpy

    from ..io.raw import MAX_PIXELS

    try:
        with rawpy.imread(str(path)) as raw:
            declared = int(raw.sizes.raw_height) * int(raw.sizes.raw_width)
            if declared > MAX_PIXELS:  # a hostile header must not make LibRaw allocate it
                raise ValueError(f"cannot read image {path}: it declares {declared} pixels, more than the limit "
                                 f"of {MAX_PIXELS}")
            developed = raw.postprocess(gamma=(1, 1), no_auto_bright=True, output_bps=16, use_camera_wb=True,
                                        output_color=rawpy.ColorSpace.sRGB)
    except (rawpy.LibRawError, OSError, RuntimeError):
        return None
    return _to_rgb(np.asarray(developed, dtype=np.float32) / 65535.0, path)


def area_resize(image: np.ndarray, height: int, width: int) -> np.ndarray:
    """Downscale ``(H, W, 3)`` by averaging (OpenImageIO's resize with a box filter)."""
    h, w = image.shape[:2]
    if height >= h and width >= w:
        return image
    height, width = min(height, h), min(width, w)
    src = oiio.ImageBuf(oiio.ImageSpec(w, h, image.shape[2], oiio.FLOAT))
    src.set_pixels(oiio.ROI(), np.ascontiguousarray(image, dtype=np.float32))
    dst = oiio.ImageBufAlgo.resize(src, filtername="box", roi=oiio.ROI(0, width, 0, height, 0, 1, 0, image.shape[2]))
    return np.asarray(dst.get_pixels(oiio.FLOAT), dtype=np.float32).reshape(height, width, image.shape[2])


class ImageTexture:
    """``image`` (linear ``(H, W, 3)``) covering the frame box ``(y0, x0, y1, x1)``."""

    def __init__(self, image: np.ndarray, box):
        y0, x0, y1, x1 = (float(c) for c in box)
        bh, bw = max(y1 - y0, 1e-6), max(x1 - x0, 1e-6)
        h, w = image.shape[:2]
        zoom = max(bh / h, bw / w)  # lenses per image pixel, "cover" fit
        # Keep at most PIXELS_PER_LENS image pixels per lens.
        if 1.0 / zoom > PIXELS_PER_LENS:
            factor = PIXELS_PER_LENS * zoom
            image = area_resize(image, max(1, round(h * factor)), max(1, round(w * factor)))
            zoom *= h / image.shape[0]
            h, w = image.shape[:2]
        self.image = np.ascontiguousarray(image, dtype=np.float32)
        self.zoom = zoom
        # Image pixel centres: pixel (i, j) sits at frame y = cy + (i + 0.5 - h/2) * zoom.
        self.cy, self.cx = (y0 + y1) / 2.0, (x0 + x1) / 2.0

    def __call__(self, x, y):
        h, w = self.image.shape[:2]
        fi = np.clip((y - self.cy) / self.zoom + h / 2.0 - 0.5, 0, h - 1)
        fj = np.clip((x - self.cx) / self.zoom + w / 2.0 - 0.5, 0, w - 1)
        i0 = np.minimum(fi.astype(np.int64), max(h - 2, 0))
        j0 = np.minimum(fj.astype(np.int64), max(w - 2, 0))
        i1, j1 = np.minimum(i0 + 1, h - 1), np.minimum(j0 + 1, w - 1)
        a = (fi - i0).astype(np.float32)[:, None]
        b = (fj - j0).astype(np.float32)[:, None]
        img = self.image
        top = img[i0, j0] * (1 - b) + img[i0, j1] * b
        bottom = img[i1, j0] * (1 - b) + img[i1, j1] * b
        return top * (1 - a) + bottom * a
