"""lfcl.pipeline.stages / lfcl.pipeline.recipes and `lfcl process --recipe` (docs/stages.md)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from lfcl.cli import cli
from lfcl.pipeline.recipes import DEFAULTS, PACKAGED, load_recipe, pipeline_from_recipe
from lfcl.pipeline.stages import Decode, Demosaic, Demosaiced, Grid, Gridded, Outputs, Pipeline


@pytest.fixture(scope="module")
def capture(tmp_path_factory):
    from lfcl.sim import simulate, write_capture

    out = tmp_path_factory.mktemp("stages") / "capture"
    write_capture(simulate("deadleaves", lenses=(12, 14), lux=4, seed=3), out)
    return out / "raw.dng"


def expected_files(recipe: dict) -> set:
    ext = {"exr": ".exr", "tiff": ".tif"}[recipe["format"]]
    names = {"summary.json"}
    for kind in recipe["outputs"]:
        if kind == "lightfield":
            names.add("lightfield.npy")
        else:
            assert kind in ("center", "mean", "views")  # what the packaged recipes use
            names.add(kind + ext)
            if recipe["previews"]:
                names.add(kind + ".png")
    return names


@pytest.mark.parametrize("name", PACKAGED)
def test_each_packaged_recipe_writes_its_outputs(name, capture, tmp_path):
    recipe = load_recipe(name)
    out = tmp_path / name
    summary = pipeline_from_recipe(recipe).run(capture, out)
    assert {p.name for p in out.iterdir()} == expected_files(recipe)
    assert summary["method"] == recipe["method"]
    assert summary["recipe"]["name"] == name
    assert summary["options"]["strength"] == recipe["strength"]
    assert summary["options"]["outputs"] == recipe["outputs"]
    ran = summary["parameters"].get("auto", {}).get("method", summary["method"])
    # admm-epi's disparity is timed apart from the rest of the demosaic stage
    assert set(summary["seconds"]) == {"decode", "grid", "demosaic", "outputs"} | ({"disparity"} if ran == "admm-epi"
                                                                                   else set())
    assert json.loads((out / "summary.json").read_text())["options"] == summary["options"]
    assert summary["lenses"] == [12, 14]


def test_recipes_by_name_and_path(tmp_path):
    assert load_recipe("preview")["method"] == "malvar"
    assert load_recipe("lowlight")["method"] == "admm-epi" and "views" in load_recipe("lowlight")["outputs"]
    assert load_recipe("default")["outputs"] == ["center", "mean", "lightfield"]
    path = tmp_path / "mine.toml"
    path.write_text('method = "admm-st"\noutputs = "center,refocus"\nrefocus = "-0.5,0.5"\niterations = 3\n')
    recipe = load_recipe(path)
    assert recipe["method"] == "admm-st" and recipe["outputs"] == ["center", "refocus"]
    assert recipe["iterations"] == 3 and recipe["name"] == "mine"
    assert recipe["strength"] == DEFAULTS["strength"] and recipe["lambda"] is None  # defaults filled in
    assert load_recipe(str(path)) == recipe
    assert recipe["auto_costly"] is True
    path.write_text("auto_costly = false\n")  # auto without its costly methods, as --auto-cheap
    assert pipeline_from_recipe(load_recipe(path)).options()["auto_costly"] is False


@pytest.mark.parametrize("text, word", [
    ('methd = "malvar"', "methd"),
    ('method = "bilinear"', "method"),
    ("strength = 0", "strength"),
    ('strength = "2"', "strength"),
    ("iterations = 1.5", "iterations"),
    ("iterations = 0", "iterations"),
    ("lambda = -1", "lambda"),
    ('outputs = ["center", "thumbnail"]', "thumbnail"),
    ('format = "jpeg"', "format"),
    ('previews = "yes"', "previews"),
    ('auto_costly = "no"', "auto_costly"),
    ('refocus = "x:y"', "refocus"),
    ("method = ", "TOML"),
])
def test_bad_recipes_are_rejected(tmp_path, text, word):
    path = tmp_path / "bad.toml"
    path.write_text(text + "\n")
    with pytest.raises(ValueError, match=word):
        load_recipe(path)


def test_unknown_recipe_name_and_missing_file():
    with pytest.raises(ValueError, match="unknown recipe 'nope'.*default"):
        load_recipe("nope")
    with pytest.raises(ValueError, match="does not exist"):
        load_recipe("no/such/recipe.toml")
    with pytest.raises(ValueError, match="unknown option 'speed'"):
        pipeline_from_recipe("default", speed=3)
    with pytest.raises(ValueError, match="strength"):
        pipeline_from_recipe("default", strength=-1)


def test_stage_contracts(capture, tmp_path):
    with pytest.raises(ValueError, match="Decode takes a path"):
        Decode()(42)
    with pytest.raises(ValueError, match="does not exist"):
        Decode()(tmp_path / "missing.dng")
    with pytest.raises(ValueError, match="Grid takes a Mosaic"):
        Grid()(np.zeros((18, 18)))
    with pytest.raises(ValueError, match="pitch and white"):
        Grid(pitch=9, white=capture)
    with pytest.raises(ValueError, match="pitch must be an integer"):
        Grid(pitch=1)
    with pytest.raises(ValueError, match="calibration"):
        Grid(calibration=tmp_path / "none.json")
    with pytest.raises(ValueError, match="Demosaic takes a Gridded"):
        Demosaic()("raw.dng")
    with pytest.raises(ValueError, match="unknown method"):
        Demosaic("bilinear")
    with pytest.raises(ValueError, match="strength"):
        Demosaic(strength=0)
    with pytest.raises(ValueError, match="iterations"):
        Demosaic(iterations=0)
    with pytest.raises(ValueError, match="Outputs: unknown outputs"):
        Outputs(outputs=("center", "thumbnail"))
    with pytest.raises(ValueError, match="Outputs: unknown --format"):
        Outputs(fmt="jpeg")
    with pytest.raises(ValueError, match="Outputs takes a Demosaiced"):
        Outputs()(np.zeros((2, 2, 3, 3, 3)), tmp_path)
    with pytest.raises(ValueError, match="in that order"):
        Pipeline([Grid(), Decode(), Demosaic()])
    with pytest.raises(ValueError, match="callback must be callable"):
        Demosaic("admm-uv", callback=3)
    with pytest.raises(ValueError, match="metadata must be a dict"):
        Outputs(["center"], metadata=[1, 2])
    with pytest.raises(ValueError, match="metadata must be plain JSON data"):
        Outputs(["center"], metadata={"x": object()})

    # the stages one by one: what each returns
    mosaic = Decode()(capture)
    gridded = Grid(pitch=9)(mosaic)
    assert isinstance(gridded, Gridded) and gridded.pitch == 9 and gridded.origin == (0, 0)
    assert gridded.data.shape == (12 * 9, 14 * 9) and gridded.lens_response is None
    assert gridded.metadata["geometry"]["from"] == "--pitch"
    demosaiced = Demosaic("malvar")(gridded)
    assert isinstance(demosaiced, Demosaiced) and demosaiced.lightfield.shape == (12, 14, 9, 9, 3)
    with pytest.raises(ValueError, match="takes an lfcl.depth.DisparityMap as its disparity"):
        Demosaic("malvar")(gridded, disparity=np.zeros((12, 14)))
    with pytest.raises(ValueError, match="output folder"):
        Outputs()(demosaiced, None)
    written = Outputs(outputs=["lightfield"], previews=False)(demosaiced, tmp_path / "one")
    assert [p.name for p in written.paths] == ["lightfield.npy"]
    np.testing.assert_array_equal(np.load(tmp_path / "one" / "lightfield.npy"), demosaiced.lightfield)


def test_the_depth_output_runs_on_the_demosaic_stages_device(capture, tmp_path, monkeypatch):
    # `--device cpu` on a machine whose default is a GPU must keep the depth output's kernels off that GPU too
    import lfcl.depth.estimate as estimate

    real, seen = estimate.estimate_disparity, []

    def spy(*args, device=None, **kwargs):
        seen.append(device)
        return real(*args, device=device, **kwargs)

    monkeypatch.setattr(estimate, "estimate_disparity", spy)
    mosaic = Decode()(capture)
    demosaiced = Demosaic("malvar", device="cpu")(Grid(pitch=9)(mosaic))
    assert demosaiced.device == "cpu"
    written = Outputs(outputs=["depth"], previews=False)(demosaiced, tmp_path / "d")
    assert seen == ["cpu"] and "depth.exr" in [p.name for p in written.paths]

    seen.clear()
    result = CliRunner().invoke(cli, ["process", str(capture), "--method", "malvar", "--device", "cpu", "--outputs",
                                      "depth", "--no-previews", "-o", str(tmp_path / "e"), "--json"])
    assert result.exit_code == 0, result.output
    assert seen == ["cpu"]


def test_admm_epi_takes_the_depth_outputs_disparity_instead_of_estimating_its_own(capture, tmp_path, monkeypatch):
    import lfcl.depth
    import lfcl.depth.estimate as estimate
    from lfcl.io.images import read_image

    real, steps = estimate.estimate_disparity, []

    def spy(*args, **kwargs):
        steps.append(kwargs.get("step", estimate.DEFAULTS["step"]))
        return real(*args, **kwargs)

    monkeypatch.setattr(estimate, "estimate_disparity", spy)  # the depth output's import
    monkeypatch.setattr(lfcl.depth, "estimate_disparity", spy)  # admm-epi's
    runs = {}
    for name, outputs in (("alone", "center"), ("with_depth", "center,depth")):
        steps.clear()
        result = CliRunner().invoke(cli, ["process", str(capture), "--method", "admm-epi", "--outputs", outputs,
                                          "--no-previews", "-o", str(tmp_path / name), "--json"])
        assert result.exit_code == 0, result.output
        runs[name] = (json.loads(result.output), list(steps))
    alone, with_depth = runs["alone"], runs["with_depth"]
    assert len(alone[1]) == 1 and alone[1][0] != estimate.DEFAULTS["step"]  # admm-epi's own, coarser candidates
    assert with_depth[1] == [estimate.DEFAULTS["step"]]  # one estimate in the run: the depth output's
    assert alone[0]["parameters"]["disparity"]["source"] == "estimated for admm-epi"
    used = with_depth[0]["parameters"]["disparity"]
    assert used["source"] == "given (the depth output's estimate)" and used["step"] == estimate.DEFAULTS["step"]
    written = read_image(tmp_path / "with_depth" / "depth.exr")[..., 0]
    assert float(written.min()) == used["min"] and float(written.max()) == used["max"]  # the map the solve used
    assert "disparity" in alone[0]["seconds"] and "disparity" not in with_depth[0]["seconds"]


def test_depth_on_a_resampled_grid_is_refused_before_the_demosaic(tmp_path, monkeypatch):
    from lfcl.sim import write_capture
    from lfcl.sim.capture import simulate_grid

    out = tmp_path / "hex"
    write_capture(simulate_grid("charts", "hex", 9.4, 0.7, (0.3, -0.2), lenses=(10, 10), lux=12, seed=0), out)
    import lfcl.demosaic.driver as driver

    def never(*args, **kwargs):
        raise AssertionError("the demosaic ran")

    monkeypatch.setattr(driver, "demosaic_grid", never)
    result = CliRunner().invoke(cli, ["process", str(out / "raw.dng"), "--white", str(out / "white.dng"),
                                      "--outputs", "center,depth", "-o", str(tmp_path / "o")])
    assert result.exit_code == 1 and "the depth output needs an aligned square lens grid" in result.output
    assert not (tmp_path / "o").exists()


def test_process_pipeline_preview_and_explicit_options_win(capture, tmp_path):
    out = tmp_path / "p"
    result = CliRunner().invoke(cli, ["process", str(capture), "--recipe", "preview", "-o", str(out), "--json"])
    assert result.exit_code == 0, result.output
    summary = json.loads(result.output)
    assert summary["method"] == "malvar" and summary["recipe"]["name"] == "preview"
    assert sorted(p.name for p in out.iterdir()) == ["center.exr", "center.png", "summary.json"]

    out2 = tmp_path / "q"
    result = CliRunner().invoke(cli, ["process", str(capture), "--recipe", "preview", "--method", "admm-uv",
                                      "--iterations", "2", "-o", str(out2), "--json"])
    assert result.exit_code == 0, result.output
    summary = json.loads(result.output)
    assert summary["method"] == "admm-uv" and summary["iterations"] == 2
    assert summary["recipe"]["from_command_line"] == ["iterations", "method"]
    assert sorted(p.name for p in out2.iterdir()) == ["center.exr", "center.png", "summary.json"]  # from the recipe

    result = CliRunner().invoke(cli, ["process", str(capture), "--recipe", "nope", "-o", str(tmp_path / "r")])
    assert result.exit_code != 0 and "unknown recipe 'nope'" in result.output


def test_process_pipeline_by_path(capture, tmp_path):
    path = tmp_path / "r.toml"
    path.write_text('method = "malvar"\noutputs = ["lightfield"]\n')
    out = tmp_path / "out"
    result = CliRunner().invoke(cli, ["process", str(capture), "--recipe", str(path), "-o", str(out), "--json"])
    assert result.exit_code == 0, result.output
    assert sorted(p.name for p in out.iterdir()) == ["lightfield.npy", "summary.json"]


@pytest.mark.parametrize("recipe", ["lowlight", "preview"])
def test_pipeline_equals_process(recipe, capture, tmp_path):
    summary = pipeline_from_recipe(recipe, outputs=["lightfield"], iterations=3).run(capture, tmp_path / "stages")
    result = CliRunner().invoke(cli, ["process", str(capture), "--recipe", recipe, "--outputs", "lightfield",
                                      "--iterations", "3", "-o", str(tmp_path / "cli"), "--json"])
    assert result.exit_code == 0, result.output
    cli_summary = json.loads(result.output)
    assert (tmp_path / "stages" / "lightfield.npy").read_bytes() == (tmp_path / "cli" / "lightfield.npy").read_bytes()
    assert summary["parameters"] == cli_summary["parameters"]
    assert summary["iterations"] == cli_summary["iterations"]


def test_demosaic_refuses_an_unknown_grid_kind_and_finish_edits_the_summary(capture, tmp_path):
    gridded = Grid(pitch=9)(Decode()(capture))
    assert gridded.metadata["geometry"]["grid"] == "aligned-square" and gridded.seconds == {}
    hexagonal = gridded._replace(metadata={**gridded.metadata,
                                           "geometry": {**gridded.metadata["geometry"], "grid": "hexagonal"}})
    with pytest.raises(ValueError, match="lens grid 'hexagonal'"):
        Demosaic("malvar")(hexagonal)

    def finish(summary):
        summary["note"] = "edited"
        return summary

    pipeline = Pipeline([Decode(), Grid(pitch=9), Demosaic("malvar"), Outputs(["center"], previews=False)])
    summary = pipeline.run(capture, tmp_path / "out", finish=finish)
    assert summary["note"] == "edited" and json.loads((tmp_path / "out" / "summary.json").read_text()) == summary
    assert summary["outputs"] == ["center.exr"] and summary["options"]["max_memory"] is None
    with pytest.raises(ValueError, match="finish must return the summary"):  # it would be summary.json: null
        pipeline.run(capture, tmp_path / "none", finish=lambda summary: None)
    assert not (tmp_path / "none").exists()


def test_a_recipe_run_judges_auto_on_its_outputs_as_process_does(capture, tmp_path):
    summary = pipeline_from_recipe("default", outputs=["center"]).run(capture, tmp_path / "stages")
    result = CliRunner().invoke(cli, ["process", str(capture), "--recipe", "default", "--outputs", "center",
                                      "-o", str(tmp_path / "cli"), "--json"])
    assert result.exit_code == 0, result.output
    cli_summary = json.loads(result.output)
    assert summary["method"] == cli_summary["method"] == "auto"
    assert summary["options"]["auto_view"] == cli_summary["options"]["auto_view"] == "center"
    assert summary["parameters"]["auto"]["view"] == cli_summary["parameters"]["auto"]["view"] == "center"
    assert (tmp_path / "stages" / "center.exr").is_file()
