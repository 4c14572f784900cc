"""lfcl.pipeline.parameters: one schema per stage, from which the click options of `lfcl process` / `lfcl batch`,
the recipe keys and the options in summary.json derive (docs/stages.md, "Parameters")."""

from __future__ import annotations

import dataclasses
import json

import pytest
from click.testing import CliRunner

from lfcl.cli import cli
from lfcl.cli.commands import PROCESS_SECTIONS
from lfcl.cli.commands import batch as batch_command
from lfcl.cli.commands import process as process_command
from lfcl.demosaic.names import DEFAULT_METHOD
from lfcl.pipeline import parameters as P
from lfcl.pipeline.recipes import DEFAULTS, load_recipe, pipeline_from_recipe
from lfcl.pipeline.stages import Decode, Demosaic, Grid, Outputs, Pipeline

#: The options of `lfcl process` that are not stage parameters: the raw, where the files go, how the run
#: reports, the recipe that supplies defaults, and where it runs (shared with every command; not recorded).
NOT_PARAMETERS = {"raw", "out_dir", "as_json", "pipeline", "device"}
#: `lfcl batch`'s own, besides those (its INPUTS instead of RAW).
BATCH_ONLY = {"inputs", "scheduler", "workers", "resume"}
#: How a message names a field in words, where not by its name.
IN_WORDS = {"auto_view": "auto's view"}


def click_params(command) -> dict:
    return {p.name: p for p in command.params}


def schema_cli_names() -> dict:
    """click parameter name -> (entry, the Param of the option: the field's or an alias's)."""
    out = {}
    for e in P.entries():
        if e.param.cli:
            out[e.cli_name] = (e, e.param)
            out.update({a.cli_name: (e, a) for a in e.param.aliases})
    return out


@pytest.mark.parametrize("command, own", [(process_command.command, NOT_PARAMETERS),
                                          (batch_command.command, NOT_PARAMETERS - {"raw"} | BATCH_ONLY)])
def test_every_click_option_is_a_schema_field_and_back(command, own):
    params, schema = click_params(command), schema_cli_names()
    assert set(params) == set(schema) | own  # nothing missing, nothing extra
    for name, (entry, param) in schema.items():
        option = params[name]
        flag = entry.flag if param is entry.param else param.flag
        assert option.opts + option.secondary_opts == flag.replace("/", " ").split(), name
        assert option.hidden == param.hidden and option.help == param.help, name
    placed = {n for names in PROCESS_SECTIONS.values() for n in names}
    assert {n for n, p in params.items() if not getattr(p, "hidden", False)} - placed <= {"raw"} | BATCH_ONLY


def test_the_options_keep_their_spellings():
    """The command line as users type it (written out here, not derived)."""
    flags = {n: p.opts + p.secondary_opts for n, p in click_params(process_command.command).items()}
    assert flags["lam"] == ["--lambda"] and flags["fmt"] == ["--format"] and flags["refocus_spec"] == ["--refocus"]
    assert flags["tolerance_db"] == ["--tolerance-db"] and flags["max_memory"] == ["--max-memory"]
    assert flags["skip_flat"] == ["--skip-flat", "--solve-flat"] and flags["flat_p"] == ["--flat-p"]
    assert flags["safety_net"] == ["--safety-net", "--no-safety-net"]
    assert flags["previews"] == ["--previews", "--no-previews"]
    hidden = {p.name for p in process_command.command.params if getattr(p, "hidden", False)}
    assert hidden == {"skip_flat", "flat_p"}
    # a method and its ADMM start are one option, --method METHOD[:START]: no --start
    assert flags["method"] == ["--method"] and "start" not in flags
    for command in (process_command.command, batch_command.command):
        assert not [p for p in command.params if "--start" in p.opts + p.secondary_opts], command.name


