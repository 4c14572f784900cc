"""``lfcl demosaic``: one Bayer mosaic in, one RGB image out.

INPUT is an image mosaic (EXR, TIFF, PNG: --pattern required) or a DNG / camera
raw (the pattern comes from the file; a --pattern given as well must agree). The
mosaic is normalised as in :func:`lfcl.io.raw.read_mosaic` (black 0, white 1, per
CFA channel; no white balance, camera RGB) and demosaiced on the OpenCL device.

OUT's extension picks the format: .exr keeps float32 values as they are (nothing
clipped), .tif/.tiff is 16-bit and .png 8-bit (both clipped to [0, 1]). OUT is
written atomically, with the method, pattern, source and black/white levels in
its header (``lfcl:*`` attributes); on any error nothing is written.
"""

from __future__ import annotations

from pathlib import Path

import click

from . import device_option, user_errors

METHODS = ("malvar",)
OUTPUT_EXTENSIONS = (".exr", ".tif", ".tiff", ".png")


@click.command("demosaic")
@click.argument("input_path", metavar="INPUT", type=click.Path(path_type=Path, readable=False))
@click.option("--pattern", default=None, metavar="PATTERN",
              help="Bayer pattern of the mosaic's first 2x2 pixels: RGGB, GRBG, GBRG or BGGR. "
                   "Required for image files; read from raws (and checked if given).")
@click.option("--method", type=click.Choice(METHODS), default="malvar", show_default=True,
              help="Demosaicing method (Malvar-He-Cutler 2004).")
@click.option("-o", "--output", "output_path", required=True, metavar="OUT",
              type=click.Path(path_type=Path, readable=False),
              help="Output image: .exr (float, unclipped), .tif/.tiff (16-bit) or .png (8-bit).")
@device_option
@user_errors
def command(input_path: Path, pattern: str | None, method: str, output_path: Path, device: str | None):
    """Demosaic the Bayer mosaic INPUT into the RGB image OUT."""
    from ...io.raw import read_mosaic
    from ...layout import parse_pattern

    if output_path.suffix.lower() not in OUTPUT_EXTENSIONS:
        raise ValueError(
            f"unsupported output extension {output_path.suffix or '(none)'!r} for {output_path.name}: "
            f"use {', '.join(OUTPUT_EXTENSIONS)}"
        )
    if pattern is not None:
        pattern = parse_pattern(pattern)
    mosaic = read_mosaic(input_path, pattern)

    if method == "malvar":
        # imported here: the operator module is optional at import time
        from ...ops.malvar import malvar

        rgb = malvar(mosaic.data, mosaic.pattern, mosaic.origin, device=device)
    else:  # pragma: no cover - click.Choice keeps this out
        raise ValueError(f"unknown method {method!r}")

    metadata = dict(mosaic.metadata(), method=method, normalisation="(raw - black) / (white - black), not white balanced")
    from ...io.images import write_image

    write_image(output_path, rgb, metadata)
    click.echo(f"wrote {output_path} ({rgb.shape[1]}x{rgb.shape[0]}, {method}, {mosaic.pattern})")
