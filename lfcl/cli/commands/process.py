"""`lfcl process`: a lenslet raw in, a demosaiced 4D light field and images out (docs/outputs.md).

The options (:func:`process_options`, shared with `lfcl batch`; derived from the stages' parameter schemas in
lfcl/pipeline/parameters.py, all but ``--recipe`` and ``--device``) become a
:class:`ProcessSettings` (:func:`settings_from_options`: the ``--recipe``
fills the options not given, and every option a user can get wrong is checked
before any work), which builds a :class:`lfcl.pipeline.stages.Pipeline` (Decode, Grid,
Demosaic, Outputs) and runs it (:func:`run_capture`): the outputs asked for, each
file written atomically, ``summary.json`` last, all of them or none. Then a
one-screen summary (``--json``: the summary as JSON).
"""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import click

from ...demosaic.names import method_spec, parse_method_spec
from ...pipeline.parameters import (
    DEFAULT_PITCH,  # noqa: F401 (lfcl batch's)
    DEFAULT_REFOCUS,
    OUTPUTS,  # noqa: F401 (the output kinds, without numpy)
    DemosaicParameters,
    OutputParameters,
    Param,
    defaults,
    entries,
    recipe_entries,
)
from ...pipeline.recipes import PACKAGED
from . import PROCESS_SECTIONS, SectionedCommand, device_option, user_errors

#: Options a ``--recipe`` supplies when not given (click parameter name -> recipe key; the schema's recipe keys).
RECIPE_KEYS = {e.cli_name: e.key for e in recipe_entries()}


def _click_option(flag: str, name: str, param: Param, default):
    """One click option of a schema field (or of an alias of one): lfcl/pipeline/parameters.py says what."""
    kind = param.cli_kind or param.kind
    bounds = param.cli_bounds or param.bounds
    kwargs: dict = {"default": default, "help": param.help}
    if default is not None:
        kwargs["show_default"] = True
    elif param.show_default:
        kwargs["show_default"] = param.show_default
    if param.choices:
        kwargs["type"] = click.Choice(param.choices)
    elif kind == "path":
        kwargs["type"] = click.Path(path_type=Path, readable=False)
    elif kind in (int, float) and bounds is not None:
        kwargs["type"] = (click.IntRange if kind is int else click.FloatRange)(
            min=bounds.low, max=bounds.high, min_open=bounds.low_open, max_open=bounds.high_open)
    elif kind in (int, float):
        kwargs["type"] = kind
    if param.metavar:
        kwargs["metavar"] = param.metavar
    if param.hidden:
        kwargs["hidden"] = True
    return click.option(flag, name, **kwargs)


def _schema_options() -> list:
    """The click options of every stage's schema fields (and their aliases, e.g. ``--flat-p``)."""
    out = []
    for e in entries():
        if e.param.cli:
            out.append(_click_option(e.flag, e.cli_name, e.param, e.cli_default))
            out.extend(_click_option(a.flag, a.cli_name, a, None) for a in e.param.aliases)
    return out


_OPTIONS = (
    *_schema_options(),
    click.option("--recipe", "pipeline", default=None, metavar="NAME|PATH",
                 help=f"A recipe ({', '.join(PACKAGED)}, or a .toml file; docs/stages.md) supplying defaults "
                      f"for {', '.join(e.flag.split('/')[0] for e in recipe_entries())}; options given on the "
                      "command line win."),
    device_option,
)


