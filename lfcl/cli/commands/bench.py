"""`lfcl bench`: kernel timings and bandwidth, quality against run time, ADMM iteration cost.

Thin: parse the options and call :mod:`lfcl.bench.kernels` / :mod:`lfcl.bench.pareto`.
BENCHMARKS.md explains the columns and holds measured figures.
"""

from __future__ import annotations

import json
from pathlib import Path

import click

from ...bench.matrix import LUX as MATRIX_LUX
from ...demosaic.names import DEFAULT_METHOD
from . import device_option, user_errors


@click.group("bench")
def command():
    """Benchmarks: per-kernel bandwidth, PSNR against run time, ADMM iteration cost (see BENCHMARKS.md)."""


@command.command("kernels")
@click.option("--size", default="4500x4500", show_default=True, metavar="HxW",
              help="Sensor size in pixels (a whole number of --pitch lenses); 4500x4500 is the paper's full sensor.")
@click.option("--pitch", type=int, default=9, show_default=True, help="Pixels per microlens (square).")
@click.option("--repeats", type=int, default=5, show_default=True, help="Timed calls per kernel (median reported).")
@click.option("--numpy-repeats", type=int, default=1, show_default=True,
              help="Timed calls of each numpy twin (0: skip numpy; slow at full size).")
@click.option("--only", default=None, metavar="NAME,...",
              help="Only the kernels whose name contains one of these substrings (the copy reference always runs).")
@click.option("--json", "as_json", is_flag=True, help="Print the results as JSON instead of a table.")
@device_option
@user_errors
def kernels_command(size, pitch, repeats, numpy_repeats, only, as_json, device):
    """Median time, effective bandwidth and numpy speed-up of every OpenCL kernel."""
    from ...bench import kernels
    from ...bench.timing import parse_size
    from ...device import get_runtime

    height, width = parse_size(size, "--size")
    only_list = [s.strip() for s in only.split(",") if s.strip()] if only else None
    runtime = get_runtime(device)
    progress = None if as_json else (lambda name: click.echo(f"  {name} ...", err=True))
    report = kernels.run(runtime, (height, width), (pitch, pitch), repeats=repeats, numpy_repeats=numpy_repeats,
                         only=only_list, progress=progress)
    click.echo(json.dumps(report, indent=2) if as_json else kernels.format_report(report))


def capture_source(func):
    """CAPTURE_DIR, or the scene simulated in memory (--lenses, --lux, --scene)."""
    for decorate in reversed([
        click.argument("capture_dir", required=False, type=click.Path(file_okay=False, path_type=Path)),
        click.option("--lenses", default="64x64", show_default=True, metavar="SxT",
                     help="Lens array of the in-memory simulation (ignored with CAPTURE_DIR)."),
        click.option("--lux", type=float, default=12.0, show_default=True, help="Illuminance of the in-memory simulation."),
        click.option("--scene", default="charts", show_default=True, help="Scene of the in-memory simulation."),
    ]):
        func = decorate(func)
    return func


@command.command("pareto")
@capture_source
@click.option("--seed", type=int, default=0, show_default=True, help="Seed of the in-memory simulation.")
@click.option("--budgets", default="1,2,5,10,20,40", show_default=True, metavar="K,...",
              help="ADMM iteration budgets.")
@click.option("--reference-budgets", default=None, metavar="K,...|none",
              help="Budgets for the numpy reference ADMM (slow). Default: the --budgets up to 10.")
@click.option("--methods", default="admm-uv,admm-st,admm-uvst", show_default=True,
              help="ADMM methods, each METHOD[:START] as lfcl process --method takes it (e.g. admm-uv-xc:linear4d); "
                   "lfcl's Malvar and linear4d and the two peers always run.")
@click.option("--repeats", type=int, default=1, show_default=True, help="Timed runs per point (median).")
@click.option("--skip-flat", is_flag=True,
              help="Leave flat lenses out of the solve (admm-uv, admm-uv-xc; lfcl process --skip-flat, off by "
                   "default since it took fine texture for noise); default: every lens solved, as the reference.")
