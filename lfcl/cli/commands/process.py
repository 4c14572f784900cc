"""`lfcl process`: a lenslet raw in, a demosaiced 4D light field and images out (docs/outputs.md).

The options (:func:`process_options`, shared with `lfcl batch`) become a
:class:`ProcessSettings` (:func:`settings_from_options`: the ``--recipe``
fills the options not given, and every option a user can get wrong is checked
before any work), which builds a :class:`lfcl.pipeline.stages.Pipeline` (Decode, Grid,
Demosaic, Outputs) and runs it (:func:`run_capture`): the outputs asked for, each
file written atomically, ``summary.json`` last, all of them or none. Then a
one-screen summary (``--json``: the summary as JSON).
"""

from __future__ import annotations

import dataclasses
import json
import sys
from pathlib import Path

import click

from ...demosaic.names import DEFAULT_METHOD, FLAT_P, METHODS, STARTS
from . import PROCESS_SECTIONS, SectionedCommand, device_option, user_errors

DEFAULT_OUTPUTS = "center,mean,lightfield"
DEFAULT_REFOCUS = "-1:1:0.25"
DEFAULT_PITCH = 9

#: The output kinds (lfcl.outputs.files.KINDS, repeated here so that `lfcl --help` does not import numpy).
OUTPUTS = ("center", "mean", "views", "views-each", "refocus", "lightfield", "depth")

#: Options a ``--recipe`` supplies when not given (parameter name -> recipe key).
RECIPE_KEYS = {"method": "method", "strength": "strength", "lam": "lambda", "iterations": "iterations",
               "outputs": "outputs", "refocus_spec": "refocus", "fmt": "format", "previews": "previews"}

_OPTIONS = (
    click.option("--method", default=DEFAULT_METHOD, show_default=True,
                 type=click.Choice(METHODS),
                 help="Demosaic/denoise method. auto: chosen from the raw's noise level, judged on --outputs "
                      "(center alone: the centre view; mean/refocus alone: the mean image; else both; docs/auto.md)."),
    click.option("--pitch", default=None, type=click.IntRange(min=2), show_default=str(DEFAULT_PITCH),
                 help="Pixels per microlens of an aligned square grid starting at the sensor's first pixel "
                      "(not with --calibration / --white)."),
    click.option("--calibration", type=click.Path(path_type=Path, readable=False), default=None,
                 metavar="CAL.json",
                 help="Lens grid from `lfcl calibrate`. An aligned square grid of integer pitch is sliced exactly; "
                      "a rotated, non-integer-pitch or hexagonal one is resampled inside the solver "
                      "(docs/geometry.md; methods auto, malvar, admm-uv, admm-st, admm-uvst)."),
    click.option("--white", type=click.Path(path_type=Path, readable=False), default=None, metavar="WHITE",
                 help="Calibrate from this white image first (as `lfcl calibrate WHITE`), then as --calibration."),
    click.option("--pattern", default=None, help="Bayer pattern; required for EXR/TIFF/PNG mosaics, read from raws."),
    click.option("--outputs", default=DEFAULT_OUTPUTS, show_default=True,
                 help=f"Comma-separated: {', '.join(OUTPUTS)}. Only these are computed."),
    click.option("--refocus", "refocus_spec", default=None, metavar="START:STOP:STEP|A,B,..",
                 help=f"Refocus slopes (lenses per view step): a range, stop included when on the grid, or a "
                      f"comma list. Implies the refocus output; refocus without it uses {DEFAULT_REFOCUS}."),
    click.option("--format", "fmt", default="exr", show_default=True, type=click.Choice(["exr", "tiff", "dng"]),
                 help="Images: EXR (float, scene-linear), TIFF (16-bit linear, clipped to [0, 1]) or DNG "
                      "(LinearRaw for raw editors, with the raw's colour matrix and white balance; "
                      "docs/darktable.md)."),
    click.option("--previews/--no-previews", default=True, show_default=True,
                 help="Also write an 8-bit sRGB PNG of every image (white balance and colour matrix from the raw)."),
    click.option("--lambda", "lam", default=None, type=float,
                 help="TV weight; default: follows the noise level estimated from the raw (docs/admm.md)."),
    click.option("--iterations", default=None, type=click.IntRange(min=1),
                 help="Run exactly this many ADMM iterations; default: the method's early-stopping rule."),
    click.option("--strength", default=1.0, show_default=True, type=float, help="Multiplier on the default lambda."),
    click.option("--tolerance-db", "tolerance_db", default=None, type=click.FloatRange(min=0, min_open=True),
                 metavar="DB",
                 help="Stop the ADMM iterations once one can move PSNR by less than DB dB (docs/auto.md); "
                      "default: the method's own stopping rule. With --iterations: at most that many."),
    click.option("--start", default=None, type=click.Choice(STARTS),
                 help="First estimate of the ADMM methods: malvar (the paper's), linear4d (the learned 4D "
                      "filter; gains on textured and multi-plane scenes), lens-malvar (Malvar bounded to each "
                      "lens; gains on the mean image) or guarded (linear4d, with Malvar in the lenses where it "
                      "breaks: high-contrast edges, clipped highlights), docs/auto.md. Default: malvar; with "
                      "--method auto, the start its rule names."),
    click.option("--skip-flat/--solve-flat", "skip_flat", default=None, hidden=True,  # measured: off by default
                 help="Flat lenses (constant per colour within the noise: a chi-square test against the raw's "
                      "noise model) get their colour means and leave the ADMM solve (admm-uv, admm-uv-xc, auto's "
                      "picks; docs/auto.md). Default: solve every lens (the test took fine texture for noise)."),
    click.option("--safety-net/--no-safety-net", "safety_net", default=True, show_default=True,
                 help="Keep every lens's colour means within the noise of Malvar's (lfcl/demosaic/safety_net.py; "
                      "docs/auto.md): never a mean image worse than Malvar's."),
    click.option("--flat-p", "flat_p", default=None, hidden=True, type=click.FloatRange(min=0, max=1, min_open=True, max_open=True),
                 metavar="P",
                 help=f"A lens is flat when its chi-square p-value is above P (default {FLAT_P:g}); implies --skip-flat."),
    click.option("--max-memory", default=None, type=click.FloatRange(min=0.01), metavar="GIB",
                 help="Device memory the solver may use, GiB; default 80% of the device's. A larger admm-uv "
                      "problem runs in bands of lens rows (exact: the (u, v) prior couples no two lenses)."),
    click.option("--recipe", "pipeline", default=None, metavar="NAME|PATH",
                 help="A recipe (default, lowlight, preview, or a .toml file; docs/stages.md) supplying defaults "
                      "for --method, --strength, --lambda, --iterations, --outputs, --refocus, --format, "
                      "--previews; options given on the command line win."),
    device_option,
)


