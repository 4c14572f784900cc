"""One parameter schema per stage of `lfcl process` (docs/stages.md, "Parameters").

Each stage's options are a frozen dataclass that checks itself: :class:`DecodeParameters`,
:class:`GridParameters`, :class:`DemosaicParameters`, :class:`OutputParameters`. Every field
declares, once, in ``dataclasses.field(metadata={"param": Param(...)})``: its default, its help
text, its type and range, its name in recipes and ``summary.json`` (``key``, e.g. ``lambda`` for
``lam``), its click spelling where that differs (``--lambda``, ``--format``), whether it is a recipe
key and whether ``--help`` hides it. From the schema derive:

* the click options of `lfcl process` and `lfcl batch` (lfcl/cli/commands/process.py);
* the recipe keys, their defaults and their checks (lfcl/pipeline/recipes.py: ``DEFAULTS``, ``_check``);
* the options every stage records in ``summary.json`` (each stage's ``options()``, lfcl/pipeline/stages.py);

so the command line and the Python pipeline cannot disagree. A bad value is a one-line
:class:`ParameterError` (a ``ValueError``) naming the field.

Not parameters: where a run happens (``--device``), what it writes to (``-o``), how it reports
(``--json``) and the ``--recipe`` that supplies defaults. Importable without numpy: the checks that
need it import it when they run.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
import os
from typing import Any, NamedTuple

from ..demosaic.names import DEFAULT_METHOD, FLAT_P, METHODS, STARTS, parse_method_spec

#: The aligned square grid's pitch when no lens grid is given (the Grid stage).
DEFAULT_PITCH = 9
DEFAULT_OUTPUTS = ("center", "mean", "lightfield")
DEFAULT_REFOCUS = "-1:1:0.25"
#: The output kinds and image formats (lfcl.outputs.files.KINDS, FORMATS; repeated here, without numpy,
#: for the click options; tests/test_outputs.py and tests/test_parameters.py check they agree).
OUTPUTS = ("center", "mean", "views", "views-each", "refocus", "lightfield", "depth")
FORMATS = ("exr", "tiff", "dng")
_SAME = object()  # Param.cli_default: the field's own default


class Bounds(NamedTuple):
    """A range of numbers: ``low`` / ``high`` (None: unbounded), open or closed."""

    low: float | None = None
    high: float | None = None
    low_open: bool = False
    high_open: bool = False

    def holds(self, x) -> bool:
        return ((self.low is None or (x > self.low if self.low_open else x >= self.low))
                and (self.high is None or (x < self.high if self.high_open else x <= self.high)))

    def words(self) -> str:
        parts = []
        if self.low is not None:
            parts.append(f"{'>' if self.low_open else '>='} {self.low:g}")
        if self.high is not None:
            parts.append(f"{'<' if self.high_open else '<='} {self.high:g}")
        return " and ".join(parts)


@dataclasses.dataclass(frozen=True)
class Param:
    """What one field of a stage's schema is (``dataclasses.field(metadata={"param": Param(...)})``).

    ``kind``: ``int``, ``float``, ``bool``, ``str``, ``"path"`` or ``"choice"`` (``choices``) are checked
    here (``bounds`` for numbers; None allowed where the default is None); None: the dataclass checks
    the field itself. ``key``: its name in recipes and ``summary.json`` (default: the field's).
    ``recipe``: its place among the recipe keys (the order recipes record them in), None: not a recipe key.
    ``recorded``: in the stage's ``options()`` (``summary.json``).

    The click option: ``flag`` (default ``--key`` with ``-`` for ``_``, ``--x/--no-x`` for a bool),
    ``cli_name`` (the click parameter name; default the field's), ``hidden``, ``metavar``,
    ``show_default`` (text shown when the default is None), ``cli_default`` (when it is not the field's:
    ``--refocus`` defaults to None, "not asked for"), ``cli_kind`` / ``cli_bounds`` / ``cli_scale``
    (the command line's unit: ``--max-memory`` takes GiB, the field bytes) and ``aliases`` (further
    options that set this field, e.g. ``--flat-p`` for ``skip_flat``; the command combines them).
    ``cli``: False for a field with no option (``auto_view`` follows ``--outputs``).
    """

    help: str
    kind: Any = None
    choices: tuple = ()
    bounds: Bounds | None = None
    key: str | None = None
    recipe: int | None = None
    recorded: bool = True
    cli: bool = True
    flag: str | None = None
    cli_name: str | None = None
    hidden: bool = False
    metavar: str | None = None
    show_default: str | None = None
    cli_default: Any = _SAME
    cli_kind: Any = None
    cli_bounds: Bounds | None = None
    cli_scale: float | None = None
    aliases: tuple = ()


def param(default, **facts) -> Any:
    """A schema field: ``default`` and the :class:`Param` ``facts``."""
    return dataclasses.field(default=default, metadata={"param": Param(**facts)})


class ParameterError(ValueError):
    """A bad value of one field: ``name`` (the field), ``key`` (its recipe / summary name), ``value``, ``why``
    (``must be ...``, as a recipe error says it); ``str()``: one line naming the field."""

    def __init__(self, name: str, key: str, value, why: str, message: str | None = None):
        self.name, self.key, self.value, self.why = name, key, value, why
        super().__init__(message or f"{name} {why}, got {value!r}")


class Entry(NamedTuple):
    """One field of a stage's schema, resolved: the stage's dataclass, the field's name, default and facts."""

    stage: type
    name: str
    default: Any
    param: Param

    @property
    def key(self) -> str:
        return self.param.key or self.name

    @property
    def cli_name(self) -> str:
        return self.param.cli_name or self.name

    @property
    def flag(self) -> str:
        if self.param.flag:
            return self.param.flag
        flag = "--" + self.key.replace("_", "-")
        return f"{flag}/--no-{flag[2:]}" if (self.param.cli_kind or self.param.kind) is bool else flag

    @property
    def cli_default(self):
        """The click default: the field's (a tuple as a comma list), or ``Param.cli_default``."""
        if self.param.cli_default is not _SAME:
            return self.param.cli_default
        return ",".join(self.default) if isinstance(self.default, tuple) else self.default

    def error(self, value, why: str, message: str | None = None) -> ParameterError:
        return ParameterError(self.name, self.key, value, why, message)

    def check(self, value):
        """``value`` checked against ``kind``/``choices``/``bounds`` and normalised (int, float); a
        :class:`ParameterError` otherwise. Fields of kind None come back as they are."""
        p = self.param
        if p.kind is None or (value is None and self.default is None):
            return value
        words = f" {p.bounds.words()}" if p.bounds else ""
        if p.kind is int:
            if isinstance(value, bool) or not isinstance(value, numbers.Integral) \
                    or (p.bounds and not p.bounds.holds(value)):
                raise self.error(value, f"must be an integer{words}")
            return int(value)
        if p.kind is float:
            if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(value) \
                    or (p.bounds and not p.bounds.holds(value)):
                raise self.error(value, f"must be a number{words}")
            return float(value)
        if p.kind is bool:
            if not isinstance(value, bool):
                raise self.error(value, "must be true or false")
            return value
        if p.kind is str:
            if not isinstance(value, str):
                raise self.error(value, "must be a string")
            return value
        if p.kind == "path":
            if not isinstance(value, (str, os.PathLike)):
                raise self.error(value, "must be a path")
            return value
        if p.kind == "choice":
            if not isinstance(value, str) or value not in p.choices:
                listed = ", ".join(p.choices)
                raise self.error(value, f"must be one of {listed}",
                                 f"unknown {self.name} {value!r}: expected one of {listed}")
            return value
        raise TypeError(f"{self.stage.__name__}.{self.name}: unknown kind {p.kind!r}")

    def record(self, value):
        """The value as ``summary.json`` and a recipe hold it: a list for a tuple, a str for a path."""
        if isinstance(value, tuple):
            return list(value)
        if self.param.kind == "path" and value is not None:
            return str(value)
        return value


class _Schema:
    """What every stage's dataclass does: check its fields (``Entry.check``, then ``_check``), record them."""

    def __post_init__(self):
        for entry in entries(type(self)):
            object.__setattr__(self, entry.name, entry.check(getattr(self, entry.name)))
        self._check()

    def _check(self) -> None:
        """The checks the schema's kinds do not express (a subclass's)."""

    def _set(self, name: str, value) -> None:
        object.__setattr__(self, name, value)

    def options(self) -> dict:
        """The recorded fields by ``key`` (a stage's ``options()``, part of ``summary.json``)."""
        return {e.key: e.record(getattr(self, e.name)) for e in entries(type(self)) if e.param.recorded}


@dataclasses.dataclass(frozen=True)
class DecodeParameters(_Schema):
    """The Decode stage: the Bayer pattern of an image mosaic."""

    pattern: str | None = param(None, kind=str,
                                help="Bayer pattern; required for EXR/TIFF/PNG mosaics, read from raws.")

    def _check(self):
        if self.pattern is not None:  # checked before the raw is read, and recorded as the name it is (RGGB, ...)
            from ..layout import parse_pattern

            (entry,) = (e for e in entries(DecodeParameters) if e.name == "pattern")
            try:
                self._set("pattern", parse_pattern(self.pattern))
            except ValueError as error:
                raise entry.error(self.pattern, "is no Bayer pattern", str(error)) from None


@dataclasses.dataclass(frozen=True)
class GridParameters(_Schema):
    """The Grid stage: at most one of ``pitch``, ``calibration``, ``white`` (none: ``pitch`` :data:`DEFAULT_PITCH`)."""

    pitch: int | None = param(
        None, kind=int, bounds=Bounds(2), show_default=str(DEFAULT_PITCH),
        help="Pixels per microlens of an aligned square grid starting at the sensor's first pixel "
             "(not with --calibration / --white).")
    calibration: str | os.PathLike | None = param(  # noqa: RUF009 (param returns a dataclasses.field)
        None, kind="path", metavar="CAL.json",
        help="Lens grid from `lfcl calibrate`. An aligned square grid of integer pitch is sliced exactly; "
             "a rotated, non-integer-pitch or hexagonal one is resampled inside the solver "
             "(docs/geometry.md; methods auto, malvar, admm-uv, admm-st, admm-uvst).")
    white: str | os.PathLike | None = param(  # noqa: RUF009
        None, kind="path", metavar="WHITE",
        help="Calibrate from this white image first (as `lfcl calibrate WHITE`), then as --calibration.")

    def _check(self):
        given = [e for e in entries(GridParameters) if getattr(self, e.name) is not None]
        if len(given) > 1:
            names = " and ".join(e.name for e in given)
            raise given[-1].error(getattr(self, given[-1].name), f"goes with no {given[0].name}",
                                  f"give the lens grid once, not {names} together")
        for e in given:
            if e.param.kind == "path" and not os.path.isfile(getattr(self, e.name)):
                value = getattr(self, e.name)
                raise e.error(value, "does not exist", f"{e.name} {str(value)!r} does not exist")


@dataclasses.dataclass(frozen=True)
class DemosaicParameters(_Schema):
    """The Demosaic stage (what each does: lfcl.pipeline.stages.Demosaic, docs/admm.md, docs/auto.md)."""

    method: str = param(
        DEFAULT_METHOD, recipe=1, metavar="METHOD[:START]",
        help=f"Demosaic/denoise method ({', '.join(METHODS)}), optionally with the ADMM methods' first "
             f"estimate START ({', '.join(STARTS)}), as admm-uv-xc:guarded. auto: chosen from the raw's noise "
             "level, judged on --outputs (center alone: the centre view; mean/refocus alone: the mean image; else "
             "both; docs/auto.md). START: malvar (the paper's, the default; admm-epi: its schedule's, guarded; "
             "with auto, the start its rule names), linear4d (the learned 4D filter; gains on textured and multi-plane scenes), lens-malvar "
             "(Malvar bounded to each lens; gains on the mean image) or guarded (linear4d, with Malvar in the "
             "lenses where it breaks: high-contrast edges, clipped highlights), docs/auto.md.")
    lam: float | None = param(
        None, kind=float, bounds=Bounds(0), key="lambda", recipe=3,
        help="TV weight; default: follows the noise level estimated from the raw (docs/admm.md).")
    iterations: int | None = param(
        None, kind=int, bounds=Bounds(1), recipe=4,
        help="Run exactly this many ADMM iterations (from the Malvar start the first leaves x as it is: z = D x, "
             "u = 0); default: the method's early-stopping rule.")
    strength: float = param(1.0, kind=float, bounds=Bounds(0, low_open=True), recipe=2,
                            help="Multiplier on the default lambda.")
    tolerance_db: float | None = param(
        None, kind=float, bounds=Bounds(0, low_open=True), metavar="DB",
        help="Stop the ADMM iterations once one can move PSNR by less than DB dB (docs/auto.md); "
             "default: the method's own stopping rule. With --iterations: at most that many.")
    max_memory: int | None = param(
        None, kind=int, bounds=Bounds(1), cli_kind=float, cli_bounds=Bounds(0.01), cli_scale=2**30, metavar="GIB",
        help="Device memory the solver may use, GiB; default 80% of the device's (admm-epi on a CPU "
             "device: at most 2). A larger admm-uv problem runs in bands of lens rows (the (u, v) prior couples no "
             "two lenses: with --iterations exactly the whole frame's result; with the default stop each band "
             "stops on its own), a larger admm-epi one in bands with a halo of lens rows.")
    skip_flat: bool | float | None = param(  # measured: off by default, so hidden
        None, cli_kind=bool, flag="--skip-flat/--solve-flat", hidden=True,
        help="Flat lenses (constant per colour within the noise: a chi-square test against the raw's "
             "noise model) get their colour means and leave the ADMM solve (admm-uv, admm-uv-xc, auto's "
             "picks; docs/auto.md). Default: solve every lens (the test took fine texture for noise).",
        aliases=(Param(kind=float, bounds=Bounds(0, 1, True, True), flag="--flat-p", cli_name="flat_p",
                       metavar="P", hidden=True,
                       help=f"A lens is flat when its chi-square p-value is above P (default {FLAT_P:g}); "
                            "implies --skip-flat."),))
    safety_net: bool = param(
        True, kind=bool,
        help="Keep every lens's colour means within the noise of Malvar's (lfcl/demosaic/safety_net.py; "
             "docs/auto.md), after every method but malvar and admm-epi (whose lens means, averaged along the "
             "epipolar lines, are its own).")
    auto_costly: bool = param(
        True, kind=bool, flag="--auto-costly/--auto-cheap", recipe=5,
        help="With auto: --auto-costly (the default) lets its rule pick admm-epi, several times the others' time, "
             "where its worst case on the training captures beats theirs by 1 dB; --auto-cheap keeps to the rule "
             "fitted without it (the methods of about admm-uv's time, never worse than Malvar on the training "
             "captures either; docs/auto.md). Recorded for auto only.")
    auto_view: str = param(
        "both", cli=False,
        help="With auto, the view its rule is judged on (lfcl.demosaic.auto.VIEWS); `lfcl process` passes "
             "lfcl.demosaic.auto.view_for_outputs of its outputs. Recorded for auto only.")

    @property
    def method_and_start(self) -> tuple[str, str | None]:
        """``method`` (``METHOD[:START]``) split: the method's name and its start or None (the method's)."""
        return parse_method_spec(self.method)

    def _check(self):
        try:
            method, _ = self.method_and_start
        except ValueError as e:
            raise _entry(DemosaicParameters, "method").error(
                self.method, f"must be one of {', '.join(METHODS)}, optionally METHOD:START with START one of "
                             f"{', '.join(STARTS)}", str(e)) from None
        if self.skip_flat is not None and self.skip_flat is not False:
            from ..demosaic.methods import flat_threshold_for

            try:  # auto passes it on to the method it picks, so check the value as for admm-uv
                flat_threshold_for("admm-uv" if method == "auto" else method, self.skip_flat)
            except ValueError as e:
                raise _entry(DemosaicParameters, "skip_flat").error(self.skip_flat, str(e), str(e)) from None
        from ..demosaic.auto import VIEWS, check_view

        try:
            check_view(self.auto_view)
        except (ValueError, TypeError) as e:
            raise _entry(DemosaicParameters, "auto_view").error(
                self.auto_view, f"must be one of {', '.join(VIEWS)}", str(e)) from None

    def options(self) -> dict:
        """As ``summary.json`` records them: ``method`` the name and ``start`` (None: the method's) apart, after
        ``max_memory``; ``auto_view`` and ``auto_costly`` for auto only."""
        method, start = self.method_and_start
        out: dict = {}
        for key, value in super().options().items():
            if key in ("auto_view", "auto_costly") and method != "auto":
                continue
            out[key] = method if key == "method" else value
            if key == "max_memory":
                out["start"] = start
        return out


@dataclasses.dataclass(frozen=True)
class OutputParameters(_Schema):
    """The Outputs stage: what is written, in which format (docs/outputs.md)."""

    outputs: tuple = param(
        DEFAULT_OUTPUTS, recipe=6, help=f"Comma-separated: {', '.join(OUTPUTS)}. Only these are computed.")
    refocus: str = param(
        DEFAULT_REFOCUS, recipe=7, cli_name="refocus_spec", cli_default=None, metavar="START:STOP:STEP|A,B,..",
        help=f"Refocus slopes (lenses per view step): a range, stop included when on the grid, or a "
             f"comma list. Implies the refocus output; refocus without it uses {DEFAULT_REFOCUS}.")
    fmt: str = param(
        "exr", key="format", choices=FORMATS, recipe=8,
        help="Images: EXR (float, scene-linear), TIFF (16-bit linear, clipped to [0, 1]) or DNG "
             "(LinearRaw for raw editors, with the raw's colour matrix and white balance; docs/darktable.md).")
    previews: bool = param(
        True, kind=bool, recipe=9,
        help="Also write an 8-bit sRGB PNG of every image (white balance and colour matrix from the raw).")

    def _check(self):
        from ..outputs.files import parse_format, parse_outputs
        from ..outputs.refocus import parse_slopes

        outputs = self.outputs
        if not isinstance(outputs, str):
            try:
                names = list(outputs)
            except TypeError:
                names = None
            if names is None or not all(isinstance(n, str) for n in names):
                raise _entry(OutputParameters, "outputs").error(
                    outputs, "must be a list of output names or a comma-separated string")
            outputs = ",".join(names)
        try:
            self._set("outputs", tuple(parse_outputs(outputs)))
        except ValueError as e:
            raise _entry(OutputParameters, "outputs").error(self.outputs, str(e), str(e)) from None
        refocus = _entry(OutputParameters, "refocus")
        if not isinstance(self.refocus, str):
            raise refocus.error(self.refocus, "must be a string like '-1:1:0.25' or '-0.5,0,0.5'")
        try:
            parse_slopes(self.refocus)
        except ValueError as e:
            raise refocus.error(self.refocus, str(e), str(e)) from None
        fmt, why = _entry(OutputParameters, "fmt"), f"must be {', '.join(FORMATS[:-1])} or {FORMATS[-1]}"
        if not isinstance(self.fmt, str):
            raise fmt.error(self.fmt, why)
        try:
            self._set("fmt", parse_format(self.fmt))
        except ValueError as e:
            raise fmt.error(self.fmt, why, str(e)) from None


#: The stages' schemas, in the pipeline's order.
STAGES = (DecodeParameters, GridParameters, DemosaicParameters, OutputParameters)


def entries(stage: type | None = None) -> tuple[Entry, ...]:
    """The fields of one stage's schema (``stage``), or of every stage's, in order."""
    stages = STAGES if stage is None else (stage,)
    return tuple(Entry(s, f.name, f.default, f.metadata["param"]) for s in stages for f in dataclasses.fields(s))


def _entry(stage: type, name: str) -> Entry:
    return next(e for e in entries(stage) if e.name == name)


def defaults(stage: type) -> dict:
    """A stage's defaults by field name (without building the dataclass: no checks, no imports)."""
    return {e.name: e.default for e in entries(stage)}


def recipe_entries() -> tuple[Entry, ...]:
    """The fields that are recipe keys, in the order recipes record them."""
    return tuple(sorted((e for e in entries() if e.param.recipe is not None), key=lambda e: e.param.recipe))


def recipe_defaults() -> dict:
    """Recipe key -> its default, as a loaded recipe holds it (lfcl.pipeline.recipes.DEFAULTS)."""
    return {e.key: e.record(e.default) for e in recipe_entries()}


def recipe_values(values: dict) -> dict:
    """Recipe key -> value (every key of :func:`recipe_defaults`) checked by the stages' schemas and
    normalised as a loaded recipe holds them; a :class:`ParameterError` (with the ``key``) otherwise."""
    by_stage: dict = {}
    for e in recipe_entries():
        by_stage.setdefault(e.stage, {})[e.name] = values[e.key]
    built = {stage: stage(**fields) for stage, fields in by_stage.items()}
    return {e.key: e.record(getattr(built[e.stage], e.name)) for e in recipe_entries()}