def _field_value(name: str, value):
    """A click value -> the field's (``Param.cli_scale``: ``--max-memory`` GiB -> bytes)."""
    scale = next(e.param.cli_scale for e in entries() if e.cli_name == name)
    return value if value is None or scale is None else int(value * scale)


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
    method's rule); ``method`` and ``start``: ``--method METHOD[:START]`` apart, the start None where none is
    named (the method's); ``recipe``: what the outputs record about a
    ``--recipe`` (name, path, options, from_command_line) or None. Defaults: the stages' schemas
    (lfcl/pipeline/parameters.py).
    """

    method: str = defaults(DemosaicParameters)["method"]
    pitch: int | None = None
    calibration: str | None = None
    white: str | None = None
    pattern: str | None = None
    outputs: tuple = defaults(OutputParameters)["outputs"]
    refocus: str | None = None
    fmt: str = defaults(OutputParameters)["fmt"]
    previews: bool = defaults(OutputParameters)["previews"]
    lam: float | None = None
    iterations: int | None = None
    strength: float = defaults(DemosaicParameters)["strength"]
    max_memory: int | None = None
    device: str | None = None
    recipe: dict | None = None
    tolerance_db: float | None = None
    start: str | None = None
    skip_flat: bool | float | None = None
    safety_net: bool = defaults(DemosaicParameters)["safety_net"]
    auto_costly: bool = defaults(DemosaicParameters)["auto_costly"]

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
            Demosaic(method_spec(self.method, self.start), lam=self.lam, iterations=self.iterations,
                     strength=self.strength, device=self.device, callback=callback, max_memory=self.max_memory,
                     tolerance_db=self.tolerance_db, skip_flat=self.skip_flat,
                     safety_net=self.safety_net, auto_costly=self.auto_costly,
                     auto_view=view_for_outputs(self.outputs)),  # auto judges its choice on what is written
            Outputs(list(self.outputs), refocus=self.refocus or DEFAULT_REFOCUS, fmt=self.fmt,
                    previews=self.previews, metadata=extra),
        ])


def settings_from_options(options: dict, ctx: click.Context | None = None) -> ProcessSettings:
    """The :func:`process_options` values of a command -> :class:`ProcessSettings`; one-line errors.

    With ``pipeline`` (a recipe), the recipe's values replace the options that were not
    given on the command line (``ctx``'s parameter sources tell which were).
    """
    values = {param: options[param] for param in RECIPE_KEYS}
    recipe_meta = None
    if options["pipeline"] is not None:
        from click.core import ParameterSource

        from ...pipeline.recipes import load_recipe

        recipe = load_recipe(options["pipeline"])
        ctx = ctx or click.get_current_context()
        explicit = {p for p in RECIPE_KEYS if ctx.get_parameter_source(p) not in (ParameterSource.DEFAULT,
                                                                                 ParameterSource.DEFAULT_MAP)}
        for param, key in RECIPE_KEYS.items():
            if param in explicit:
                continue
            if param == "refocus_spec":  # --refocus asks for the refocus output; a recipe's slopes serve where it does
                if "refocus" in recipe["outputs"]:
                    values[param] = recipe[key]
            else:  # a list (outputs) as the comma list the option takes
                values[param] = ",".join(recipe[key]) if isinstance(recipe[key], list) else recipe[key]
        recipe_meta = {"name": recipe["name"], "path": recipe["path"],
                       "options": {key: values[param] for param, key in RECIPE_KEYS.items()},
                       "from_command_line": sorted(RECIPE_KEYS[p] for p in explicit)}
    method, strength, lam, iterations = values["method"], values["strength"], values["lam"], values["iterations"]
    outputs, refocus_spec, fmt, previews = values["outputs"], values["refocus_spec"], values["fmt"], values["previews"]
    from ...outputs.files import parse_format, parse_outputs
    from ...outputs.refocus import parse_slopes

    # --- everything a user can get wrong in the options, before any work ------------------
    method, start = parse_method_spec(method)
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
        _check_method_for_calibration(method, calibration, start)
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
        strength=float(strength), max_memory=_field_value("max_memory", max_memory),
        device=options["device"], recipe=recipe_meta,
        tolerance_db=None if tolerance_db is None else float(tolerance_db), start=start,
        skip_flat=skip_flat, safety_net=bool(options.get("safety_net", True)), auto_costly=bool(values["auto_costly"]))
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
        raise ValueError(f"--method {method}:{start} needs an aligned square lens grid; {what} gives the {words} "
                         f"lens grid ({describe_grid(cal)}): leave :{start} out")


def process_summary(summary: dict) -> dict:
    """The Pipeline's summary with `lfcl process`'s timing keys (docs/outputs.md): ``decode`` (reading
    the raw and cutting it to whole lenses), ``calibrate`` (with ``--white``: the whole grid step),
    ``disparity`` (admm-epi's estimate), ``demosaic`` (the rest of that stage), ``outputs``."""
    seconds = dict(summary["seconds"])
    grid = seconds.pop("grid", 0.0)
    if "calibrate" in seconds:
        seconds["calibrate"] += grid
    else:
        seconds["decode"] = seconds.get("decode", 0.0) + grid
    order = ("decode", "calibrate", "disparity", "demosaic", "outputs")
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
        from ...io.images import to_json

        click.echo(to_json(summary, indent=2))
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
    noise = summary.get("noise")
    if noise:
        origin = ("the DNG's noise profile" if noise["source"] == "dng-noise-profile" else
                  f"estimated from the raw: {noise['method']}")
        lines.append(f"noise: sigma {noise['sigma']:.3g} ({origin})")
    net = params.get("safety_net")
    if net and not net["lenses"]:
        lines.append(f"safety net: {net['why']}")
    elif net:
        filled = net.get("lenses_filled_flat", 0)
        mixed = net["lenses"] - net["lenses_from_malvar"] - net["lenses_kept"] - filled
        if net["k"] is None:  # no soft threshold: the method keeps its lens means
            parts = [f"{net['lenses_kept']} of {net['lenses']} lenses kept the method's own colour means"]
        else:
            parts = [f"{net['lenses_from_malvar']} of {net['lenses']} lenses took Malvar's colour means (within the "
                     "noise)"]
            if net["lenses_kept"]:
                parts.append(f"{net['lenses_kept']} kept theirs, moved {net['k']:g} noise sds towards Malvar's")
        if filled:
            parts.append(f"{filled} flat ones took their own samples' means (Malvar's read a neighbouring lens)")
        if mixed:
            parts.append(f"{mixed} some colours of each")
        lines.append("safety net: " + "; ".join(parts))
    if summary.get("device"):
        lines.append("device: {name} ({type}) on {platform}".format(**summary["device"]))
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