def test_a_method_and_its_start_are_one_spelling(tmp_path):
    """``METHOD[:START]`` on the command line, in a recipe and in the Demosaic stage; the stage keeps them apart,
    its options record the method's name as ``method`` and the start as ``start``."""
    result = CliRunner().invoke(cli, ["process", "raw.dng", "-o", str(tmp_path / "out"), "--start", "guarded"])
    assert result.exit_code == 2 and "No such option '--start'" in result.output
    stage = Demosaic("admm-uv-xc:guarded")
    assert (stage.method, stage.start) == ("admm-uv-xc", "guarded")
    assert (stage.options()["method"], stage.options()["start"]) == ("admm-uv-xc", "guarded")
    plain = Demosaic("admm-uv-xc")
    assert (plain.method, plain.start, plain.options()["start"]) == ("admm-uv-xc", None, None)
    with pytest.raises(TypeError, match="start"):
        Demosaic("admm-uv-xc", start="guarded")
    with pytest.raises(ValueError, match="^Demosaic: unknown start 'nearest' .*lens-malvar, guarded$"):
        Demosaic("admm-uv:nearest")
    recipe = tmp_path / "guarded.toml"
    recipe.write_text('method = "admm-uv-xc:guarded"\n')
    assert load_recipe(recipe)["method"] == "admm-uv-xc:guarded"
    from_recipe = pipeline_from_recipe(recipe).options()
    assert (from_recipe["method"], from_recipe["start"]) == ("admm-uv-xc", "guarded")
    ctx = process_command.command.make_context("process", ["raw.dng", "-o", "out", "--method", "admm-uv-xc:guarded"])
    settings = process_command.settings_from_options(ctx.params, ctx)
    assert (settings.method, settings.start) == ("admm-uv-xc", "guarded")
    assert settings.pipeline().options() == from_recipe
    recipe.write_text('method = "admm-uv:nearest"\n')
    with pytest.raises(ValueError, match="guarded.toml: method = 'admm-uv:nearest': must be one of auto, .*guarded$"):
        load_recipe(recipe)
    with pytest.raises(ValueError, match="unknown option 'start'"):
        pipeline_from_recipe("default", start="guarded")
    # a recipe given as a dict is checked as a file is: a misspelt key is refused, not left to its default
    with pytest.raises(ValueError, match="recipe given as a dict: unknown key 'metod'"):
        pipeline_from_recipe({"metod": "malvar"})
    with pytest.raises(ValueError, match="method = 'bogus'"):
        pipeline_from_recipe({"method": "bogus"})
    assert pipeline_from_recipe({"method": "malvar"}).options()["method"] == "malvar"
    with pytest.raises(ValueError, match="give 'lam' or 'lambda', not both"):  # one value per option
        pipeline_from_recipe("default", lam=0.1, **{"lambda": 0.2})


def test_every_recipe_key_is_a_schema_field_and_a_click_option():
    keys = {e.key: e for e in P.recipe_entries()}
    assert list(DEFAULTS) == ["description", "method", "strength", "lambda", "iterations", "auto_costly", "outputs",
                              "refocus", "format", "previews"]  # the order recipes record them in (summary.json)
    assert set(DEFAULTS) - {"description"} == set(keys)
    params = click_params(process_command.command)
    assert {e.cli_name: e.key for e in keys.values()} == process_command.RECIPE_KEYS
    for key, entry in keys.items():
        assert entry.cli_name in params, key
        assert entry.flag.split("/")[0] in params["pipeline"].help, key  # --recipe lists what it supplies


def test_defaults_agree_click_recipe_dataclass():
    # the recipe defaults, as they were written out before the schema
    assert DEFAULTS == {"description": "", "method": DEFAULT_METHOD, "strength": 1.0, "lambda": None,
                        "iterations": None, "auto_costly": True, "outputs": ["center", "mean", "lightfield"],
                        "refocus": "-1:1:0.25",
                        "format": "exr", "previews": True}
    default_toml = load_recipe("default")
    assert {k: default_toml[k] for k in DEFAULTS if k != "description"} == {k: v for k, v in DEFAULTS.items()
                                                                          if k != "description"}
    params = click_params(process_command.command)
    for e in P.entries():
        as_recipe = e.record(e.default)
        if e.param.recipe is not None:
            assert DEFAULTS[e.key] == as_recipe, e.key
        if not e.param.cli:
            continue
        click_default = params[e.cli_name].default
        if e.name == "refocus":  # None: refocus not asked for; with it the slopes default to the field's
            assert click_default is None and e.default == process_command.DEFAULT_REFOCUS
        elif e.name == "outputs":
            assert click_default.split(",") == as_recipe
        else:
            assert click_default == e.default, e.name
    # what `lfcl process` with no options builds = the stages' defaults = the default recipe's pipeline
    ctx = process_command.command.make_context("process", ["raw.dng", "-o", "out"])
    settings = process_command.settings_from_options(ctx.params, ctx)
    cli_options = settings.pipeline().options()
    assert cli_options == Pipeline([Decode(), Grid(), Demosaic(auto_view="both"), Outputs()]).options()
    assert cli_options == pipeline_from_recipe("default").options()
    assert cli_options["strength"] == 1.0 and cli_options["safety_net"] is True and cli_options["pitch"] is None
    assert cli_options["auto_costly"] is True
    assert settings == process_command.ProcessSettings(method="auto", outputs=("center", "mean", "lightfield"), fmt="exr",
                                                       previews=True, strength=1.0, safety_net=True)


