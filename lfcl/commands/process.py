"""`lfcl process`: a lenslet raw in, a demosaiced 4D light field and images out (docs/outputs.md).

Stages: decode the raw, find the lens grid (``--pitch``, ``--calibration`` or
``--white``), demosaic/denoise (a progress bar over the ADMM iterations on a
terminal), compute the outputs that were asked for (only those), write them
(each atomically; if one fails, the ones already written are removed) and
``summary.json``, print a one-screen summary (``--json``: the summary as JSON).
"""

from __future__ import annotations

import json
import math
import sys
import time
from pathlib import Path

import click
import numpy as np

from ..method_names import METHODS
from . import device_option, user_errors

DEFAULT_OUTPUTS = "center,mean,lightfield"
DEFAULT_REFOCUS = "-1:1:0.25"
DEFAULT_PITCH = 9
#: A calibrated grid is processed as aligned when every lens centre on the sensor is
#: closer than this to the centre of the same lens on an aligned integer-pitch grid.
ALIGNED_TOLERANCE_PX = 0.5

#: The output kinds (lfcl.outputs.KINDS, repeated here so that `lfcl --help` does not import numpy).
OUTPUTS = ("center", "mean", "views", "views-each", "refocus", "lightfield")


def aligned_geometry(cal, what: str = "the calibration") -> dict:
    """The aligned square grid of integer pitch that ``cal`` describes, or a one-line ``ValueError``.

    Returns ``pitch`` (int), ``first`` (sensor row, col of the first whole lens's
    top-left pixel), ``lenses`` (S, T of whole lenses from there) and
    ``max_deviation_px`` (largest distance of a calibrated lens centre from the
    aligned grid's).
    """
    import numpy as np

    g = cal.grid
    H, W = cal.sensor_shape
    desc = (f"pitch {g.pitch:.4f} px, rotation {g.rotation_deg:+.4f} deg, "
            f"offset {g.offset[0]:.3f},{g.offset[1]:.3f} px")
    tail = "is not implemented yet: lfcl process takes aligned square grids of integer pitch and zero rotation"
    if g.packing != "square":
        raise ValueError(f"processing a hexagonal lens grid ({what}: {desc}) {tail}")
    P = round(g.pitch)
    i, j, rows, cols = cal.centres()
    if P < 2 or rows.size == 0:
        raise ValueError(f"{what} has no usable lenses on its {H}x{W} sensor ({desc})")
    half = (P - 1) / 2
    R0 = round(float(np.median(rows - i * P)) - half)
    C0 = round(float(np.median(cols - j * P)) - half)
    deviation = float(np.max(np.hypot(rows - (R0 + half + i * P), cols - (C0 + half + j * P))))
    if not deviation < ALIGNED_TOLERANCE_PX:
        span = max(H, W)
        kinds = []
        if abs(math.radians(g.rotation_deg)) * span > 0.1:
            kinds.append("rotated")
        if abs(g.pitch - P) * span / g.pitch > 0.1:
            kinds.append("non-integer-pitch")
        if not kinds:
            kinds.append("sub-pixel-offset" if abs(g.offset[0] - round(g.offset[0])) > 0.1
                         or abs(g.offset[1] - round(g.offset[1])) > 0.1 else "non-aligned")
        raise ValueError(
            f"processing a {', '.join(kinds)} square lens grid ({what}: {desc}; lens centres up to "
            f"{deviation:.2f} px off the nearest aligned grid of pitch {P}, less than {ALIGNED_TOLERANCE_PX:g} px "
            f"is processed as aligned) {tail}")
    r0, c0 = R0 % P, C0 % P
    S, T = (H - r0) // P, (W - c0) // P
    if S < 1 or T < 1:
        raise ValueError(f"{what}: no whole {P}x{P} lens fits on the {H}x{W} sensor from pixel ({r0}, {c0})")
    return {"pitch": P, "first": (r0, c0), "lenses": (S, T), "max_deviation_px": deviation}