def process_options(func):
    """The options of `lfcl process` (all but RAW, -o and --json) as one click decorator.

    `lfcl batch` takes them too, with the same meaning and defaults; the command receives
    them as keyword arguments and hands them to :func:`settings_from_options`.
    """
    for option in reversed(_OPTIONS):
        func = option(func)
    return func


@dataclasses.dataclass(frozen=True)
class ProcessSettings:
    """Everything `lfcl process` does to a raw, resolved and checked (plain values: picklable, JSON-able).

    ``outputs``: the output kinds (``refocus`` added when ``--refocus`` was given);
    ``refocus``: the slopes spec (None when refocus is not among the outputs);
    ``max_memory``: bytes or None; ``tolerance_db``: the ADMM stop in dB or None (the
    method's rule); ``start``: the ADMM methods' first estimate or None (the method's); ``recipe``: what the outputs record about a
    ``--recipe`` (name, path, options, from_command_line) or None.
    """

    method: str = DEFAULT_METHOD
    pitch: int | None = None
    calibration: str | None = None
    white: str | None = None
    pattern: str | None = None
    outputs: tuple = ("center", "mean", "lightfield")
    refocus: str | None = None
    fmt: str = "exr"
    previews: bool = True
    lam: float | None = None
    iterations: int | None = None
    strength: float = 1.0
    max_memory: int | None = None
    device: str | None = None
    recipe: dict | None = None
    tolerance_db: float | None = None
    start: str | None = None
    skip_flat: bool | float | None = None
    safety_net: bool = True

    def pipeline(self, callback=None):
        """The :class:`lfcl.pipeline.stages.Pipeline` of these settings; ``callback``: per ADMM iteration (progress)."""
        from ... import __version__
        from ...demosaic.auto import view_for_outputs
        from ...pipeline.stages import Decode, Demosaic, Grid, Outputs, Pipeline

        extra: dict = {"generator": f"lfcl {__version__} process"}
        if self.recipe is not None:
            extra["recipe"] = self.recipe
        return Pipeline([
            Decode(self.pattern),
            Grid(pitch=self.pitch, calibration=self.calibration, white=self.white, pattern=self.pattern),
            Demosaic(self.method, lam=self.lam, iterations=self.iterations, strength=self.strength,
                     device=self.device, callback=callback, max_memory=self.max_memory,
                     tolerance_db=self.tolerance_db, start=self.start, skip_flat=self.skip_flat,
                     safety_net=self.safety_net, auto_view=view_for_outputs(self.outputs)),  # auto judges its choice on what is written
            Outputs(list(self.outputs), refocus=self.refocus or DEFAULT_REFOCUS, fmt=self.fmt,
                    previews=self.previews, metadata=extra),
        ])