@pytest.mark.parametrize("schema, values, name", [
    (P.DecodeParameters, {"pattern": 4}, "pattern"),
    (P.GridParameters, {"pitch": 1}, "pitch"),
    (P.GridParameters, {"pitch": 9.0}, "pitch"),
    (P.GridParameters, {"calibration": "no/such/cal.json"}, "calibration"),
    (P.DemosaicParameters, {"method": "bilinear"}, "method"),
    (P.DemosaicParameters, {"lam": -0.1}, "lam"),
    (P.DemosaicParameters, {"iterations": True}, "iterations"),
    (P.DemosaicParameters, {"strength": float("inf")}, "strength"),
    (P.DemosaicParameters, {"tolerance_db": 0}, "tolerance_db"),
    (P.DemosaicParameters, {"max_memory": 0}, "max_memory"),
    (P.DemosaicParameters, {"method": "admm-uv:bilinear"}, "method"),  # METHOD[:START]: the start is the method's
    (P.DemosaicParameters, {"skip_flat": 2.0}, "skip_flat"),
    (P.DemosaicParameters, {"safety_net": "yes"}, "safety_net"),
    (P.DemosaicParameters, {"auto_view": "left"}, "auto_view"),
    (P.OutputParameters, {"outputs": "center,thumbnail"}, "outputs"),
    (P.OutputParameters, {"refocus": "1:2:0"}, "refocus"),
    (P.OutputParameters, {"fmt": "jpeg"}, "fmt"),
    (P.OutputParameters, {"previews": 1}, "previews"),
])
def test_a_bad_value_is_one_line_naming_the_field(schema, values, name):
    with pytest.raises(ValueError) as info:
        schema(**values)
    assert isinstance(info.value, P.ParameterError) and info.value.name == name
    text = str(info.value)
    assert "\n" not in text and (IN_WORDS.get(name, name) in text or info.value.key in text), text


def test_every_field_refuses_a_value_of_no_kind():
    for e in P.entries():
        with pytest.raises(P.ParameterError) as info:
            e.stage(**{e.name: object()})
        assert info.value.name == e.name and IN_WORDS.get(e.name, e.name) in str(info.value), e.name


def test_checked_values_are_normalised():
    p = P.DemosaicParameters(lam=1, strength=2, tolerance_db=1, max_memory=2**30)
    assert (p.lam, p.strength, p.tolerance_db) == (1.0, 2.0, 1.0) and isinstance(p.lam, float)
    o = P.OutputParameters(outputs=["mean", "center", "mean"], fmt="TIF")
    assert o.outputs == ("mean", "center") and o.fmt == "tiff"
    assert o.options() == {"outputs": ["mean", "center"], "refocus": "-1:1:0.25", "format": "tiff", "previews": True}
    with pytest.raises(dataclasses.FrozenInstanceError):
        p.strength = 3.0


@pytest.mark.parametrize("key", [e.key for e in P.recipe_entries()])
def test_a_bad_recipe_value_names_its_key(tmp_path, key):
    path = tmp_path / "bad.toml"
    path.write_text(f"{key} = {{ a = 1 }}\n")  # a TOML table: no key takes one
    with pytest.raises(ValueError, match=f"recipe .*bad.toml: {key} = "):
        load_recipe(path)


@pytest.fixture(scope="module")
def capture(tmp_path_factory):
    from lfcl.sim import simulate, write_capture

    out = tmp_path_factory.mktemp("parameters") / "capture"
    write_capture(simulate("deadleaves", lenses=(8, 10), lux=4, seed=5), out)
    return out / "raw.dng"


def run_cli(capture, out, *args) -> dict:
    result = CliRunner().invoke(cli, ["process", str(capture), "-o", str(out), "--json", *args])
    assert result.exit_code == 0, result.output
    return json.loads((out / "summary.json").read_text())


def test_a_recipe_run_and_a_cli_run_record_the_same_options(capture, tmp_path):
    cli_summary = run_cli(capture, tmp_path / "cli", "--recipe", "preview", "--format", "tiff", "--no-previews",
                          "--tolerance-db", "0.5", "--max-memory", "1", "--pitch", "9", "--no-safety-net")
    py_summary = pipeline_from_recipe("preview", fmt="tiff", previews=False, tolerance_db=0.5, max_memory=2**30,
                                      pitch=9, safety_net=False).run(capture, tmp_path / "py")
    expected = {"pattern": None, "pitch": 9, "calibration": None, "white": None, "method": "malvar", "lambda": None,
                "iterations": None, "strength": 1.0, "tolerance_db": 0.5, "max_memory": 2**30, "start": None,
                "skip_flat": None, "safety_net": False, "outputs": ["center"], "refocus": "-1:1:0.25",
                "format": "tiff", "previews": False}
    assert cli_summary["options"] == py_summary["options"] == expected
    assert list(cli_summary["options"]) == list(py_summary["options"]) == list(expected)
    assert (tmp_path / "cli" / "center.tif").read_bytes() != b""
    assert sorted(p.name for p in (tmp_path / "cli").iterdir()) == ["center.tif", "summary.json"]
    assert sorted(p.name for p in (tmp_path / "py").iterdir()) == ["center.tif", "summary.json"]
    # what the CLI records of its recipe: the recipe keys, in the recipe order
    assert list(cli_summary["recipe"]["options"]) == [k for k in DEFAULTS if k != "description"]
    assert cli_summary["recipe"]["from_command_line"] == ["format", "previews"]