def _calibration_metadata(cal, how: str, path, geo: dict) -> dict:
    g = cal.grid
    return {
        "how": how, "file": None if path is None else str(path), "source": cal.source,
        "packing": g.packing, "pitch_px": g.pitch, "rotation_deg": g.rotation_deg, "offset_px": list(g.offset),
        "sensor_shape": list(cal.sensor_shape), "aligned_max_deviation_px": geo["max_deviation_px"],
    }


def _progress_bar(method: str, iterations, as_json: bool):
    """A tqdm bar over the ADMM iterations (terminals only; never with --json) and its callback."""
    if as_json or method == "malvar":
        return None, None
    from tqdm import tqdm

    from ..methods import ADMM_DEFAULTS

    total = iterations if iterations is not None else ADMM_DEFAULTS[method].max_iter
    bar = tqdm(total=total, desc=method, unit="it", disable=None, leave=False, file=sys.stderr,
               dynamic_ncols=True)
    band = [0]

    def callback(record, x):
        if record.iteration == 1 and bar.n:  # a new band of lens rows
            band[0] += 1
            bar.reset()
            bar.set_description(f"{method} band {band[0] + 1}")
        bar.update(1)
        bar.set_postfix_str(f"change {record.rms_change:.2e}", refresh=False)

    return bar, callback


@click.command("process")
@click.argument("raw", type=click.Path(path_type=Path, readable=False))
@click.option("-o", "--output", "out_dir", required=True, type=click.Path(file_okay=False, path_type=Path),
              help="Output folder (created if missing).")
@click.option("--method", default="admm-uv", show_default=True,
              type=click.Choice(METHODS), help="Demosaic/denoise method.")
@click.option("--pitch", default=None, type=click.IntRange(min=2), show_default=str(DEFAULT_PITCH),
              help="Pixels per microlens of an aligned square grid starting at the sensor's first pixel "
                   "(not with --calibration / --white).")
@click.option("--calibration", type=click.Path(path_type=Path, readable=False), default=None, metavar="CAL.json",
              help="Lens grid from `lfcl calibrate`: pitch and first lens from it (aligned square grids only).")
@click.option("--white", type=click.Path(path_type=Path, readable=False), default=None, metavar="WHITE",
              help="Calibrate from this white image first (as `lfcl calibrate WHITE`), then as --calibration.")
@click.option("--pattern", default=None, help="Bayer pattern; required for EXR/TIFF/PNG mosaics, read from raws.")
@click.option("--outputs", default=DEFAULT_OUTPUTS, show_default=True,
              help=f"Comma-separated: {', '.join(OUTPUTS)}. Only these are computed.")
@click.option("--refocus", "refocus_spec", default=None, metavar="START:STOP:STEP|A,B,..",
              help=f"Refocus slopes (lenses per view step): a range, stop included when on the grid, or a "
                   f"comma list. Implies the refocus output; refocus without it uses {DEFAULT_REFOCUS}.")
@click.option("--format", "fmt", default="exr", show_default=True, type=click.Choice(["exr", "tiff"]),
              help="Images: EXR (float, scene-linear) or TIFF (16-bit linear, clipped to [0, 1]).")
@click.option("--previews/--no-previews", default=True, show_default=True,
              help="Also write an 8-bit sRGB PNG of every image (white balance and colour matrix from the raw).")
@click.option("--lambda", "lam", default=None, type=float,
              help="TV weight; default: follows the noise level estimated from the raw (docs/admm.md).")
@click.option("--iterations", default=None, type=click.IntRange(min=1),
              help="Run exactly this many ADMM iterations; default: the method's early-stopping rule.")
@click.option("--strength", default=1.0, show_default=True, type=float, help="Multiplier on the default lambda.")
@click.option("--max-memory", default=None, type=click.FloatRange(min=0.01), metavar="GIB",
              help="Device memory the solver may use, GiB; default 80% of the device's. A larger admm-uv "
                   "problem runs in bands of lens rows (exact: the (u, v) prior couples no two lenses).")