def settings_from_options(options: dict, ctx: click.Context | None = None) -> ProcessSettings:
    """The :func:`process_options` values of a command -> :class:`ProcessSettings`; one-line errors.

    With ``pipeline`` (a recipe), the recipe's values replace the options that were not
    given on the command line (``ctx``'s parameter sources tell which were).
    """
    method, strength, lam, iterations = options["method"], options["strength"], options["lam"], options["iterations"]
    outputs, refocus_spec, fmt, previews = options["outputs"], options["refocus_spec"], options["fmt"], options["previews"]
    recipe_meta = None
    if options["pipeline"] is not None:
        from click.core import ParameterSource

        from ...pipeline.recipes import load_recipe

        recipe = load_recipe(options["pipeline"])
        ctx = ctx or click.get_current_context()
        explicit = {p for p in RECIPE_KEYS if ctx.get_parameter_source(p) not in (ParameterSource.DEFAULT,
                                                                                 ParameterSource.DEFAULT_MAP)}
        values = {"method": method, "strength": strength, "lam": lam, "iterations": iterations, "outputs": outputs,
                  "refocus_spec": refocus_spec, "fmt": fmt, "previews": previews}
        for param, key in RECIPE_KEYS.items():
            if param in explicit:
                continue
            if param == "outputs":
                values[param] = ",".join(recipe["outputs"])
            elif param == "refocus_spec":
                if "refocus" in recipe["outputs"]:
                    values[param] = recipe["refocus"]
            else:
                values[param] = recipe[key]
        method, strength, lam, iterations = values["method"], values["strength"], values["lam"], values["iterations"]
        outputs, refocus_spec, fmt, previews = (values["outputs"], values["refocus_spec"], values["fmt"],
                                                values["previews"])
        recipe_meta = {"name": recipe["name"], "path": recipe["path"],
                       "options": {"method": method, "strength": strength, "lambda": lam,
                                   "iterations": iterations, "outputs": outputs, "refocus": refocus_spec,
                                   "format": fmt, "previews": previews},
                       "from_command_line": sorted(RECIPE_KEYS[p] for p in explicit)}
    from ...outputs.files import parse_format, parse_outputs
    from ...outputs.refocus import parse_slopes

    # --- everything a user can get wrong in the options, before any work ------------------
    wanted = parse_outputs(outputs)
    if refocus_spec is not None and "refocus" not in wanted:
        wanted.append("refocus")
    if "refocus" in wanted:
        refocus_spec = refocus_spec if refocus_spec is not None else DEFAULT_REFOCUS
        parse_slopes(refocus_spec)
    else:
        refocus_spec = None
    fmt = parse_format(fmt)
    pitch, calibration, white = options["pitch"], options["calibration"], options["white"]
    given = [name for name, value in (("--pitch", pitch), ("--calibration", calibration), ("--white", white))
             if value is not None]
    if len(given) > 1:
        raise ValueError(f"give the lens grid once: {' and '.join(given)} together")
    if calibration is not None and not Path(calibration).is_file():
        raise FileNotFoundError(f"calibration {str(calibration)!r} does not exist")
    if white is not None and not Path(white).is_file():
        raise FileNotFoundError(f"white image {str(white)!r} does not exist")
    if calibration is not None:
        _check_method_for_calibration(method, calibration, options.get("start"))
    max_memory, tolerance_db = options["max_memory"], options.get("tolerance_db")
    skip_flat, flat_p = options.get("skip_flat"), options.get("flat_p")
    if flat_p is not None:
        if skip_flat is False:
            raise ValueError("--flat-p sets how flat lenses are skipped: it does not go with --solve-flat")
        skip_flat = float(flat_p)
    settings = ProcessSettings(
        method=method, pitch=pitch, calibration=None if calibration is None else str(calibration),
        white=None if white is None else str(white), pattern=options["pattern"], outputs=tuple(wanted),
        refocus=refocus_spec, fmt=fmt, previews=bool(previews), lam=lam, iterations=iterations,
        strength=float(strength), max_memory=None if max_memory is None else int(max_memory * 2**30),
        device=options["device"], recipe=recipe_meta,
        tolerance_db=None if tolerance_db is None else float(tolerance_db), start=options.get("start"),
        skip_flat=skip_flat, safety_net=bool(options.get("safety_net", True)))
    settings.pipeline()  # the stages check the rest (--strength, --lambda, ...), still before any work
    return settings


