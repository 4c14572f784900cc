"""``lfcl simulate``: a simulated lenslet capture with exact ground truth (docs/simulator.md)."""

from __future__ import annotations

import time
from pathlib import Path

import click

from . import user_errors


@click.command("simulate")
@click.option("--scene", default="charts", show_default=True, metavar="NAME",
              help="Built-in scene: charts (three resolution charts at different depths), deadleaves, "
                   "finetexture (lens-scale grain, thin wedges and fine text off the focal plane), periodic "
                   "(gratings and checkerboards, one beyond the disparity search range: a stress scene) or gratings "
                   "(four sine gratings off the focal plane, their periods, disparities and colours drawn from --seed).")
@click.option("--texture", type=click.Path(path_type=Path, readable=False), default=None, metavar="IMAGE",
              help="Image mapped onto the scene's planes instead of their textures (8/16-bit: sRGB, decoded to linear; "
                   "a camera raw: developed linear by LibRaw).")
@click.option("--lightfield", type=click.Path(path_type=Path, readable=False), default=None, metavar="PATH",
              help="An existing light field instead of a scene: a folder of HCI views input_Cam000.png... "
                   "(row-major over u, v) or a .npy [S, T, U, V, 3]; its own S, T, U, V are used.")
@click.option("--lenses", default=None, metavar="SxT", show_default="64x64, or the light field's own size",
              help="Microlens array size (N alone: NxN); with --lightfield, a smaller size crops the centre.")
@click.option("--pitch", type=float, default=None, show_default="9",
              help="Pixels per microlens: an integer for the aligned grid (U = V); any value >= 2 with --grid.")
@click.option("--pattern", default="GRBG", show_default=True, help="Bayer pattern: RGGB, GRBG, GBRG or BGGR.")
@click.option("--lux", type=float, default=12.0, show_default=True, help="Mean illuminance at the sensor, lux.")
@click.option("--seed", type=int, default=0, show_default=True, help="Random seed (noise, dead leaves, fine texture).")
@click.option("--exposure", default="1/90", show_default=True, metavar="SECONDS", help="Exposure time, s.")
@click.option("--vignetting/--no-vignetting", default=False, show_default=True,
              help="Microlens cos^4 falloff in raw and white images (never in the truth).")
@click.option("--grid", default=None, metavar="square|hex",
              help="Lens grid of any pitch/rotation/offset (with --pitch, --rotation, --offset): micro-images "
                   "are discs, the truth is on the solvers' regular grid (docs/geometry.md).")
@click.option("--pitch-px", type=float, default=None, metavar="P",
              help="Lens pitch in pixels, any value >= 2 (like --grid; same as --pitch P with --grid).")
@click.option("--rotation", type=float, default=None, metavar="DEG",
              help="Lens grid rotation in degrees, positive clockwise on screen (like --grid).")
@click.option("--offset", default=None, metavar="ROW,COL",
              help="Lens grid offset in pixels, e.g. 0.3,0.7 (like --grid; negative: --offset=-0.3,0.7).")
@click.option("--views", type=click.IntRange(min=2), default=None, metavar="N",
              help="Views U = V of the regular light field of a --grid capture (default round(pitch)).")
@click.option("--white-only", is_flag=True,
              help="With --grid: write only white.dng and meta.json (for calibration).")
@click.option("-o", "--output", "output", required=True, type=click.Path(file_okay=False, path_type=Path),
              metavar="DIR", help="Output folder: raw.dng, white.dng, meta.json, truth.npy, truth_views.exr "
                                   "(a scene on the aligned grid: also disparity.npy).")
