"""`lfcl process`: a lenslet raw in, a demosaiced 4D light field and images out."""

from __future__ import annotations

import json
import time
from pathlib import Path

import click

from . import device_option, user_errors

OUTPUTS = ("center", "mean", "views", "lightfield")


def _parse_outputs(text: str) -> list[str]:
    names = [n.strip() for n in text.split(",") if n.strip()]
    unknown = [n for n in names if n not in OUTPUTS]
    if unknown or not names:
        raise ValueError(f"unknown outputs {', '.join(unknown) or '(none)'}: choose from {', '.join(OUTPUTS)}")
    return names


@click.command("process")
@click.argument("raw", type=click.Path(dir_okay=False, path_type=Path))
@click.option("-o", "--output", "out_dir", required=True, type=click.Path(file_okay=False, path_type=Path),
              help="Output folder (created if missing).")
@click.option("--method", default="admm-uv", show_default=True,
              type=click.Choice(["malvar", "admm-uv", "admm-st", "admm-uvst"]), help="Demosaic/denoise method.")
@click.option("--pitch", default=9, show_default=True, type=click.IntRange(min=2),
              help="Pixels per microlens of an aligned square grid starting at the sensor's first pixel.")
@click.option("--pattern", default=None, help="Bayer pattern; required for EXR/TIFF/PNG mosaics, read from raws.")
@click.option("--outputs", default="center,mean,lightfield", show_default=True,
              help=f"Comma-separated: {', '.join(OUTPUTS)}.")
@click.option("--lambda", "lam", default=None, type=float,
              help="TV weight; default: follows the noise level estimated from the raw (docs/admm.md).")
@click.option("--iterations", default=None, type=click.IntRange(min=1),
              help="Run exactly this many ADMM iterations; default: the method's early-stopping rule.")
@click.option("--strength", default=1.0, show_default=True, type=float, help="Multiplier on the default lambda.")
@click.option("--max-memory", default=None, type=click.FloatRange(min=0.01), metavar="GIB",
              help="Device memory the solver may use, GiB; default 80% of the device's. A larger admm-uv "
                   "problem runs in bands of lens rows (exact: the (u, v) prior couples no two lenses).")
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON.")
@device_option
@user_errors
def command(raw, out_dir, method, pitch, pattern, outputs, lam, iterations, strength, max_memory, as_json, device):
    """Demosaic a lenslet RAW (DNG, camera raw, or EXR/TIFF/PNG mosaic) into a 4D light field."""
    from ..imageio import write_image, write_npy
    from ..layout import LightFieldShape, planes_to_exchange, tiled_views
    from ..methods import demosaic_lightfield
    from ..metrics import centre_view, mean_image
    from ..noise import from_noise_profile
    from ..raw import read_mosaic

    wanted = _parse_outputs(outputs)
    timings = {}
    start = time.perf_counter()
    mosaic = read_mosaic(raw, pattern)
    timings["decode"] = time.perf_counter() - start
    shape = LightFieldShape.from_sensor(mosaic.data.shape, (pitch, pitch))
    H, W = shape.sensor_shape
    noise = None
    if mosaic.noise_profile is not None and method != "malvar":
        noise = from_noise_profile(mosaic.noise_profile, mosaic.data[:H, :W])
    result = demosaic_lightfield(mosaic.data[:H, :W], mosaic.pattern, (pitch, pitch), method, lam=lam,
                                 iterations=iterations, strength=strength, noise=noise, device=device,
                                 max_memory=None if max_memory is None else int(max_memory * 2**30))
    timings["demosaic"] = result.seconds
    lightfield = planes_to_exchange(result.planes, shape)
    metadata = {
        "method": method, "parameters": result.parameters, "source": str(raw), "pattern": mosaic.pattern,
        "geometry": {"grid": "aligned-square", "pitch": [pitch, pitch], "lenses": [shape.S, shape.T]},
        "iterations": result.iterations, "stop_reason": result.stop_reason,
        "noise_sigma": None if result.noise is None else result.noise.sigma,
    }
    start = time.perf_counter()
    written = []
    images = {"center": lambda: centre_view(lightfield), "mean": lambda: mean_image(lightfield),
              "views": lambda: tiled_views(lightfield)}
    for name in wanted:
        if name == "lightfield":
            written.append(str(write_npy(out_dir / "lightfield.npy", lightfield)))
        else:
            written.append(str(write_image(out_dir / f"{name}.exr", images[name](), metadata)))
    timings["write"] = time.perf_counter() - start
    summary = {**metadata, "lenses": [shape.S, shape.T], "seconds": timings, "outputs": written,
               "skipped": [n for n in OUTPUTS if n not in wanted]}
    if as_json:
        click.echo(json.dumps(summary, indent=2))
    else:
        click.echo(f"{raw} -> {out_dir}  ({shape.S}x{shape.T} lenses of {pitch}x{pitch}, {mosaic.pattern})")
        click.echo(f"method {method}: {result.iterations} iterations ({result.stop_reason})")
        click.echo("time: " + ", ".join(f"{k} {v:.2f} s" for k, v in timings.items()))
        click.echo("wrote: " + ", ".join(Path(p).name for p in written))