def _check_method_for_calibration(method: str, calibration, start: str | None = None) -> None:
    """A method (or start) the calibration's grid path does not run: one line before any raw is read (once per
    batch)."""
    from ...grid import load_calibration
    from ...grid.aligned import describe_grid, fit_grid
    from ...pipeline.stages import check_method_for_grid, grid_words

    cal = load_calibration(calibration)
    what = f"calibration {calibration}"
    geo = fit_grid(cal, what)
    words = grid_words({"grid": geo["kind"], "packing": cal.grid.packing, "features": geo["features"]})
    check_method_for_grid(method, geo["kind"], f"the {words} lens grid of {what} ({describe_grid(cal)})")
    if geo["kind"] == "resampled" and start not in (None, "malvar"):
        raise ValueError(f"--start {start} needs an aligned square lens grid; {what} gives the {words} lens grid "
                         f"({describe_grid(cal)}): leave --start out")


def process_summary(summary: dict) -> dict:
    """The Pipeline's summary with `lfcl process`'s timing keys (docs/outputs.md): ``decode`` (reading
    the raw and cutting it to whole lenses), ``calibrate`` (with ``--white``: the whole grid step),
    ``demosaic``, ``outputs``."""
    seconds = dict(summary["seconds"])
    grid = seconds.pop("grid", 0.0)
    if "calibrate" in seconds:
        seconds["calibrate"] += grid
    else:
        seconds["decode"] = seconds.get("decode", 0.0) + grid
    order = ("decode", "calibrate", "demosaic", "outputs")
    summary["seconds"] = {k: seconds[k] for k in order if k in seconds}
    return summary


def run_capture(settings: ProcessSettings, raw, out_dir, callback=None) -> dict:
    """Process one raw into ``out_dir`` (all files or none) and return its summary (= summary.json)."""
    return settings.pipeline(callback).run(raw, out_dir, finish=process_summary)


def iteration_total(method: str, iterations: int | None = None, tolerance_db: float | None = None) -> int | None:
    """The most ADMM iterations ``method`` runs (a progress bar's total), or None when unknown before the run.

    Any name of lfcl.demosaic.names.METHODS: an explicit ``iterations``; else the method's cap
    (lfcl.demosaic.methods.admm_params: with ``tolerance_db``, at least 60); None for ``auto`` (the
    method is chosen during the run) and for methods without ADMM iterations (no bar is drawn).
    """
    if iterations is not None:
        return int(iterations)
    from ...demosaic.methods import ADMM_DEFAULTS

    defaults = ADMM_DEFAULTS.get(method)
    if defaults is None:
        return None
    return max(defaults.max_iter, 60) if tolerance_db is not None else defaults.max_iter


class IterationBar:
    """A tqdm bar over the ADMM iterations on stderr (terminals only), made on the first iteration."""

    def __init__(self, method: str, iterations: int | None, tolerance_db: float | None = None):
        self.method, self.iterations, self.tolerance_db, self.bar, self.band = method, iterations, tolerance_db, None, 0

    def __call__(self, record, x):
        if self.bar is None:
            from tqdm import tqdm

            total = iteration_total(self.method, self.iterations, self.tolerance_db)
            self.bar = tqdm(total=total, desc=self.method, unit="it", disable=None, leave=False, file=sys.stderr,
                            dynamic_ncols=True)
        elif record.iteration == 1:  # a new band of lens rows
            self.band += 1
            self.bar.reset()
            self.bar.set_description(f"{self.method} band {self.band + 1}")
        self.bar.update(1)
        self.bar.set_postfix_str(f"change {record.rms_change:.2e}", refresh=False)

    def close(self):
        if self.bar is not None:
            self.bar.close()


