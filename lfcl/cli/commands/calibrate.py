"""``lfcl calibrate``: the lens grid and white-image weights of a lenslet camera (docs/calibration.md)."""

from __future__ import annotations

import time
from pathlib import Path

import click

from . import user_errors


def _parse_shape(value: str) -> tuple[int, int]:
    parts = value.lower().replace("×", "x").split("x")
    try:
        numbers = [int(p.strip()) for p in parts]
    except ValueError:
        raise ValueError(f"malformed --sensor-shape {value!r}: expected HxW in pixels, e.g. 576x576") from None
    if len(numbers) != 2 or min(numbers) < 1:
        raise ValueError(f"malformed --sensor-shape {value!r}: expected HxW in pixels, e.g. 576x576")
    return numbers[0], numbers[1]


def _parse_offset(value: str) -> tuple[float, float]:
    try:
        numbers = [float(p.strip()) for p in value.split(",")]
    except ValueError:
        numbers = []
    if len(numbers) != 2 or not all(abs(v) < float("inf") for v in numbers):
        raise ValueError(f"malformed --offset {value!r}: expected ROW,COL in pixels, e.g. 0.3,0.7")
    return numbers[0], numbers[1]


def _check_paths(white, output, export_centers) -> None:
    """The two files written must be two, and neither the white image: one line before any work."""
    import os

    if export_centers is not None and os.path.abspath(output) == os.path.abspath(export_centers):
        raise ValueError(f"-o and --export-centers name the same file, {output}: give two")
    for written in (output, export_centers):
        if written is not None and os.path.isdir(written):
            raise ValueError(f"{written} is a folder: name the file to write")
    for written in (output, export_centers):
        if written is None or white is None:
            continue
        if os.path.abspath(written) == os.path.abspath(white) or (
                os.path.exists(written) and os.path.exists(white) and os.path.samefile(written, white)):
            raise ValueError(f"{written} is the white image: writing it would replace the input; name another file")


@click.command("calibrate")
@click.argument("white", required=False, type=click.Path(path_type=Path, readable=False), metavar="[WHITE]")
@click.option("-o", "--output", "output", required=True, type=click.Path(path_type=Path, readable=False),
              metavar="CAL.json", help="The calibration file to write.")
@click.option("--export-centers", "export_centers", type=click.Path(path_type=Path, readable=False), default=None,
              metavar="FILE.csv", help="Also write every lens centre on the sensor as row,col (pixels) with a header.")
@click.option("--packing", default="auto", show_default=True, metavar="auto|square|hex",
              help="Lens packing; with a white image 'auto' detects it, a named one must match it.")
@click.option("--pitch", type=float, default=None, metavar="P",
              help="With a white image: the approximate pitch (px) to look for. Without: the grid's pitch.")
@click.option("--sensor-shape", "sensor_shape", default=None, metavar="HxW",
              help="Without a white image: the sensor size in pixels (required then).")
@click.option("--rotation", type=float, default=None, metavar="DEG",
              help="Without a white image: the grid rotation, degrees (default 0).")
@click.option("--offset", default=None, metavar="ROW,COL",
              help="Without a white image: the grid offset in pixels (default 0,0; negative: --offset=-0.3,0.7).")
@click.option("--pattern", default=None, metavar="P",
              help="Bayer pattern: needed for image files (EXR, TIFF); for raws it must match the file's. "
                   "Without a white image: recorded in the calibration.")
@user_errors
def command(white, output, export_centers, packing, pitch, sensor_shape, rotation, offset, pattern):
    """Estimate the lenslet grid (and per-pixel weights) from a WHITE image, or write one from --pitch."""
    from ...grid import calibrate_white, calibration_from_pitch, save_calibration, write_centres_csv
    from ...grid.lattice import check_packing

    start = time.perf_counter()
    _check_paths(white, output, export_centers)
    packing = "auto" if str(packing).lower() == "auto" else check_packing(packing)
    if white is None:
        if pitch is None or sensor_shape is None:
            raise ValueError("give a white image, or --pitch P and --sensor-shape HxW for a grid without one")
        cal = calibration_from_pitch(pitch, _parse_shape(sensor_shape), packing,
                                     0.0 if rotation is None else rotation,
                                     (0.0, 0.0) if offset is None else _parse_offset(offset), pattern)
        how = "from parameters, uniform weights"
    else:
        if rotation is not None or offset is not None:
            raise ValueError("--rotation and --offset are for a grid without a white image: the white image sets them")
        if not white.is_file():
            raise FileNotFoundError(f"white image {str(white)!r} does not exist")
        cal = calibrate_white(white, pattern, packing=packing, pitch=pitch)
        if sensor_shape is not None and _parse_shape(sensor_shape) != cal.sensor_shape:
            H, W = cal.sensor_shape
            raise ValueError(f"--sensor-shape {sensor_shape} disagrees with the white image ({H}x{W})")
        fit = cal.fit
        how = (f"{fit['lenses_fitted']} lenses fitted, {fit['outliers']} outliers, "
               f"lens scatter {fit['lens_rms_px']:.3f} px rms")
    _, _, rows, cols = cal.centres()
    created = []
    try:
        if export_centers is not None:
            write_centres_csv(export_centers, rows, cols)
            created.append(export_centers)
        save_calibration(cal, output)
    except BaseException:
        for path in created:
            path.unlink(missing_ok=True)
        raise
    g = cal.grid
    H, W = cal.sensor_shape
    click.echo(
        f"wrote {output}: {g.packing} grid, pitch {g.pitch:.4f} px, rotation {g.rotation_deg:+.4f} deg, "
        f"offset {g.offset[0]:.3f},{g.offset[1]:.3f}; {rows.size} lenses on the {H}x{W} sensor ({how})"
        + (f"; centres in {export_centers}" if export_centers is not None else "")
        + f" in {time.perf_counter() - start:.1f} s"
    )
