"""``lfcl simulate``: a simulated lenslet capture with exact ground truth (docs/simulator.md)."""

from __future__ import annotations

import time
from pathlib import Path

import click

from . import user_errors


@click.command("simulate")
@click.option("--scene", default="charts", show_default=True, metavar="NAME",
              help="Built-in scene: charts (three resolution charts at different depths) or deadleaves.")
@click.option("--texture", type=click.Path(dir_okay=False, path_type=Path), default=None, metavar="IMAGE",
              help="Image mapped onto the scene's planes instead of their textures (8/16-bit: sRGB, decoded to linear).")
@click.option("--lightfield", type=click.Path(path_type=Path), default=None, metavar="PATH",
              help="An existing light field instead of a scene: a folder of HCI views input_Cam000.png... "
                   "(row-major over u, v) or a .npy [S, T, U, V, 3]; its own S, T, U, V are used.")
@click.option("--lenses", default=None, metavar="SxT", show_default="64x64, or the light field's own size",
              help="Microlens array size; with --lightfield, a smaller size crops the centre.")
@click.option("--pitch", type=int, default=None, show_default="9",
              help="Pixels per microlens (square, U = V).")
@click.option("--pattern", default="GRBG", show_default=True, help="Bayer pattern: RGGB, GRBG, GBRG or BGGR.")
@click.option("--lux", type=float, default=12.0, show_default=True, help="Mean illuminance at the sensor, lux.")
@click.option("--seed", type=int, default=0, show_default=True, help="Random seed (noise, dead leaves).")
@click.option("--exposure", default="1/90", show_default=True, metavar="SECONDS", help="Exposure time, s.")
@click.option("--vignetting/--no-vignetting", default=False, show_default=True,
              help="Microlens cos^4 falloff in raw and white images (never in the truth).")
@click.option("-o", "--output", "output", required=True, type=click.Path(file_okay=False, path_type=Path),
              metavar="DIR", help="Output folder: raw.dng, white.dng, meta.json, truth.npy, truth_views.exr.")
@user_errors
def command(scene, texture, lightfield, lenses, pitch, pattern, lux, seed, exposure, vignetting, output):
    """Simulate a lenslet (plenoptic) camera capture with exact ground truth."""
    from ..sim import simulate, write_capture

    if texture is not None and not texture.is_file():
        raise ValueError(f"cannot read texture {texture}: no such file")
    start = time.perf_counter()
    capture = simulate(
        scene=scene, lenses=lenses, pitch=pitch, pattern=pattern, lux=lux, seed=seed,
        exposure=exposure, vignetting=vignetting, texture=texture, lightfield=lightfield, progress=None,
    )
    write_capture(capture, output)
    S, T = capture.geometry.lenses
    U, V = capture.geometry.pitch
    click.echo(
        f"wrote {output}: {S}x{T} lenses of {U}x{V} pixels, {capture.pattern}, {lux:g} lux "
        f"({capture.meta['exposure']['mean_electrons']:.0f} e- mean, noise sigma "
        f"{capture.meta['noise']['sigma_at_mean']:.4f}) in {time.perf_counter() - start:.1f} s"
    )