@user_errors
def command(scene, texture, lightfield, lenses, pitch, pattern, lux, seed, exposure, vignetting, grid, pitch_px,
            rotation, offset, views, white_only, output):
    """Simulate a lenslet (plenoptic) camera capture with exact ground truth."""
    from ...sim import simulate, write_capture

    if grid is not None or pitch_px is not None or rotation is not None or offset is not None:
        if white_only:
            return _white_only(lenses, pitch, pattern, seed, vignetting, grid, pitch_px, rotation, offset,
                               texture, lightfield, output)
        return _grid_capture(scene, texture, lightfield, lenses, pitch, pattern, lux, seed, exposure, vignetting,
                             grid, pitch_px, rotation, offset, views, output)
    if white_only or views is not None:
        raise ValueError("--white-only and --views need a lens grid: add --grid square|hex")
    if pitch is not None and not float(pitch).is_integer():
        raise ValueError(f"--pitch {pitch:g} is not a whole number of pixels: a non-integer pitch needs --grid square|hex")
    pitch = None if pitch is None else int(pitch)
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


def _grid_params(grid, pitch, pitch_px):
    """The packing and the pitch of ``--grid``/``--pitch``/``--pitch-px``."""
    if pitch is not None and pitch_px is not None:
        raise ValueError("give the pitch once: --pitch or --pitch-px")
    grid = "square" if grid is None else grid.lower()
    if grid not in ("square", "hex"):
        raise ValueError(f"unknown lens grid {grid!r}: expected square or hex")
    return grid, float(pitch if pitch_px is None and pitch is not None else 9.0 if pitch_px is None else pitch_px)


def _grid_capture(scene, texture, lightfield, lenses, pitch, pattern, lux, seed, exposure, vignetting, grid, pitch_px,
                  rotation, offset, views, output):
    """``--grid/--pitch-px/--rotation/--offset``: raw, white and truth of a general lens grid."""
    from ...sim.capture import simulate_grid, write_capture

    if lightfield is not None:
        raise ValueError("--lightfield needs the aligned grid (a sampled light field has no values between its "
                         "samples): with --grid use --scene or --texture")
    if texture is not None and not texture.is_file():
        raise ValueError(f"cannot read --texture {texture}: no such file")
    grid, pitch_px = _grid_params(grid, pitch, pitch_px)
    start = time.perf_counter()
    capture = simulate_grid(scene, grid, pitch_px, 0.0 if rotation is None else rotation,
                            "0,0" if offset is None else offset, lenses=lenses, pattern=pattern, lux=lux, seed=seed,
                            exposure=exposure, vignetting=vignetting, views=views, texture=texture)
    write_capture(capture, output)
    g, (H, W) = capture.geometry, capture.geometry.sensor_shape
    S, T, U, V = capture.truth.shape[:4]
    click.echo(
        f"wrote {output}: {g.grid} grid, pitch {g.pitch:g} px, rotation {g.rotation_deg:g} deg, offset "
        f"{g.offset[0]:g},{g.offset[1]:g}; {H}x{W} sensor; truth {S}x{T} lenses of {U}x{V} views; "
        f"{capture.pattern}, {capture.meta['lux']:g} lux in {time.perf_counter() - start:.1f} s"
    )


def _white_only(lenses, pitch, pattern, seed, vignetting, grid, pitch_px, rotation, offset, texture, lightfield,
                output):
    """``--white-only``: white.dng and meta.json of a general lens grid."""
    from ...sim.capture import simulate_white, write_white_capture

    if texture is not None or lightfield is not None:
        raise ValueError("--texture/--lightfield make no sense with --white-only: only the white image is simulated")
    grid, pitch_px = _grid_params(grid, pitch, pitch_px)
    start = time.perf_counter()
    capture = simulate_white(grid, pitch_px, 0.0 if rotation is None else rotation,
                             "0,0" if offset is None else offset, lenses=lenses, pattern=pattern, seed=seed,
                             vignetting=vignetting)
    write_white_capture(capture, output)
    H, W = capture.geometry.sensor_shape
    g = capture.geometry
    click.echo(
        f"wrote {output}: white.dng and meta.json only ({g.grid} grid, pitch {g.pitch:g} px, rotation "
        f"{g.rotation_deg:g} deg, offset {g.offset[0]:g},{g.offset[1]:g}; {H}x{W} sensor, "
        f"{capture.meta['lenslet']['lenses_on_sensor']} lenses) in {time.perf_counter() - start:.1f} s"
    )