@click.option("--pipeline", "pipeline", default=None, metavar="NAME|PATH",
              help="A recipe (default, lowlight, preview, or a .toml file; docs/stages.md) supplying defaults for "
                   "--method, --strength, --lambda, --iterations, --outputs, --refocus, --format, --previews; "
                   "options given on the command line win.")
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON (no progress bar).")
@device_option
@user_errors
def command(raw, out_dir, method, pitch, calibration, white, pattern, outputs, refocus_spec, fmt, previews, lam,
            iterations, strength, max_memory, pipeline, as_json, device):
    """Demosaic a lenslet RAW (DNG, camera raw, or EXR/TIFF/PNG mosaic) into a 4D light field."""
    recipe_meta = None
    if pipeline is not None:  # the recipe's values replace the options not given explicitly
        from click.core import ParameterSource

        from ..recipes import load_recipe

        recipe = load_recipe(pipeline)
        ctx = click.get_current_context()
        explicit = {p for p in ("method", "strength", "lam", "iterations", "outputs", "refocus_spec", "fmt",
                                "previews") if ctx.get_parameter_source(p) not in (ParameterSource.DEFAULT,
                                                                                  ParameterSource.DEFAULT_MAP)}
        if "method" not in explicit:
            method = recipe["method"]
        if "strength" not in explicit:
            strength = recipe["strength"]
        if "lam" not in explicit:
            lam = recipe["lambda"]
        if "iterations" not in explicit:
            iterations = recipe["iterations"]
        if "outputs" not in explicit:
            outputs = ",".join(recipe["outputs"])
        if "refocus_spec" not in explicit and "refocus" in recipe["outputs"]:
            refocus_spec = recipe["refocus"]
        if "fmt" not in explicit:
            fmt = recipe["format"]
        if "previews" not in explicit:
            previews = recipe["previews"]
        recipe_meta = {"name": recipe["name"], "path": recipe["path"],
                       "options": {"method": method, "strength": strength, "lambda": lam,
                                   "iterations": iterations, "outputs": outputs, "refocus": refocus_spec,
                                   "format": fmt, "previews": previews},
                       "from_command_line": sorted({"lam": "lambda", "refocus_spec": "refocus",
                                                    "fmt": "format"}.get(p, p) for p in explicit)}
    from .. import __version__
    from ..layout import LightFieldShape, planes_to_exchange
    from ..outputs import (
        PlannedFile,
        parse_format,
        parse_outputs,
        plan_outputs,
        write_outputs,
    )
    from ..refocus import parse_slopes

    # --- everything a user can get wrong in the options, before any work ------------------
    wanted = parse_outputs(outputs)
    if refocus_spec is not None and "refocus" not in wanted:
        wanted.append("refocus")
    slopes = parse_slopes(refocus_spec if refocus_spec is not None else DEFAULT_REFOCUS) if "refocus" in wanted else []
    fmt = parse_format(fmt)
    given = [name for name, value in (("--pitch", pitch), ("--calibration", calibration), ("--white", white))
             if value is not None]
    if len(given) > 1:
        raise ValueError(f"give the lens grid once: {' and '.join(given)} together")
    if calibration is not None and not calibration.is_file():
        raise FileNotFoundError(f"calibration {str(calibration)!r} does not exist")
    if white is not None and not white.is_file():
        raise FileNotFoundError(f"white image {str(white)!r} does not exist")

    timings: dict = {}
    skipped: list = []
    start = time.perf_counter()
    from ..raw import read_mosaic

    mosaic = read_mosaic(raw, pattern)
    timings["decode"] = time.perf_counter() - start

    # --- lens grid ---------------------------------------------------------------------------
    cal_meta, lens_response = None, None
    if calibration is not None or white is not None:
        from ..calib import calibrate_white, load_calibration

        start = time.perf_counter()
        if calibration is not None:
            cal = load_calibration(calibration, mosaic.shape, mosaic.pattern)
            how, what = "--calibration", f"calibration {calibration}"
        else:
            cal = calibrate_white(white, pattern)
            cal.check(mosaic.shape, mosaic.pattern, what=f"{Path(raw).name}")
            how, what = "--white", f"white image {white}"
            timings["calibrate"] = time.perf_counter() - start
        geo = aligned_geometry(cal, what)
        cal_meta = _calibration_metadata(cal, how, calibration if calibration is not None else white, geo)
        P, (r0, c0), (S, T) = geo["pitch"], geo["first"], geo["lenses"]
        if cal.weight is not None:  # the white image's vignetting: flat-field, weight the data term
            from ..flatfield import lens_response_from_calibration

            lens_response = lens_response_from_calibration(cal, (P, P))
    else:
        P, (r0, c0) = pitch or DEFAULT_PITCH, (0, 0)
        how = "--pitch" if pitch is not None else "default pitch"
        full = LightFieldShape.from_sensor(mosaic.shape, (P, P))
        S, T = full.S, full.T
    shape = LightFieldShape(S, T, P, P)
    H, W = shape.sensor_shape
    data = mosaic.data[r0:r0 + H, c0:c0 + W]

    # --- demosaic ----------------------------------------------------------------------------
    from ..methods import demosaic_lightfield
    from ..noise import from_noise_profile

    noise = None
    if mosaic.noise_profile is not None and method != "malvar":
        noise = from_noise_profile(mosaic.noise_profile, data)
    bar, callback = _progress_bar(method, iterations, as_json)
    start = time.perf_counter()
    try:
        result = demosaic_lightfield(data, mosaic.pattern, (P, P), method, origin=(r0, c0), lam=lam,
                                     iterations=iterations, strength=strength, noise=noise, device=device,
                                     callback=callback, lens_response=lens_response,
                                     max_memory=None if max_memory is None else int(max_memory * 2**30))
    finally:
        if bar is not None:
            bar.close()
    timings["demosaic"] = time.perf_counter() - start
    lightfield = planes_to_exchange(result.planes, shape)

    metadata = {
        "method": method, "parameters": result.parameters, "source": str(raw), "pattern": mosaic.pattern,
        "geometry": {"grid": "aligned-square", "pitch": [P, P], "lenses": [S, T], "first_lens_pixel": [r0, c0],
                     "from": how},
        "iterations": result.iterations, "stop_reason": result.stop_reason,
        "noise_sigma": None if result.noise is None else result.noise.sigma,
        "input": mosaic.metadata(), "generator": f"lfcl {__version__} process",
    }
    if recipe_meta is not None:
        metadata["recipe"] = recipe_meta
    if cal_meta is not None:
        metadata["calibration"] = cal_meta
    if lens_response is not None:
        metadata["flat_field"] = {
            "lens_response": np.round(lens_response, 4).tolist(),
            "left_out_below": 0.2, "data_term_weight": "response^2 (docs: lfcl/flatfield.py)",
        }

    # --- outputs: compute all, then write all (or none) ---------------------------------------
    start = time.perf_counter()
    colour = None
    if previews:
        from ..colour import ColourPipeline

        colour = ColourPipeline.from_mosaic(mosaic)
    colour_seconds = time.perf_counter() - start
    plan = plan_outputs(lightfield, wanted, slopes=slopes, fmt=fmt, previews=previews, metadata=metadata,
                        colour=colour)
    if "previews-setup" in plan.seconds:
        plan.seconds["previews-setup"] += colour_seconds
    compute_seconds = time.perf_counter() - start
    skipped.extend(plan.skipped)
    if "refocus" not in wanted:
        skipped = [s if s["output"] != "refocus" else {"output": "refocus",
                                                      "reason": "not asked for (--outputs, --refocus)"}
                   for s in skipped]
    summary = {
        **metadata, "lenses": [S, T], "format": fmt, "previews": plan.previews, "colour": plan.colour,
        "seconds": timings, "outputs": [], "refocus": plan.refocus, "skipped": skipped,
    }
    out_dir = Path(out_dir)
    files = list(plan.files)
    write_seconds: dict = {}

    def final_summary():
        summary["outputs"] = [f.name for f in files if f.name != "summary.json"]
        total_write = sum(v for k, v in write_seconds.items() if k != "summary")
        timings["outputs"] = compute_seconds + total_write
        summary["output_seconds"] = {
            kind: {"compute": plan.seconds.get(kind, 0.0), "write": write_seconds.get(kind, 0.0),
                   "files": n} for kind, n in plan.counts().items()}
        if "previews-setup" in plan.seconds:
            summary["output_seconds"]["previews-setup"] = {"compute": plan.seconds["previews-setup"],
                                                             "write": 0.0, "files": 0}
        summary["output_seconds"]["total"] = {"compute": compute_seconds, "write": total_write,
                                              "files": len(files) - 1}
        return summary

    files.append(PlannedFile("summary.json", "summary", "json", final_summary))
    write_outputs(out_dir, files, write_seconds)
    write_seconds.pop("summary", None)
    final_summary()

    if as_json:
        click.echo(json.dumps(summary, indent=2))
    else:
        _print_summary(raw, out_dir, summary, mosaic)