@click.option("--safety-net/--no-safety-net", default=True, show_default=True,
              help="lfcl's methods with the safety net, as lfcl process runs them; off: the solver alone, like the "
                   "numpy reference.")
@click.option("-o", "--output", "out_dir", default=None, type=click.Path(file_okay=False, path_type=Path),
              help="Folder for pareto.json, pareto.md and pareto.png. Default: CAPTURE_DIR/pareto, else ./pareto.")
@click.option("--json", "as_json", is_flag=True, help="Print the results as JSON instead of a table.")
@device_option
@user_errors
def pareto_command(capture_dir, lenses, lux, scene, seed, budgets, reference_budgets, methods, repeats, skip_flat,
                   safety_net, out_dir, as_json, device):
    """PSNR (centre view, mean image) against seconds for every method and iteration budget, with peers."""
    from ...bench import pareto
    from ...bench.timing import parse_ints, parse_size
    from ...io.images import atomic_path, write_json

    budget_list = parse_ints(budgets, "--budgets")
    if reference_budgets is None:
        reference_list = None
    elif reference_budgets.strip().lower() in ("none", ""):
        reference_list = []
    else:
        reference_list = parse_ints(reference_budgets, "--reference-budgets")
    method_list = [m.strip() for m in methods.split(",") if m.strip()]
    capture = pareto.make_capture(capture_dir, parse_size(lenses, "--lenses"), lux, scene, seed)
    out_dir = out_dir or (capture_dir / "pareto" if capture_dir is not None else Path("pareto"))
    progress = None if as_json else (lambda label: click.echo(f"  {label} ...", err=True))
    report = pareto.run(capture, budget_list, reference_list, method_list, repeats=repeats, device=device,
                        progress=progress, skip_flat=True if skip_flat else None, safety_net=safety_net)
    table = pareto.format_report(report)
    figure = pareto.plot(report, out_dir / "pareto.png")
    report["files"] = {"json": str(out_dir / "pareto.json"), "markdown": str(out_dir / "pareto.md"), "plot": str(figure)}
    write_json(out_dir / "pareto.json", report)
    with atomic_path(out_dir / "pareto.md") as tmp:
        tmp.write_text(table + "\n")
    if as_json:
        click.echo(json.dumps(report, indent=2))
    else:
        click.echo(table)
        click.echo(f"\nwrote {out_dir / 'pareto.json'}, {out_dir / 'pareto.md'} and {figure}")


@command.command("admm")
@capture_source
@click.option("--methods", default="admm-uv,admm-st,admm-uvst", show_default=True, help="ADMM methods.")
@click.option("--iterations", type=int, default=5, show_default=True, help="ADMM iterations per timed solve.")
@click.option("--cg-steps", type=int, default=4, show_default=True, help="CG steps per iteration (cg_tol = 0).")
@click.option("--repeats", type=int, default=3, show_default=True, help="Timed device solves (median).")
@click.option("--reference-repeats", type=int, default=1, show_default=True,
              help="Timed numpy reference solves (median; 0 skips the reference).")
@click.option("--json", "as_json", is_flag=True, help="Print the results as JSON instead of a table.")
@device_option
@user_errors
def admm_command(capture_dir, lenses, lux, scene, methods, iterations, cg_steps, repeats, reference_repeats,
                 as_json, device):
    """Seconds per ADMM iteration: AdmmSolver on the device against the numpy reference."""
    from ...bench import pareto
    from ...bench.timing import parse_size

    method_list = [m.strip() for m in methods.split(",") if m.strip()]
    capture = pareto.make_capture(capture_dir, parse_size(lenses, "--lenses"), lux, scene)
    progress = None if as_json else (lambda label: click.echo(f"  {label} ...", err=True))
    report = pareto.admm_iteration(capture, method_list, iterations, cg_steps, repeats, reference_repeats,
                                   device=device, progress=progress)
    click.echo(json.dumps(report, indent=2) if as_json else pareto.format_admm(report))