@click.command("process", cls=SectionedCommand, sections=PROCESS_SECTIONS)
@click.argument("raw", type=click.Path(path_type=Path, readable=False))
@click.option("-o", "--output", "out_dir", required=True, type=click.Path(file_okay=False, path_type=Path),
              help="Output folder (created if missing).")
@process_options
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON (no progress bar).")
@user_errors
def command(raw, out_dir, as_json, **options):
    """Demosaic a lenslet RAW (DNG, camera raw, or EXR/TIFF/PNG mosaic) into a 4D light field."""
    settings = settings_from_options(options)
    bar = None if as_json else IterationBar(settings.method, settings.iterations, settings.tolerance_db)
    try:
        summary = run_capture(settings, raw, out_dir, callback=bar)
    finally:
        if bar is not None:
            bar.close()
    if as_json:
        click.echo(json.dumps(summary, indent=2))
    else:
        click.echo(summary_text(raw, out_dir, summary))


def summary_text(raw, out_dir, summary: dict) -> str:
    """The run on one screen: geometry, method, time per stage, what was written and what was skipped."""
    from ...pipeline.stages import grid_words

    S, T = summary["lenses"]
    geo = summary["geometry"]
    U, V = geo["pitch"]
    if geo["grid"] == "resampled":
        lines = [f"{raw} -> {out_dir}  ({S}x{T} lenses of {U}x{V} views from {geo['from']}, {summary['pattern']})",
                 f"path: resampled ({grid_words(geo)} grid): the regular light field "
                 "is fitted to the sensor samples through the resampling (lfcl.demosaic.resampled, docs/geometry.md)"]
    else:
        lines = [f"{raw} -> {out_dir}  ({S}x{T} lenses of {U}x{V} px from {geo['from']}, {summary['pattern']}"
                 + (f", first lens at pixel {geo['first_lens_pixel'][0]},{geo['first_lens_pixel'][1]}"
                    if any(geo["first_lens_pixel"]) else "") + ")",
                 "path: aligned square grid of integer pitch, sliced exactly (lfcl.demosaic.methods)"]
    if "calibration" in summary:
        c = summary["calibration"]
        deviation = c["aligned_max_deviation_px"]
        off = ("" if deviation is None else
               f"; aligned within {deviation:.2f} px" if geo["grid"] != "resampled" else
               f"; up to {deviation:.2f} px off an aligned grid")
        lines.append(f"calibration: {c['packing']} grid, pitch {c['pitch_px']:.4f} px, rotation "
                     f"{c['rotation_deg']:+.4f} deg{off}")
    params = summary["parameters"]
    lam = f", lambda {params['lam']:.3g}" if "lam" in params else ""
    tolerance = summary.get("options", {}).get("tolerance_db")
    stop = f", tolerance {tolerance:g} dB" if tolerance is not None and summary["iterations"] else ""
    auto = params.get("auto")
    method = summary["method"]
    start = f" from a {params['start']} start" if params.get("start", "malvar") != "malvar" else ""
    if auto:
        strength = f" at strength {auto['strength']:g}" if auto["strength"] != 1 else ""
        method = f"auto -> {auto['method']}{strength}{start} ({auto['reason']})\n  ran {auto['method']}"
        start = ""
    lines.append(f"method {method}{start}: {summary['iterations']} iterations ({summary['stop_reason']}){lam}{stop}")
    net = params.get("safety_net")
    if net and not net["lenses"]:
        lines.append(f"safety net: {net['why']}")
    elif net:
        mixed = net["lenses"] - net["lenses_from_malvar"] - net["lenses_kept"]
        parts = [f"{net['lenses_from_malvar']} of {net['lenses']} lenses took Malvar's colour means (within the noise)"]
        if net["lenses_kept"]:
            parts.append(f"{net['lenses_kept']} kept theirs, moved {net['k']:g} noise sds towards Malvar's")
        if mixed:
            parts.append(f"{mixed} some colours of each")
        lines.append("safety net: " + "; ".join(parts))
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
    return "\n".join(lines)
