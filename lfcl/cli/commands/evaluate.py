"""`lfcl evaluate`: score methods against a simulated capture's ground truth (paper, section 4),
with the colour-artefact metrics of docs/colour-metrics.md (paper, section 5)."""

from __future__ import annotations

import json
from pathlib import Path

import click

from . import device_option, user_errors


def _floats(text: str, name: str) -> list[float]:
    try:
        values = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise ValueError(f"{name} must be comma-separated numbers, got {text!r}") from None
    if not values or any(not v > 0 for v in values):
        raise ValueError(f"{name} must be positive numbers, got {text!r}")
    return values


@click.command("evaluate")
@click.argument("capture_dir", type=click.Path(file_okay=False, path_type=Path))
@click.option("--methods", default="malvar,admm-uv,admm-st,admm-uvst", show_default=True,
              help="Comma-separated methods to compare, each METHOD[:START] as lfcl process --method takes it "
                   "(an ADMM method may name its start, as admm-uv-xc:linear4d).")
@click.option("-o", "--output", "out_dir", default=None, type=click.Path(file_okay=False, path_type=Path),
              help="Where eval.json, eval.md and the figures go. Default: CAPTURE_DIR/eval.")
@click.option("--sweep-lux", default=None, metavar="LUX,...",
              help="Also re-simulate the scene at these illuminations and tabulate/plot PSNR (paper, Fig. 10) "
                   "and the colour errors (psnr_vs_lux.png, de2000_vs_lux.png).")
@click.option("--gradients", is_flag=True, help="Report the ground truth's gradient sparsity along u, v, s, t (Fig. 5).")
@click.option("--json", "as_json", is_flag=True, help="Print the results as JSON instead of tables.")
@device_option
@user_errors
def command(capture_dir, methods, out_dir, sweep_lux, gradients, as_json, device):
    """Run METHODS on CAPTURE_DIR/raw.dng and score them against CAPTURE_DIR/truth.npy.

    Scores: PSNR, CIEDE2000 mean and 95th percentile, false colour on grey edges and chroma
    error at high frequencies, on the centre view and the mean image (docs/colour-metrics.md).
    """
    from tqdm import tqdm

    from ...evaluation import evaluate as ev
    from ...evaluation import plots
    from ...io.images import atomic_path, write_json

    method_list = ev.check_methods(methods.split(","))
    lux_list = _floats(sweep_lux, "--sweep-lux") if sweep_lux else None
    capture = ev.load_capture(capture_dir)
    out_dir = out_dir or capture_dir / "eval"
    label = f"{capture.meta['scene'].get('name', 'scene')} at {capture.meta['lux']:g} lux"

    bar_off = True if as_json else None  # None: a bar on terminals only, none in logs and pipes
    results = [ev.run_method(capture, m, device) for m in tqdm(method_list, desc="methods", disable=bar_off)]
    report = {"capture": str(capture_dir), "scene": capture.meta["scene"], "lux": capture.meta["lux"],
              "lenses": capture.meta["lenses"],
              "results": [{k: v for k, v in r.items() if k != "lightfield"} for r in results]}
    markdown = [ev.format_table(results, f"PSNR and colour errors, {label} ({capture.meta['lenses'][0]}x{capture.meta['lenses'][1]} lenses)")]
    deferred_figures = []  # drawn at the end, with the other outputs

    if gradients:
        sparsity = ev.gradient_sparsity(capture.truth)
        report["gradients"] = sparsity
        markdown.append("\n**Ground-truth gradients** (share of |gradient| < 0.01, mean |gradient|)\n")
        markdown.append("| dim | share < 0.01 | mean abs |\n|---|---|---|")
        markdown += [f"| {d} | {v['share_below']:.3f} | {v['mean_abs']:.4f} |" for d, v in sparsity.items()]
        deferred_figures.append(lambda: plots.gradient_images(ev.centre_gradient_images(capture.truth), out_dir / "gradients.png",
                                                     f"{label}: ground truth and |gradient| of the centre view"))

    if lux_list:
        sweep = []
        for lux in tqdm(lux_list, desc="lux sweep", disable=bar_off):
            swept = ev.capture_in_memory(capture.meta, lux)
            rows = [ev.run_method(swept, m, device) for m in method_list]
            sweep.append({"lux": lux, "results": [{k: v for k, v in r.items() if k != "lightfield"} for r in rows]})
        report["sweep"] = sweep
        markdown.append("\n" + ev.format_sweep(sweep))
        deferred_figures.append(lambda: ev.plot_sweep(sweep, out_dir / "psnr_vs_lux.png", label))
        deferred_figures.append(lambda: ev.plot_colour_sweep(sweep, out_dir / "de2000_vs_lux.png", label))

    # Everything is computed; only now write, so a failure above leaves no partial output.
    figures = ev.write_figures(capture, results, out_dir, label) + [str(draw()) for draw in deferred_figures]
    report["figures"] = figures
    write_json(out_dir / "eval.json", report)
    with atomic_path(out_dir / "eval.md") as tmp:
        tmp.write_text("\n".join(markdown) + "\n")
    if as_json:
        click.echo(json.dumps(report, indent=2))
    else:
        click.echo("\n".join(markdown))
        click.echo(f"\nwrote {out_dir / 'eval.json'}, {out_dir / 'eval.md'} and {len(figures)} figures")