@command.command("process")
@capture_source
@click.option("--seed", type=int, default=5, show_default=True, help="Seed of the in-memory simulation.")
@click.option("--methods", default="auto,admm-epi", show_default=True,
              help="Methods to time, each METHOD[:START] as lfcl process --method takes it.")
@click.option("--peer", default="admm-uv", show_default=True, help="The method the times are divided by.")
@click.option("--outputs", default="center", show_default=True, metavar="KIND,...",
              help="What each run writes (lfcl process --outputs; auto's choice depends on it), the centre view among "
                   "them.")
@click.option("--repeats", type=int, default=1, show_default=True, help="Runs per method (median).")
@click.option("--json", "as_json", is_flag=True, help="Print the results as JSON instead of a table.")
@device_option
@user_errors
def process_command(capture_dir, lenses, lux, scene, seed, methods, peer, outputs, repeats, as_json, device):
    """`lfcl process` end to end per method: seconds and peak memory, as ratios against a peer method."""
    import tempfile

    from ...bench import process
    from ...bench.timing import parse_size
    from ...evaluation.evaluate import load_capture

    method_list = [m.strip() for m in methods.split(",") if m.strip()]
    progress = None if as_json else (lambda label: click.echo(f"  {label} ...", err=True))
    with tempfile.TemporaryDirectory(prefix="lfcl_bench_capture_") as tmp:
        label = str(capture_dir)
        if capture_dir is None:  # the scene simulated into a temporary capture folder
            from ...sim import simulate, write_capture

            size = parse_size(lenses, "--lenses")
            capture_dir = write_capture(simulate(scene, lenses=size, lux=lux, seed=seed), Path(tmp) / "capture")
            label = f"{scene}, {size[0]}x{size[1]} lenses, {lux:g} lux, seed {seed}"
        capture = load_capture(capture_dir)  # a folder of `lfcl simulate`: its pitch and truth
        report = process.run(capture_dir / "raw.dng", method_list, peer, pitch=capture.pitch[0], truth=capture.truth,
                             repeats=repeats, device=device, progress=progress, label=label, outputs=outputs)
    click.echo(json.dumps(report, indent=2) if as_json else process.format_report(report))


@command.command("stress")
@click.option("--lenses", default="8x8", show_default=True, metavar="SxT",
              help="Lens array of the simulated scenes (9x9 pixels a lens); the shape cases add 1x1, 1xT, Sx1 and 3x5.")
@click.option("--only", default=None, metavar="NAME,...",
              help="Only the cases whose name contains one of these substrings, or whose group is one of them "
                   "(grid, images, input, params, shape, raw, noise, weights).")
@click.option("--reference", "with_reference", is_flag=True,
              help="Also compare the float32 device solver with the float64 numpy reference over the "
                   "lambda/rho grid (3x4 lenses; slower).")
@click.option("--json", "as_json", is_flag=True, help="Print the results as JSON instead of a table.")
@device_option
@user_errors
def stress_command(lenses, only, with_reference, as_json, device):
    """Numerical stress suite: every method on extreme parameters and inputs, checked against the contract.

    The contract: no NaN/Inf in any output or ADMM history; bad input is a ValueError and
    a solver that overflows a FloatingPointError, never a silent garbage image; the same
    input gives the same bytes twice. Exits with status 1 when a row breaks it.
    """
    import sys

    from ...bench import stress
    from ...bench.timing import parse_size

    size = parse_size(lenses, "--lenses")
    only_list = [s.strip() for s in only.split(",") if s.strip()] if only else None
    progress = None if as_json else (lambda label: click.echo(f"  {label} ...", err=True))
    report = stress.run(size, device=device, only=only_list, progress=progress)
    failures = report["failures"]
    if with_reference:
        report["reference"] = stress.reference_agreement(device=device, progress=progress)
        failures += report["reference"]["failures"]
    if as_json:
        click.echo(json.dumps(report, indent=2))
    else:
        click.echo(stress.format_report(report))
        if with_reference:
            click.echo("\n" + stress.format_reference(report["reference"]))
    if failures:
        click.echo(f"lfcl: stress: {failures} row(s) break the contract", err=True)
        sys.exit(1)