def _print_summary(raw, out_dir, summary: dict, mosaic) -> None:
    """The run on one screen: geometry, method, time per stage, what was written and what was skipped."""
    S, T = summary["lenses"]
    P = summary["geometry"]["pitch"][0]
    geo = summary["geometry"]
    lines = [f"{raw} -> {out_dir}  ({S}x{T} lenses of {P}x{P} px from {geo['from']}, {mosaic.pattern}"
             + (f", first lens at pixel {geo['first_lens_pixel'][0]},{geo['first_lens_pixel'][1]}"
                if any(geo["first_lens_pixel"]) else "") + ")"]
    if "calibration" in summary:
        c = summary["calibration"]
        lines.append(f"calibration: {c['packing']} grid, pitch {c['pitch_px']:.4f} px, rotation "
                     f"{c['rotation_deg']:+.4f} deg; aligned within {c['aligned_max_deviation_px']:.2f} px")
    params = summary["parameters"]
    lam = f", lambda {params['lam']:.3g}" if "lam" in params else ""
    lines.append(f"method {summary['method']}: {summary['iterations']} iterations ({summary['stop_reason']}){lam}")
    secs = summary["seconds"]
    lines.append("time: " + ", ".join(f"{k} {v:.2f} s" for k, v in secs.items()))
    per = summary.get("output_seconds", {})
    parts = [f"{k} {v['compute'] + v['write']:.2f} s" + (f" ({v['files']} file{'s' if v['files'] > 1 else ''})" if v["files"] else "")
             for k, v in per.items() if k != "total"]
    if "total" in per:
        parts.append(f"computing {per['total']['compute']:.2f} s, writing {per['total']['write']:.2f} s")
    if parts:
        lines.append("  outputs: " + ", ".join(parts))
    names = summary["outputs"]
    shown = [n for n in names if not n.startswith(("view_", "refocus_"))]
    views = [n for n in names if n.startswith("view_")]
    if views:
        shown.append(f"{len(views)} view files ({views[0]} .. {views[-1]})")
    if summary["refocus"]:
        slopes = [r["slope"] for r in summary["refocus"]]
        shown.append(f"{len(slopes)} refocused images (slopes {', '.join(f'{a:+g}' for a in slopes)})")
    lines.append(f"wrote {len(names) + 1} files: " + ", ".join(shown + ["summary.json"]))
    colour = summary.get("colour")
    if colour:
        wb = colour["white_balance"]
        note = "; ".join(colour.get("notes", []))
        lines.append(f"previews: sRGB PNG, white balance {wb['source']} "
                     f"({', '.join(f'{g:.3f}' for g in wb['gains'])}), scale x{colour['scale']:.3g}"
                     + (f"; {note}" if note else ""))
    if summary["skipped"]:
        by_reason: dict = {}
        for s in summary["skipped"]:
            by_reason.setdefault(s["reason"], []).append(s["output"])
        lines.append("skipped: " + "; ".join(f"{', '.join(names)} ({reason})" for reason, names in by_reason.items()))
    click.echo("\n".join(lines))