@command.command("matrix")
@click.option("--scenes", default=None, metavar="NAME,...",
              help="Built-in scenes to simulate; default: every built-in scene (lfcl.sim.SCENES).")
@click.option("--shared", default="../shared", show_default=True, type=click.Path(path_type=Path),
              help="The workplace's shared folder: its real light fields (antinous, Lytro 2067) join the matrix "
                   "where present.")
@click.option("--lux", "lux_text", default=",".join(f"{v:g}" for v in MATRIX_LUX), show_default=True,
              metavar="LUX,...")
@click.option("--methods", default=",".join(dict.fromkeys((DEFAULT_METHOD, "auto", "admm-uvst"))), show_default=True,
              metavar="METHOD,...", help="Methods compared with Malvar (default: `lfcl process`'s default, auto "
                                         "and admm-uvst).")
@click.option("--lenses", type=click.IntRange(min=4), default=48, show_default=True,
              help="Lenses per side of every capture (real light fields: a centre crop).")
@click.option("--seed", type=click.IntRange(min=0), default=7, show_default=True,
              help="Scene and noise seed (the defaults were fitted on seeds 1 and 2).")
@click.option("--noise", "noise_text", default="profile,raw", show_default=True, metavar="SOURCE,...",
              help="Where the methods' noise model comes from: 'profile' (the DNG's NoiseProfile) and/or 'raw' "
                   "(estimated from the raw, as for a raw without one).")
@click.option("--json", "as_json", is_flag=True, help="Print the rows as JSON instead of a table.")
@device_option
@user_errors
def matrix_command(scenes, shared, lux_text, methods, lenses, seed, noise_text, as_json, device):
    """Every scene and real light field x light level x method: PSNR against Malvar, the worst cell first.

    Each row also gives how noisy its ground truth is itself, over the sensor's noise (the Lytro frame's truth
    carries a real camera's noise; docs/auto.md, "A truth with noise of its own").
    """
    from ...bench import matrix
    from ...evaluation.evaluate import check_methods
    from ...sim.scenes import SCENES, check_scene

    scene_list = [check_scene(s.strip()) for s in scenes.split(",") if s.strip()] if scenes else list(SCENES)
    method_list = check_methods([m.strip() for m in methods.split(",") if m.strip()])
    lux = matrix.parse_lux(lux_text)
    progress = None if as_json else (lambda r: click.echo(
        f"  {r['capture']} {r['lux']:g} lux {r['noise']} {r['method']}: {r['centre_gain']:+.2f} / "
        f"{r['mean_gain']:+.2f} dB", err=True))
    noise = tuple(n.strip() for n in noise_text.split(",") if n.strip())
    rows = matrix.run(scene_list, matrix.real_lightfields(shared), lux, method_list, lenses=lenses, seed=seed,
                      noise_sources=noise, device=device, progress=progress)
    click.echo(json.dumps(rows, indent=2) if as_json else matrix.format_rows(rows))


@command.command("api")
@click.option("--size", default="4500x4500", show_default=True, metavar="HxW",
              help="Mosaic size in pixels; 4500x4500 is the paper's full sensor.")
@click.option("--repeats", type=click.IntRange(min=1), default=3, show_default=True, help="Timed calls (median).")
@click.option("--json", "as_json", is_flag=True, help="Print the result as JSON instead of text.")
@device_option
@user_errors
def api_command(size, repeats, as_json, device):
    """The public lfcl.malvar and lfcl.lightfield calls (copies and transfers included) against
    colour-demosaicing's Malvar2004 (cut into the light-field layout for the second)."""
    from ...bench import api
    from ...bench.timing import parse_size

    height, width = parse_size(size, "--size")
    report = api.run(height, width, repeats=repeats, device=device)
    click.echo(json.dumps(report, indent=2) if as_json else api.format_report(report))
